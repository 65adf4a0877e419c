"""Benchmark: the PX4 bridge's lockstep ceiling (frames per second with an instant peer).

The bridge (``ft_sitl.bridge.px4.Px4Bridge``, 250 Hz frames, default platform, no scenario,
``speed_factor=None``) serves a peer process that plays PX4 with no work of its own: it
frames the incoming MAVLink 2 stream by its header bytes only and answers every HIL_SENSOR
at once with one pre-packed HIL_ACTUATOR_CONTROLS (lockstep flag, time_usec 0 = not
stamped, motors at 0). So the round trip is the bridge's work (physics step, sensor
models, MAVLink encoding and parsing, socket calls) plus two loopback hops: the most
frames per second any PX4 can get out of the bridge. Bridge and peer run in separate
processes on separate CPUs (pinned when the machine has two). Reported: lockstep frames
per wall second and the simulated speed-up (x 4 ms), the bridge process's CPU
microseconds per frame, with and without HIL_STATE_QUATERNION (ground truth). The first
500 frames (connection, JIT cache loading) are not timed. Timings are never asserted.

    .venv/bin/python bench/bench_bridge_px4.py            # ~30 s
    .venv/bin/python bench/bench_bridge_px4.py --quick    # smoke run
    .venv/bin/python bench/bench_bridge_px4.py --json
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
import multiprocessing  # noqa: E402
import socket  # noqa: E402
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from benchutil import machine_info  # noqa: E402

PLATFORM = "0.98kg-EGO Planner DIY"
WARMUP_FRAMES = 500
HIL_SENSOR_ID = 107


def instant_peer(port: int, n_frames: int, cpu: int | None, result) -> None:
    """PX4 without PX4: answer each HIL_SENSOR at once; reports wall time of the timed part."""
    from pymavlink.dialects.v20 import common as mav

    if cpu is not None:
        os.sched_setaffinity(0, {cpu})
    answer = mav.MAVLink_hil_actuator_controls_message(
        0, [0.0] * 16, mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
        mav.HIL_ACTUATOR_CONTROLS_FLAGS_LOCKSTEP).pack(mav.MAVLink(None, 1, 1))
    deadline = time.monotonic() + 60.0
    while True:
        try:
            s = socket.create_connection(("127.0.0.1", port), timeout=5.0)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.01)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    buf = bytearray()
    count = 0
    t0 = None
    while count < n_frames:
        data = s.recv(65536)
        if not data:
            raise ConnectionError("the bridge closed the connection")
        buf += data
        while len(buf) >= 12:  # MAVLink 2: STX, len, incompat, compat, seq, sys, comp, id[3]
            if buf[0] != 0xFD:
                raise ValueError(f"not MAVLink 2: 0x{buf[0]:02x}")
            total = 12 + buf[1] + (13 if buf[2] & 1 else 0)
            if len(buf) < total:
                break
            msgid = buf[7] | buf[8] << 8 | buf[9] << 16
            del buf[:total]
            if msgid == HIL_SENSOR_ID:
                count += 1
                if count == WARMUP_FRAMES:
                    t0 = time.perf_counter()
                if count < n_frames:
                    s.sendall(answer)
    result.put((count - WARMUP_FRAMES, time.perf_counter() - t0))
    s.close()


def run(n_frames: int, ground_truth: bool, instance: int, cpus) -> dict:
    from ft_sitl.bridge.px4 import Px4Bridge
    from ft_sitl.physics.catalog import get_platform

    ctx = multiprocessing.get_context("spawn")
    result = ctx.Queue()
    bridge = Px4Bridge(get_platform(PLATFORM), instance=instance, ground_truth=ground_truth)
    bridge.start()
    peer = ctx.Process(target=instant_peer,
                       args=(bridge.port, n_frames, cpus[0] if cpus else None, result))
    peer.start()
    # the bridge's CPU time over the timed frames: sample process time at both ends
    while bridge.stats.sensor_frames < WARMUP_FRAMES:
        time.sleep(0.001)
    c0, f0 = time.process_time(), bridge.stats.sensor_frames
    frames, wall = result.get(timeout=600)
    c1, f1 = time.process_time(), bridge.stats.sensor_frames
    peer.join(30)
    bridge.stop()
    s = bridge.stats
    fps = frames / wall
    return {"ground_truth": ground_truth, "frames": frames, "wall_s": wall,
            "frames_per_s": fps, "sim_speed_factor": fps * bridge.period_us / 1e6,
            "bridge_cpu_us_per_frame": (c1 - c0) / max(1, f1 - f0) * 1e6,
            "bad_packets": s.bad_packets, "boot_frames": s.boot_frames}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="short runs, one repeat")
    ap.add_argument("--json", action="store_true", help="results as JSON on stdout")
    ap.add_argument("--frames", type=int, default=20_000, help="timed frames per run")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--instance", type=int, default=45, help="PX4 instance (port 4560 + I)")
    args = ap.parse_args(argv)
    n = 3_000 if args.quick else args.frames
    repeats = 1 if args.quick else args.repeats
    allowed = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    cpus = (allowed[0], allowed[-1]) if len(allowed) >= 2 else None
    if cpus:
        os.sched_setaffinity(0, {cpus[1]})  # the bridge; the peer pins itself to cpus[0]
    out = {"machine": machine_info(cpus[1] if cpus else None, platform=PLATFORM,
                                   peer_cpu=cpus[0] if cpus else None), "results": []}
    for gt in (False, True):
        runs = [run(n + WARMUP_FRAMES, gt, args.instance, cpus) for _ in range(repeats)]
        fps = [r["frames_per_s"] for r in runs]
        best = max(runs, key=lambda r: r["frames_per_s"])
        summary = {"ground_truth": gt, "frames_per_s_median": statistics.median(fps),
                   "frames_per_s_all": fps,
                   "sim_speed_factor_median": statistics.median(r["sim_speed_factor"]
                                                                for r in runs),
                   "bridge_cpu_us_per_frame_median": statistics.median(
                       r["bridge_cpu_us_per_frame"] for r in runs),
                   "bad_packets": best["bad_packets"]}
        out["results"].append(summary)
        if not args.json:
            print(f"ground truth {'on ' if gt else 'off'}: "
                  f"{summary['frames_per_s_median']:7.0f} lockstep frames/s (median of "
                  f"{repeats}: {', '.join(f'{v:.0f}' for v in fps)}) = "
                  f"{summary['sim_speed_factor_median']:5.1f}x real time at 250 Hz; bridge "
                  f"CPU {summary['bridge_cpu_us_per_frame_median']:.0f} us/frame", flush=True)
    if args.json:
        json.dump(out, sys.stdout, indent=2)
        print()
    else:
        m = out["machine"]
        print(f"{m['date_utc']}  {m['cpu_model']}  {m['n_cpus']} CPUs  load "
              f"{m['load_avg_1min']:.2f}  Python {m['python']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
