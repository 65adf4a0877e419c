"""Benchmark: what the instruction-set pins cost, per stage of a trial.

``ft_sitl.numeric_env`` pins numba, numpy, OpenBLAS and Embree at x86-64-v3 so rows are
equal on every processor of our kind; on a processor with AVX-512 that gives up numpy's
AVX-512 loops and numba's AVX-512 code. This script flies the same stored rows (one per
(algorithm, family) of a result directory, seeded) at ``FT_SITL_ISA=host`` and at the
pinned level, in alternation (host, pinned, host, pinned, ...: this machine is shared, so
the ratio is measured in one run), each round in a fresh process pinned to one CPU by
``bench_trial_costs.py`` (warm-up flight, timed flight, profiled flight per row). It prints
the trial time per simulated second, and each stage's seconds (camera, map fusion,
planner, the loop), at both levels and their ratio. Timings are never asserted.

    .venv/bin/python bench/bench_pins.py docs/results/paper            # ~25 min
    .venv/bin/python bench/bench_pins.py docs/results/paper --families forest,maze,urban
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (its numeric pins before numpy loads)
# isort: on

import argparse  # noqa: E402
import json  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

from benchutil import machine_info  # noqa: E402

from ft_sitl import numeric_env  # noqa: E402

HERE = Path(__file__).resolve().parent
STAGES = ("camera", "fusion", "planner", "loop")
LEVELS = (numeric_env.HOST, numeric_env.PINNED)


def one_round(level: str, directory: Path, seed: int, cpu: int | None,
              families: str | None) -> list[dict]:
    cmd = [sys.executable, str(HERE / "bench_trial_costs.py"), str(directory), "--json",
           "--seed", str(seed)] + ([] if cpu is None else ["--cpu", str(cpu)]) + \
        ([] if families is None else ["--families", families])
    out = subprocess.run(cmd, env=numeric_env.child_env(level), capture_output=True,
                         text=True)
    if not out.stdout.strip():
        raise SystemExit(f"bench_trial_costs at {level} failed:\n{out.stderr[-2000:]}")
    doc = json.loads(out.stdout)
    return doc["sample"]


def totals(sample: list[dict]) -> dict[str, float]:
    wall = sum(r["wall_s"] for r in sample)
    out = {"wall_s": wall, "sim_s": sum(r["sim_time_s"] for r in sample)}
    for k in STAGES:
        out[k] = sum(r["wall_s"] * r[k] for r in sample)
    out["per_sim_s"] = wall / out["sim_s"]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path, help="a result directory with trials.parquet")
    ap.add_argument("--rounds", type=int, default=2, help="rounds of (host, pinned)")
    ap.add_argument("--seed", type=int, default=0, help="which rows (default 0)")
    ap.add_argument("--cpu", type=int, default=None, help="CPU to pin to (default: the last)")
    ap.add_argument("--families", default=None,
                    help="comma-separated families to sample (default: all)")
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")
    args = ap.parse_args(argv)
    if args.rounds < 1:
        ap.error(f"--rounds must be at least 1, got {args.rounds}")
    runs: dict[str, list[dict]] = {lv: [] for lv in LEVELS}
    for k in range(args.rounds):
        for level in LEVELS:
            print(f"round {k + 1}/{args.rounds}: {level}", file=sys.stderr, flush=True)
            runs[level].append(totals(one_round(level, args.dir, args.seed, args.cpu,
                                                args.families)))
    best = {lv: {key: min(r[key] for r in runs[lv]) for key in runs[lv][0]}
            for lv in LEVELS}
    info = machine_info(args.cpu, directory=str(args.dir), rounds=args.rounds,
                        seed=args.seed, families=args.families)
    if args.json:
        print(json.dumps({"machine": info, "rounds": runs, "best": best}, indent=1))
        return 0
    print(f"machine: {info}")
    print("\n| | host (s) | x86-64-v3 (s) | pinned / host |\n|---|---:|---:|---:|")
    for key in ("per_sim_s", "wall_s", *STAGES):
        h, p = best[numeric_env.HOST][key], best[numeric_env.PINNED][key]
        print(f"| {key} | {h:.3f} | {p:.3f} | {p / h:.3f} |")
    print(f"\n(best of {args.rounds} rounds per level; {len(runs[LEVELS[0]])} rounds of "
          f"{best[numeric_env.HOST]['sim_s']:.0f} simulated s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
