"""The acceleration-limit sweep's report: success against the kinodynamic indicators and the
footprint at each protocol acceleration limit (and controller-gain mode), per algorithm.

Reads result directories (``ft-sitl campaign run`` output, or a directory holding only
``trials.parquet``), one condition each -- the campaigns of docs/results/accel-sweep/ fly
``limits.max_acc_m_s2`` = 1.5, 3 and 6 m/s^2 with bandwidth gains and 3 m/s^2 with PX4's
gains -- and writes into ``--out``:

* ``success_vs_indicators_<algorithm>.png``: one panel per indicator (TWR_max,
  alpha_xy,max on a log axis, alpha_z,max, the footprint: what the trial told its
  navigator, the body's half span from protocol 5, else the collision radius), one colour
  per condition: a marker per platform (its success rate over the trials kept) and a line
  through the mean success of the platforms in each bin of the indicator (dashed for
  gains other than bandwidth);
* ``success_vs_indicators.png``: the same for every algorithm, one row each;
* ``summary.md``: the sources, the success rate per algorithm and condition (overall and
  per family), Spearman correlations of per-platform success with each indicator, and an
  OLS regression of per-platform success on the four standardised indicators
  (coefficient per standard deviation, HC3 p-value, R^2), per condition and algorithm,
  with the indicators' variance inflation factors;
* ``per_platform.csv``: the per-platform success table everything above is computed from.

A condition is named by its acceleration limit and gains ("3 m/s^2, bandwidth"); rows of
protocol 1 or 2, which had no protocol limit, are "own limits" (each planner's own).
Only the families given with ``--families`` (default: the three classic ones) count.
Run::

    PYTHONPATH=$PWD .venv/bin/python scripts/accel_sweep_report.py \\
        runs/accel-sweep/acc-1.5 runs/accel-sweep/acc-3 runs/accel-sweep/acc-6 \\
        runs/accel-sweep/acc-3-px4 --out runs/accel-sweep/report

Uses statsmodels (a dependency of ft-sitl, for the campaign report).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from scipy import stats  # noqa: E402

from ft_sitl.autopilot.params import DEFAULT_GAINS  # noqa: E402
from ft_sitl.missions.results import rows_from_parquet, to_frame  # noqa: E402
from ft_sitl.missions.spec import (  # noqa: E402
    TrialSpec,
    platform_for,
    vehicle_half_span_m,
)
from ft_sitl.missions.store import load_rows  # noqa: E402

CLASSIC = ("forest", "urban", "random_angle_cylinder")
#: (column, axis label, log axis)
INDICATORS = (
    ("twr_max", "TWR_max", False),
    ("alpha_xy_max", "alpha_xy,max (rad/s^2)", True),
    ("alpha_z_max", "alpha_z,max (rad/s^2)", False),
    ("footprint_m", "footprint (m)", False),
)
ALGORITHM_ORDER = ("straight", "ego", "fast", "pgo", "navrl")


class SweepError(ValueError):
    """A result directory that cannot be read as one condition of the sweep."""


# --- reading ------------------------------------------------------------------------------
def read_dir(path: Path) -> pd.DataFrame:
    """The trials of one result directory as the typed table (results.to_frame)."""
    path = Path(path)
    if (path / "trials.jsonl").exists():
        _, rows = load_rows(path)
    elif (path / "trials.parquet").exists():
        rows = rows_from_parquet(path / "trials.parquet")
    else:
        raise SweepError(f"{path}: no trials.jsonl or trials.parquet (not a result directory)")
    if not rows:
        raise SweepError(f"{path}: holds no trials")
    return to_frame(rows)


def condition_of(spec: dict) -> tuple[float, str]:
    """(acceleration limit in m/s^2, NaN before protocol 3; gains) of a stored spec."""
    acc = spec.get("limits", {}).get("max_acc_m_s2")
    return (float(acc) if acc is not None else math.nan, spec.get("gains", DEFAULT_GAINS))


def condition_label(acc: float, gains: str) -> str:
    limit = "own limits" if math.isnan(acc) else f"{acc:g} m/s^2"
    return f"{limit}, {gains}"


def load_sweep(dirs, families=CLASSIC) -> pd.DataFrame:
    """Every trial of ``dirs`` in ``families``, with the condition (``max_acc_m_s2``,
    ``gains``, ``condition``), the footprint (``footprint_m``) and the source directory.
    A directory must hold one condition; two directories may not hold the same one."""
    frames, seen = [], {}
    footprint: dict[tuple[str, int], float] = {}
    for d in dirs:
        df = read_dir(d)
        specs = [json.loads(s) for s in df["spec"]]
        conds = {condition_of(s) for s in specs}
        if len(conds) != 1:
            raise SweepError(f"{d}: holds {len(conds)} conditions "
                             f"({', '.join(sorted(condition_label(*c) for c in conds))}); "
                             "give one directory per acceleration limit and gains")
        ((acc, gains),) = conds
        label = condition_label(acc, gains)
        if label in seen:
            raise SweepError(f"{d}: condition {label!r} is also {seen[label]}")
        seen[label] = d
        keys = []
        for s in specs:
            key = (s["platform"], s.get("protocol", 1))
            if key not in footprint:
                spec = TrialSpec.from_dict(s)
                # what the trial told its navigator (protocol 4: the collision radius; 5:
                # the body's half span); before 4 nothing, and the vehicle's collision
                # sphere, so its radius
                footprint[key] = vehicle_half_span_m(spec.protocol, platform_for(spec))
            keys.append(key)
        df["footprint_m"] = [footprint[k] for k in keys]
        df = df[df["family"].astype(str).isin(families)].copy()
        if df.empty:
            raise SweepError(f"{d}: no trials in the families {', '.join(families)}")
        df["max_acc_m_s2"] = acc
        df["condition"] = label
        df["source"] = str(d)
        frames.append(df)
    out = pd.concat(frames, ignore_index=True)
    for c in ("algorithm", "platform", "family", "condition"):
        out[c] = out[c].astype(str)
    return out


def conditions_in_order(df: pd.DataFrame) -> list[str]:
    """Bandwidth gains first, then the others; each by acceleration limit."""
    keys = df[["condition", "max_acc_m_s2", "gains"]].drop_duplicates()
    keys = keys.assign(other=keys["gains"].astype(str) != DEFAULT_GAINS,
                       acc=keys["max_acc_m_s2"].fillna(-1.0))
    return keys.sort_values(["other", "acc"])["condition"].tolist()


def algorithms_in_order(df: pd.DataFrame) -> list[str]:
    names = set(df["algorithm"])
    return [a for a in ALGORITHM_ORDER if a in names] + sorted(names - set(ALGORITHM_ORDER))


# --- aggregation --------------------------------------------------------------------------
def per_platform(df: pd.DataFrame) -> pd.DataFrame:
    """One row per (condition, algorithm, platform): its success rate over the trials kept
    (``success``), their number (``trials``), its category and the four indicators."""
    keys = ["condition", "algorithm", "platform"]
    g = df.groupby(keys, observed=True, sort=False)
    out = g.agg(success=("success", "mean"), trials=("success", "size"),
                category=("platform_category", "first"),
                **{c: (c, "first") for c, _, _ in INDICATORS}).reset_index()
    out["category"] = out["category"].astype(str)
    return out


def _z(x: np.ndarray) -> np.ndarray:
    sd = x.std(ddof=0)
    return (x - x.mean()) / sd if sd > 0 else np.zeros_like(x)


def _design(pp: pd.DataFrame) -> pd.DataFrame:
    """The regressors: the four indicators standardised (alpha_xy in log10)."""
    cols = {}
    for c, _, log in INDICATORS:
        x = pp[c].to_numpy(float)
        cols[c] = _z(np.log10(x) if log else x)
    return pd.DataFrame(cols, index=pp.index)


def correlations(pp: pd.DataFrame) -> pd.DataFrame:
    """Per (condition, algorithm): platforms, mean success and the Spearman rho (and p) of
    per-platform success with each indicator (NaN where success does not vary)."""
    rows = []
    for (cond, alg), g in pp.groupby(["condition", "algorithm"], sort=False):
        r = {"condition": cond, "algorithm": alg, "platforms": len(g),
             "success": float(g["success"].mean())}
        for c, _, _ in INDICATORS:
            if g["success"].nunique() < 2 or g[c].nunique() < 2:
                r[f"rho_{c}"], r[f"p_{c}"] = math.nan, math.nan
            else:
                rho, p = stats.spearmanr(g[c], g["success"])
                r[f"rho_{c}"], r[f"p_{c}"] = float(rho), float(p)
        rows.append(r)
    return pd.DataFrame(rows)


def regressions(pp: pd.DataFrame) -> pd.DataFrame:
    """Per (condition, algorithm): OLS of per-platform success on the four standardised
    indicators (coefficient = change in success rate per standard deviation; HC3 p-values),
    weighted by the trials per platform; ``note`` says why a fit was skipped."""
    import statsmodels.api as sm

    rows = []
    for (cond, alg), g in pp.groupby(["condition", "algorithm"], sort=False):
        r = {"condition": cond, "algorithm": alg, "platforms": len(g), "note": ""}
        x = _design(g)
        k = x.shape[1] + 1
        if g["success"].nunique() < 2:
            r["note"] = f"success is {g['success'].iloc[0]:.2f} on every platform"
        elif len(g) <= k + 1:
            r["note"] = f"{len(g)} platforms: too few for {k} coefficients"
        else:
            fit = sm.WLS(g["success"].to_numpy(float), sm.add_constant(x),
                         weights=g["trials"].to_numpy(float)).fit(cov_type="HC3")
            for c, _, _ in INDICATORS:
                r[f"beta_{c}"], r[f"p_{c}"] = float(fit.params[c]), float(fit.pvalues[c])
            r["r2"] = float(fit.rsquared)
        rows.append(r)
    return pd.DataFrame(rows)


def inflation_factors(pp: pd.DataFrame) -> dict[str, float]:
    """The variance inflation factor of each standardised indicator over the platforms."""
    from statsmodels.stats.outliers_influence import variance_inflation_factor

    plat = pp.drop_duplicates("platform")
    x = _design(plat)
    if len(plat) <= x.shape[1] + 1:
        return {c: math.nan for c, _, _ in INDICATORS}
    xc = np.column_stack([np.ones(len(x)), x.to_numpy()])
    return {c: float(variance_inflation_factor(xc, i + 1)) for i, (c, _, _) in
            enumerate(INDICATORS)}


# --- plots --------------------------------------------------------------------------------
def binned_means(x: np.ndarray, y: np.ndarray, log: bool, bins: int = 6):
    """(bin centre, mean y) over quantile bins of x (log10 x when ``log``)."""
    u = np.log10(x) if log else x
    n = min(bins, len(np.unique(u)))
    if n < 2:
        return np.array([x.mean()]), np.array([y.mean()])
    edges = np.unique(np.quantile(u, np.linspace(0, 1, n + 1)))
    which = np.clip(np.searchsorted(edges, u, side="right") - 1, 0, len(edges) - 2)
    cx, cy = [], []
    for b in range(len(edges) - 1):
        m = which == b
        if m.any():
            cx.append(u[m].mean())
            cy.append(y[m].mean())
    cx = np.array(cx)
    return (10 ** cx if log else cx), np.array(cy)


def _panel_row(axes, pp_alg: pd.DataFrame, conditions: list[str], colours: dict) -> None:
    for ax, (c, label, log) in zip(axes, INDICATORS, strict=True):
        for cond in conditions:
            g = pp_alg[pp_alg["condition"] == cond]
            if g.empty:
                continue
            x, y = g[c].to_numpy(float), g["success"].to_numpy(float)
            ax.scatter(x, y, s=14, alpha=0.45, color=colours[cond])
            bx, by = binned_means(x, y, log)
            style = "-o" if cond.endswith(f", {DEFAULT_GAINS}") else "--s"  # other gains
            ax.plot(bx, by, style, ms=3, lw=1.6, color=colours[cond], label=cond)
        if log:
            ax.set_xscale("log")
        ax.set_xlabel(label)
        ax.set_ylim(-0.05, 1.05)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("success rate")


def plot(pp: pd.DataFrame, out: Path, conditions: list[str], algorithms: list[str]) -> list:
    cmap = plt.get_cmap("viridis")
    bw = [c for c in conditions if c.endswith(f", {DEFAULT_GAINS}")]
    colours = {c: cmap(0.1 + 0.8 * i / max(1, len(bw) - 1)) for i, c in enumerate(bw)}
    others = [c for c in conditions if c not in colours]
    for i, c in enumerate(others):
        colours[c] = ("tab:red", "tab:orange", "tab:purple", "tab:brown")[i % 4]
    written = []
    for alg in algorithms:
        fig, axes = plt.subplots(1, 4, figsize=(16, 3.6), sharey=True)
        _panel_row(axes, pp[pp["algorithm"] == alg], conditions, colours)
        axes[0].legend(fontsize=8, loc="best")
        fig.suptitle(f"{alg}: per-platform success against the indicators, per "
                     "acceleration limit and gains")
        fig.tight_layout()
        path = out / f"success_vs_indicators_{alg}.png"
        fig.savefig(path, dpi=110)
        plt.close(fig)
        written.append(path)
    fig, axes = plt.subplots(len(algorithms), 4, figsize=(16, 3.1 * len(algorithms)),
                             sharey=True, squeeze=False)
    for row, alg in zip(axes, algorithms, strict=True):
        _panel_row(row, pp[pp["algorithm"] == alg], conditions, colours)
        row[0].set_ylabel(f"{alg}\nsuccess rate")
    axes[0, 0].legend(fontsize=8, loc="best")
    fig.tight_layout()
    path = out / "success_vs_indicators.png"
    fig.savefig(path, dpi=100)
    plt.close(fig)
    written.append(path)
    return written


# --- the markdown -------------------------------------------------------------------------
def _f(v, fmt: str = "{:.2f}") -> str:
    return "" if v is None or (isinstance(v, float) and math.isnan(v)) else fmt.format(v)


def _table(header: list[str], rows: list[list[str]], text: int = 1) -> list[str]:
    """A markdown table, its first ``text`` columns left-aligned, the others right."""
    out = ["| " + " | ".join(header) + " |",
           "|" + "|".join("---" if i < text else "---:" for i in range(len(header))) + "|"]
    out += ["| " + " | ".join(r) + " |" for r in rows]
    return out


def _coef(beta, p) -> str:
    if beta is None or (isinstance(beta, float) and math.isnan(beta)):
        return ""
    star = "**" if p < 0.01 else ("*" if p < 0.05 else "")
    return f"{star}{beta:+.2f}{star} ({p:.2g})"


def markdown(df: pd.DataFrame, pp: pd.DataFrame, conditions: list[str],
             algorithms: list[str]) -> str:
    short = {"twr_max": "TWR", "alpha_xy_max": "α_xy (log)", "alpha_z_max": "α_z",
             "footprint_m": "footprint"}
    lines = ["# Acceleration-limit sweep", "",
             f"Families: {', '.join(sorted(df['family'].unique()))}. Per-platform success is "
             "the share of its trials in these families that succeeded.", "", "## Sources", ""]
    src = df.groupby("condition", sort=False).agg(
        source=("source", "first"), trials=("success", "size"),
        protocol=("protocol_version", "first"), campaign=("campaign", "first"))
    lines += _table(["condition", "directory", "campaign", "protocol", "trials"], text=3, rows=
                    [[c, f"`{src.loc[c, 'source']}`", str(src.loc[c, "campaign"]),
                      str(src.loc[c, "protocol"]), str(src.loc[c, "trials"])]
                     for c in conditions])
    lines += ["", "## Success rate", ""]
    rate = df.groupby(["algorithm", "condition"])["success"].mean().unstack()
    lines += _table(["algorithm"] + conditions,
                    [[a] + [_f(rate.loc[a].get(c)) for c in conditions] for a in algorithms])
    fam = df.groupby(["algorithm", "family", "condition"])["success"].mean().unstack()
    lines += ["", "Per family:", ""]
    lines += _table(["algorithm", "family"] + conditions,
                    [[a, f] + [_f(fam.loc[(a, f)].get(c)) for c in conditions]
                     for a in algorithms for f in sorted(df["family"].unique())
                     if (a, f) in fam.index], text=2)
    cor = correlations(pp)
    lines += ["", "## Spearman correlation of per-platform success with each indicator", "",
              "rho (p); empty where success does not vary.", ""]
    for alg in algorithms:
        sub = cor[cor["algorithm"] == alg].set_index("condition")
        lines += [f"**{alg}**", ""]
        lines += _table(["condition", "platforms", "success"] + [short[c] for c, _, _ in
                                                                INDICATORS],
                        [[c, str(sub.loc[c, "platforms"]), _f(sub.loc[c, "success"])] +
                         [(f"{sub.loc[c, f'rho_{k}']:+.2f} ({sub.loc[c, f'p_{k}']:.2g})"
                           if not math.isnan(sub.loc[c, f"rho_{k}"]) else "")
                          for k, _, _ in INDICATORS]
                         for c in conditions if c in sub.index])
        lines.append("")
    reg = regressions(pp)
    lines += ["## OLS of per-platform success on the standardised indicators", "",
              "Coefficient: change in success rate per standard deviation of the indicator "
              "(α_xy in log10), the others held fixed; HC3 p-value in brackets; * p < 0.05, "
              "** p < 0.01.", ""]
    for alg in algorithms:
        sub = reg[reg["algorithm"] == alg].set_index("condition")
        lines += [f"**{alg}**", ""]
        rows = []
        for c in conditions:
            if c not in sub.index:
                continue
            r = sub.loc[c]
            if r["note"]:
                rows.append([c, str(r["platforms"])] + [""] * len(INDICATORS) +
                            [r["note"]])
            else:
                rows.append([c, str(r["platforms"])] +
                            [_coef(r[f"beta_{k}"], r[f"p_{k}"]) for k, _, _ in INDICATORS] +
                            [f"R² {r['r2']:.2f}"])
        lines += _table(["condition", "platforms"] + [short[c] for c, _, _ in INDICATORS] +
                        ["fit"], rows)
        lines.append("")
    vif = inflation_factors(pp)
    lines += ["Variance inflation factors of the standardised indicators over the platforms "
              "(above ~5, the coefficients of correlated indicators share their effect and "
              "their p-values grow): " +
              ", ".join(f"{short[c]} {_f(v, '{:.1f}')}" for c, v in vif.items()) + ".", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dirs", nargs="+", type=Path, help="result directories, one per condition")
    ap.add_argument("--out", type=Path, required=True, help="directory for the report")
    ap.add_argument("--families", nargs="+", default=list(CLASSIC),
                    help="scenario families that count (default: the three classic ones)")
    args = ap.parse_args(argv)
    try:
        df = load_sweep(args.dirs, tuple(args.families))
    except SweepError as exc:
        print(f"accel_sweep_report: error: {exc}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    conditions, algorithms = conditions_in_order(df), algorithms_in_order(df)
    pp = per_platform(df)
    pp.to_csv(args.out / "per_platform.csv", index=False)
    figures = plot(pp, args.out, conditions, algorithms)
    (args.out / "summary.md").write_text(markdown(df, pp, conditions, algorithms))
    print(f"{len(df)} trials, {len(conditions)} conditions ({'; '.join(conditions)}), "
          f"{len(algorithms)} algorithms: wrote {args.out / 'summary.md'}, "
          f"{args.out / 'per_platform.csv'} and {len(figures)} figures")
    return 0


if __name__ == "__main__":
    sys.exit(main())
