"""Benchmark: collision-check cost per simulated second of flight (ft_sitl.scenarios.collision).

Scene: a dense synthetic forest, 800 vertical cylinders (radius 0.25-0.5 m, height 6 m,
16-sided prisms, 51k triangles) scattered over 40 x 60 m with a fixed seed. A vehicle of
collision radius 0.3 m flies a straight line at 1.5 m altitude, 4 m/s, through the forest
(70 m, 17.5 s); positions are precomputed at 1 kHz. Trees whose surface would come within
``--gap`` (0.1 m) of the vehicle's sphere are removed, so the flight is collision-free but
grazes trees all along (the real minimum clearance is printed).

Measured (process CPU time, median of repeats, GC off): CPU microseconds and fcl queries per
simulated second for

* the monitor called every physics step (``CollisionMonitor.update``),
* the monitor fed whole batches (``update_path``) of 20 steps (a 50 Hz caller) and 1000
  steps (1 Hz),
* the naive approaches: ``CollisionWorld.check`` every step (exact at the step points, may
  tunnel) and ``CollisionWorld.sweep`` every step (continuous, no tunnelling);
* "fcl only": the monitor's fcl queries times the measured cost of one query, i.e. what the
  monitor would cost if its per-step skip test (a path length compared with a clearance)
  ran inside the compiled physics loop.

Each is compared with the physics cost, taken as 400 ns per 1 kHz step, i.e. 400 us per
simulated second; the target is 5 % of it, 20 us per simulated second. Timings are never
asserted.

    .venv/bin/python bench/bench_collision.py            # ~5 s
    .venv/bin/python bench/bench_collision.py --quick    # smoke run
    .venv/bin/python bench/bench_collision.py --json     # results as JSON on stdout
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import datetime  # noqa: E402
import gc  # noqa: E402
import json  # noqa: E402
import platform as pyplatform  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import trimesh  # noqa: E402

from ft_sitl.scenarios.collision import CollisionMonitor, CollisionWorld  # noqa: E402

SEED = 20240601
N_CYLINDERS = 800
FOREST_X = (0.0, 60.0)
FOREST_Y = (-20.0, 20.0)
RADIUS_M = 0.3
SPEED_M_S = 4.0
PHYSICS_HZ = 1000
ALTITUDE_M = 1.5
PATH_X = (-5.0, 65.0)
PHYSICS_NS_PER_STEP = 400.0
TARGET_SHARE = 0.05


def forest(gap: float, n: int = N_CYLINDERS, seed: int = SEED):
    """The forest mesh with the flight corridor (y = 0) cleared to ``gap``; returns
    (mesh, number of trees kept)."""
    rng = np.random.default_rng(seed)
    xs, ys = rng.uniform(*FOREST_X, n), rng.uniform(*FOREST_Y, n)
    radii = rng.uniform(0.25, 0.5, n)
    parts = []
    for x, y, r in zip(xs, ys, radii):
        if abs(y) < r + RADIUS_M + gap:
            continue
        c = trimesh.creation.cylinder(radius=r, height=6.0, sections=16)
        c.apply_translation([x, y, 3.0])
        parts.append(c)
    return trimesh.util.concatenate(parts), len(parts)


def path() -> np.ndarray:
    """Positions at every physics step along the straight flight."""
    step = SPEED_M_S / PHYSICS_HZ
    xs = np.arange(PATH_X[0], PATH_X[1] + 0.5 * step, step)
    return np.column_stack([xs, np.zeros_like(xs), np.full_like(xs, ALTITUDE_M)])


def timed(fn, repeats: int) -> tuple[float, object]:
    """Median process CPU seconds of fn() over repeats (GC off); and its last result."""
    times, out = [], None
    gc.collect()
    gc.disable()
    try:
        for _ in range(repeats):
            c0 = time.process_time()
            out = fn()
            times.append(time.process_time() - c0)
    finally:
        gc.enable()
    return statistics.median(times), out


def run_monitor_steps(world, pts):
    mon = CollisionMonitor(world)
    hits = 0
    for i in range(len(pts) - 1):
        if mon.update(pts[i], pts[i + 1], RADIUS_M) is not None:
            hits += 1
    return mon.queries, hits


def run_monitor_batches(world, pts, batch: int):
    mon = CollisionMonitor(world)
    hits = 0
    for i in range(0, len(pts) - 1, batch):
        if mon.update_path(pts[i:i + batch + 1], RADIUS_M) is not None:
            hits += 1
    return mon.queries, hits


def run_naive_check(world, pts):
    q0 = world.queries
    hits = sum(world.check(p, RADIUS_M) is not None for p in pts[1:])
    return world.queries - q0, hits


def run_naive_sweep(world, pts):
    q0 = world.queries
    hits = sum(world.sweep(pts[i], pts[i + 1], RADIUS_M) is not None
               for i in range(len(pts) - 1))
    return world.queries - q0, hits


def fcl_query_seconds(world, pts, n: int = 4000) -> float:
    """CPU seconds of one raw fcl distance query (the monitor's refresh query)."""
    sample = pts[np.linspace(0, len(pts) - 1, n).astype(int)]

    def run():
        for p in sample:
            world._dist_fast(p)

    t, _ = timed(run, 3)
    return t / n


def machine_info() -> dict:
    model = pyplatform.processor() or ""
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    import fcl

    return {
        "date_utc": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "cpu_model": model,
        "python": pyplatform.python_version(),
        "numpy": np.__version__,
        "trimesh": trimesh.__version__,
        "python_fcl": getattr(fcl, "__version__", "?"),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="one repeat, smoke run")
    ap.add_argument("--json", action="store_true", help="print JSON instead of markdown")
    ap.add_argument("--gap", type=float, default=0.1,
                    help="clearance (m) kept between the vehicle sphere and the trees")
    args = ap.parse_args(argv)
    repeats = 1 if args.quick else 3

    mesh, kept = forest(args.gap)
    lo = (FOREST_X[0] - 10.0, FOREST_Y[0] - 5.0, 0.0)
    hi = (FOREST_X[1] + 10.0, FOREST_Y[1] + 5.0, 10.0)
    t0 = time.perf_counter()
    world = CollisionWorld(mesh, lo, hi)
    build_s = time.perf_counter() - t0
    pts = path()
    n_steps = len(pts) - 1
    sim_s = n_steps / PHYSICS_HZ
    clearances = [world.clearance(p, RADIUS_M) for p in pts[::25]]
    t_query = fcl_query_seconds(world, pts)

    methods = [
        ("monitor, update() every step", lambda: run_monitor_steps(world, pts)),
        ("monitor, update_path() 20 steps a call", lambda: run_monitor_batches(world, pts, 20)),
        ("monitor, update_path() 1000 steps a call",
         lambda: run_monitor_batches(world, pts, 1000)),
        ("naive: check() every step", lambda: run_naive_check(world, pts)),
        ("naive: sweep() every step", lambda: run_naive_sweep(world, pts)),
    ]
    physics_us = PHYSICS_NS_PER_STEP * 1e-3 * PHYSICS_HZ  # per simulated second
    rows = []
    for name, fn in methods:
        cpu_s, (queries, hits) = timed(fn, repeats)
        us = cpu_s / sim_s * 1e6
        rows.append({"method": name, "cpu_us_per_sim_s": us, "fcl_queries_per_sim_s":
                     queries / sim_s, "share_of_physics": us / physics_us, "contacts": hits})
    mon = rows[0]
    fcl_only = mon["fcl_queries_per_sim_s"] * t_query * 1e6
    rows.append({"method": "monitor, fcl queries only (skip test compiled)",
                 "cpu_us_per_sim_s": fcl_only, "fcl_queries_per_sim_s":
                 mon["fcl_queries_per_sim_s"], "share_of_physics": fcl_only / physics_us,
                 "contacts": None})
    res = {
        "machine": machine_info(),
        "scene": {"n_cylinders": N_CYLINDERS, "kept": kept, "n_triangles": world.n_triangles,
                  "seed": SEED, "gap_m": args.gap, "build_ms": build_s * 1e3,
                  "min_clearance_m": float(min(clearances))},
        "flight": {"radius_m": RADIUS_M, "speed_m_s": SPEED_M_S, "physics_hz": PHYSICS_HZ,
                   "steps": n_steps, "sim_s": sim_s},
        "fcl_query_us": t_query * 1e6,
        "physics_us_per_sim_s": physics_us,
        "target_us_per_sim_s": TARGET_SHARE * physics_us,
        "repeats": repeats,
        "results": rows,
    }
    if args.json:
        json.dump(res, sys.stdout, indent=2)
        print()
        return 0
    m, s, f = res["machine"], res["scene"], res["flight"]
    print(f"# {m['cpu_model']}, {m['date_utc']}, python-fcl {m['python_fcl']}, "
          f"trimesh {m['trimesh']}")
    print(f"# forest: {s['kept']} of {s['n_cylinders']} trees kept (corridor gap "
          f"{s['gap_m']} m), {s['n_triangles']} triangles, BVH build {s['build_ms']:.0f} ms; "
          f"flight {f['sim_s']:.1f} s at {f['speed_m_s']} m/s, {f['physics_hz']} Hz, radius "
          f"{f['radius_m']} m, min clearance {s['min_clearance_m']:.3f} m")
    print(f"# one fcl distance query: {res['fcl_query_us']:.1f} us; physics "
          f"{physics_us:.0f} us per simulated second, target < {res['target_us_per_sim_s']:.0f}"
          f" us (5 %)")
    print()
    print("| method | fcl queries / sim s | CPU us / sim s | share of physics | contacts |")
    print("|---|---:|---:|---:|---:|")
    for r in rows:
        hits = "" if r["contacts"] is None else r["contacts"]
        print(f"| {r['method']} | {r['fcl_queries_per_sim_s']:.0f} | "
              f"{r['cpu_us_per_sim_s']:.0f} | {r['share_of_physics']:.1%} | {hits} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
