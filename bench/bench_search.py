"""Benchmark: the search and optimisation cases whose speed the tests used to time.

The tests check what these cases compute and how much work they do (expansions, cost
evaluations: deterministic); their wall-clock time is measured here instead, with this
script's own copies of the test set-ups:

* ``astar``: voxel A* (``ft_sitl.navigation.planners.astar.search``) across a 100 x 100 x 40 grid,
  25 % of the voxels blocked at random (seed 0) plus a wall at x = 5 m open only near
  y = 0, corner to corner (tests/navigation/test_astar.py; target "tens of milliseconds",
  the old test's bound 0.1 s for the best of 3);
* ``kino``: Fast-Planner's kinodynamic A* around a 4.2 m wall to a goal 6 m ahead from
  rest, max speed 3 m/s (tests/navigation/test_kino_astar.py; target ~30 ms, old bound
  0.25 s for the best of 3);
* ``kino_time_cap``: the same search engine against a closed box with a 0.05 s wall-clock
  cap, point queries and voxel grid: how far past its deadline it stops (the test checks
  only that it did not stop before it);
* ``ego``: EGO-Planner's optimiser on a 7.5 m straight B-spline at 3 m/s through a pillar
  (tests/navigation/test_ego_optim.py; target well under 20 ms median, old bound 40 ms);
* ``report``: ``write_report`` on a synthetic 2,520-row table, the 36 catalog platforms x
  7 families x 10 trials of one algorithm (tests/missions/test_report.py; target ~20 s,
  old bound 60 s). ``--no-report`` skips it.

Each case is run once untimed (numba kernels compiled or loaded from the cache), then
timed ``--repeats`` times (the report: ``--report-repeats``) with the garbage collector off,
in one process pinned to one CPU; the median, min and max are reported with the CPU share
of wall time (below 1: the process was descheduled). Timings are never asserted.

    .venv/bin/python bench/bench_search.py              # ~1 min with the report
    .venv/bin/python bench/bench_search.py --quick      # smoke run, no report
    .venv/bin/python bench/bench_search.py --json       # results as JSON on stdout
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

# before numpy: ft_sitl pins the BLAS threads and kernels the planners' results depend on
import ft_sitl  # noqa: E402, F401

# isort: split

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from benchutil import machine_info, pin_to_one_cpu, timed  # noqa: E402

from ft_sitl.navigation.optimisers.ego import EgoOptimizer, EgoParams  # noqa: E402
from ft_sitl.navigation.planners.astar import OccupancyView, search  # noqa: E402
from ft_sitl.navigation.planners.kino_astar import (  # noqa: E402
    KinoAstarParams,
    KinodynamicAstar,
    VoxelOccupancy,
)
from ft_sitl.navigation.trajectories.bspline import BSpline, fit_samples  # noqa: E402

RES = 0.1


def _stats(t: dict, **extra) -> dict:
    return {"median_s": t["median_s"], "min_s": t["min_s"], "max_s": t["max_s"],
            "cpu_share_median": round(t["cpu_share_median"], 3), "wall_s": t["wall_s"],
            **extra}


# --- voxel A* ------------------------------------------------------------------------------
def _grid_view(blocked: np.ndarray) -> OccupancyView:
    """Voxel (0, 0, 0) centred at RES / 2; outside the array is occupied."""
    shape = np.array(blocked.shape)

    def occupied(p):
        i = np.floor(p / RES).astype(np.int64)
        inside = np.all((i >= 0) & (i < shape), axis=1)
        out = np.ones(len(p), dtype=bool)
        j = i[inside]
        out[inside] = blocked[j[:, 0], j[:, 1], j[:, 2]]
        return out

    return OccupancyView(occupied, RES, bounds=(np.zeros(3), shape * RES))


def bench_astar(repeats: int) -> dict:
    rng = np.random.default_rng(0)
    blocked = rng.random((100, 100, 40)) < 0.25
    blocked[50, 5:, :] = True
    blocked[:3, -3:, :3] = blocked[-3:, -3:, -3:] = False
    grid = _grid_view(blocked)
    start, goal = [0.05, 9.95, 0.05], [9.95, 9.95, 3.95]
    out = {}

    def run():
        out["res"] = search(start, goal, grid, margins_m=(10.0,), max_expansions=400_000)

    run()  # compile / load the kernels
    t = timed(run, repeats)
    r = out["res"]
    return _stats(t, found=r.found, expansions=r.expansions,
                  free_voxels=int((~blocked).sum()),
                  expansions_per_s=round(r.expansions / t["median_s"]))


# --- kinodynamic A* ------------------------------------------------------------------------
def _boxes_map(*boxes, floor=0.1, ceiling=3.0):
    def occupied(points):
        p = np.asarray(points, dtype=float)
        occ = (p[:, 2] < floor) | (p[:, 2] > ceiling)
        for lo, hi in boxes:
            occ |= np.all((p >= lo) & (p <= hi), axis=1)
        return occ

    return occupied


def _shell(center, inner_half, thickness=0.8):
    """Six thick boxes forming a closed hollow cube."""
    c = np.asarray(center, dtype=float)
    out = inner_half + thickness
    boxes = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            lo, hi = c - out, c + out
            if sign < 0:
                hi[axis] = c[axis] - inner_half
            else:
                lo[axis] = c[axis] + inner_half
            boxes.append((lo, hi))
    return boxes


def bench_kino(repeats: int) -> dict:
    wall = (np.array([2.9, -2.1, -10.0]), np.array([3.4, 2.1, 10.0]))
    bounds = (np.array([-2.0, -6.0, -0.5]), np.array([12.0, 6.0, 3.5]))
    planner = KinodynamicAstar(_boxes_map(wall), RES, bounds=bounds,
                               params=KinoAstarParams(max_vel=3.0))
    args = ([0, 0, 1.5], [0, 0, 0], [0, 0, 0], [6.0, 0.0, 1.5])
    out = {}

    def run():
        out["r"] = planner.search(*args)

    run()
    t = timed(run, repeats)
    r = out["r"]
    return _stats(t, status=r.status.value, expansions=r.expansions, nodes=r.nodes,
                  attempts=r.attempts)


def bench_kino_time_cap(repeats: int) -> dict:
    lo, hi = np.array([-1.0, -3.0, 0.0]), np.array([5.9, 3.0, 3.0])
    occ = _boxes_map(*_shell([4.0, 0.0, 1.5], inner_half=1.3))
    n = np.ceil((hi - lo) / RES).astype(int)
    idx = np.stack(np.meshgrid(*[np.arange(k) for k in n], indexing="ij"), -1).reshape(-1, 3)
    grid = VoxelOccupancy(occ(lo + (idx + 0.5) * RES).reshape(n), lo, RES)
    cap = 0.05
    params = KinoAstarParams(max_expansions=10**6, max_nodes=10**6, max_time_s=cap)
    out = {}
    for name, o in (("points", occ), ("grid", grid)):
        planner = KinodynamicAstar(o, RES, bounds=(lo, hi), params=params)
        planner.search([0, 0, 1.5], [0, 0, 0], [0, 0, 0], [4.0, 0.0, 1.5])  # warm
        over = []
        reasons = set()
        for _ in range(repeats):
            r = planner.search([0, 0, 1.5], [0, 0, 0], [0, 0, 0], [4.0, 0.0, 1.5])
            over.append(r.search_time_s - cap)
            reasons.add(r.stop_reason)
        out[name] = {"overshoot_median_s": float(np.median(over)),
                     "overshoot_max_s": float(np.max(over)), "stop_reasons": sorted(reasons),
                     "overshoot_s": over}
    return {"cap_s": cap, **out}


# --- EGO's optimiser -----------------------------------------------------------------------
def bench_ego(repeats: int) -> dict:
    centre, half, inflation = np.array([3.5, 0.05, 1.0]), np.array([0.3, 0.5, 3.0]), 0.1

    def occupied(p):
        inside = np.all(np.abs(p - centre) <= half + inflation, axis=1)
        return inside | (p[:, 2] < 0.0) | (p[:, 2] > 3.0)

    start, goal, speed = np.array([0.0, 0.0, 1.0]), np.array([7.5, 0.0, 1.0]), 3.0
    duration = float(np.linalg.norm(goal - start)) / speed
    vel = (goal - start) / duration
    zero = np.zeros(3)

    def line(t):
        return start + (goal - start) * (np.asarray(t) / duration)[:, None]

    pts, dt = fit_samples(line, duration, 4.0)
    sp = BSpline.fit(pts, dt, vel, vel, zero, zero)
    opt = EgoOptimizer(OccupancyView(occupied, RES), EgoParams(max_vel=4.0, max_acc=3.0))
    out = {}

    def run():
        out["res"] = opt.optimize(sp, vel, vel, zero, zero)

    run()
    t = timed(run, repeats)
    r = out["res"]
    return _stats(t, success=r.success, control_points=sp.num_control_points,
                  iterations=r.iterations, evaluations=r.evaluations,
                  astar_calls=r.astar_calls)


# --- the campaign report -------------------------------------------------------------------
def _report_frame():
    """2,520 synthetic rows: 36 platforms x 7 families x 10 trials of one algorithm, success
    more likely with a larger TWR_max (as a campaign writes them)."""
    from ft_sitl.missions.results import COLUMNS, REASONS, to_frame
    from ft_sitl.physics.catalog import catalog
    from ft_sitl.scenarios.families import CATEGORY, FAMILIES

    rng = np.random.default_rng(2)
    rows = []
    for p in catalog().values():
        ind = p.indicators()
        for fam in FAMILIES:
            for t in range(10):
                ok = bool(rng.random() < min(0.95, 0.12 * ind.twr_max))
                r = dict.fromkeys(COLUMNS)
                r.update(
                    trial_id=f"ego/{p.name}/{fam}/{t}", campaign="bench", algorithm="ego",
                    algorithm_params="{}", platform=p.name, platform_category=p.category,
                    mass_kg=p.mass_kg, twr_max=ind.twr_max,
                    alpha_xy_max=float(ind.alpha_xy_max_rad_s2),
                    alpha_z_max=float(ind.alpha_z_max_rad_s2), family=fam,
                    scenario_category=CATEGORY.get(fam, "user"), scenario_index=t,
                    scenario_seed=0, scenario=f"{fam}-{t}", trial=t, seed=t, success=ok,
                    reason="success" if ok else str(rng.choice(REASONS[1:])),
                    detail="" if ok else "synthetic",
                    time_to_goal_s=float(rng.uniform(10, 40)) if ok else math.nan,
                    path_length_m=float(rng.uniform(40, 80)), max_tilt_deg=math.nan,
                    sim_time_s=60.0, wall_time_s=0.5, code_version="bench")
                rows.append(r)
    return to_frame(rows), list(FAMILIES)


def bench_report(repeats: int) -> dict:
    from ft_sitl.missions.report import write_report

    df, families = _report_frame()
    spec = {"name": "bench campaign", "algorithms": ["ego"], "families": families,
            "trials": 10}
    meta = {"code_version": "bench", "machine": "bench", "wall_time_s": 1.0}
    runs = []
    with tempfile.TemporaryDirectory() as tmp:

        def run():
            out = Path(tmp) / str(len(runs))  # a fresh directory per run
            runs.append(len(write_report(df, out, campaign_spec=spec, meta=meta)))

        run()  # matplotlib imported and fonts cached
        t = timed(run, repeats)
    return _stats(t, rows=len(df), files=runs[-1])


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, timeout=10, cwd=Path(__file__).parent).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="3 repeats, no report")
    ap.add_argument("--json", action="store_true", help="results as JSON on stdout")
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--report-repeats", type=int, default=3)
    ap.add_argument("--no-report", action="store_true", help="skip the report case")
    ap.add_argument("--cpu", type=int, default=None, help="CPU to pin to (default: last)")
    ap.add_argument("--no-pin", action="store_true")
    args = ap.parse_args(argv)
    cpu = None if args.no_pin else pin_to_one_cpu(args.cpu)
    repeats = 3 if args.quick else args.repeats
    cases = {"astar": bench_astar, "kino": bench_kino, "kino_time_cap": bench_kino_time_cap,
             "ego": bench_ego}
    results = {}
    for name, fn in cases.items():
        results[name] = fn(repeats)
        if not args.json:
            _print(name, results[name])
    if not (args.quick or args.no_report):
        results["report"] = bench_report(args.report_repeats)
        if not args.json:
            _print("report", results["report"])
    out = {"machine": machine_info(cpu, commit=_commit()), "repeats": repeats,
           "results": results}
    if args.json:
        json.dump(out, sys.stdout, indent=2)
        print()
    return 0


def _print(name: str, r: dict) -> None:
    if "median_s" not in r:  # the time cap
        for kind in ("points", "grid"):
            k = r[kind]
            print(f"{name:14s} {kind:6s} past the {1e3 * r['cap_s']:.0f} ms cap: median "
                  f"{1e3 * k['overshoot_median_s']:7.2f} ms  max "
                  f"{1e3 * k['overshoot_max_s']:7.2f} ms  ({', '.join(k['stop_reasons'])})",
                  flush=True)
        return
    skip = {"median_s", "min_s", "max_s", "cpu_share_median", "wall_s"}
    facts = "  ".join(f"{k} {v}" for k, v in r.items() if k not in skip)
    print(f"{name:14s} median {1e3 * r['median_s']:9.2f} ms  (min {1e3 * r['min_s']:.2f}, "
          f"max {1e3 * r['max_s']:.2f})  cpu share {r['cpu_share_median']:.2f}  {facts}",
          flush=True)


if __name__ == "__main__":
    sys.exit(main())
