"""A learned policy on the paper's cells in the Gymnasium environment: every catalog
platform in every benchmark configuration (7 families x 10, seed 0: never seen in
training), 2,520 episodes judged by the referee's rules, with the scan cast into the true
world as in training. It separates what the policy can do from what its perception in
trials (the scan cast into the depth camera's map) costs it.

``--blind`` also flies every episode with the platform vector replaced by the catalog's
middle (0.5 for each component): how much the policy's success depends on knowing its
vehicle. Writes ``eval.parquet`` (one row per episode: family, index, platform, outcome,
detail, time, blind) and ``eval.md`` (success per family, the spread of per-platform
success and its correlations with the indicators); ``--summary`` rewrites eval.md from
eval.parquet.

    PYTHONPATH=$PWD .venv/bin/python scripts/learned_eval.py [--policy v1] --out DIR [--blind]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import numpy as np
import pandas as pd
from tqdm import tqdm

from ft_sitl.gym.envs import NavigateVectorEnv
from ft_sitl.gym.train import ENV_DEFAULTS
from ft_sitl.missions.spec import PROTOCOL_VERSION, vehicle_half_span_m
from ft_sitl.navigation.learned.learned import load_policy
from ft_sitl.navigation.learned.policy_io import EDGE_NAMES, N_STATE, PLATFORM_NAMES, policy_input
from ft_sitl.physics.catalog import catalog
from ft_sitl.scenarios.families import REGISTRY

PLATFORM_SLICE = slice(N_STATE + len(EDGE_NAMES), N_STATE + len(EDGE_NAMES)
                       + len(PLATFORM_NAMES))


def fly(policy, family: str, index: int, platforms, blind: bool) -> list[dict]:
    m = policy.meta
    env = NavigateVectorEnv(len(platforms), autoreset_mode="SameStep",
                            **{**ENV_DEFAULTS, **{k: m["env"][k] for k in m["env"]},
                               "family": family, "scenario_index": [index, index],
                               "scenario_seed": [0, 0]})
    obs, _ = env.reset(seed=index)
    for i, p in enumerate(platforms):
        mask = np.zeros(len(platforms), bool)
        mask[i] = True
        o, _ = env.reset(options={"platform": p, "reset_mask": mask})
        for k in obs:
            obs[k][i] = o[k][i]
    live = np.ones(len(platforms), bool)
    rows = []
    while live.any():
        x = policy_input(obs["state"], obs["edges"], obs["platform"], obs["last_action"],
                         obs["rays"])
        if blind:
            x[:, PLATFORM_SLICE] = 0.5
        obs, _, term, trunc, info = env.step(policy.act(x).astype(np.float32))
        for i in np.flatnonzero(live & (term | trunc)):
            fin = info["final_info"]
            rows.append({"family": family, "scenario_index": index,
                         "platform": platforms[i].name, "outcome": fin["outcome"][i],
                         "detail": fin["detail"][i], "time_s": float(fin["time_s"][i]),
                         "blind": blind})
        live &= ~(term | trunc)
    env.close()
    return rows


def summary(df: pd.DataFrame) -> str:
    """Markdown: success per family (and platform-blind), the outcomes, and the spread of
    per-platform success with its correlations with the indicators."""
    df = df.assign(success=df.outcome == "success")
    out = ["| family | success | success, platform-blind |", "|---|---:|---:|"]
    fam = df.groupby(["family", "blind"]).success.mean().unstack()
    for f, r in fam.iterrows():
        out.append(f"| {f} | {r[False]:.2f} | " + (f"{r[True]:.2f} |" if True in r else "- |"))
    tot = df.groupby("blind").success.mean()
    out.append(f"| **all** | **{tot[False]:.2f}** | " + (f"**{tot[True]:.2f}** |"
                                                         if True in tot else "- |"))
    out += ["", "| platform vector | per-platform success: mean | sd | min | max | r(TWR) "
            "| r(log alpha_xy) | r(alpha_z) | r(footprint) |", "|---|---|---|---|---|---|---|"
            "---|---|"]
    cat = catalog()
    ind = pd.DataFrame({n: {"twr": p.indicators().twr_max,
                            "axy": np.log(p.indicators().alpha_xy_max_rad_s2),
                            "az": p.indicators().alpha_z_max_rad_s2,
                            "fp": vehicle_half_span_m(PROTOCOL_VERSION, p)}
                        for n, p in cat.items()}).T
    for b, g in df.groupby("blind"):
        per = g.groupby("platform").success.mean()
        x = ind.loc[per.index]
        label = "0.5 (blind)" if b else "the platform's"
        out.append(f"| {label} | {per.mean():.2f} | "
                   f"{per.std():.3f} | {per.min():.2f} | {per.max():.2f} | "
                   + " | ".join(f"{per.corr(x[c]):+.2f}" for c in ("twr", "axy", "az", "fp"))
                   + " |")
    return "\n".join(out) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--policy", default="v1")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--blind", action="store_true")
    ap.add_argument("--summary", action="store_true",
                    help="only summarise OUT/eval.parquet into OUT/eval.md")
    a = ap.parse_args()
    if a.summary:
        (a.out / "eval.md").write_text(summary(pd.read_parquet(a.out / "eval.parquet")))
        print((a.out / "eval.md").read_text())
        return 0
    policy = load_policy(a.policy)
    platforms = list(catalog().values())
    jobs = [(f, i, b) for f in REGISTRY for i in range(1, 11)
            for b in ((False, True) if a.blind else (False,))]
    rows = []
    for f, i, b in tqdm(jobs, unit="config"):
        rows += fly(policy, f, i, platforms, b)
    df = pd.DataFrame(rows)
    a.out.mkdir(parents=True, exist_ok=True)
    df.to_parquet(a.out / "eval.parquet")
    (a.out / "eval.md").write_text(summary(df))
    print((a.out / "eval.md").read_text())
    print(pd.crosstab([df.family, df.blind], df.outcome))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
