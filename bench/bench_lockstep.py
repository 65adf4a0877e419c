"""Benchmark: wall seconds per simulated second of a lockstep wire trial (issues 43/45).

Flies trials of docs/results/wire-agreement/campaign.toml with ``--transport mavlink``'s
lockstep transport (:func:`ft_sitl.transport.lockstep.run_trial_lockstep`, an embedded
broker, one worker) and in-process, and prints for each its wall seconds, simulated
seconds, their ratio and whether the lockstep row equals the in-process row in every column
but the wall times. Each child process first flies one unmeasured warm-up trial (the
worker's start-up: imports, broker, numba's cache).

With ``--vs DIR`` (a snapshot of another commit, e.g. ``git archive C | tar -x -C DIR``)
the children run in turn, this checkout then DIR, ``--pairs`` times (A B A B: a shared,
noisy machine drifts between runs), and each pair's ratio A/B is printed with the median.
A child imports ``ft_sitl`` from its tree (its working directory comes first on sys.path),
and the navigator process it starts (``python -m ft_sitl navigate``) inherits that
directory. A fresh tree compiles numba's kernels on its first run: run once before timing.

    .venv/bin/python bench/bench_lockstep.py                        # ~2 min
    .venv/bin/python bench/bench_lockstep.py --vs /tmp/base --pairs 3

Timings are never asserted: this is a script, not a test.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
CAMPAIGN = "docs/results/wire-agreement/campaign.toml"
#: Forest 1 (straight, 4.6 s: the warm-up), Narrow-Gap 1 (straight, 16.8 s simulated,
#: 20 Hz), Forest 2 (EGO, 23.6 s simulated, 100 Hz)
WARM_UP = "eb5a272c15890952"
TRIALS = ("1f03b5b868c6803d", "05ab098060417582")
#: the columns that measure wall time (as docs/results/wire-agreement/identical.py)
WALL_COLUMNS = ("wall_time_s", "planner_time_s", "finished_utc")


def child(trials: list[str]) -> None:
    """Fly the warm-up, then each trial in lockstep and in-process; one JSON line each."""
    sys.path.insert(0, os.getcwd())
    # isort: off
    import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
    # isort: on
    from ft_sitl.missions.campaign_file import load_campaign
    from ft_sitl.missions.trial import run_trial
    from ft_sitl.transport import fly_wire

    specs = {s.trial_id: s for s in load_campaign(HERE / CAMPAIGN).trial_specs()}
    missing = [t for t in [WARM_UP, *trials] if t not in specs]
    if missing:
        sys.exit(f"bench_lockstep: trial ids not in {CAMPAIGN}: {', '.join(missing)}")
    fly_wire(specs[WARM_UP], 2.0, None)
    for tid in trials:
        t0 = time.perf_counter()
        row = fly_wire(specs[tid], 2.0, None)
        wall = time.perf_counter() - t0
        ref = run_trial(specs[tid]).row
        differ = [k for k in ref if k not in WALL_COLUMNS
                  and json.dumps(ref[k]) != json.dumps(row.get(k))]
        print(json.dumps({"trial": tid, "algorithm": row["algorithm"],
                          "wall_s": round(wall, 3), "sim_s": row["sim_time_s"],
                          "wall_per_sim": round(wall / row["sim_time_s"], 4),
                          "planner_calls": row["planner_calls"], "reason": row["reason"],
                          "differs_from_in_process": differ}), flush=True)


def run_child(tree: Path, trials: list[str]) -> dict:
    """One child in ``tree``: {trial: its JSON line}."""
    out = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child", *trials],
                         cwd=tree, capture_output=True, text=True, check=False)
    lines = [json.loads(ln) for ln in out.stdout.splitlines() if ln.startswith("{")]
    if out.returncode != 0 or len(lines) != len(trials):
        sys.exit(f"bench_lockstep: the child in {tree} failed:\n{out.stderr[-2000:]}")
    return {d["trial"]: d for d in lines}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vs", type=Path, help="another tree to compare with (A B A B)")
    ap.add_argument("--pairs", type=int, default=3, help="A/B pairs with --vs (default 3)")
    ap.add_argument("--trials", nargs="+", default=list(TRIALS), help="trial ids of "
                    f"{CAMPAIGN} (default: {' '.join(TRIALS)})")
    ap.add_argument("--child", nargs="+", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child)
        return
    trees = [Path.cwd()] + ([args.vs.resolve()] if args.vs else [])
    if args.vs is not None and not (args.vs / "ft_sitl" / "__init__.py").is_file():
        sys.exit(f"bench_lockstep: --vs {args.vs}: not a tree with ft_sitl/")
    ratios: dict = {t: [] for t in args.trials}
    for i in range(args.pairs if args.vs else 1):
        got = []
        for tree in trees:
            res = run_child(tree, args.trials)
            got.append(res)
            for d in res.values():
                print(f"pair {i + 1} {tree}: {json.dumps(d)}", flush=True)
        if args.vs:
            for t in args.trials:
                ratios[t].append(got[0][t]["wall_per_sim"] / got[1][t]["wall_per_sim"])
    if args.vs:
        for t, r in ratios.items():
            print(f"{t}: wall/sim ratio A/B per pair {[round(x, 3) for x in r]}, "
                  f"median {statistics.median(r):.3f}")


if __name__ == "__main__":
    main()
