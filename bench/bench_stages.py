"""Benchmark: what the wind and estimator stages cost the lockstep kernel.

Batches of 1 and 64 hovering vehicles (1.00kg-SunnySky) step 10 s of simulated time in
calm air, in a mean wind (written once: the stage is off), in the same mean wind with the
stage running every step (a gust an hour away), in a mean wind with Dryden turbulence
(moderate) and a gust, and in calm air with the flight controller on an imperfect estimate
(noise on every group; the same with 50 ms of latency on every group); the cases are timed
in turn, ``--repeats`` times, and the medians compared (ratios measured in one run: this
machine is shared). Timings are never asserted.

    .venv/bin/python bench/bench_stages.py          # ~2 min
    .venv/bin/python bench/bench_stages.py --json
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (its BLAS settings before numpy loads)
# isort: on

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

from benchutil import machine_info  # noqa: E402

from ft_sitl.physics.catalog import catalog  # noqa: E402
from ft_sitl.sim.lockstep import Simulation  # noqa: E402

NOISY = {"position_noise_m": 0.05, "velocity_noise_m_s": 0.05, "attitude_noise_deg": 0.5,
         "rate_noise_deg_s": 1.0, "noise_correlation_s": 0.2}
LATE = {f"{g}_latency_s": 0.05 for g in ("position", "velocity", "attitude", "rate")}
#: case -> (wind settings, estimator settings)
CASES = {
    "calm": (None, None),
    "mean wind": ({"speed_m_s": 6.0}, None),
    # the stage running every step with nothing to add (a gust an hour away)
    "mean wind, stage on": ({"speed_m_s": 6.0, "gust_m_s": 1.0, "gust_start_s": 3600.0},
                            None),
    "turbulence + gust": ({"speed_m_s": 6.0, "turbulence": "moderate", "gust_m_s": 3.0,
                           "gust_start_s": 2.0}, None),
    "estimator: noise": (None, NOISY),
    "estimator: noise + latency": (None, {**NOISY, **LATE}),
}


def one(n: int, case, seconds: float) -> float:
    wind, estimator = case
    p = catalog()["1.00kg-SunnySky"]
    sim = Simulation([p] * n)
    for i in range(n):
        sim.start_hovering(i, [3.0 * i, 0.0, 2.0])
        sim.set_wind(i, wind, seed=i)
        sim.set_estimator(i, estimator, seed=i)
    sim.run(0.01)  # compiled already; warm the caches
    t0 = time.perf_counter()
    sim.run(seconds)
    return n * seconds / (time.perf_counter() - t0)  # vehicle-seconds per wall second


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    out = {"machine": machine_info(None), "batches": {}}
    for n, seconds in ((1, 10.0), (64, 1.0)):
        times = {k: [] for k in CASES}
        for _ in range(args.repeats):
            for k, w in CASES.items():
                times[k].append(one(n, w, seconds))
        med = {k: statistics.median(v) for k, v in times.items()}
        out["batches"][n] = {"vehicle_s_per_wall_s": med,
                             "cost_vs_calm": {k: med["calm"] / v - 1.0 for k, v in med.items()},
                             "cost_vs_mean_wind": {k: med["mean wind"] / v - 1.0
                                                   for k, v in med.items()}}
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    for n, b in out["batches"].items():
        for k, v in b["vehicle_s_per_wall_s"].items():
            print(f"batch {n:3d} {k:27s} {v:8.1f} vehicle-s per wall-s  "
                  f"({100 * b['cost_vs_calm'][k]:+.1f} % time vs calm, "
                  f"{100 * b['cost_vs_mean_wind'][k]:+.1f} % vs the mean wind)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
