"""The capability-envelope figures (tables from :mod:`ft_sitl.missions.envelope`):

* :func:`fig_dose_response` -- success against the indicator a series varies, one panel
  per algorithm (columns) and family (rows), one line per aggressiveness level, one
  line style per body, 95 % Wilson bars, log x.
* :func:`fig_envelope` -- the envelope: per algorithm (columns) and series kind (rows),
  the smallest indicator value from which success stays within 10 points of the series'
  best, against the level, one line per family and body, bootstrap bars; a reader finds
  a vehicle's TWR_max (or alpha_xy,max) on the y axis and reads off the levels and
  families above whose lines it lies.
* :func:`fig_level_tolerance` -- per algorithm, each catalog platform's success at every
  level relative to its gentlest level's, platforms sorted by TWR_max.

Figures are :class:`matplotlib.figure.Figure` objects (no pyplot; this module loads
matplotlib, so the report imports it only when it draws), drawn with text no
smaller than the report's :data:`~ft_sitl.missions.report.MIN_FONT_PT`.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FixedLocator, NullLocator

from ft_sitl.missions.envelope import KIND_LABEL, level_order

#: the smallest text (pt): the report's
MIN_FONT_PT = 7.0
_STYLES = ("-", "--", ":", "-.")


def _figure(w: float, h: float):
    return Figure(figsize=(w, h), layout="constrained")


def _plain_log_ticks(axis, values) -> None:
    """Log scale with ticks at ``values`` printed plainly (``1.5``, ``348``), no minor
    ticks: the members' own values, not powers of ten over each other."""
    vals = sorted({float(f"{v:.4g}") for v in values if np.isfinite(v) and v > 0})
    if not vals:
        return
    if len(vals) > 7:  # keep every other one, the ends included
        vals = vals[::2] + ([vals[-1]] if len(vals) % 2 == 0 else [])
    axis.set_major_locator(FixedLocator(vals))
    axis.set_minor_locator(NullLocator())
    axis.set_ticklabels([f"{v:.3g}" for v in vals])


def _grid(fig, nrows: int, ncols: int):
    axes = fig.subplots(nrows, ncols, squeeze=False, sharey="row")
    return axes


def fig_dose_response(dose: pd.DataFrame, kind: str):
    """Success against the varied indicator (``kind``: twr or axy), per algorithm and
    family, one colour per level, one line style per body."""
    d = dose[dose["kind"] == kind]
    algos = sorted(d["algorithm"].unique())
    fams = sorted(d["family"].unique())
    levels = level_order(d["level"])
    bases = sorted(d["base"].unique())
    fig = _figure(2.6 * max(1, len(algos)) + 1.2, 2.1 * max(1, len(fams)) + 0.6)
    if d.empty:
        ax = fig.subplots()
        ax.text(0.5, 0.5, "no series rows", ha="center", va="center")
        ax.set_axis_off()
        return fig
    cmap = colormaps["plasma"]
    colours = {lv: cmap(0.85 * i / max(1, len(levels) - 1)) for i, lv in enumerate(levels)}
    axes = _grid(fig, len(fams), len(algos))
    for r, fam in enumerate(fams):
        for c, algo in enumerate(algos):
            ax = axes[r][c]
            cell = d[(d["family"] == fam) & (d["algorithm"] == algo)]
            for lv in levels:
                for b, base in enumerate(bases):
                    g = cell[(cell["level"] == lv) & (cell["base"] == base)].sort_values("value")
                    if g.empty:
                        continue
                    x, y = g["value"].to_numpy(), g["rate"].to_numpy()
                    yerr = np.vstack([y - g["lo"].to_numpy(), g["hi"].to_numpy() - y])
                    ax.errorbar(x, y, yerr=np.clip(yerr, 0, None), color=colours[lv],
                                linestyle=_STYLES[b % len(_STYLES)], marker="o",
                                markersize=3, capsize=2, linewidth=1.2)
            ax.set_xscale("log")
            _plain_log_ticks(ax.xaxis, d["value"])
            ax.set_ylim(-0.05, 1.05)
            ax.set_title(f"{algo} · {fam}", fontsize=9)
            ax.tick_params(labelsize=MIN_FONT_PT + 1)
            if r == len(fams) - 1:
                ax.set_xlabel(KIND_LABEL[kind], fontsize=9)
            if c == 0:
                ax.set_ylabel("success", fontsize=9)
    _legend(fig, levels, colours, bases)
    return fig


def _legend(fig, levels, colours, bases):
    handles = [Line2D([], [], color=colours[lv], marker="o", label=f"level {lv}")
               for lv in levels]
    handles += [Line2D([], [], color="0.3", linestyle=_STYLES[b % len(_STYLES)],
                       label=f"body {base}") for b, base in enumerate(bases)]
    fig.legend(handles=handles, loc="outside right center", fontsize=8, frameon=False)


def fig_envelope(env: pd.DataFrame):
    """The envelope: the threshold against the level, per algorithm (columns) and series
    kind (rows), one colour per family and one line style per body, bootstrap bars."""
    algos = sorted(env["algorithm"].unique())
    kinds = [k for k in ("twr", "axy") if k in set(env["kind"])]
    fig = _figure(2.8 * max(1, len(algos)) + 1.8, 2.4 * max(1, len(kinds)) + 0.6)
    if env.empty:
        ax = fig.subplots()
        ax.text(0.5, 0.5, "no series rows", ha="center", va="center")
        ax.set_axis_off()
        return fig
    levels = level_order(env["level"])
    fams = sorted(env["family"].unique())
    bases = sorted(env["base"].unique())
    cmap = colormaps["tab10"]
    colours = {f: cmap(i % 10) for i, f in enumerate(fams)}
    axes = _grid(fig, len(kinds), len(algos))
    xs = {lv: i for i, lv in enumerate(levels)}
    for r, kind in enumerate(kinds):
        for c, algo in enumerate(algos):
            ax = axes[r][c]
            cell = env[(env["kind"] == kind) & (env["algorithm"] == algo)]
            for fi, fam in enumerate(fams):
                for b, base in enumerate(bases):
                    g = cell[(cell["family"] == fam) & (cell["base"] == base)]
                    if g.empty:
                        continue
                    g = g.assign(x=g["level"].map(xs)).sort_values("x")
                    x = g["x"].to_numpy() + 0.06 * (fi - (len(fams) - 1) / 2)
                    y = g["threshold"].to_numpy()
                    yerr = np.vstack([y - g["lo"].to_numpy(), g["hi"].to_numpy() - y])
                    ax.errorbar(x, y, yerr=np.clip(yerr, 0, None), color=colours[fam],
                                linestyle=_STYLES[b % len(_STYLES)], marker="o",
                                markersize=3, capsize=2, linewidth=1.2)
            ax.set_yscale("log")
            _plain_log_ticks(ax.yaxis, env.loc[env["kind"] == kind, "threshold"])
            ax.set_xticks(range(len(levels)), levels, fontsize=MIN_FONT_PT + 1)
            ax.tick_params(labelsize=MIN_FONT_PT + 1)
            ax.set_title(algo, fontsize=9)
            if c == 0:
                ax.set_ylabel(f"smallest {KIND_LABEL[kind]}\nwithin 10 pts of the best",
                              fontsize=9)
            if r == len(kinds) - 1:
                ax.set_xlabel("aggressiveness level", fontsize=9)
    handles = [Line2D([], [], color=colours[f], marker="o", label=f) for f in fams]
    handles += [Line2D([], [], color="0.3", linestyle=_STYLES[b % len(_STYLES)],
                       label=f"body {base}") for b, base in enumerate(bases)]
    fig.legend(handles=handles, loc="outside right center", fontsize=8, frameon=False)
    return fig


def fig_level_tolerance(tol: pd.DataFrame):
    """Per algorithm (a panel each): every catalog platform's success at each level as a
    fraction of its gentlest level's (a heat map; platforms sorted by TWR_max)."""
    algos = sorted(tol["algorithm"].unique())
    rate_cols = [c for c in tol.columns if c.startswith("rate_")]
    levels = level_order([c[len("rate_"):] for c in rate_cols])
    n_plat = tol["platform"].nunique()
    fig = _figure(1.0 + 1.9 * max(1, len(algos)), 0.9 + 0.17 * max(1, n_plat))
    if tol.empty:
        ax = fig.subplots()
        ax.text(0.5, 0.5, "no catalog rows", ha="center", va="center")
        ax.set_axis_off()
        return fig
    axes = fig.subplots(1, len(algos), squeeze=False, sharey=True)[0]
    order = tol.drop_duplicates("platform").sort_values("twr_max")["platform"].tolist()
    im = None
    for ax, algo in zip(axes, algos, strict=True):
        g = tol[tol["algorithm"] == algo].set_index("platform").reindex(order)
        base = g["gentlest_rate"].to_numpy()
        m = np.column_stack([g[f"rate_{lv}"].to_numpy() if f"rate_{lv}" in g else
                             np.full(len(g), np.nan) for lv in levels])
        with np.errstate(invalid="ignore", divide="ignore"):
            rel = np.where(base[:, None] > 0, m / base[:, None], np.nan)
        im = ax.imshow(rel, aspect="auto", cmap="RdYlGn", vmin=0.0, vmax=1.2,
                       interpolation="nearest")
        ax.set_xticks(range(len(levels)), levels, rotation=45, ha="right",
                      fontsize=MIN_FONT_PT + 1)
        ax.set_yticks(range(len(order)), order, fontsize=MIN_FONT_PT)
        ax.set_title(algo, fontsize=9)
    if im is not None:
        cb = fig.colorbar(im, ax=list(axes), shrink=0.6)
        cb.set_label("success / success at the gentlest level", fontsize=8)
        cb.ax.tick_params(labelsize=MIN_FONT_PT + 1)
    return fig
