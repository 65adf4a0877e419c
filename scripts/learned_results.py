"""The learned navigator against the five algorithms (issue 25's results): tables and
figures for docs/results/learned/.

Reads the rows of the campaigns that flew ``learned`` (``--learned DIR [DIR ...]``: their
rows together, each trial once) and the rows of the paper matrix (``--others DIR``),
keeps the other algorithms' rows of the cells the learned campaigns flew (platform,
family, configuration), and writes into ``--out``:

* ``comparison.md``: success per family and algorithm (with the number of trials), mean
  speed of the successful flights, the spread of per-platform success, and the logistic
  regression of success on the indicators per algorithm
  (:func:`ft_sitl.missions.regression.fit_success_models`);
* ``success_by_family.png``, ``success_by_platform.png`` (per-platform success against
  TWR_max and against the footprint, one panel per algorithm);
* ``rows.parquet``: the rows compared.

Run::

    PYTHONPATH=$PWD .venv/bin/python scripts/learned_results.py \\
        --learned runs/learned-v1-sample runs/learned-v1-rest --others docs/results/paper \\
        --out docs/results/learned

A directory is read from its ``trials.jsonl`` (a campaign being flown) or, without one,
its ``trials.parquet`` (a committed result).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after the backend)
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from ft_sitl.missions.regression import (  # noqa: E402
    coefficient_table,
    fit_success_models,
    footprints,
)
from ft_sitl.missions.results import rows_from_parquet  # noqa: E402

ORDER = ["straight", "ego", "fast", "pgo", "navrl", "learned"]
CELL = ["platform", "family", "scenario_index"]


def rows(directory: Path) -> pd.DataFrame:
    live = directory / "trials.jsonl"
    if live.exists():
        with open(live) as f:
            return pd.DataFrame([json.loads(line) for line in f if line.strip()])
    return pd.DataFrame(rows_from_parquet(directory / "trials.parquet"))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--learned", type=Path, nargs="+", required=True)
    ap.add_argument("--others", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args()
    learned = pd.concat([rows(d) for d in a.learned], ignore_index=True)
    learned = learned.drop_duplicates("trial_id")
    learned = learned[learned.algorithm == "learned"]
    others = rows(a.others)
    cells = learned[CELL].drop_duplicates()
    others = others.merge(cells, on=CELL)
    df = pd.concat([others, learned], ignore_index=True)
    # the cells every algorithm has flown (the paper run may not have reached them all)
    n_algo = df.algorithm.nunique()
    per_cell = df.groupby(CELL).algorithm.nunique()
    common = per_cell[per_cell == n_algo].reset_index()[CELL]
    df["success"] = df["reason"] == "success"
    df["footprint_m"] = footprints(df)
    a.out.mkdir(parents=True, exist_ok=True)
    df.drop(columns=["spec"], errors="ignore").to_parquet(a.out / "rows.parquet")
    algos = [x for x in ORDER if x in set(df.algorithm)]
    out = []

    # success per family
    t = df.groupby(["family", "algorithm"]).success.agg(["mean", "size"]).reset_index()
    tab = t.pivot(index="family", columns="algorithm", values="mean")[algos]
    n = t.pivot(index="family", columns="algorithm", values="size")[algos]
    out.append("## Success per family\n")
    out.append("Success rate (trials)." + (
        "" if len(common) == len(cells) else
        " Cells the paper run has not flown for every algorithm count only for the "
        "algorithms that flew them; the last line keeps the cells all have flown.") + "\n")
    out.append("| family | " + " | ".join(algos) + " |")
    out.append("|---|" + "---|" * len(algos))
    for fam in tab.index:
        cells_txt = [f"{tab.loc[fam, x]:.2f} ({int(n.loc[fam, x])})"
                     if not np.isnan(tab.loc[fam, x]) else "-" for x in algos]
        out.append(f"| {fam} | " + " | ".join(cells_txt) + " |")
    both = df.merge(common, on=CELL)
    full = sorted(set(both.family))
    if len(both):
        tot = both.groupby("algorithm").success.agg(["mean", "size"])
        out.append("| **cells all have flown** | " + " | ".join(
            f"**{tot.loc[x, 'mean']:.2f}** ({int(tot.loc[x, 'size'])})" for x in algos) + " |")
    out.append("")

    # speed
    ok = df[df.success]
    sp = ok.groupby("algorithm").mean_speed_m_s.median()
    out.append("## How fast the successful flights are\n")
    out.append("Median of the successful trials' mean speed (m/s): " + ", ".join(
        f"{x} {sp[x]:.2f}" for x in algos if x in sp.index) + ".\n")

    # platform dependence
    out.append("## Does success depend on the platform?\n")
    out.append("Per algorithm, over the cells every algorithm has flown: the spread "
               "of per-platform success (standard deviation over the 36 platforms) and "
               "its correlation with the platform's TWR_max, log alpha_xy,max, "
               "alpha_z,max and footprint.\n")
    out.append("| algorithm | success | sd over platforms | r(TWR) | r(log alpha_xy) | "
               "r(alpha_z) | r(footprint) |")
    out.append("|---|---|---|---|---|---|---|")
    for x in algos:
        g = both[both.algorithm == x]
        if g.empty:
            continue
        per = g.groupby("platform").agg(s=("success", "mean"), twr=("twr_max", "first"),
                                        axy=("alpha_xy_max", "first"),
                                        az=("alpha_z_max", "first"),
                                        fp=("footprint_m", "first"))
        r = [per.s.corr(per.twr), per.s.corr(np.log(per.axy)), per.s.corr(per.az),
             per.s.corr(per.fp)]
        out.append(f"| {x} | {g.success.mean():.2f} | {per.s.std():.2f} | " + " | ".join(
            f"{v:+.2f}" if np.isfinite(v) else "-" for v in r) + " |")
    out.append("")
    coef = coefficient_table(fit_success_models(both))
    out.append("Logistic regression of success on the indicators with the family as a "
               "factor (docs/scoring.md, \"Success against the indicators\"): odds ratio "
               "per step [95 % interval], p.\n")
    out.append("| algorithm | indicator | per | odds ratio | p | method |")
    out.append("|---|---|---|---|---|---|")
    for _, r in coef.iterrows():
        if np.isnan(r.odds_ratio):
            txt, p = "not fitted", "-"
        else:
            txt, p = f"{r.odds_ratio:.2f} [{r.or_lo:.2f}, {r.or_hi:.2f}]", f"{r.p:.3f}"
        out.append(f"| {r.algorithm} | {r.indicator} | {r.per} | {txt} | {p} | "
                   f"{r.method} |")
    out.append("")
    (a.out / "comparison.md").write_text("\n".join(out) + "\n")

    # figures
    fig, ax = plt.subplots(figsize=(9, 4))
    w = 0.8 / len(algos)
    fams = list(tab.index)
    for k, x in enumerate(algos):
        ax.bar(np.arange(len(fams)) + k * w, tab[x].fillna(0).to_numpy(), w, label=x)
    ax.set_xticks(np.arange(len(fams)) + 0.4 - w / 2, fams, rotation=20)
    ax.set_ylabel("success rate")
    ax.set_ylim(0, 1)
    ax.legend(fontsize=8, ncol=3)
    ax.set_title("success per family (same platforms and configurations)")
    fig.tight_layout()
    fig.savefig(a.out / "success_by_family.png", dpi=100)
    plt.close(fig)

    fig, axes = plt.subplots(2, len(algos), figsize=(2.6 * len(algos), 5), sharey=True)
    for k, x in enumerate(algos):
        g = both[both.algorithm == x]
        per = g.groupby("platform").agg(s=("success", "mean"), twr=("twr_max", "first"),
                                        fp=("footprint_m", "first"))
        axes[0, k].scatter(per.twr, per.s, s=12)
        axes[0, k].set_title(x, fontsize=9)
        axes[0, k].set_xlabel("TWR_max", fontsize=8)
        axes[1, k].scatter(per.fp, per.s, s=12, color="tab:orange")
        axes[1, k].set_xlabel("footprint (m)", fontsize=8)
    axes[0, 0].set_ylabel("per-platform success")
    axes[1, 0].set_ylabel("per-platform success")
    fig.suptitle(f"per-platform success over the cells all have flown ({', '.join(full)})",
                 fontsize=9)
    fig.tight_layout()
    fig.savefig(a.out / "success_by_platform.png", dpi=100)
    plt.close(fig)
    print(f"wrote {a.out}/comparison.md and figures ({len(df)} rows)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
