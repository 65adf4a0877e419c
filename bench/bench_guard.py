"""Benchmark: cost of collision checking inside the physics loop, per simulated second.

For configuration 10 of every scenario family (the densest of each), a batch of vehicles
flies the scenario's proven collision-free path (``solvability.scenario_path`` for a 0.6 m
radius, 0.4 m for Narrow-Gap's gaps; the vehicle's collision radius is 0.25 m, 0.2 m on
Narrow-Gap, leaving at least 0.2 m for tracking errors): vehicle k starts hovering at the
fraction k/N of the path and follows a carrot moving along it at 3 m/s (1.5 m/s in the
tight turns of Maze, Narrow-Gap and Sudden-Drop; a position setpoint with the carrot's
velocity as feed-forward), for 10 simulated seconds, commanded every 20 ms (the setpoints
are computed before timing). A vehicle that touches an obstacle anyway crashes as in a
trial (motors off, no further checks: a trial ends there) and is counted. The same flight
is run without and with a CollisionGuard attached (``ft_sitl.sim.guard``: free ball,
anchor and distance grid in the compiled loop, python-fcl only near obstacles),
alternating, several repeats, in one process pinned to one CPU.

Reported per family: the physics cost (controller + plant, no guard) and the guard's extra
cost, both in CPU microseconds per vehicle per simulated second (median of repeats), the
share guard / physics (target: under 5 %), the kernel stops (trips) and exact fcl steps per
vehicle-second, collisions seen (vehicles that strayed into an obstacle; 0 expected), and the
one-off cost of building the distance grid. Timings are never asserted.

    .venv/bin/python bench/bench_guard.py            # ~1-2 min
    .venv/bin/python bench/bench_guard.py --quick    # smoke run
    .venv/bin/python bench/bench_guard.py --json     # results as JSON on stdout
    .venv/bin/python bench/bench_guard.py --body     # vehicles are their bodies (protocol 5)
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
import time  # noqa: E402

import numpy as np  # noqa: E402
from benchutil import machine_info, pin_to_one_cpu  # noqa: E402

from ft_sitl.autopilot.setpoints import Setpoint  # noqa: E402
from ft_sitl.physics.catalog import catalog  # noqa: E402
from ft_sitl.scenarios.collision import CollisionWorld  # noqa: E402
from ft_sitl.scenarios.distance_grid import DistanceGrid  # noqa: E402
from ft_sitl.scenarios.families import FAMILIES, build_scenario  # noqa: E402
from ft_sitl.scenarios.solvability import scenario_path  # noqa: E402
from ft_sitl.sim.guard import G_BOUNDS, G_ON, CollisionGuard, GuardEventKind  # noqa: E402  # noqa: E402
from ft_sitl.sim.lockstep import Simulation  # noqa: E402

PLATFORM = "0.98kg-EGO Planner DIY"
PATH_RADIUS_M = 0.6
VEHICLE_RADIUS_M = 0.25
SPEED_M_S = 3.0
SLOW_M_S = 1.5
SLOW_FAMILIES = ("maze", "narrow_gap", "sudden_drop")
CHUNK_STEPS = 20  # 50 Hz setpoints at 1 kHz physics
TARGET_SHARE = 0.05


def _along(path: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Points at arc lengths s along the polyline path."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    s = np.clip(s, 0.0, cum[-1])
    return np.column_stack([np.interp(s, cum, path[:, k]) for k in range(3)])


def plan(scenario, n: int, seconds: float):
    speed = SLOW_M_S if scenario.family in SLOW_FAMILIES else SPEED_M_S
    for r_path in (PATH_RADIUS_M, 0.45, 0.4):  # Narrow-Gap's 0.85 m gaps need the last
        path = scenario_path(scenario, r_path)
        if path is not None:
            break
    else:
        raise RuntimeError(f"{scenario.name}: no path for radius 0.4 m")
    length = float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1)))
    s0 = length * np.arange(n) / n
    chunks = int(round(seconds * 1000 / CHUNK_STEPS))
    t = (np.arange(chunks) + 1) * CHUNK_STEPS * 1e-3
    rows = np.empty((chunks, n, len(Setpoint.off().row)))
    for k in range(n):
        pts = _along(path, s0[k] + speed * t)
        ahead = _along(path, s0[k] + speed * t + 0.1)
        for c in range(chunks):  # the carrot, with its velocity as feed-forward
            u = ahead[c] - pts[c]
            norm = float(np.linalg.norm(u))
            vel = speed * u / norm if norm > 1e-9 else np.zeros(3)
            rows[c, k] = Setpoint.position(pts[c], velocity=vel).row
    return _along(path, s0), rows, length, r_path


def fly(platform, starts, rows, guard: CollisionGuard | None):
    n = len(starts)
    sim = Simulation([platform] * n)
    for k in range(n):
        sim.start_hovering(k, starts[k])
    crashed = np.zeros(n, dtype=bool)
    if guard is not None:
        guard.events.clear()
        guard.trips = guard.queries = 0
        def crash(ev):
            # as in a trial, a collision ends that vehicle's flight: motors off, and no
            # more checks (what a crashed vehicle costs while it falls and rests against
            # the obstacle is not flight; the unguarded run flies it on, same physics cost)
            if ev.kind == GuardEventKind.COLLISION:
                crashed[ev.vehicle] = True
                sim.sp[ev.vehicle] = Setpoint.off().row
                guard.rows[ev.vehicle, [G_ON, G_BOUNDS]] = 0.0
        sim.attach_guard(guard, crash)
    off = Setpoint.off().row
    c0 = time.process_time()
    for c in range(len(rows)):
        sim.sp[:] = rows[c]
        sim.sp[crashed] = off
        sim.step(CHUNK_STEPS)
    return time.process_time() - c0


def bench_family(family: str, n: int, seconds: float, repeats: int, body: bool = False) -> dict:
    sc = build_scenario(family, 10)
    p = catalog().get(PLATFORM)
    starts, rows, length, r_path = plan(sc, n, seconds)
    radius = min(VEHICLE_RADIUS_M, r_path - 0.2)  # >= 0.2 m left for tracking errors
    bodies = None
    if body:  # the platform's body (protocol 5), its bounding sphere the broad phase
        bodies = [p.body()] * n
        radius = p.body().bounding_radius_m
    t0 = time.perf_counter()
    grid = DistanceGrid.build(sc.mesh, sc.bounds_min, sc.bounds_max)
    grid_s = time.perf_counter() - t0
    world = CollisionWorld(sc.mesh, sc.bounds_min, sc.bounds_max)
    guard = CollisionGuard(world, [radius] * n, grid=grid, names=sc.obstacle_name,
                           bodies=bodies)
    # with bodies, the sphere of the same (bounding) radius flies too, in the same rounds
    sphere = CollisionGuard(world, [radius] * n, grid=grid) if body else None
    fly(p, starts, rows[:5], None)  # warm-up (JIT load)
    fly(p, starts, rows[:5], guard)
    plain, guarded, spheres = [], [], []
    for _ in range(repeats):
        plain.append(fly(p, starts, rows, None))
        guarded.append(fly(p, starts, rows, guard))
        if sphere is not None:
            spheres.append(fly(p, starts, rows, sphere))
    veh_s = n * seconds
    phys = statistics.median(plain) / veh_s * 1e6
    # paired: each guarded run against the unguarded run just before it
    extra = statistics.median(g - q for g, q in zip(guarded, plain)) / veh_s * 1e6
    collisions = sum(1 for e in guard.events if e.kind == "collision")
    more = {}
    if sphere is not None:
        more["sphere_guard_us_per_vehicle_s"] = round(
            statistics.median(g - q for g, q in zip(spheres, plain)) / veh_s * 1e6, 2)
        more["sphere_trips_per_vehicle_s"] = round(sphere.trips / veh_s, 2)
    return {**more,
        "family": family, "scenario": sc.name, "triangles": int(len(sc.mesh.faces)),
        "path_m": round(length, 1), "path_radius_m": r_path, "vehicle_radius_m": radius,
        "body": body,
        "vehicles": n, "sim_s": seconds,
        "grid_shape": list(grid.shape), "grid_pitch_m": grid.pitch,
        "grid_build_s": round(grid_s, 3),
        "physics_us_per_vehicle_s": round(phys, 1),
        "guard_us_per_vehicle_s": round(extra, 2),
        "share": round(extra / phys, 4),
        "trips_per_vehicle_s": round(guard.trips / veh_s, 2),
        "fcl_steps_per_vehicle_s": round(guard.queries / veh_s, 2),
        "fcl_queries_per_vehicle_s": round(world.queries / veh_s / (repeats + 1), 2),
        "collisions": collisions,
        "plain_s": plain, "guarded_s": guarded,
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="two families, short flights")
    ap.add_argument("--json", action="store_true", help="results as JSON on stdout")
    ap.add_argument("--families", nargs="+", choices=FAMILIES, help="default: all seven")
    ap.add_argument("--vehicles", type=int, default=16)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--cpu", type=int, default=None, help="CPU to pin to (default: last)")
    ap.add_argument("--no-pin", action="store_true")
    ap.add_argument("--body", action="store_true",
                    help="vehicles are their bodies (protocol 5), not 0.25 m spheres; a "
                         "sphere of the body's bounding radius flies in the same rounds")
    args = ap.parse_args(argv)
    cpu = None if args.no_pin else pin_to_one_cpu(args.cpu)
    families = args.families or (("forest", "perlin") if args.quick else FAMILIES)
    seconds = 2.0 if args.quick else args.seconds
    repeats = 1 if args.quick else args.repeats
    results = []
    for fam in families:
        r = bench_family(fam, args.vehicles, seconds, repeats, body=args.body)
        results.append(r)
        if not args.json:
            print(f"{r['scenario']:26s} physics {r['physics_us_per_vehicle_s']:7.1f} us/veh-s  "
                  f"guard {r['guard_us_per_vehicle_s']:6.2f} us/veh-s  "
                  f"share {100 * r['share']:5.2f} %  trips {r['trips_per_vehicle_s']:6.2f}/s  "
                  f"fcl {r['fcl_queries_per_vehicle_s']:6.2f}/s  collisions "
                  f"{r['collisions']}  grid {r['grid_build_s']:.2f} s"
                  + (f"  | sphere of the bounding radius: guard "
                     f"{r['sphere_guard_us_per_vehicle_s']:6.2f} us/veh-s, trips "
                     f"{r['sphere_trips_per_vehicle_s']:.2f}/s" if args.body else ""),
                  flush=True)
    worst = max(results, key=lambda r: r["share"])
    out = {"machine": machine_info(cpu), "target_share": TARGET_SHARE, "results": results,
           "worst": {"scenario": worst["scenario"], "share": worst["share"]}}
    if args.json:
        json.dump(out, sys.stdout, indent=2)
        print()
    else:
        print(f"worst: {worst['scenario']} at {100 * worst['share']:.2f} % of the physics cost "
              f"(target < {100 * TARGET_SHARE:.0f} %)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
