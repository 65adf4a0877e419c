"""Benchmark: the ArduPilot JSON bridge in lockstep with an instant peer.

1. Lockstep frames per second over UDP: the bridge serves in its own process (as
   ``ft-sitl bridge ardupilot`` would), a peer in this process plays ArduPilot's side and
   sends the next servo packet the moment an answer arrives (no autopilot work in
   between), at ArduPilot's default 1200 Hz frame rate; also as simulated seconds per wall
   second (frames / 1200), i.e. how much faster than real time the bridge alone can go.
2. The same without sockets: ``ArduPilotBridge.handle`` called in a loop (the bridge's own
   cost per frame: mapping, plant steps, JSON).

Each figure is the median of several repeats, after a warm-up (numba loaded, plant in the
air). A real ArduPilot adds its own work per frame, so this is an upper bound for the pair.

    .venv/bin/python bench/bench_bridge_ardupilot.py            # ~30 s
    .venv/bin/python bench/bench_bridge_ardupilot.py --quick    # a few seconds
    .venv/bin/python bench/bench_bridge_ardupilot.py --json

Timings are never asserted: this is a script, not a test.
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import multiprocessing as mp  # noqa: E402
import socket  # noqa: E402
import statistics  # noqa: E402
import struct  # noqa: E402
import threading  # noqa: E402
import time  # noqa: E402

from benchutil import machine_info  # noqa: E402

PLATFORM = "1.50kg-DJI"
RATE_HZ = 1200
MAGIC_16 = 18458


def packet(count: int) -> bytes:
    """Frame count's servo packet: around this platform's hover (1745 us), airborne and
    climbing slowly, new widths every third frame as ArduCopter's 400 Hz loop at 1200 Hz."""
    pwm = 1752 + (count // 3) % 2 * 4
    return struct.pack("<HHI16H", MAGIC_16, RATE_HZ, count, *([pwm] * 4 + [0] * 12))


def _serve(port_out, stop, physics_hz: int) -> None:
    """Child process: a bridge on a free port until stop is set."""
    from ft_sitl.bridge.ardupilot import ArduPilotBridge
    from ft_sitl.physics.catalog import get_platform

    bridge = ArduPilotBridge(get_platform(PLATFORM), port=0, physics_hz=physics_hz)
    port_out.send(bridge.open()[1])
    runner = threading.Thread(target=bridge.run, daemon=True)
    runner.start()
    stop.wait()
    bridge.stop()
    runner.join()
    bridge.close()


def udp_lockstep(frames: int, repeats: int, physics_hz: int) -> dict:
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    stop = ctx.Event()
    proc = ctx.Process(target=_serve, args=(child, stop, physics_hz))
    proc.start()
    try:
        port = parent.recv()
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        sock.bind(("127.0.0.1", 0))
        sock.settimeout(30.0)
        addr = ("127.0.0.1", port)
        count = 0

        def run(n: int) -> float:
            nonlocal count
            t0 = time.perf_counter()
            for _ in range(n):
                sock.sendto(packet(count), addr)
                sock.recvfrom(65536)
                count += 1
            return time.perf_counter() - t0

        run(2 * RATE_HZ)  # warm-up: 2 s simulated, off the ground
        walls = [run(frames) for _ in range(repeats)]
        sock.close()
    finally:
        stop.set()
        proc.join(30)
    per_s = [frames / w for w in walls]
    return {"frames_per_s_median": statistics.median(per_s), "frames_per_s_min": min(per_s),
            "frames_per_s_max": max(per_s), "speedup_median": statistics.median(per_s) / RATE_HZ,
            "us_per_frame_median": 1e6 / statistics.median(per_s)}


def in_process(frames: int, repeats: int, physics_hz: int) -> dict:
    from ft_sitl.bridge.ardupilot import ArduPilotBridge
    from ft_sitl.physics.catalog import get_platform

    bridge = ArduPilotBridge(get_platform(PLATFORM), port=0, physics_hz=physics_hz)
    count = 0

    def run(n: int) -> float:
        nonlocal count
        t0 = time.perf_counter()
        for _ in range(n):
            bridge.handle(packet(count))
            count += 1
        return time.perf_counter() - t0

    run(2 * RATE_HZ)
    walls = [run(frames) for _ in range(repeats)]
    per_s = [frames / w for w in walls]
    return {"frames_per_s_median": statistics.median(per_s), "frames_per_s_min": min(per_s),
            "frames_per_s_max": max(per_s), "us_per_frame_median": 1e6 / statistics.median(per_s)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer frames and repeats")
    ap.add_argument("--json", action="store_true", help="results as JSON on stdout")
    ap.add_argument("--physics-hz", type=int, default=4000, help="the bridge's physics rate")
    args = ap.parse_args()
    frames, repeats = (2400, 3) if args.quick else (12000, 5)
    res = {
        "machine": machine_info(None, platform=PLATFORM, frame_rate_hz=RATE_HZ,
                                physics_hz=args.physics_hz, frames=frames, repeats=repeats),
        "udp_lockstep": udp_lockstep(frames, repeats, args.physics_hz),
        "in_process": in_process(frames, repeats, args.physics_hz),
    }
    if args.json:
        print(json.dumps(res, indent=2))
        return
    m, u, h = res["machine"], res["udp_lockstep"], res["in_process"]
    print(f"{m['date_utc']}  {m['cpu_model']}  {m['n_cpus']} CPUs  load {m['load_avg_1min']:.2f}")
    print(f"platform {PLATFORM}, ArduPilot frame rate {RATE_HZ} Hz, bridge physics "
          f"{args.physics_hz} Hz, {frames} frames x {repeats}")
    print(f"UDP lockstep, instant peer in another process: {u['frames_per_s_median']:,.0f} "
          f"frames/s (min {u['frames_per_s_min']:,.0f}, max {u['frames_per_s_max']:,.0f}), "
          f"{u['us_per_frame_median']:.1f} us/frame, {u['speedup_median']:.1f}x real time")
    print(f"in process (handle() only): {h['frames_per_s_median']:,.0f} frames/s, "
          f"{h['us_per_frame_median']:.1f} us/frame")


if __name__ == "__main__":
    main()
