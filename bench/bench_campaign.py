"""Benchmark: campaign throughput for the straight-flight baseline, and the runner's overhead.

Runs one campaign (the ``quick`` preset's shape by default: 6 platforms x 7 families x 3
trials of the baseline = 126 trials) into fresh temporary directories, first in-process
(``workers=1``), then with ``--workers`` processes, and reports

* trials per wall-second, and per wall-second per core (workers=1 is one core);
* the runner's own overhead with one worker: campaign wall time minus the sum of the
  trials' own wall times (``wall_time_s`` of each row: scenario, grid and flight), i.e.
  chunking, the durable store (one fsync per trial), the progress bar and the Parquet file;
* the share of trial time spent building scenarios' collision grids (first trial of each
  configuration in a process);
* the extrapolation to the paper's baseline matrix (2,520 trials, 70 configurations) with
  the measured per-trial and per-configuration costs.

The paper matrix itself is timed with the CLI (``ft-sitl campaign run paper``); see
docs/benchmarks.md. Timings are never asserted.

    .venv/bin/python bench/bench_campaign.py             # ~1-2 min
    .venv/bin/python bench/bench_campaign.py --json
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
import statistics  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402

from benchutil import machine_info  # noqa: E402

from ft_sitl.missions.campaign import run_campaign  # noqa: E402
from ft_sitl.missions.campaign_file import load_campaign, parse_algorithms  # noqa: E402
from ft_sitl.missions.store import load_rows  # noqa: E402
from ft_sitl.scenarios.distance_grid import DistanceGrid  # noqa: E402
from ft_sitl.scenarios.families import build_scenario  # noqa: E402

PAPER_TRIALS = 2520
PAPER_CONFIGS = 70


def one_run(campaign, workers: int) -> dict:
    with tempfile.TemporaryDirectory() as d:
        t0 = time.perf_counter()
        s = run_campaign(campaign, d, workers=workers, progress=False)
        wall = time.perf_counter() - t0
        _, rows = load_rows(d)
    trial_wall = sum(r["wall_time_s"] for r in rows)
    return {"workers": workers, "trials": s.ran, "errors": len(s.errors), "wall_s": wall,
            "trials_per_s": s.ran / wall, "sum_trial_wall_s": trial_wall,
            "runner_overhead_s": wall - trial_wall if workers == 1 else None,
            "successes": sum(bool(r["success"]) for r in rows)}


def grid_cost(campaign) -> float:
    """Mean seconds to build a configuration's scenario + grid (what a trial pays once)."""
    times = []
    for sc in campaign.scenarios:
        for i in sorted(set(sc.indices))[:2]:
            t = time.perf_counter()
            s = build_scenario(sc.family, i, campaign.scenario_seed)
            DistanceGrid.build(s.mesh, s.bounds_min, s.bounds_max)
            times.append(time.perf_counter() - t)
    return statistics.mean(times)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--campaign", default="quick", help="campaign file or preset (quick)")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--algorithms", nargs="+", default=["straight"],
                    help="navigators to run (default: the baseline)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    campaign = load_campaign(args.campaign)
    campaign.algorithms = parse_algorithms("--algorithms", list(args.algorithms))
    configs = len({(s.family, i) for s in campaign.scenarios for i in s.indices})
    serial = one_run(campaign, 1)
    parallel = one_run(campaign, args.workers)
    per_config = grid_cost(campaign)
    n = serial["trials"]
    grid_total = per_config * configs
    per_trial = (serial["sum_trial_wall_s"] - grid_total) / n
    paper_core_s = PAPER_TRIALS * per_trial + PAPER_CONFIGS * per_config
    speedup = parallel["trials_per_s"] / serial["trials_per_s"]
    out = {
        "machine": machine_info(None), "campaign": campaign.name, "trials": n,
        "configurations": configs, "serial": serial, "parallel": parallel,
        "speedup": speedup, "grid_s_per_configuration": per_config,
        "flight_s_per_trial": per_trial,
        "runner_overhead_share": serial["runner_overhead_s"] / serial["wall_s"],
        "paper_matrix_estimate_s": {"one_core": paper_core_s,
                                    f"{args.workers}_workers": paper_core_s / speedup},
    }
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"campaign {campaign.name}: {n} baseline trials over {configs} configurations")
    for r in (serial, parallel):
        print(f"  workers {r['workers']}: {r['wall_s']:.1f} s, {r['trials_per_s']:.2f} "
              f"trials/s ({r['trials_per_s'] / r['workers']:.2f} per core), "
              f"{r['successes']} successes, {r['errors']} errors")
    print(f"  runner overhead (1 worker): {serial['runner_overhead_s']:.2f} s = "
          f"{100 * out['runner_overhead_share']:.1f} % of the wall time")
    print(f"  per configuration (scenario + grid): {per_config:.2f} s; per trial flight: "
          f"{1000 * per_trial:.0f} ms")
    print(f"  paper baseline matrix estimate: {paper_core_s / 60:.1f} min on one core, "
          f"{paper_core_s / speedup / 60:.1f} min with {args.workers} workers "
          f"(speed-up {speedup:.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
