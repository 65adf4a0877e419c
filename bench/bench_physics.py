"""Benchmark: how fast the lockstep simulation (controller + plant) and the plant alone run.

Measures, on one pinned core, with numba compiled before any timing:

1. simulated seconds per wall second for one vehicle flying the full control cascade at
   1 kHz physics (Simulation, moving position setpoint), and for the plant kernel alone
   (dynamics.plant_step, batch of one, constant rotor commands);
2. vehicle-steps per second and ns per vehicle-step for batches of 1, 64 and 1024
   vehicles (catalog platforms, cycled), full lockstep (Simulation.step) and plant alone;
3. ratios: controller overhead (full / plant, per vehicle-step) and speed relative to
   ArduPilot SITL's often quoted ~230x real time (a stated figure, not measured here).

Every figure is the median of several repeats; spread (min..max) and the CPU share of
wall time (process CPU time / wall time, < 1 when the process was descheduled on a busy
machine) are reported alongside. Timings are never asserted: this is a script, not a test.

    .venv/bin/python bench/bench_physics.py            # ~1 minute
    .venv/bin/python bench/bench_physics.py --quick    # smoke run, a few seconds
    .venv/bin/python bench/bench_physics.py --json     # results as JSON on stdout
    .venv/bin/python bench/bench_physics.py --plot     # also docs/img/bench_physics.png
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import os

# One thread everywhere, set before numpy / numba are imported.
for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numba  # noqa: E402
import numpy as np  # noqa: E402
from benchutil import machine_info, pin_to_one_cpu, timed  # noqa: E402
from numba import njit  # noqa: E402

from ft_sitl.autopilot.setpoints import Setpoint  # noqa: E402
from ft_sitl.physics import dynamics as d  # noqa: E402
from ft_sitl.physics.catalog import catalog, get_platform  # noqa: E402
from ft_sitl.sim.lockstep import Simulation  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_PLOT = ROOT / "docs" / "img" / "bench_physics.png"
PLATFORM = "0.98kg-EGO Planner DIY"
PHYSICS_HZ = 1000
ARDUPILOT_SITL_SPEEDUP = 230.0  # stated figure for ArduPilot SITL, context only
TARGET_SPEEDUP = 500.0
HOVER_Z = 10.0


# --- plant-only drivers (compiled here, outside the package) ------------------------------
@njit(cache=False)
def plant_loop(n_steps, x, w_cmd, prm, alloc, env, status, dt):
    """n_steps calls of the public batch kernel dynamics.plant_step (step-major)."""
    for _ in range(n_steps):
        d.plant_step(x, w_cmd, prm, alloc, env, status, dt)


@njit(cache=False)
def plant_loop_vehicle_major(n_steps, x, w_cmd, prm, alloc, env, status, dt):
    """The same work in lockstep.run_steps' loop order: each vehicle runs all its steps."""
    for i in range(x.shape[0]):
        xi = x[i]
        for _ in range(n_steps):
            d.plant_step_one(xi, w_cmd[i], prm[i], alloc[i], env[i], status[i], dt)


# --- timing helpers ------------------------------------------------------------------------
def circle_waypoints(n: int, centre, radius: float, period_s: float, dt_s: float):
    """n position setpoints on a horizontal circle, dt_s apart in time."""
    cx, cy, cz = centre
    out = []
    for k in range(n):
        a = 2.0 * math.pi * (k + 1) * dt_s / period_s
        out.append(Setpoint.position([cx + radius * math.cos(a), cy + radius * math.sin(a), cz],
                                     yaw=0.0))
    return out


def platforms_cycled(n: int):
    cat = list(catalog().values())
    return [cat[i % len(cat)] for i in range(n)]


def hover_plant(platforms):
    """A plant batch hovering at HOVER_Z with constant hover rotor commands."""
    pb = d.PlantBatch.from_platforms(platforms)
    n = len(platforms)
    pb.x[:, d.X_POS] = np.arange(n) * 3.0
    pb.x[:, d.X_POS + 2] = HOVER_Z
    w_hover = np.array([p.hover_rotor_speed_rad_s for p in platforms])
    pb.x[:, d.X_ROTOR:] = w_hover[:, None]
    w_cmd = np.repeat(w_hover[:, None], platforms[0].n_rotors, axis=1)
    return pb, w_cmd


def hovering_sim(platforms):
    sim = Simulation(platforms, physics_hz=PHYSICS_HZ)
    for i in range(sim.n):
        sim.start_hovering(i, [i * 3.0, 0.0, HOVER_Z])
    return sim


# --- 1. one vehicle: simulated seconds per wall second -------------------------------------
def bench_one_vehicle(chunk_s: float, repeats: int) -> dict:
    p = get_platform(PLATFORM)
    steps_per_s = PHYSICS_HZ
    n_chunk = round(chunk_s * steps_per_s)
    centre = (0.0, 0.0, HOVER_Z)

    # (a) full cascade, a new waypoint on a 2 m circle every simulated second (kernel-bound:
    # 1000 physics steps per Python call, setpoints built before timing)
    sim = hovering_sim([p])
    seg = steps_per_s
    wps = circle_waypoints(round(chunk_s), centre, 2.0, 12.0, 1.0)
    sim.step(10)  # warm-up: loads / compiles run_steps

    def full_chunk():
        for sp in wps:
            sim.set_setpoint(0, sp)
            sim.step(seg)

    full_chunk()  # one untimed chunk: the vehicle is on its circle when timing starts
    full = timed(full_chunk, repeats)
    pos_err = float(np.linalg.norm(sim.position(0) - wps[-1].row[1:4]))

    # (b) same cascade, setpoint streamed at 50 Hz as an offboard node would, built in Python
    # each time (Setpoint validation + one Simulation.step call per 20 ms of simulated time)
    sim_s = hovering_sim([p])
    every = steps_per_s // 50
    n_stream = n_chunk // every
    t_state = [0.0]

    def stream_chunk():
        t = t_state[0]
        for _ in range(n_stream):
            t += every / steps_per_s
            a = 2.0 * math.pi * t / 12.0
            sim_s.set_setpoint(0, Setpoint.position(
                [2.0 * math.cos(a), 2.0 * math.sin(a), HOVER_Z], yaw=0.0))
            sim_s.step(every)
        t_state[0] = t

    stream_chunk()
    stream = timed(stream_chunk, repeats)

    # (c) plant alone: dynamics.plant_step on a batch of one, constant hover commands
    pb, w_cmd = hover_plant([p])
    args = (pb.x, w_cmd, pb.prm, pb.alloc, pb.env, pb.status, 1.0 / PHYSICS_HZ)
    plant_loop(10, *args)  # compile
    plant = timed(lambda: plant_loop(n_chunk, *args), repeats)
    drift = float(abs(pb.x[0, d.X_POS + 2] - HOVER_Z))

    def speed(t):
        return {**t, "sim_s": chunk_s, "speedup_median": chunk_s / t["median_s"],
                "speedup_min": chunk_s / t["max_s"], "speedup_max": chunk_s / t["min_s"],
                "ns_per_step": t["median_s"] / n_chunk * 1e9}

    return {
        "platform": PLATFORM,
        "chunk_sim_s": chunk_s,
        "full_waypoint_1hz": speed(full) | {"final_pos_err_m": pos_err},
        "full_stream_50hz": speed(stream),
        "plant_only": speed(plant) | {"hover_z_drift_m": drift},
    }


# --- 2. batches: vehicle-steps per second --------------------------------------------------
def bench_batches(sizes, vehicle_steps: int, repeats: int) -> list[dict]:
    out = []
    dt = 1.0 / PHYSICS_HZ
    seg = 2 * PHYSICS_HZ  # 2 s of simulated time per Simulation.step call
    for n in sizes:
        plats = platforms_cycled(n)
        n_steps = max(seg, round(vehicle_steps / n / seg) * seg)
        vs = n * n_steps

        # full lockstep: every segment moves every vehicle's waypoint 2 m along a square
        sim = hovering_sim(plats)
        base = np.array([[i * 3.0, 0.0, HOVER_Z] for i in range(n)])
        offsets = [(2.0, 0.0), (2.0, 2.0), (0.0, 2.0), (0.0, 0.0)]
        sps = [[Setpoint.position(base[i] + [ox, oy, 0.0], yaw=0.0) for i in range(n)]
               for ox, oy in offsets]
        sim.step(10)
        k_state = [0]

        def full_run(sim=sim, sps=sps, n_steps=n_steps, n=n, k_state=k_state):
            for _ in range(n_steps // seg):
                row = sps[k_state[0] % len(sps)]
                for i in range(n):
                    sim.set_setpoint(i, row[i])
                sim.step(seg)
                k_state[0] += 1

        full = timed(full_run, repeats)
        airborne = bool(np.all(sim.x[:, d.X_POS + 2] > 1.0))

        pb, w_cmd = hover_plant(plats)
        args = (pb.x, w_cmd, pb.prm, pb.alloc, pb.env, pb.status, dt)
        plant_loop(10, *args)
        plant = timed(lambda args=args, n_steps=n_steps: plant_loop(n_steps, *args), repeats)
        pb2, w_cmd2 = hover_plant(plats)
        args2 = (pb2.x, w_cmd2, pb2.prm, pb2.alloc, pb2.env, pb2.status, dt)
        plant_loop_vehicle_major(10, *args2)
        plant_vm = timed(
            lambda args2=args2, n_steps=n_steps: plant_loop_vehicle_major(n_steps, *args2),
            repeats)

        def rates(t, vs=vs):
            return {**t, "vehicle_steps": vs,
                    "vehicle_steps_per_s": vs / t["median_s"],
                    "ns_per_vehicle_step": t["median_s"] / vs * 1e9,
                    "ns_per_vehicle_step_min": t["min_s"] / vs * 1e9,
                    "ns_per_vehicle_step_max": t["max_s"] / vs * 1e9}

        row = {
            "n_vehicles": n,
            "n_steps": n_steps,
            "full": rates(full) | {"all_airborne": airborne},
            "plant": rates(plant),
            "plant_vehicle_major": rates(plant_vm),
        }
        row["controller_overhead_ratio"] = (row["full"]["ns_per_vehicle_step"]
                                            / row["plant"]["ns_per_vehicle_step"])
        # the same ratio against the plant driven in run_steps' own loop order
        row["controller_overhead_ratio_matched"] = (
            row["full"]["ns_per_vehicle_step"]
            / row["plant_vehicle_major"]["ns_per_vehicle_step"])
        out.append(row)
    base_full = out[0]["full"]["ns_per_vehicle_step"]
    base_plant = out[0]["plant"]["ns_per_vehicle_step"]
    for row in out:
        row["full"]["cost_vs_batch1"] = row["full"]["ns_per_vehicle_step"] / base_full
        row["plant"]["cost_vs_batch1"] = row["plant"]["ns_per_vehicle_step"] / base_plant
    return out


# --- reporting -------------------------------------------------------------------------------
def print_report(res: dict, file=sys.stdout) -> None:
    m = res["machine"]
    cfg = res["config"]
    print(f"# ft-sitl physics benchmark  {m['date_utc']}", file=file)
    print(f"# {m['cpu_model']}, {m['n_cpus']} CPUs (pinned to {m['pinned_cpu']}), "
          f"Python {m['python']}, numba {m['numba']}, numpy {m['numpy']}, "
          f"NUMBA_NUM_THREADS={m['numba_num_threads']}", file=file)
    print(f"# repeats={cfg['repeats']} (median reported), quick={cfg['quick']}", file=file)
    one = res["one_vehicle"]
    print(f"\n## One vehicle ({one['platform']}), 1 kHz physics, "
          f"{one['chunk_sim_s']:g} s simulated per repeat\n", file=file)
    print("| what | x real time (median) | min..max | ns/step | CPU share |", file=file)
    print("|---|---:|---:|---:|---:|", file=file)
    labels = [
        ("full_waypoint_1hz", "full cascade + plant, new waypoint every 1 s"),
        ("full_stream_50hz", "full cascade + plant, setpoint streamed at 50 Hz from Python"),
        ("plant_only", "plant alone (plant_step, batch of 1, constant commands)"),
    ]
    for key, label in labels:
        r = one[key]
        print(f"| {label} | {r['speedup_median']:,.0f} | {r['speedup_min']:,.0f}.."
              f"{r['speedup_max']:,.0f} | {r['ns_per_step']:.0f} | "
              f"{r['cpu_share_median']:.2f} |", file=file)
    print(f"\n## Batches (catalog platforms cycled), "
          f"~{cfg['vehicle_steps']:,} vehicle-steps per repeat\n", file=file)
    print("| vehicles | full: Mvehicle-steps/s | full: ns/vehicle-step | "
          "plant: Mvehicle-steps/s | plant: ns/vehicle-step | "
          "plant, run_steps order: ns/vehicle-step | full / plant | "
          "full / plant (run_steps order) |", file=file)
    print("|---:|---:|---:|---:|---:|---:|---:|---:|", file=file)
    for row in res["batches"]:
        f, p, pv = row["full"], row["plant"], row["plant_vehicle_major"]
        print(f"| {row['n_vehicles']} | {f['vehicle_steps_per_s'] / 1e6:.2f} | "
              f"{f['ns_per_vehicle_step']:.0f} ({f['ns_per_vehicle_step_min']:.0f}.."
              f"{f['ns_per_vehicle_step_max']:.0f}) | {p['vehicle_steps_per_s'] / 1e6:.2f} | "
              f"{p['ns_per_vehicle_step']:.0f} ({p['ns_per_vehicle_step_min']:.0f}.."
              f"{p['ns_per_vehicle_step_max']:.0f}) | {pv['ns_per_vehicle_step']:.0f} | "
              f"{row['controller_overhead_ratio']:.1f} | "
              f"{row['controller_overhead_ratio_matched']:.1f} |", file=file)
    r = res["ratios"]
    print("\n## Ratios\n", file=file)
    print(f"- one vehicle, full lockstep: {r['one_vehicle_speedup']:,.0f}x real time = "
          f"{r['vs_target_500x']:.1f}x the 500x target, "
          f"{r['vs_ardupilot_sitl_230x']:.1f}x ArduPilot SITL's stated ~230x (not measured)",
          file=file)
    print(f"- controller overhead (full / plant per vehicle-step), batch of 1: "
          f"{r['controller_overhead_batch1']:.1f}x against plant_step, "
          f"{r['controller_overhead_batch1_matched']:.1f}x against the plant in "
          "run_steps' loop order", file=file)
    print(f"- cost per vehicle-step, largest batch vs batch of 1: full "
          f"{r['full_cost_growth']:.2f}x, plant {r['plant_cost_growth']:.2f}x", file=file)


def write_plot(res: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = res["batches"]
    n = [r["n_vehicles"] for r in rows]
    fig, ax = plt.subplots(figsize=(5.5, 3.6), dpi=110)
    for key, label, marker in (("full", "controller + plant (Simulation.step)", "o"),
                               ("plant", "plant alone (plant_step)", "s"),
                               ("plant_vehicle_major", "plant alone, run_steps' loop order",
                                "^")):
        med = np.array([r[key]["ns_per_vehicle_step"] for r in rows])
        lo = np.array([r[key]["ns_per_vehicle_step_min"] for r in rows])
        hi = np.array([r[key]["ns_per_vehicle_step_max"] for r in rows])
        ax.errorbar(n, med, yerr=[med - lo, hi - med], marker=marker, capsize=3, label=label)
    ax.set_xscale("log")
    ax.set_xticks(n, [str(v) for v in n])
    ax.set_ylim(bottom=0)
    ax.set_xlabel("vehicles in the batch")
    ax.set_ylabel("ns per vehicle-step (median)")
    m = res["machine"]
    ax.set_title(f"ft-sitl, 1 kHz physics, one core\n{m['cpu_model']}, {m['date_utc'][:10]}",
                 fontsize=9)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="smoke run: short chunks, 2 repeats")
    ap.add_argument("--json", action="store_true", help="print the results as JSON on stdout")
    ap.add_argument("--plot", nargs="?", const=str(DEFAULT_PLOT), default=None, metavar="PNG",
                    help=f"write ns/vehicle-step vs batch size (default {DEFAULT_PLOT})")
    ap.add_argument("--repeats", type=int, default=None, help="repeats per measurement")
    ap.add_argument("--cpu", type=int, default=None, help="CPU to pin to (default: last one)")
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU")
    args = ap.parse_args(argv)

    cpu = None if args.no_pin else pin_to_one_cpu(args.cpu)
    if args.quick:
        cfg = {"quick": True, "repeats": args.repeats or 2, "chunk_s": 5.0,
               "vehicle_steps": 100_000, "sizes": [1, 64, 1024]}
    else:
        cfg = {"quick": False, "repeats": args.repeats or 7, "chunk_s": 60.0,
               "vehicle_steps": 2_000_000, "sizes": [1, 64, 1024]}

    t0 = time.perf_counter()
    one = bench_one_vehicle(cfg["chunk_s"], cfg["repeats"])
    batches = bench_batches(cfg["sizes"], cfg["vehicle_steps"], cfg["repeats"])
    speed = one["full_waypoint_1hz"]["speedup_median"]
    res = {
        "machine": machine_info(cpu, numba=numba.__version__,
                                numba_num_threads=numba.config.NUMBA_NUM_THREADS),
        "config": cfg,
        "one_vehicle": one,
        "batches": batches,
        "ratios": {
            "one_vehicle_speedup": speed,
            "vs_target_500x": speed / TARGET_SPEEDUP,
            "vs_ardupilot_sitl_230x": speed / ARDUPILOT_SITL_SPEEDUP,
            "one_vehicle_plant_speedup": one["plant_only"]["speedup_median"],
            "controller_overhead_batch1": batches[0]["controller_overhead_ratio"],
            "controller_overhead_batch1_matched":
                batches[0]["controller_overhead_ratio_matched"],
            "controller_overhead_by_batch": {
                r["n_vehicles"]: r["controller_overhead_ratio"] for r in batches},
            "full_cost_growth": batches[-1]["full"]["cost_vs_batch1"],
            "plant_cost_growth": batches[-1]["plant"]["cost_vs_batch1"],
        },
        "ardupilot_sitl_speedup_stated": ARDUPILOT_SITL_SPEEDUP,
    }
    res["bench_wall_s"] = time.perf_counter() - t0
    if args.plot:
        write_plot(res, Path(args.plot))
        res["plot"] = args.plot
    if args.json:
        json.dump(res, sys.stdout, indent=2)
        print()
    else:
        print_report(res)
        if args.plot:
            print(f"\nplot: {args.plot}")
        print(f"(benchmark took {res['bench_wall_s']:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
