"""Benchmark: the planners' compute per replan, and their cost per simulated flight second.

For each planner (ego, fast, pgo, and navrl when its checkpoint is installed: see
docs/planners.md) one trial per scenario family (configuration 2) on two
platforms (the agile "0.98kg-EGO Planner DIY" and the low-TWR real "2.00kg-T-MOTOR") is
flown in-process, one CPU. Reported per planner:

* compute time per replan (the navigator's own wall-clock measurement of each plan,
  including its ESDF/map preparation): median, p95, max, count;
* wall time of the whole trial per simulated second (physics, collision guard, camera
  ray casting, map fusion, planning, protocol), and the navigator's share of it;
* outcomes;
* the extrapolation to the paper preset's 2,520 trials per planner from the mean trial wall
  time here, and for the whole five-algorithm paper campaign (the planners measured here;
  the 2.2 min baseline matrix from docs/benchmarks.md) with two workers (speed-up 1.85,
  measured in bench_campaign.py). Each configuration's scenario and collision grid are
  built before the timing (a campaign builds them once per configuration per worker, for
  up to 180 trials), so no planner pays them. The campaign measured on the paper sample
  (docs/results/paper-sample/) is the better figure: this one is 14 trials per planner.

Map fusion per depth frame is measured by bench/bench_mapping.py. Timings are never
asserted.

    .venv/bin/python bench/bench_planners.py            # ~3-5 min
    .venv/bin/python bench/bench_planners.py --json
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402

import numpy as np  # noqa: E402
from benchutil import machine_info, pin_to_one_cpu  # noqa: E402

from ft_sitl.missions.trial import TrialSpec, run_trial  # noqa: E402
from ft_sitl.navigation.registry import create  # noqa: E402
from ft_sitl.scenarios.families import FAMILIES  # noqa: E402

PLANNERS = ("ego", "fast", "pgo", "navrl")
PLATFORMS = ("0.98kg-EGO Planner DIY", "2.00kg-T-MOTOR")
PAPER_TRIALS = 2520
BASELINE_PAPER_S = 130.6  # docs/benchmarks.md, two workers
SPEEDUP_2 = 1.85


def bench(planner: str, families, platforms, index: int) -> dict:
    compute, rows = [], []
    for fam in families:
        for plat in platforms:
            nav = create(planner)
            spec = TrialSpec(algorithm=planner, platform=plat, family=fam,
                             scenario_index=index)
            row = run_trial(spec, navigator=nav).row
            compute.extend(getattr(nav, "compute_s", []))
            rows.append(row)
    c = np.array(compute) * 1e3
    wall = sum(r["wall_time_s"] for r in rows)
    sim = sum(r["sim_time_s"] for r in rows)
    nav_s = sum(r["planner_time_s"] for r in rows)
    return {
        "planner": planner, "trials": len(rows),
        "replan_ms": {"median": float(np.median(c)), "p95": float(np.percentile(c, 95)),
                      "max": float(c.max()), "count": int(len(c))},
        "wall_per_sim_s": wall / sim, "navigator_share": nav_s / wall,
        "mean_trial_wall_s": wall / len(rows),
        "outcomes": {f"{r['family']}/{r['platform']}": r["reason"] for r in rows},
        "successes": sum(bool(r["success"]) for r in rows),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--planners", nargs="+", default=list(PLANNERS))
    ap.add_argument("--index", type=int, default=2)
    ap.add_argument("--quick", action="store_true", help="forest and perlin, one platform")
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--cpu", type=int, default=None)
    args = ap.parse_args(argv)
    cpu = pin_to_one_cpu(args.cpu)
    families = ("forest", "perlin") if args.quick else FAMILIES
    platforms = PLATFORMS[:1] if args.quick else PLATFORMS
    results = []
    from ft_sitl.navigation.registry import available

    for fam in families:  # scenario + collision grid into the process caches, untimed
        run_trial(TrialSpec(algorithm="straight", platform=platforms[0], family=fam,
                            scenario_index=args.index))

    planners = []
    for p in args.planners:
        cls = available().get(p)
        why = cls if isinstance(cls, str) else (cls.unavailable() if cls else "not registered")
        if why:
            print(f"# {p} left out: {why}", file=sys.stderr)
        else:
            planners.append(p)
    for p in planners:
        r = bench(p, families, platforms, args.index)
        results.append(r)
        if not args.json:
            m = r["replan_ms"]
            print(f"{p:5s} replan median {m['median']:6.1f} ms  p95 {m['p95']:6.1f} ms  max "
                  f"{m['max']:6.1f} ms  ({m['count']} plans)  wall/sim-s "
                  f"{r['wall_per_sim_s']:.3f}  navigator {100 * r['navigator_share']:.0f} %  "
                  f"trial {r['mean_trial_wall_s']:.2f} s  successes {r['successes']}/"
                  f"{r['trials']}", flush=True)
    per_planner_s = {r["planner"]: r["mean_trial_wall_s"] * PAPER_TRIALS / SPEEDUP_2
                     for r in results}
    total = BASELINE_PAPER_S + sum(per_planner_s.values())
    out = {"machine": machine_info(cpu), "index": args.index, "families": list(families),
           "platforms": list(platforms), "results": results,
           "paper_estimate_s": {"per_planner_2_workers": per_planner_s,
                                "baseline_2_workers": BASELINE_PAPER_S,
                                "total_2_workers": total}}
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        missing = [p for p in ("ego", "fast", "pgo", "navrl") if p not in per_planner_s]
        print("paper preset estimate, two workers: " + ", ".join(
            f"{k} {v / 60:.0f} min" for k, v in per_planner_s.items())
              + f"; with the baseline {total / 3600:.2f} h"
              + (f" (without {', '.join(missing)})" if missing else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
