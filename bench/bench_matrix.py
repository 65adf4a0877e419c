"""Standing benchmark of the paper matrix's cost: CPU per simulated second, two commits.

A fixed stratified sample of committed rows made under the instruction-set pins
(docs/results/paper-pinned-sample: every algorithm x family; for each cell the rows of the
smallest, the median and the largest platform by mass the cell holds, so the sample spans
the catalog's sizes) is flown by two commits of ft-sitl in one run, alternated (A B A B
...: this machine is shared, so only a ratio measured in one run means anything). Each
commit flies from its own ``git archive`` snapshot in a fresh process at the pinned
level, pinned to one CPU, one row at a time after a warm-up flight of the first row.
Printed: CPU seconds per simulated second per algorithm and over the whole sample for
each commit, the ratio B / A, and whether every re-flown row equals its stored row (all
but the wall-clock columns) -- a speed-up that changes rows is not one.

    .venv/bin/python bench/bench_matrix.py cb1d2ae HEAD                 # 105 rows, 2 rounds
    .venv/bin/python bench/bench_matrix.py cb1d2ae HEAD --sizes median --rounds 1

Timings are never asserted; results go to docs/benchmarks.md with machine and date.
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (its numeric pins before numpy loads)
# isort: on

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tarfile  # noqa: E402
import tempfile  # noqa: E402
from collections import defaultdict  # noqa: E402
from pathlib import Path  # noqa: E402

import pandas as pd  # noqa: E402
from benchutil import machine_info  # noqa: E402

from ft_sitl import numeric_env  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "docs" / "results" / "paper-pinned-sample" / "trials.parquet"
SIZES = ("smallest", "median", "largest")
#: columns that depend on the wall clock or the code that ran, not on the spec
NOT_COMPARED = ("wall_time_s", "planner_time_s", "finished_utc", "code_version", "software")

#: what runs inside a commit's snapshot: only APIs every commit since the paper run has
#: (TrialSpec.from_dict, run_trial); one JSON line per row
WORKER = r"""
import json, os, sys, time
import ft_sitl
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import run_trial
cpu = int(sys.argv[1])
if cpu >= 0 and hasattr(os, "sched_setaffinity"):
    os.sched_setaffinity(0, {cpu})
specs = json.load(sys.stdin)
run_trial(TrialSpec.from_dict(json.loads(specs[0])), wall_budget_s=None)  # warm-up
for text in specs:
    spec = TrialSpec.from_dict(json.loads(text))
    c0 = time.process_time()
    row = run_trial(spec, wall_budget_s=None).row
    cpu_s = time.process_time() - c0
    print(json.dumps({"trial_id": spec.trial_id, "cpu_s": cpu_s, "row": row},
                     default=str, allow_nan=True), flush=True)
"""


def sample(sizes: tuple[str, ...]) -> pd.DataFrame:
    """The fixed sample: per (algorithm, family), the row of each size class's platform
    (the lowest trial number of it, for a deterministic pick)."""
    df = pd.read_parquet(SOURCE)
    picks = []
    for _, cell in df.groupby(["algorithm", "family"], observed=True):
        masses = sorted(cell["mass_kg"].unique())
        chosen = {"smallest": masses[0], "median": masses[len(masses) // 2],
                  "largest": masses[-1]}
        for size in sizes:
            rows = cell[cell["mass_kg"] == chosen[size]].sort_values(["trial", "trial_id"])
            picks.append(rows.iloc[0])
    return pd.DataFrame(picks).drop_duplicates("trial_id")


def snapshot(rev: str, into: Path) -> Path:
    """``git archive`` of ``rev`` unpacked into ``into``/<sha>; its path."""
    sha = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", rev], check=True,
                         capture_output=True, text=True).stdout.strip()
    where = into / sha
    if not where.exists():
        where.mkdir(parents=True)
        tar = into / f"{sha}.tar"
        subprocess.run(["git", "-C", str(ROOT), "archive", "-o", str(tar), sha], check=True)
        with tarfile.open(tar) as t:
            t.extractall(where, filter="data")
    return where


def fly(tree: Path, specs: list[str], cpu: int) -> dict[str, dict]:
    env = {**numeric_env.child_env(numeric_env.PINNED), "PYTHONPATH": str(tree)}
    out = subprocess.run([sys.executable, "-c", WORKER, str(cpu)], input=json.dumps(specs),
                         capture_output=True, text=True, env=env, cwd=tree)
    got = {}
    for line in out.stdout.splitlines():
        doc = json.loads(line)
        got[doc["trial_id"]] = doc
    if len(got) != len(specs):
        raise SystemExit(f"{tree.name}: {len(got)} of {len(specs)} rows flew:\n"
                         f"{out.stderr[-3000:]}")
    return got


def same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", help="baseline commit")
    ap.add_argument("b", help="commit to compare")
    ap.add_argument("--sizes", default=",".join(SIZES),
                    help=f"size classes per cell, of {', '.join(SIZES)}")
    ap.add_argument("--rounds", type=int, default=2, help="A B rounds (default 2)")
    ap.add_argument("--cpu", type=int, default=-1, help="pin the flights to this CPU")
    ap.add_argument("--algorithms", default=None,
                    help="comma-separated algorithms to keep (default: all)")
    ap.add_argument("--limit", type=int, default=None,
                    help="the first N rows of the sample only (a smoke run)")
    ap.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "bench-matrix")
    args = ap.parse_args(argv)
    sizes = tuple(s for s in args.sizes.split(",") if s)
    if not sizes or set(sizes) - set(SIZES) or args.rounds < 1:
        ap.error(f"--sizes: some of {', '.join(SIZES)}; --rounds: at least 1")
    rows = sample(sizes)
    if args.algorithms:
        keep = set(args.algorithms.split(","))
        rows = rows[rows["algorithm"].astype(str).isin(keep)]
        if rows.empty:
            ap.error(f"--algorithms: none of {sorted(keep)} is in the sample")
    if args.limit is not None:
        rows = rows.iloc[:args.limit]
    stored = {r["trial_id"]: r for r in rows.to_dict("records")}
    specs = [r["spec"] for r in rows.to_dict("records")]
    trees = {rev: snapshot(rev, args.work) for rev in (args.a, args.b)}
    cpu = defaultdict(lambda: defaultdict(list))  # rev -> trial -> cpu seconds
    flown = {}
    for k in range(args.rounds):
        for rev, tree in trees.items():
            print(f"round {k + 1}/{args.rounds}: {rev} ({tree.name}) flies {len(specs)} rows",
                  file=sys.stderr, flush=True)
            for tid, doc in fly(tree, specs, args.cpu).items():
                cpu[rev][tid].append(doc["cpu_s"])
                flown[(rev, tid)] = doc["row"]
    print(json.dumps(machine_info(None if args.cpu < 0 else args.cpu,
                                  commits={rev: tree.name for rev, tree in trees.items()})))
    sim = {tid: float(stored[tid]["sim_time_s"]) for tid in stored}
    header = f"{'algorithm':10s} {'rows':>4s} " + " ".join(
        f"{rev[:10]:>12s}" for rev in trees) + "   ratio (CPU s per simulated s)"
    print(header)
    by_alg = defaultdict(list)
    for tid, r in stored.items():
        by_alg[str(r["algorithm"])].append(tid)
    for alg, tids in sorted(by_alg.items()) + [("all", list(stored))]:
        rate = {rev: sum(min(cpu[rev][t]) for t in tids) / sum(sim[t] for t in tids)
                for rev in trees}
        a, b = (rate[rev] for rev in trees)
        print(f"{alg:10s} {len(tids):4d} " + " ".join(f"{rate[rev]:12.4f}" for rev in trees)
              + f"   {b / a:.3f}")
    for rev in trees:
        bad = [tid for tid in stored if any(
            not same(flown[(rev, tid)].get(c), stored[tid][c]) for c in stored[tid]
            if c not in NOT_COMPARED and c in flown[(rev, tid)])]
        print(f"{rev}: {len(stored) - len(bad)} of {len(stored)} rows identical to the "
              f"stored ones" + (f" (differ: {', '.join(t[:10] for t in bad)})" if bad else ""))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
