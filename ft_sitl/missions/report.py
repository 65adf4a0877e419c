"""The campaign report: figures, tables and run facts from the results table.

:func:`write_report` writes into ``<out_dir>/report/``:

* ``report.html`` -- one self-contained page (figures embedded as base64 PNG, styles
  inline, no external asset);
* ``summary.md`` -- the same facts and tables in Markdown, linking the PNG files;
* every figure as ``<name>.png`` and ``<name>.svg``:

  ``success_by_family``         per-scenario success, one bar per algorithm, 95 % CI
  ``success_vs_indicators``     success vs TWR_max, alpha_xy,max (log x), alpha_z,max;
                                one marker per platform and algorithm, pooled over
                                scenarios, with CI bars
  ``success_partial_dependence`` the logistic regression's predicted success vs each
                                indicator (TWR_max, alpha_xy,max, alpha_z,max, footprint),
                                one line and band per algorithm
  ``platform_grid``             one small bar chart per platform, placed by alpha_xy,max
                                (rows, bottom to top) and TWR_max (left to right in a row)
  ``heatmap_<algorithm>``       per algorithm: platforms (y, by TWR_max) x scenarios (x);
                                each cell: successes / trials and the Wilson interval
  ``composite_score``           Score and FinalScore per algorithm, each bar with its value
  ``failures_by_algorithm``     exit reasons, stacked fractions per algorithm
  ``failures_by_family``        exit reasons per scenario family, one panel per algorithm
                                (the legend in the grid's empty slot when it has one)

Exit-reason figures and the exit-reason table show the reasons that occur
(:func:`occurring_reasons`); no text is set below :data:`MIN_FONT_PT`.

Figures are drawn on :class:`matplotlib.figure.Figure` objects rendered by the Agg / SVG
backends: no pyplot, no global state (style settings are applied inside
``matplotlib.rc_context`` and restored). The files carry no date, and SVG ids are salted
with a constant, so the same table gives byte-identical figures; only the report's
"generated" time and the timestamps passed in ``meta`` change between runs.

The statistics are those of :mod:`ft_sitl.missions.scoring` and, for success against the
indicators, :mod:`ft_sitl.missions.regression`; what they mean and what the report
contains is written up in ``docs/scoring.md``.
"""

from __future__ import annotations

import base64
import html
import io
import json
import math
import re
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from ft_sitl import markdown as md
from ft_sitl.missions import envelope, envelope_report, regression, scoring
from ft_sitl.missions.results import REASONS
from ft_sitl.scenarios.difficulty import default_cache_dir
from ft_sitl.scenarios.families import FAMILIES, PAPER_NAMES

#: ``meta`` keys the report reads, in the order it shows them; any other key of ``meta``
#: is listed after them as given.
META_KEYS = ("code_version", "machine", "started_utc", "finished_utc", "wall_time_s",
             "trials_run")
#: ``meta["machine"]`` keys shown first when it is a mapping (as bench/benchutil writes).
MACHINE_KEYS = ("cpu_model", "n_cpus")
#: Heatmaps carry the value in each cell up to this many cells.
ANNOTATE_MAX_CELLS = 400
#: Metric columns summarised (median over successful trials) per algorithm, with the
#: header each is printed under (words, so a narrow window can wrap them).
METRICS_SHOWN = {"time_to_goal_s": "time to goal (s)", "path_length_m": "path length (m)",
                 "mean_speed_m_s": "mean speed (m/s)", "max_speed_m_s": "max speed (m/s)",
                 "min_clearance_m": "min clearance (m)", "max_tilt_deg": "max tilt (deg)",
                 "saturation_fraction": "saturation fraction", "energy_j": "energy (J)",
                 "replans": "replans", "planner_time_s": "planner time (s)"}

REASON_COLOURS = {"success": "#2ca02c", "collision": "#d62728", "mover_collision": "#e377c2",
                  "out_of_bounds": "#ff7f0e", "geofence": "#bcbd22",
                  "timeout": "#7f7f7f", "unstable": "#9467bd", "loss_of_control": "#8c564b",
                  "navigator_error": "#17becf"}
_RC = {"svg.hashsalt": "ft-sitl-report", "svg.fonttype": "none", "font.size": 9,
       "axes.titlesize": 9, "axes.labelsize": 9, "legend.fontsize": 8,
       "xtick.labelsize": 8, "ytick.labelsize": 8, "figure.dpi": 100}
_DPI = 120
#: no text in a figure is set smaller than this (pt; sub- and superscripts are 0.7 of
#: their text): an SVG viewed at 100 % shows it at 9.3 px, the report page at 9 px or
#: more (the report's browser test measures both)
MIN_FONT_PT = 7.0
#: no figure is drawn wider than this (in): the page's column (1,250 px less its padding)
#: then scales a PNG by 0.78 at least, which keeps MIN_FONT_PT at 9 px
MAX_WIDTH_IN = 13.0
_REQUIRED = ("algorithm", "platform", "platform_category", "twr_max", "alpha_xy_max",
             "alpha_z_max", "family", "scenario_category", "success", "reason")


# --------------------------------------------------------------------------- data
class _Tables:
    """Everything the figures and tables need, computed once."""

    def __init__(self, df: pd.DataFrame, B: int, seed: int, weights: Mapping | None = None):
        self.df = df
        self.algorithms = sorted(df["algorithm"].astype(str).unique())
        present = set(df["family"].astype(str).unique())
        self.families = [f for f in FAMILIES if f in present] + sorted(present - set(FAMILIES))
        self.family_label = {f: PAPER_NAMES.get(f, f) for f in self.families}
        with_footprint = df.assign(footprint_m=regression.footprints(df))
        keep = ["platform", "platform_category", "twr_max", "alpha_xy_max", "alpha_z_max",
                "footprint_m"]
        ind = with_footprint[keep].astype({"platform": str, "platform_category": str})
        ind = ind.drop_duplicates("platform").set_index("platform")
        self.indicators = ind
        self.platforms_by_twr = list(
            ind.assign(_n=ind.index).sort_values(["twr_max", "alpha_xy_max", "_n"],
                                                 na_position="last").index)
        self.cells = scoring.success_table(df, ("algorithm", "family", "platform"), B=B,
                                           seed=seed)
        self.by_family = scoring.success_table(df, ("algorithm", "family"), B=B, seed=seed)
        self.by_platform = scoring.success_table(df, ("algorithm", "platform"), B=B,
                                                 seed=seed)
        self.by_algorithm = scoring.success_table(df, ("algorithm",), B=B, seed=seed)
        w = dict(weights or {})
        self.scores = scoring.composite_score(
            df, scenario_weights=w.get("scenarios"), platform_weights=w.get("platforms"),
            beta=w.get("beta", 0.3))
        self.fits = regression.fit_success_models(with_footprint)
        self.coefficients = regression.coefficient_table(self.fits)
        self.collinearity = regression.collinearity(with_footprint)
        self.fail_algo = scoring.failure_breakdown(df, ("algorithm",))
        self.fail_family = scoring.failure_breakdown(df, ("algorithm", "family"))
        # the capability envelopes, for a campaign with levels or the controlled series
        # (each row's time-optimal bound needs its body's path: cached between reports)
        self.envelope = (envelope_report.envelope_tables(
            df, n_boot=B, seed=seed,
            bounds=envelope.time_bounds(envelope.with_levels(df), default_cache_dir()))
            if envelope_report.has_envelope(df) else None)
        self.B = B
        self.seed = seed

    def colour(self, algo: str):
        # matplotlib: heavy, loaded only when plotting
        from matplotlib import colormaps

        i = self.algorithms.index(algo)
        cmap = colormaps["tab10" if len(self.algorithms) <= 10 else "tab20"]
        return cmap(i % cmap.N)


def _lookup(table: pd.DataFrame, keys: Sequence[str], values: Sequence) -> pd.Series | None:
    mask = np.ones(len(table), dtype=bool)
    for k, v in zip(keys, values, strict=True):
        mask &= (table[k].astype(str) == str(v)).to_numpy()
    if not mask.any():
        return None
    return table[mask].iloc[0]


def _yerr(rate: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.vstack([np.clip(rate - lo, 0, None), np.clip(hi - rate, 0, None)])


# --------------------------------------------------------------------------- layout
def platform_grid_layout(indicators: pd.DataFrame) -> tuple[int, int, dict[str, tuple]]:
    """Where each platform goes in the platform grid: ``(nrows, ncols, {name: (row,
    col)})`` with row 0 at the bottom.

    ``ncols = ceil(sqrt(n))``, ``nrows = ceil(n / ncols)``. Platforms are sorted by
    (alpha_xy_max, twr_max, name) and cut into consecutive rows of ``ncols``: the bottom row
    holds the ``ncols`` lowest alpha_xy,max, the top row the highest (and is the short one
    when ``n`` is not a multiple of ``ncols``). Inside a row, platforms are ordered by
    (twr_max, alpha_xy_max, name), left to right. Missing indicators sort last. For the 36
    catalog platforms this is the paper's 6 x 6 arrangement: up = more roll/pitch
    authority, right = more thrust."""
    ind = indicators.assign(_name=indicators.index.astype(str))
    n = len(ind)
    if n == 0:
        raise ValueError("platform_grid_layout: no platforms")
    ncols = math.ceil(math.sqrt(n))
    nrows = math.ceil(n / ncols)
    by_axy = ind.sort_values(["alpha_xy_max", "twr_max", "_name"], na_position="last")
    where = {}
    for r in range(nrows):
        chunk = by_axy.iloc[r * ncols:(r + 1) * ncols]
        chunk = chunk.sort_values(["twr_max", "alpha_xy_max", "_name"], na_position="last")
        for c, name in enumerate(chunk["_name"]):
            where[name] = (r, c)
    return nrows, ncols, where


# --------------------------------------------------------------------------- figures
def _new_figure(w: float, h: float):
    # matplotlib: heavy, loaded only when plotting
    from matplotlib.figure import Figure

    return Figure(figsize=(min(w, MAX_WIDTH_IN), h), layout="constrained")


def _fig_success_by_family(t: _Tables):
    # matplotlib: heavy, loaded only when plotting
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    fig = _new_figure(max(6.0, 1.1 * len(t.families) + 2.0), 3.8)
    ax = fig.add_subplot()
    n_alg = len(t.algorithms)
    width = 0.8 / n_alg
    x0 = np.arange(len(t.families))
    missing = zero = False
    for i, algo in enumerate(t.algorithms):
        xs, r, lo, hi, none = [], [], [], [], []
        for j, fam in enumerate(t.families):
            x = x0[j] + (i - (n_alg - 1) / 2) * width
            row = _lookup(t.by_family, ("algorithm", "family"), (algo, fam))
            if row is None:
                none.append(x)
                continue
            xs.append(x)
            r.append(row["rate"])
            lo.append(row["ci_lo"])
            hi.append(row["ci_hi"])
        if none:   # no trials: an empty hatched bar over the whole range, labelled n/a
            missing = True
            ax.bar(none, np.ones(len(none)), width=width * 0.95, facecolor="none",
                   edgecolor="#aaaaaa", hatch="////", linewidth=0.6)
            for x in none:
                ax.text(x, 0.5, "n/a", rotation=90, ha="center", va="center",
                        fontsize=MIN_FONT_PT,
                        color="#555555", bbox={"facecolor": "white", "edgecolor": "none",
                                               "pad": 0.5})
        if not xs:
            continue
        r, lo, hi = map(np.asarray, (r, lo, hi))
        ax.bar(xs, r, width=width * 0.95, color=t.colour(algo), label=algo,
               yerr=_yerr(r, lo, hi), capsize=2, error_kw={"elinewidth": 0.8})
        at_zero = np.asarray(xs)[r == 0]
        if at_zero.size:   # a rate of 0: a marker on the axis and a "0", not just nothing
            zero = True
            ax.plot(at_zero, np.zeros(at_zero.size), ls="none", marker="^", ms=4,
                    color=t.colour(algo), clip_on=False, zorder=3)
            for x in at_zero:
                ax.text(x, 0.035, "0", ha="center", va="bottom", fontsize=MIN_FONT_PT,
                        color=t.colour(algo))
    ax.set_xticks(x0, [t.family_label[f] for f in t.families], rotation=20, ha="right")
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("success rate")
    handles, labels = ax.get_legend_handles_labels()
    if zero:
        handles.append(Line2D([], [], ls="none", marker="^", ms=4, color="#444444"))
        labels.append("rate 0")
    if missing:
        handles.append(Patch(facecolor="none", edgecolor="#aaaaaa", hatch="////"))
        labels.append("no trials (n/a)")
    fig.legend(handles, labels, loc="outside upper center", ncols=min(len(labels), 7),
               frameon=False)
    ax.grid(axis="y", alpha=0.3)
    return fig


TURBULENCE_STYLE = {"none": "-", "light": "--", "moderate": "-.", "severe": ":",
                    "standard": (0, (6, 2, 1, 2))}


def _setting(df: pd.DataFrame, column: str, key: str, default: float) -> pd.Series:
    """One numeric setting out of a JSON settings column ("" or missing: the default)."""
    def get(text):
        if not isinstance(text, str) or not text:
            return default
        return float(json.loads(text).get(key, default))
    return df[column].map(get).astype(float) if column in df else \
        pd.Series(default, index=df.index)


def axis_values(df: pd.DataFrame) -> dict[str, pd.Series]:
    """The numeric axes the trials vary, by name (only those with more than one value):
    mean wind speed, perception latency, the weakest motor's efficiency, and the moving
    obstacles' count and speed (0 in a static world)."""
    out = {}
    if "wind_speed_m_s" in df:
        out["wind"] = df["wind_speed_m_s"].astype(float)
    for axis, col in (("movers", "mover_count"), ("mover_speed", "mover_speed_m_s")):
        if col in df:
            out[axis] = df[col].astype(float).fillna(0.0)
    out["latency"] = _setting(df, "perception", "latency_s", 0.0)
    eff = _setting(df, "actuators", "efficiency", 1.0)
    one = _setting(df, "actuators", "degraded_efficiency", 1.0)
    weak = _setting(df, "actuators", "degraded_motor", 0.0)
    out["efficiency"] = eff.where(weak == 0, np.minimum(eff, one))
    return {k: v for k, v in out.items() if v.nunique() > 1}


#: per axis: figure name, x label, caption's words
AXIS_FIGURES = {
    "wind": ("success_vs_wind", "mean wind speed (m/s)", "the mean wind speed"),
    "latency": ("success_vs_latency", "perception latency (s)",
                "the navigator's perception latency"),
    "efficiency": ("success_vs_efficiency", "weakest motor's thrust efficiency",
                   "the weakest motor's thrust efficiency"),
    "movers": ("success_vs_movers", "moving obstacles placed",
               "the number of moving obstacles"),
    "mover_speed": ("success_vs_mover_speed", "moving obstacles' speed (m/s; 0: static)",
                    "the moving obstacles' speed"),
}


def _fig_success_vs_axis(t: _Tables, axis: str):
    """Success against one axis's value, per algorithm (for the wind, line style: the
    turbulence), pooled over everything else; Wilson intervals."""
    x = axis_values(t.df)[axis]
    df = t.df.assign(_x=x, _kind=t.df["turbulence"].astype(str) if axis == "wind" else "")
    # one line per turbulence intensity only where one wind speed was flown with several
    # (calm air has none: a calm point and turbulent winds are one line otherwise)
    if df.groupby(["algorithm", "_x"], observed=True)["_kind"].nunique().max() <= 1:
        df = df.assign(_kind="")
    g = (df.groupby(["algorithm", "_kind", "_x"], observed=True)["success"]
         .agg(["sum", "count"]).reset_index())
    kinds = sorted(g["_kind"].unique())
    fig = _new_figure(7.0, 3.8)
    ax = fig.add_subplot()
    for algo in t.algorithms:
        for kind in kinds:
            sub = g[(g["algorithm"].astype(str) == algo) & (g["_kind"] == kind)]
            if sub.empty:
                continue
            sub = sub.sort_values("_x")
            n, k = sub["count"].to_numpy(), sub["sum"].to_numpy()
            rate = k / n
            ci = np.array([scoring.wilson_interval(int(a), int(b)) for a, b in zip(n, k)])
            label = algo if len(kinds) == 1 else f"{algo}, turbulence {kind}"
            ax.errorbar(sub["_x"], rate, yerr=_yerr(rate, ci[:, 0], ci[:, 1]),
                        color=t.colour(algo), ls=TURBULENCE_STYLE.get(kind, "-"), marker="o",
                        ms=3, capsize=2, elinewidth=0.8, label=label)
    ax.set_xlabel(AXIS_FIGURES[axis][1])
    ax.set_ylabel("success rate")
    ax.set_ylim(-0.02, 1.05)
    ax.grid(alpha=0.3)
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside upper center",
               ncols=min(len(labels), 5 if len(kinds) == 1 else 3), frameon=False)
    return fig


def _fig_success_vs_indicators(t: _Tables):
    fig = _new_figure(12.0, 3.8)
    axes = fig.subplots(1, 3, sharey=True)
    specs = (("twr_max", r"$\mathrm{TWR}_{\max}$", False),
             ("alpha_xy_max", r"$\alpha_{xy,\max}$ (rad/s$^2$, log)", True),
             ("alpha_z_max", r"$\alpha_{z,\max}$ (rad/s$^2$)", False))
    markers = "osD^vP*Xh<>p"
    for ax, (col, label, log) in zip(axes, specs, strict=True):
        for i, algo in enumerate(t.algorithms):
            sub = t.by_platform[t.by_platform["algorithm"].astype(str) == algo]
            x = t.indicators.loc[sub["platform"].astype(str), col].to_numpy(dtype=float)
            ok = np.isfinite(x) & ((x > 0) if log else True)
            if not ok.any():
                continue
            r = sub["rate"].to_numpy()[ok]
            ax.errorbar(x[ok], r, yerr=_yerr(r, sub["ci_lo"].to_numpy()[ok],
                                             sub["ci_hi"].to_numpy()[ok]),
                        fmt=markers[i % len(markers)], color=t.colour(algo), ms=4,
                        capsize=1.5, elinewidth=0.6, alpha=0.85, label=algo)
        if log:
            ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_ylim(-0.03, 1.05)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("success rate (pooled over scenarios)")
    handles, labels = axes[0].get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="outside upper center", ncols=min(len(labels), 6),
                   frameon=False)
    return fig


def _fig_partial_dependence(t: _Tables):
    fig = _new_figure(12.0, 3.9)
    axes = fig.subplots(1, len(regression.INDICATORS), sharey=True)
    labels = {"twr_max": r"$\mathrm{TWR}_{\max}$",
              "alpha_xy_max": r"$\alpha_{xy,\max}$ (rad/s$^2$, log)",
              "alpha_z_max": r"$\alpha_{z,\max}$ (rad/s$^2$)",
              "footprint_m": "footprint (m)"}
    fitted = [f for f in t.fits if f.fitted]
    for ax, ind in zip(axes, regression.INDICATORS, strict=True):
        col = ind.column
        for f in fitted:
            if col not in f.indicators:
                continue
            lo_x, hi_x = f.ranges[col]
            grid = (np.geomspace(lo_x, hi_x, 60) if ind.log2 else np.linspace(lo_x, hi_x, 60))
            mean, lo, hi = f.partial_dependence(col, grid, seed=t.seed)
            colour = t.colour(f.algorithm)
            ax.fill_between(grid, lo, hi, color=colour, alpha=0.15, linewidth=0)
            ax.plot(grid, mean, color=colour, lw=1.6, label=f.algorithm)
        x = t.indicators[col].to_numpy(dtype=float)
        x = x[np.isfinite(x) & ((x > 0) if ind.log2 else True)]
        ax.plot(x, np.full(x.size, 0.0), ls="none", marker="|", ms=7, color="#555555",
                alpha=0.6, clip_on=False)   # the platforms' values
        if ind.log2:
            ax.set_xscale("log")
        ax.set_xlabel(labels[col])
        ax.set_ylim(0.0, 1.02)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("predicted success\n(others at their means, mean over families)")
    if not fitted:
        axes[0].text(0.05, 0.5, "no algorithm could be fitted\n(see the regression table)",
                     transform=axes[0].transAxes, fontsize=8, va="center")
    handles, names = axes[0].get_legend_handles_labels()
    for ax in axes[1:]:
        for h, n in zip(*ax.get_legend_handles_labels(), strict=True):
            if n not in names:
                handles.append(h)
                names.append(n)
    if handles:
        fig.legend(handles, names, loc="outside upper center", ncols=min(len(names), 6),
                   frameon=False)
    absent = [f for f in t.fits if not f.fitted]
    if absent:   # an algorithm without a line is said, with why, not left to be guessed
        fig.supxlabel("no line: " + "; ".join(f"{f.algorithm} ({_why_not_fitted(f)})"
                                              for f in absent), fontsize=8, color="#444444")
    return fig


def _why_not_fitted(fit) -> str:
    """The short reason a fit was not made: its note's last clause, without the
    parenthesis ("not estimable: no variation between platforms")."""
    last = (fit.note or "not fitted").split("; ")[-1]
    return last.split(" (")[0]


def _fig_platform_grid(t: _Tables):
    nrows, ncols, where = platform_grid_layout(t.indicators)
    n_alg = len(t.algorithms)
    rotation = 45 if n_alg <= 6 else 90
    names_in = max(len(a) for a in t.algorithms) * 0.075 * (0.71 if rotation == 45 else 1)
    fig = _new_figure(max(4.0, 2.0 * ncols), max(2.6, 1.6 * nrows + 0.9 + names_in))
    axes = fig.subplots(nrows, ncols, squeeze=False, sharey=True)
    used = set()
    for name, (r, c) in where.items():
        ax = axes[nrows - 1 - r][c]
        used.add((r, c))
        sub = t.by_platform[t.by_platform["platform"].astype(str) == name]
        for i, algo in enumerate(t.algorithms):
            row = _lookup(sub, ("algorithm",), (algo,))
            if row is None:
                continue
            rate = np.array([row["rate"]])
            ax.bar([i], rate, width=0.8, color=t.colour(algo),
                   yerr=_yerr(rate, np.array([row["ci_lo"]]), np.array([row["ci_hi"]])),
                   capsize=1.5, error_kw={"elinewidth": 0.6})
        ind = t.indicators.loc[name]
        ax.set_title(f"{name}\nTWR {ind['twr_max']:.2f}  "
                     rf"$\alpha_{{xy}}$ {ind['alpha_xy_max']:.0f}", fontsize=8, pad=2,
                     linespacing=1.1)
        ax.set_xlim(-0.6, n_alg - 0.4)
        ax.set_ylim(0, 1.05)
        # the algorithms under the bottom row (it is always full), the bars above alone
        if r == 0:
            ax.set_xticks(np.arange(n_alg), t.algorithms, rotation=rotation,
                          ha="right" if rotation == 45 else "center",
                          rotation_mode="anchor" if rotation == 45 else "default")
        else:
            ax.set_xticks(np.arange(n_alg), [])
        ax.tick_params(axis="x", length=0)
        ax.tick_params(axis="y", labelsize=7.5)
        ax.grid(axis="y", alpha=0.3)
    for r in range(nrows):
        for c in range(ncols):
            if (r, c) not in used:
                axes[nrows - 1 - r][c].set_axis_off()
    # matplotlib: heavy, loaded only when plotting
    from matplotlib.patches import Patch

    fig.legend([Patch(color=t.colour(a)) for a in t.algorithms], t.algorithms,
               loc="outside upper center", ncols=min(n_alg, 6), frameon=False)
    fig.supxlabel(r"$\mathrm{TWR}_{\max}$ increases left to right within each row")
    fig.supylabel(r"$\alpha_{xy,\max}$ increases bottom to top (rows)")
    return fig


def _fig_heatmap(t: _Tables, algo: str):
    # matplotlib: heavy, loaded only when plotting
    from matplotlib import colormaps

    plats = t.platforms_by_twr
    sub = t.cells[t.cells["algorithm"].astype(str) == algo]
    sub = sub.assign(platform=sub["platform"].astype(str), family=sub["family"].astype(str))

    def grid(col):
        return (sub.pivot(index="platform", columns="family", values=col)
                .reindex(index=plats, columns=t.families).to_numpy(dtype=float))

    values = grid("rate")
    n_p, n_f = values.shape
    annotate = n_p * n_f <= ANNOTATE_MAX_CELLS
    row_in = 0.34 if annotate else 0.22
    fig = _new_figure(max(5.0, 0.9 * n_f + 3.4), max(3.0, row_in * n_p + 1.9))
    ax = fig.add_subplot()
    cmap = colormaps["viridis"].with_extremes(bad="#d9d9d9")
    im = ax.imshow(np.ma.masked_invalid(values), cmap=cmap, vmin=0.0, vmax=1.0,
                   aspect="auto", origin="lower", interpolation="nearest")
    ax.set_xticks(np.arange(n_f), [t.family_label[f] for f in t.families], rotation=30,
                  ha="right")
    twr = t.indicators["twr_max"]
    ax.set_yticks(np.arange(n_p), [f"{p} ({twr[p]:.2f})" for p in plats],
                  fontsize=MIN_FONT_PT if n_p > 12 else 8)
    # short: a label longer than the axes is cut off by the figure's edge
    ax.set_ylabel(r"platform ($\mathrm{TWR}_{\max}$)")
    ax.set_title(f"{algo}: success per platform and scenario family\n"
                 r"platforms by $\mathrm{TWR}_{\max}$, lowest at the bottom", fontsize=9)
    if annotate:
        k, n = grid("successes"), grid("n")
        lo, hi = grid("wilson_lo"), grid("wilson_hi")
        size = MIN_FONT_PT
        for (i, j), v in np.ndenumerate(values):
            if not np.isfinite(v):
                text = "n/a"
            else:
                text = f"{k[i, j]:.0f}/{n[i, j]:.0f}\n[{lo[i, j]:.2f}, {hi[i, j]:.2f}]"
            colour = "black" if (not np.isfinite(v) or v > 0.6) else "white"
            ax.text(j, i, text, ha="center", va="center", fontsize=size, color=colour,
                    linespacing=1.1)
    fig.colorbar(im, ax=ax, label="success rate", fraction=0.05)
    return fig


def _fig_composite(t: _Tables):
    s = t.scores
    fig = _new_figure(max(5.0, 1.0 * len(s) + 3.0), 3.6)
    ax = fig.add_subplot()
    x = np.arange(len(s))
    ax.bar(x - 0.2, s["Score"], width=0.4, color="#9ecae1", label="Score (no penalty)")
    ax.bar(x + 0.2, s["FinalScore"], width=0.4, color="#08519c", label="FinalScore")
    labels = [a if comp else f"{a} †" for a, comp in zip(s["algorithm"], s["comparable"],
                                                         strict=True)]
    ax.set_xticks(x, labels, rotation=15, ha="right")
    for dx, column in ((-0.2, "Score"), (0.2, "FinalScore")):
        for xi, v in zip(x, s[column], strict=True):
            ax.text(xi + dx, v + 1.0, f"{v:.2f}", ha="center", va="bottom", fontsize=8)
    ax.set_ylim(0, 105)
    ax.set_ylabel("score (%)")
    dagger = "" if s["comparable"].all() else "; † = not directly comparable"
    ax.set_title(f"Composite score (beta = {t.scores.attrs['beta']:g}{dagger})")
    ax.legend(frameon=False, loc="upper right")
    ax.grid(axis="y", alpha=0.3)
    return fig


def occurring_reasons(table: pd.DataFrame) -> list[str]:
    """The exit reasons (in :data:`REASONS` order) with at least one trial in a
    :func:`~ft_sitl.missions.scoring.failure_breakdown` table: the figures and the table
    show these only."""
    counts = table.groupby(table["reason"].astype(str))["count"].sum()
    return [r for r in REASONS if counts.get(r, 0) > 0]


def _stack(ax, xs, fractions: dict[str, np.ndarray], width: float, reasons: Sequence[str]):
    bottom = np.zeros(len(xs))
    for reason in reasons:
        f = fractions[reason]
        ax.bar(xs, f, width=width, bottom=bottom, color=REASON_COLOURS[reason], label=reason)
        bottom = bottom + f


def _fractions(table: pd.DataFrame, keys: Sequence[str], groups: Sequence[tuple]):
    out = {r: np.zeros(len(groups)) for r in REASONS}
    for i, g in enumerate(groups):
        mask = np.ones(len(table), dtype=bool)
        for k, v in zip(keys, g, strict=True):
            mask &= (table[k].astype(str) == str(v)).to_numpy()
        for reason, frac in zip(table.loc[mask, "reason"].astype(str),
                                table.loc[mask, "fraction"], strict=True):
            out[reason][i] = frac
    return out


def _reason_handles(reasons: Sequence[str]):
    # matplotlib: heavy, loaded only when plotting
    from matplotlib.patches import Patch

    return [Patch(color=REASON_COLOURS[r]) for r in reasons], list(reasons)


def _fig_failures_by_algorithm(t: _Tables):
    reasons = occurring_reasons(t.fail_algo)
    fig = _new_figure(max(4.5, 0.9 * len(t.algorithms) + 3.0), 3.6)
    ax = fig.add_subplot()
    groups = [(a,) for a in t.algorithms]
    _stack(ax, np.arange(len(groups)), _fractions(t.fail_algo, ("algorithm",), groups), 0.7,
           reasons)
    ax.set_xticks(np.arange(len(groups)), t.algorithms, rotation=15, ha="right")
    ax.set_ylim(0, 1.0)
    ax.set_ylabel("fraction of trials")
    ax.set_title("Exit reasons per algorithm")
    fig.legend(*_reason_handles(reasons), loc="outside right center", frameon=False)
    return fig


def panel_columns(n: int) -> int:
    """Columns of a grid of ``n`` panels: all in one row up to 3, else 3, 2 or 4 columns,
    the first that leaves at most one slot empty (that slot holds the legend)."""
    if n <= 3:
        return max(n, 1)
    return next((c for c in (3, 2, 4) if -n % c <= 1), 3)


def _fig_failures_by_family(t: _Tables):
    reasons = occurring_reasons(t.fail_family)
    n = len(t.algorithms)
    ncols = panel_columns(n)
    nrows = math.ceil(n / ncols)
    spare = nrows * ncols - n
    # a panel 0.42 in per family, so five or more fit the page at their size
    fig = _new_figure(max(5.0, (0.42 * len(t.families) + 1.0) * ncols + 0.6),
                      2.9 * nrows + (0.0 if spare else 0.5))
    axes = fig.subplots(nrows, ncols, squeeze=False, sharey=True)
    x = np.arange(len(t.families))
    for k, algo in enumerate(t.algorithms):
        ax = axes[k // ncols][k % ncols]
        groups = [(algo, f) for f in t.families]
        fr = _fractions(t.fail_family, ("algorithm", "family"), groups)
        _stack(ax, x, fr, 0.7, reasons)
        ax.set_xticks(x, [t.family_label[f] for f in t.families], rotation=40, ha="right",
                      rotation_mode="anchor")
        ax.set_title(algo)
        ax.set_ylim(0, 1.0)
    for k in range(n, nrows * ncols):
        axes[k // ncols][k % ncols].set_axis_off()
    for row in axes:
        row[0].set_ylabel("fraction of trials")
    handles, labels = _reason_handles(reasons)
    if spare:   # the legend in the empty slot, beside the panels it explains
        axes[n // ncols][n % ncols].legend(handles, labels, loc="center", frameon=False,
                                           title="exit reason")
    else:
        fig.legend(handles, labels, loc="outside upper center",
                   ncols=min(len(labels), 5), frameon=False)
    return fig


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_") or "algorithm"


def _figures(t: _Tables) -> list[tuple[str, str, object]]:
    figs = [
        ("success_by_family", "Mean success per scenario family, one bar per algorithm, "
         "pooled over platforms; error bars: 95 % percentile-bootstrap CI; a triangle and "
         "\"0\" mark a rate of 0, an empty hatched bar (n/a) a family without trials.",
         _fig_success_by_family),
        ("success_vs_indicators", "Success per platform (pooled over scenario families) "
         "against the kinodynamic indicators TWR_max, alpha_xy,max (log x) and alpha_z,max; "
         "one marker per platform and algorithm, 95 % CI bars.", _fig_success_vs_indicators),
        ("success_partial_dependence", "The logistic regression's predicted success against "
         "each indicator, the other indicators at their means and averaged over the scenario "
         "families fitted; bands: 95 % of the curves under the fit's coefficient "
         "uncertainty; ticks on the x axis: the platforms. One line per algorithm fitted "
         "(none where the indicator or the algorithm is not in the fit: the figure names "
         "the algorithms without a line and why, the regression tables say more).",
         _fig_partial_dependence),
        ("platform_grid", "One panel per platform: success per algorithm pooled over "
         "scenario families, 95 % CI; the algorithms are named under the bottom row, in the "
         "same order in every panel. Rows are bands of alpha_xy,max (bottom: lowest); "
         "within a row, TWR_max increases to the right.", _fig_platform_grid),
    ]
    for axis in axis_values(t.df):
        name, _, words = AXIS_FIGURES[axis]
        style = " (line style: the turbulence intensity)" if axis == "wind" else ""
        figs.append((name, f"Success against {words} per algorithm, pooled over platforms, "
                     f"scenario families and the other axes{style}; bars: 95 % Wilson "
                     f"intervals.", lambda t, a=axis: _fig_success_vs_axis(t, a)))
    used = set()
    for algo in t.algorithms:
        slug = _slug(algo)
        name = f"heatmap_{slug}"
        k = 2
        while name in used:
            name = f"heatmap_{slug}_{k}"
            k += 1
        used.add(name)
        figs.append((name, f"{algo}: success rate per platform (y, sorted by TWR_max) and "
                     "scenario family (x); each cell: successes / trials and the 95 % Wilson "
                     "interval; grey, n/a = no trials.",
                     lambda t, a=algo: _fig_heatmap(t, a)))
    figs += [
        ("composite_score", "Composite score per algorithm (eqs. 12-19): Score without "
         "penalty (light) and the variance-penalised FinalScore (dark), each with its "
         "value.", _fig_composite),
        ("failures_by_algorithm", "Exit reasons as fractions of each algorithm's trials "
         "(the reasons that occur).", _fig_failures_by_algorithm),
        ("failures_by_family", "Exit reasons per scenario family, one panel per algorithm "
         "(the reasons that occur).", _fig_failures_by_family),
    ]
    if t.envelope is not None:
        figs += [(name, caption, lambda t, m=make: m())
                 for name, caption, make in envelope_report.envelope_figures(t.envelope)]
    return figs


def _render(fig) -> tuple[bytes, bytes]:
    png, svg = io.BytesIO(), io.BytesIO()
    fig.savefig(png, format="png", dpi=_DPI, metadata={"Software": None})
    fig.savefig(svg, format="svg", metadata={"Date": None, "Creator": None})
    return png.getvalue(), svg.getvalue()


# --------------------------------------------------------------------------- tables
def _fmt(v, spec: str) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)) or v is pd.NA:
        return "–"
    return format(v, spec)


def _score_rows(t: _Tables) -> tuple[list[str], list[list[str]]]:
    head = ["Algorithm", "Score (no penalty)", "Var", "Var_norm", "FinalScore",
            "Missing scenarios", "Comparable", "Trials", "Missing cells"]
    rows = []
    for r in t.scores.itertuples(index=False):
        miss = ", ".join(t.family_label.get(f, f) for f in r.missing_scenarios) or "–"
        rows.append([str(r.algorithm), f"{r.Score:.2f}", f"{r.Var:.3f}", f"{r.Var_norm:.3f}",
                     f"{r.FinalScore:.2f}", miss, "yes" if r.comparable else "no †",
                     _fmt(r.n_trials, "d"), str(r.missing_cells)])
    return head, rows


def _ci_text(row) -> str:
    """Rate (successes/n), bootstrap and Wilson intervals, one per line."""
    return (f"{row['rate']:.2f} ({row['successes']}/{row['n']})\n"
            f"boot [{row['ci_lo']:.2f}, {row['ci_hi']:.2f}]\n"
            f"Wilson [{row['wilson_lo']:.2f}, {row['wilson_hi']:.2f}]")


def _family_rows(t: _Tables) -> tuple[list[str], list[list[str]]]:
    head = ["Algorithm", *[t.family_label[f] for f in t.families], "All"]
    rows = []
    for algo in t.algorithms:
        row = [algo]
        for fam in t.families:
            r = _lookup(t.by_family, ("algorithm", "family"), (algo, fam))
            row.append("–" if r is None else _ci_text(r))
        row.append(_ci_text(_lookup(t.by_algorithm, ("algorithm",), (algo,))))
        rows.append(row)
    return head, rows


def _failure_rows(t: _Tables) -> tuple[list[str], list[list[str]]]:
    reasons = occurring_reasons(t.fail_algo)
    head = ["Algorithm", "Trials", *reasons]
    rows = []
    for algo in t.algorithms:
        sub = t.fail_algo[t.fail_algo["algorithm"].astype(str) == algo]
        counts = dict(zip(sub["reason"].astype(str), sub["count"], strict=True))
        n = int(sub["n"].iloc[0])
        rows.append([algo, str(n), *[f"{counts[r]} ({counts[r] / n:.0%})" for r in reasons]])
    return head, rows


def _absent_reasons_note(t: _Tables) -> str:
    """The exit reasons no trial ended with ("" when every one occurs)."""
    absent = [r for r in REASONS if r not in occurring_reasons(t.fail_algo)]
    return f"No trial ended with: {', '.join(absent)}." if absent else ""


def _metric_text(v: float) -> str:
    """Three significant digits, without an exponent: 0.307, 17.8, 3,720."""
    rounded = float(f"{v:.3g}")
    return f"{rounded:,.0f}" if abs(rounded) >= 1000 else f"{v:.3g}"


def _metric_rows(t: _Tables) -> tuple[list[str], list[list[str]]]:
    cols = [c for c in METRICS_SHOWN if c in t.df.columns]
    head = ["Algorithm", "Successes", *(METRICS_SHOWN[c] for c in cols)]
    rows = []
    ok = t.df[t.df["success"].astype(bool)]
    for algo in t.algorithms:
        sub = ok[ok["algorithm"].astype(str) == algo]
        row = [algo, str(len(sub))]
        for c in cols:
            v = pd.to_numeric(sub[c], errors="coerce").astype(float)
            v = v[np.isfinite(v)]
            row.append("–" if v.empty else _metric_text(float(v.median())))
        rows.append(row)
    return head, rows


def _fit_rows(t: _Tables) -> tuple[list[str], list[list[str]]]:
    head = ["Algorithm", "Trials", "In the fit (successes)", "Families fitted",
            "Families left out", "Indicators left out", "Fit", "Note"]
    method = {"logit": "maximum likelihood", "firth": "Firth (penalised)", "": "not fitted"}
    rows = []
    for f in t.fits:
        rows.append([
            f.algorithm, str(f.n_trials), f"{f.n_rows} ({f.n_successes})",
            ", ".join(t.family_label.get(x, x) for x in f.families) or "–",
            "; ".join(f"{t.family_label.get(x, x)} ({why})" for x, why in f.left_out) or "–",
            "; ".join(f"{x} ({why})" for x, why in f.dropped_indicators) or "–",
            "not estimable" if "not estimable:" in f.note else method[f.method],
            f.note or "–"])
    return head, rows


def _coefficient_rows(t: _Tables) -> tuple[list[str], list[list[str]]]:
    head = ["Algorithm", "Indicator", "Step", "Log-odds (SE)", "Odds ratio [95 % CI]", "p"]
    rows = []
    for r in t.coefficients.itertuples(index=False):
        if not math.isfinite(r.coef):
            continue
        rows.append([r.algorithm, r.indicator, r.per, f"{r.coef:+.2f} ({r.se:.2f})",
                     f"{regression.ratio_text(r.odds_ratio)} [{regression.ratio_text(r.or_lo)}"
                     f", {regression.ratio_text(r.or_hi)}]", regression.p_text(r.p)])
    return head, rows


def _readings(t: _Tables) -> list[tuple[str, list[str]]]:
    """(algorithm, its one-line readings) -- one line in all when it was not fitted."""
    out = []
    for f in t.fits:
        lines = list(t.coefficients.loc[t.coefficients["algorithm"] == f.algorithm,
                                        "reading"])
        out.append((f.algorithm, lines if f.fitted else lines[:1]))
    return out


def _collinearity_rows(t: _Tables) -> tuple[list[str], list[list[str]]]:
    c = t.collinearity
    names = {"alpha_xy,max": "log2 alpha_xy,max", "mass": "mass (not in the fit)"}
    head = ["Predictor", *(names.get(x, x) for x in c.columns[:-1]), "VIF"]

    def vif(v: float) -> str:
        return "inf" if v == math.inf else _fmt(v, ".1f")

    rows = [[names.get(str(i), str(i)), *(_fmt(float(v), ".2f") for v in r.iloc[:-1]),
             "–" if i == "mass" else vif(float(r.iloc[-1]))] for i, r in c.iterrows()]
    return head, rows


def _run_facts(df: pd.DataFrame, meta: Mapping) -> list[tuple[str, str]]:
    facts: list[tuple[str, str]] = []
    campaigns = sorted(df["campaign"].dropna().astype(str).unique()) if "campaign" in df else []
    if campaigns:
        facts.append(("campaign", ", ".join(campaigns)))
    facts.append(("code version", str(meta.get("code_version", "not recorded"))))
    machine = meta.get("machine")
    if isinstance(machine, Mapping):
        items = [(k, machine[k]) for k in MACHINE_KEYS if k in machine]
        items += [(k, v) for k, v in machine.items() if k not in MACHINE_KEYS]
        facts.append(("machine", "; ".join(f"{k}: {v}" for k, v in items) or "not recorded"))
    else:
        facts.append(("machine", "not recorded" if machine is None else str(machine)))
    facts.append(("started (UTC)", str(meta.get("started_utc", "not recorded"))))
    facts.append(("finished (UTC)", str(meta.get("finished_utc", "not recorded"))))
    wall = meta.get("wall_time_s")
    n = len(df)
    facts.append(("trials", f"{n}"))
    # a run stopped before its end records nothing: the rows it flew are not in the wall
    # time, so the rate counts the trials of the recorded runs (meta "trials_run")
    flown = meta.get("trials_run")
    flown = n if not isinstance(flown, int) or isinstance(flown, bool) else flown
    if flown < n:
        facts.append(("trials flown by the recorded runs",
                      f"{flown} (the other {n - flown} were flown by runs with no record "
                      "here: a run stopped before its end records none)"))
    if isinstance(wall, int | float) and math.isfinite(wall) and wall > 0:
        facts.append(("wall time", f"{wall:.1f} s"))
        facts.append(("trials per second", f"{flown / wall:.3g}"))
    else:
        facts.append(("wall time", "not recorded" if wall is None else str(wall)))
        facts.append(("trials per second", "–"))
    if "wall_time_s" in df:
        tw = pd.to_numeric(df["wall_time_s"], errors="coerce").astype(float)
        tw = tw[np.isfinite(tw)]
        if not tw.empty:
            facts.append(("sum of per-trial wall time", f"{float(tw.sum()):.1f} s"))
    for k in sorted(set(meta) - set(META_KEYS), key=str):
        facts.append((str(k), _plain(meta[k])))
    return facts


def _plain(v) -> str:
    if isinstance(v, Mapping | list | tuple):
        return json.dumps(_jsonable(v), sort_keys=False)
    return str(v)


def _jsonable(obj):
    return json.loads(json.dumps(obj, default=str))


def _spec_text(campaign_spec: Mapping) -> str:
    return yaml.safe_dump(_jsonable(dict(campaign_spec)), sort_keys=False,
                          default_flow_style=False, allow_unicode=True).rstrip()


# --------------------------------------------------------------------------- HTML, MD
_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:2em auto;
max-width:1250px;padding:0 1em;color:#222;line-height:1.4}
h1{font-size:1.5em}h2{font-size:1.2em;margin-top:1.8em;border-bottom:1px solid #ddd}
h3{font-size:1.05em;margin-top:1.4em}
table{border-collapse:collapse;margin:.6em 0;font-size:.85em}
th,td{border:1px solid #ccc;padding:.25em .5em;text-align:left;vertical-align:top;
white-space:pre-line}
th{background:#f2f2f2}tbody th{font-weight:normal}td.num{text-align:right}
figure{margin:1.2em 0}figure img{max-width:100%;height:auto;border:1px solid #eee;
box-sizing:border-box}
figcaption{font-size:.85em;color:#555}pre{background:#f7f7f7;padding:.8em;overflow-x:auto;
font-size:.8em}.note{font-size:.85em;color:#555}
"""


def _html_table(head: Sequence[str] | None, rows: Sequence[Sequence[str]],
                cls: str = "") -> str:
    """A table; ``head`` None: no header row, the first cell of each row is its header.
    A newline in a cell is a line break (``white-space: pre-line``)."""
    e = html.escape
    out = [f'<table class="{e(cls)}">' if cls else "<table>"]
    if head is not None:
        out += ["<thead><tr>", *(f"<th>{e(h)}</th>" for h in head), "</tr></thead>"]
    out.append("<tbody>")
    for r in rows:
        if head is None:
            out.append(f'<tr><th scope="row">{e(r[0])}</th>'
                       + "".join(f"<td>{e(c)}</td>" for c in r[1:]) + "</tr>")
        else:
            out.append("<tr>" + "".join(f"<td>{e(c)}</td>" for c in r) + "</tr>")
    out.append("</tbody></table>")
    return "".join(out)


def _method_notes(t: _Tables) -> list[str]:
    a = t.scores.attrs
    sw = ", ".join(f"{k} {v:g}" for k, v in a["scenario_weight_table"].items())
    pw = ", ".join(f"{k} {v:g}" for k, v in a["platform_weight_table"].items())
    return [
        f"Success rates with 95 % percentile-bootstrap confidence intervals, B = {t.B} "
        f"resamples, seed {t.seed} (resampling trials with replacement, drawn as binomial "
        "counts), and 95 % Wilson score intervals (which, unlike the bootstrap, do not "
        "collapse to a point when every trial of a group succeeds or fails); pooled rates "
        "take the trials of all platforms / scenarios together.",
        f"Composite score (eqs. 12-19): scenario weights {sw}; platform weights {pw}; "
        f"beta = {a['beta']:g}. A scenario family without any trial of an algorithm is "
        "dropped for it and its scenario weights renormalised (eq. 19)"
        + ("." if t.scores["comparable"].all() else
           "; † marks scores not computed over the full (family x platform) grid."),
        "Definitions: docs/scoring.md.",
    ]


def _regression_notes() -> list[str]:
    steps = "; ".join(f"{i.label} {i.per}" for i in regression.INDICATORS)
    return [
        "Per algorithm: logistic regression of each trial's success on TWR_max, "
        "log2 alpha_xy,max, alpha_z,max and the vehicle's footprint (its half span from "
        "protocol 5, its collision radius before), with the scenario family as a factor. "
        f"Odds ratios are per step: {steps}; each holds the other indicators and the "
        "family fixed.",
        "95 % Wald intervals and p-values from the (penalised) information matrix; an "
        f"effect is read as one when p < {regression.ALPHA:g} (the interval then excludes "
        "1). \"No detectable effect\" is not \"no effect\": read the interval.",
        "Left out of a fit, and said so: families in which the algorithm's trials all "
        "succeed or all fail (they carry no information on the indicators once the family "
        "has its own effect), indicators that are constant or a combination of the others "
        "over the platforms fitted, trials without all four indicators. Separation (some "
        "combination predicts every outcome) switches to Firth's penalised fit. Fewer than "
        f"{regression.MIN_EVENTS_PER_COEF:g} successes or failures per coefficient: not "
        "fitted.",
        "The indicators are correlated over the platforms (table below): an effect can "
        "only be told apart from the others' as far as the platforms vary independently "
        "(VIF above 10: hardly).",
    ]


def _html(t: _Tables, facts, figures, spec_text: str, generated: str) -> str:
    e = html.escape
    parts = ["<!DOCTYPE html>", '<html lang="en">', "<head>", '<meta charset="utf-8">',
             '<meta name="viewport" content="width=device-width, initial-scale=1">',
             "<title>FLYINGTRUST benchmark report</title>", f"<style>{_CSS}</style>",
             "</head>", "<body>", "<h1>FLYINGTRUST benchmark report</h1>",
             f'<p class="note">Generated {e(generated)} by ft_sitl.missions.report.</p>',
             "<h2>Run</h2>", _html_table(None, facts, "facts"),
             "<h2>Composite score</h2>", _html_table(*_score_rows(t), "scores")]
    parts.append("<ul class=\"note\">" + "".join(f"<li>{e(n)}</li>" for n in _method_notes(t))
                 + "</ul>")
    parts.append("<h2>Figures</h2>")
    for name, caption, png in figures:
        b64 = base64.b64encode(png).decode("ascii")
        parts.append(f'<figure id="fig-{e(name)}"><img alt="{e(name)}" '
                     f'src="data:image/png;base64,{b64}">'
                     f"<figcaption><b>{e(name)}</b>: {e(caption)}</figcaption></figure>")
    parts += ["<h2>Success per scenario family</h2>",
              '<p class="note">rate (successes/trials), 95 % percentile-bootstrap and Wilson '
              "intervals, pooled over platforms.</p>",
              _html_table(*_family_rows(t), "families"),
              "<h2>Success against the indicators (logistic regression)</h2>",
              "<ul class=\"note\">" + "".join(f"<li>{e(n)}</li>" for n in _regression_notes())
              + "</ul>",
              "<h3>Readings</h3>", "<ul class=\"readings\">"]
    for algo, lines in _readings(t):
        parts.append(f"<li><b>{e(algo)}</b><ul>"
                     + "".join(f"<li>{e(x)}</li>" for x in lines) + "</ul></li>")
    parts += ["</ul>", "<h3>Fits</h3>", _html_table(*_fit_rows(t), "fits"),
              "<h3>Coefficients</h3>", _html_table(*_coefficient_rows(t), "coefficients"),
              "<h3>Collinearity of the predictors over the platforms</h3>",
              '<p class="note">Pearson correlations (one point per platform) and variance '
              "inflation factors.</p>",
              _html_table(*_collinearity_rows(t), "collinearity"),
              *_envelope_html(t),
              "<h2>Exit reasons</h2>", _html_table(*_failure_rows(t), "failures"),
              *([f'<p class="note">{e(note)}</p>'] if (note := _absent_reasons_note(t))
                else []),
              "<h2>Metrics of successful trials (median)</h2>",
              _html_table(*_metric_rows(t), "metrics"),
              "<h2>Campaign spec</h2>", f"<pre>{e(spec_text)}</pre>",
              "</body>", "</html>"]
    return "\n".join(parts) + "\n"


def _envelope_html(t: _Tables) -> list[str]:
    if t.envelope is None:
        return []
    e = html.escape
    parts = ["<h2>Capability envelopes</h2>"]
    for title, note, rows, cls in envelope_report.TABLES:
        head, body = rows(t.envelope)
        if body:
            parts += [f"<h3>{e(title)}</h3>", f'<p class="note">{e(note)}</p>',
                      _html_table(head, body, cls)]
    return parts


def _envelope_markdown(t: _Tables) -> list[str]:
    if t.envelope is None:
        return []
    lines = ["## Capability envelopes", ""]
    for title, note, rows, _ in envelope_report.TABLES:
        head, body = rows(t.envelope)
        if body:
            lines += [f"### {title}", "", note, "", md.table(head, body), ""]
    return lines


def _markdown(t: _Tables, facts, figures, spec_text: str, generated: str) -> str:
    lines = ["# FLYINGTRUST benchmark report", "", f"Generated {generated}.", "", "## Run",
             ""]
    lines += [f"- **{k}**: {v}" for k, v in facts]
    lines += ["", "## Composite score", "", md.table(*_score_rows(t)), ""]
    lines += [f"- {n}" for n in _method_notes(t)]
    lines += ["", "## Success per scenario family", "",
              "rate (successes/trials), 95 % percentile-bootstrap and Wilson intervals, "
              "pooled over platforms.", "",
              md.table(*_family_rows(t)), "",
              "## Success against the indicators (logistic regression)", ""]
    lines += [f"- {n}" for n in _regression_notes()]
    lines += ["", "### Readings", ""]
    for algo, readings in _readings(t):
        lines.append(f"- **{algo}**")
        lines += [f"  - {x}" for x in readings]
    lines += ["", "### Fits", "", md.table(*_fit_rows(t)), "", "### Coefficients", "",
              md.table(*_coefficient_rows(t)), "",
              "### Collinearity of the predictors over the platforms", "",
              "Pearson correlations (one point per platform) and variance inflation factors.",
              "", md.table(*_collinearity_rows(t)), "",
              *_envelope_markdown(t),
              "## Exit reasons", "",
              md.table(*_failure_rows(t)), "",
              *([_absent_reasons_note(t), ""] if _absent_reasons_note(t) else []),
              "## Metrics of successful trials (median)", "",
              md.table(*_metric_rows(t)), "", "## Figures", ""]
    for name, caption, _ in figures:
        lines += [f"![{name}]({name}.png)", "", f"*{name}*: {caption} "
                  f"([SVG]({name}.svg))", ""]
    lines += ["## Campaign spec", "", "```yaml", spec_text, "```", ""]
    return "\n".join(lines)


# --------------------------------------------------------------------------- entry
def write_report(df: pd.DataFrame, out_dir, *, campaign_spec: Mapping, meta: Mapping,
                 B: int = 1000, seed: int = 0) -> dict[str, Path]:
    """Write the report of a results table into ``<out_dir>/report/``.

    ``df`` is the table of :func:`ft_sitl.missions.results.to_frame`. ``campaign_spec`` is
    shown as YAML. ``meta`` keys read: ``code_version``, ``machine`` (a mapping, e.g.
    ``{"cpu_model": ..., "n_cpus": ...}``, or a string), ``started_utc``,
    ``finished_utc``, ``wall_time_s`` (campaign wall time), ``trials_run`` (the trials
    flown in that wall time, default: every row; trials per second = trials_run / wall
    time). A key that is absent shows as "not recorded"; other keys are listed as
    given. ``B`` and ``seed`` are the bootstrap's.

    Returns ``{file name: path}`` for every file written (``report.html``, ``summary.md``,
    ``<figure>.png``, ``<figure>.svg``).
    """
    if not isinstance(df, pd.DataFrame):
        raise ValueError(f"write_report: df must be a pandas DataFrame, got {type(df).__name__}")
    if len(df) == 0:
        raise ValueError("write_report: the results table is empty")
    scoring._require_columns(df, _REQUIRED, "write_report")
    if not isinstance(campaign_spec, Mapping):
        raise ValueError("write_report: campaign_spec must be a mapping")
    if not isinstance(meta, Mapping):
        raise ValueError("write_report: meta must be a mapping")

    # matplotlib: heavy, loaded only when plotting
    from matplotlib import rc_context

    rdir = Path(out_dir) / "report"
    rdir.mkdir(parents=True, exist_ok=True)
    t = _Tables(df, B, seed, campaign_spec.get("weights"))
    paths: dict[str, Path] = {}
    rendered = []
    with rc_context(_RC):
        for name, caption, make in _figures(t):
            fig = make(t)
            png, svg = _render(fig)
            fig.clear()
            for ext, data in (("png", png), ("svg", svg)):
                p = rdir / f"{name}.{ext}"
                p.write_bytes(data)
                paths[p.name] = p
            rendered.append((name, caption, png))
    facts = _run_facts(df, meta)
    spec_text = _spec_text(campaign_spec)
    generated = datetime.now(UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
    for fname, text in (("report.html", _html(t, facts, rendered, spec_text, generated)),
                        ("summary.md", _markdown(t, facts, rendered, spec_text, generated))):
        p = rdir / fname
        p.write_text(text, encoding="utf-8")
        paths[fname] = p
    return paths
