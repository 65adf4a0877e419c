"""The capability-envelope section of a campaign's report (docs/scoring.md, "Capability
envelopes"): :func:`has_envelope` says whether a results table calls for it (more than
one aggressiveness level, or controlled-series rows), :func:`envelope_tables` computes
its tables from :mod:`ft_sitl.missions.envelope`, :func:`envelope_figures` lists its
figures (name, caption, maker) for the report to render, and :func:`markdown` writes the
tables as Markdown for summary.md and docs/results/envelope.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pandas as pd

from ft_sitl import markdown as md
from ft_sitl.missions import envelope as env

#: the per-row metrics summarised per algorithm, level and sample
ROW_METRICS = ("tilt_ratio", "saturation_fraction", "tracking_rms_m", "time_ratio")


@dataclass
class EnvelopeTables:
    fits: pd.DataFrame
    dose: pd.DataFrame
    thresholds: pd.DataFrame
    tolerance: pd.DataFrame
    rows: pd.DataFrame  # per-row metrics summarised per algorithm, level and sample


def has_envelope(df: pd.DataFrame) -> bool:
    """More than one aggressiveness level, or rows of the controlled series."""
    levels = set(env.with_levels(df)[env.LEVEL_COLUMN]) if env.LEVEL_COLUMN in df else set()
    series = (df["platform_category"].astype(str) == env.SERIES_CATEGORY).any() \
        if "platform_category" in df else False
    return len(levels) > 1 or bool(series)


def envelope_tables(df: pd.DataFrame, *, n_boot: int = env.N_BOOT, seed: int = 0,
                    bounds: pd.Series | None = None) -> EnvelopeTables:
    """Every table of the section (``bounds``: each row's time-optimal bound, from
    :func:`ft_sitl.missions.envelope.time_bounds`, when the caller computed them)."""
    d = env.with_levels(df)
    m = env.row_metrics(d, None if bounds is None else bounds.reindex(d.index))
    if "tracking_rms_m" in d:
        m["tracking_rms_m"] = d["tracking_rms_m"].astype(float)
    m["algorithm"], m["level"] = d["algorithm"].astype(str), d[env.LEVEL_COLUMN]
    m["sample"] = (d["platform_category"].astype(str) == env.SERIES_CATEGORY).map(
        {True: "series", False: "catalog"})
    cols = [c for c in ROW_METRICS if c in m]
    summary = m.groupby(["algorithm", "level", "sample"], sort=True)[cols].median() \
        .reset_index()
    summary = env._sorted_by_level(summary, "level")
    return EnvelopeTables(
        fits=env.size_controlled_fits(df), dose=env.dose_response(df),
        thresholds=env.envelope_thresholds(df, n_boot=n_boot, seed=seed),
        tolerance=env.level_tolerance(df), rows=summary)


def envelope_figures(t: EnvelopeTables) -> list[tuple[str, str, object]]:
    """(name, caption, maker) of the section's figures; a maker takes no argument."""
    # the figures module loads matplotlib: only when a report draws
    from ft_sitl.missions import envelope_plots as ep

    figs = []
    if not t.thresholds.empty:
        figs.append(("envelope", "The envelope: per algorithm and series kind, the smallest "
                     "TWR_max (top) or alpha_xy,max (bottom) from which every stronger member "
                     "of a controlled series succeeds within 10 points of the series' best, "
                     "against the aggressiveness level; one colour per scenario family, one "
                     "line style per body; bars: 95 % bootstrap intervals.",
                     lambda: ep.fig_envelope(t.thresholds)))
    for kind in ("twr", "axy"):
        if (t.dose["kind"] == kind).any():
            figs.append((f"envelope_dose_{kind}", f"Dose-response: success of each "
                         f"controlled-series member against {env.KIND_LABEL[kind]} (the "
                         f"indicator its series varies; all else of the body held), per "
                         f"algorithm (columns) and family (rows); one colour per level, one "
                         f"line style per body; bars: 95 % Wilson intervals.",
                         lambda k=kind: ep.fig_dose_response(t.dose, k)))
    if not t.tolerance.empty and t.tolerance.filter(like="rate_").shape[1] > 1:
        figs.append(("envelope_tolerance", "Each catalog platform's success at every level "
                     "as a fraction of its success at the gentlest level flown, per "
                     "algorithm; platforms sorted by TWR_max (top: weakest).",
                     lambda: ep.fig_level_tolerance(t.tolerance)))
    return figs


def _num(v, spec: str) -> str:
    return "–" if v is None or (isinstance(v, float) and not math.isfinite(v)) \
        else format(v, spec)


def _p(p: float) -> str:
    if not math.isfinite(p):
        return "–"
    return "< .001" if p < 0.001 else f"{p:.3f}".lstrip("0")


def fit_rows(t: EnvelopeTables) -> tuple[list[str], list[list[str]]]:
    """The size-controlled fits, one row per algorithm, level and sample."""
    head = ["Algorithm", "Level", "Sample", "log TWR_max", "log alpha_xy,max", "half span",
            "fitted"]
    rows = []
    for (algo, level, sample), g in t.fits.groupby(["algorithm", "level", "sample"],
                                                   sort=False):
        cells = []
        for term in ("log TWR_max", "log alpha_xy,max", "half span"):
            r = g[g["term"] == term].iloc[0]
            cells.append("–" if not math.isfinite(r["coef_per_sd"]) else
                         f"{r['coef_per_sd']:+.2f} (p {_p(r['p'])})")
        rows.append([algo, level, sample, *cells, str(g["note"].iloc[0])])
    return head, rows


def threshold_rows(t: EnvelopeTables) -> tuple[list[str], list[list[str]]]:
    head = ["Algorithm", "Family", "Level", "Body", "Kind", "Threshold", "95 % interval",
            "Best rate"]
    rows = [[r.algorithm, r.family, r.level, r.base, r.kind, _num(r.threshold, ".4g"),
             f"{_num(r.lo, '.4g')} – {_num(r.hi, '.4g')}", _num(r.best_rate, ".2f")]
            for r in t.thresholds.itertuples()]
    return head, rows


def tolerance_rows(t: EnvelopeTables) -> tuple[list[str], list[list[str]]]:
    rate_cols = [c for c in t.tolerance.columns if c.startswith("rate_")]
    head = ["Algorithm", "Platform", "TWR_max", *[c[len("rate_"):] for c in rate_cols],
            "Highest level keeping 80 %"]
    rows = [[r["algorithm"], r["platform"], f"{r['twr_max']:.2f}",
             *[_num(r[c], ".2f") for c in rate_cols], r["highest_kept"] or "none"]
            for _, r in t.tolerance.iterrows()]
    return head, rows


def metric_rows(t: EnvelopeTables) -> tuple[list[str], list[list[str]]]:
    cols = [c for c in ROW_METRICS if c in t.rows]
    head = ["Algorithm", "Level", "Sample", *[f"median {c}" for c in cols]]
    rows = [[r["algorithm"], r["level"], r["sample"], *[_num(r[c], ".3g") for c in cols]]
            for _, r in t.rows.iterrows()]
    return head, rows


def markdown(t: EnvelopeTables) -> str:
    """The section's tables as Markdown (:data:`TABLES`)."""
    out = []
    for title, note, rows, _ in TABLES:
        head, body = rows(t)
        if not body:
            continue
        out += [f"### {title}", "", note, "", md.table(head, body), ""]
    return "\n".join(out)


#: the section's tables: title, what it shows, rows function, CSS class
TABLES = (
    ("Q2 with size held fixed", "log-odds per standard deviation over the rows fitted "
     "(p-value), scenario family fixed effects (and the body's, over the series), errors "
     "clustered by platform; docs/scoring.md, \"Capability envelopes\".",
     fit_rows, "envelope-fits"),
    ("Envelope thresholds", "the smallest value of the indicator a controlled series varies "
     "from which every stronger member succeeds within 10 points of the series' best; 95 % "
     "bootstrap interval.", threshold_rows, "envelope-thresholds"),
    ("What each catalog platform tolerates", "success per level, and the highest level up "
     "to which every level keeps 80 % of the success at the gentlest level flown.",
     tolerance_rows, "envelope-tolerance"),
    ("Per-row metrics (medians)", "tilt_ratio: peak tilt over acos(1/TWR_max), the tilt at "
     "which full thrust still holds altitude; tracking_rms_m: RMS distance to the commanded "
     "position; time_ratio: time to the goal over the time-optimal bound on the "
     "scenario's shortest path for the body under the level.", metric_rows,
     "envelope-metrics"),
)
