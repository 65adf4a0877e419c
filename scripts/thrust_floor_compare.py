"""Issue 44: the same envelope trials flown with PX4's one thrust floor and with each
platform's own (``thrust_floor = "weight"``), paired trial by trial.

The two campaigns share every setting but the floor, so a trial of one has its twin in the
other: the same platform, planner, family, configuration, trial number and level, and the
same seed (the floor is a parameter, not part of the seed). Only the platforms whose floor
changes (TWR_max above 3: the TWR-4 and TWR-6 members and the alpha series) fly
differently; the others are the same rows. For each changed platform group, family and
level: the success of each, the discordant pairs (succeeded under one floor only), an
exact McNemar p (binomial test on the discordant pairs) and how the failures ended::

    .venv/bin/python scripts/thrust_floor_compare.py PX4_DIR WEIGHT_DIR --out DIR
"""

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import argparse  # noqa: E402
import json  # noqa: E402
from pathlib import Path  # noqa: E402

import pandas as pd  # noqa: E402
from scipy.stats import binomtest  # noqa: E402

from ft_sitl.missions.results import rows_from_parquet, to_frame  # noqa: E402
from ft_sitl.missions.store import load_rows  # noqa: E402

#: what pairs two trials: everything but the floor
PAIR = ["platform", "algorithm", "family", "scenario_index", "trial", "aggressiveness"]


def _rows(directory: Path) -> pd.DataFrame:
    rows = (load_rows(directory)[1] if (directory / "trials.jsonl").exists()
            else rows_from_parquet(directory / "trials.parquet"))
    return to_frame(rows)


def _floor(params) -> float:
    """A row's MPC_THR_MIN: from its params column (JSON), PX4's 0.12 where none is set."""
    if isinstance(params, str) and params:
        params = json.loads(params)
    return float(params.get("MPC_THR_MIN", 0.12)) if isinstance(params, dict) else 0.12


def _group(platform: str) -> str:
    """The series member's group: its TWR step or the alpha series, and its body."""
    body = "small" if "0.55kg" in platform else "large"
    step = platform.rsplit("-", 1)[1]
    return f"{'alpha series' if step.startswith('axy') else step.replace('twr', 'TWR ')}, {body}"


def paired(px4: pd.DataFrame, weight: pd.DataFrame) -> pd.DataFrame:
    """One line per trial twin whose floors differ, with both outcomes."""
    a = px4.assign(floor=px4["params"].map(_floor))
    b = weight.assign(floor=weight["params"].map(_floor))
    keep = ["success", "reason", "saturation_fraction", "floor", "trial_id"]
    m = a[PAIR + keep].merge(b[PAIR + keep], on=PAIR, suffixes=("_px4", "_weight"))
    changed = m[m["floor_px4"] != m["floor_weight"]].copy()
    same = m[m["floor_px4"] == m["floor_weight"]]
    # the unchanged twins are one trial (one id, reused): a check that the pairing is right
    assert (same["trial_id_px4"] == same["trial_id_weight"]).all()
    changed["group"] = changed["platform"].map(_group)
    return changed


def summary(changed: pd.DataFrame) -> pd.DataFrame:
    out = []
    by = ["group", "floor_weight", "family", "aggressiveness"]
    for key, g in changed.groupby(by, observed=True, sort=True):
        s_px4, s_w = g["success_px4"].astype(bool), g["success_weight"].astype(bool)
        only_w, only_px4 = int((s_w & ~s_px4).sum()), int((s_px4 & ~s_w).sum())
        n_disc = only_w + only_px4
        p = binomtest(only_w, n_disc).pvalue if n_disc else 1.0
        out.append({
            **dict(zip(by, key, strict=True)), "n": len(g),
            "success_px4": round(s_px4.mean(), 3), "success_weight": round(s_w.mean(), 3),
            "weight_only": only_w, "px4_only": only_px4, "mcnemar_p": round(p, 4),
            "out_of_bounds_px4": int((g["reason_px4"] == "out_of_bounds").sum()),
            "out_of_bounds_weight": int((g["reason_weight"] == "out_of_bounds").sum()),
            "collision_px4": int((g["reason_px4"] == "collision").sum()),
            "collision_weight": int((g["reason_weight"] == "collision").sum()),
        })
    return pd.DataFrame(out)


def markdown(t: pd.DataFrame) -> str:
    lines = ["| group | floor | family | level | n | success px4 | success weight | "
             "weight only | px4 only | McNemar p | out of bounds px4 / weight | "
             "collisions px4 / weight |", "|" + "---|" * 4 + "---:|" * 8]
    for r in t.itertuples():
        lines.append(
            f"| {r.group} | {r.floor_weight:.2f} | {r.family} | {r.aggressiveness} | {r.n} | "
            f"{r.success_px4:.2f} | {r.success_weight:.2f} | {r.weight_only} | "
            f"{r.px4_only} | {r.mcnemar_p:.3g} | {r.out_of_bounds_px4} / "
            f"{r.out_of_bounds_weight} | {r.collision_px4} / {r.collision_weight} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("px4", type=Path, help="the campaign's result directory, PX4's floor")
    ap.add_argument("weight", type=Path, help="the same campaign with thrust_floor = weight")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args()
    changed = paired(_rows(args.px4), _rows(args.weight))
    t = summary(changed)
    args.out.mkdir(parents=True, exist_ok=True)
    changed.to_csv(args.out / "pairs.csv", index=False)
    t.to_csv(args.out / "compare.csv", index=False)
    (args.out / "compare.md").write_text(markdown(t))
    print(f"{len(changed)} trial pairs whose floors differ -> {args.out}")
    print(markdown(t))


if __name__ == "__main__":
    main()
