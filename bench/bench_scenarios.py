"""Benchmark: scenario build time per family (ft_sitl.scenarios.families).

For each of the seven families, every configuration 1..10 is built (seed 0) a few times;
reported per family: the median build time of configuration 1 and 10 and of the whole ten,
the triangle count of configuration 10, and the one-off costs a simulation adds on top of a
build when it flies in the scenario: the python-fcl collision world (BVH) and the distance
grid of the collision guard, and the time to render configuration 10 to a figure
(``ft-sitl scenarios render``). One process pinned to one CPU. Timings are never asserted.

    .venv/bin/python bench/bench_scenarios.py            # ~1 min
    .venv/bin/python bench/bench_scenarios.py --quick    # smoke run
    .venv/bin/python bench/bench_scenarios.py --json     # results as JSON on stdout
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
from pathlib import Path  # noqa: E402

from benchutil import machine_info, pin_to_one_cpu  # noqa: E402

from ft_sitl.scenarios.collision import CollisionWorld  # noqa: E402
from ft_sitl.scenarios.distance_grid import DistanceGrid  # noqa: E402
from ft_sitl.scenarios.families import FAMILIES, build_scenario  # noqa: E402
from ft_sitl.scenarios.render import render_scenario  # noqa: E402


def _median_time(fn, repeats: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), out


def bench_family(family: str, indices, repeats: int) -> dict:
    per_index = {}
    last = None
    for i in indices:
        t, last = _median_time(lambda i=i: build_scenario(family, i, 0), repeats)
        per_index[i] = t
    world_s, _ = _median_time(
        lambda: CollisionWorld(last.mesh, last.bounds_min, last.bounds_max), repeats)
    grid_s, grid = _median_time(
        lambda: DistanceGrid.build(last.mesh, last.bounds_min, last.bounds_max), 1)
    with tempfile.TemporaryDirectory() as d:  # drawing happens when the PNG is written
        render_s, _ = _median_time(lambda: render_scenario(last, Path(d) / "r.png"), 1)
    return {
        "family": family,
        "build_s": {str(k): round(v, 4) for k, v in per_index.items()},
        "build_all_s": round(sum(per_index.values()), 3),
        "triangles_last": int(len(last.mesh.faces)),
        "last": last.name,
        "fcl_world_s": round(world_s, 4),
        "grid_s": round(grid_s, 3),
        "grid_cells": int(grid.data.size),
        "render_s": round(render_s, 3),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="configurations 1 and 10, once")
    ap.add_argument("--json", action="store_true", help="results as JSON on stdout")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cpu", type=int, default=None, help="CPU to pin to (default: last)")
    ap.add_argument("--no-pin", action="store_true")
    args = ap.parse_args(argv)
    cpu = None if args.no_pin else pin_to_one_cpu(args.cpu)
    indices = (1, 10) if args.quick else range(1, 11)
    repeats = 1 if args.quick else args.repeats
    build_scenario("forest", 1)  # warm-up: imports, numba kernels of the solvability check
    results = []
    if not args.json:
        print(f"{'family':22s} {'#1 s':>7s} {'#10 s':>7s} {'all s':>7s} {'tris #10':>9s} "
              f"{'fcl s':>7s} {'grid s':>7s} {'render s':>8s}")
    for fam in FAMILIES:
        r = bench_family(fam, indices, repeats)
        results.append(r)
        if not args.json:
            print(f"{fam:22s} {r['build_s']['1']:7.3f} {r['build_s']['10']:7.3f} "
                  f"{r['build_all_s']:7.2f} {r['triangles_last']:9d} {r['fcl_world_s']:7.3f} "
                  f"{r['grid_s']:7.2f} {r['render_s']:8.2f}", flush=True)
    out = {"machine": machine_info(cpu), "results": results}
    if args.json:
        json.dump(out, sys.stdout, indent=2)
        print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
