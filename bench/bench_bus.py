"""Benchmark: the MQTT bus (ft_sitl.bus) end to end, publisher -> broker -> subscriber.

1. Depth frames per second carried at 160 x 120 (38.6 kB a frame): the publisher offers
   frames as fast as its queue takes them (``publish_depth`` encodes each one, the
   simulator's cost); a subscriber in another process (``BusClient``) receives and decodes
   them. Reported: frames/s and MB/s received, frames dropped at the publisher, and the
   latency from the ``publish_depth`` call to the decoded frame in the subscriber.
2. Telemetry latency: ``publish_telemetry`` at a fixed wall rate (200 Hz by default); the
   subscriber process measures each sample's latency from the ``publish_telemetry`` call
   to the decoded ``Telemetry`` (the sample's ``time_usec`` carries the call's
   CLOCK_MONOTONIC time, which both processes share). Median, p95, p99, max.
3. The caller's cost: wall time of one ``publish_telemetry`` / ``publish_depth`` call
   (median and p99), i.e. what the simulation loop pays.

The brokers: a mosquitto process started on a free localhost port (required) and, unless
``--brokers mosquitto``, the package's EmbeddedBroker (amqtt) running in the publisher's
process as ``ft-sitl sitl`` would run it. Nothing is pinned: the publisher's bus thread,
the broker and the subscriber each need a core, so figures on a 2-core machine include
contention.

    .venv/bin/python bench/bench_bus.py            # ~40 s
    .venv/bin/python bench/bench_bus.py --quick    # ~10 s
    .venv/bin/python bench/bench_bus.py --json

Timings are never asserted: this is a script, not a test.
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import argparse
import asyncio
import dataclasses
import json
import math
import multiprocessing as mp
import os
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchutil import machine_info

VEHICLE = "bench"


# --- helpers --------------------------------------------------------------------------------
def now_us() -> int:
    return time.monotonic_ns() // 1000


def percentile(values, q: float) -> float:
    if not values:
        return math.nan
    s = sorted(values)
    return s[min(len(s) - 1, max(0, math.ceil(q / 100.0 * len(s)) - 1))]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class MosquittoProcess:
    def __init__(self):
        exe = shutil.which("mosquitto") or shutil.which("mosquitto", path="/usr/sbin:/sbin")
        if exe is None:
            sys.exit("mosquitto is not installed: scripts/setup.sh --test installs it")
        self.exe = exe
        self.port = free_port()
        self.dir = tempfile.TemporaryDirectory(prefix="bench-bus-")
        conf = Path(self.dir.name) / "mosquitto.conf"
        lines = [f"listener {self.port} 127.0.0.1", "allow_anonymous true",
                 "persistence false", "log_dest none"]
        if os.geteuid() == 0:
            lines.append("user root")
        conf.write_text("\n".join(lines) + "\n")
        self.proc = subprocess.Popen([exe, "-c", str(conf)], stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + 20.0
        while True:
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=1.0):
                    break
            except OSError:
                if self.proc.poll() is not None or time.monotonic() > deadline:
                    sys.exit("mosquitto did not start")
                time.sleep(0.05)
        self.url = f"mqtt://127.0.0.1:{self.port}"
        out = subprocess.run([exe, "-h"], capture_output=True, text=True).stdout
        self.version = out.split("\n", 1)[0].replace("mosquitto version ", "").strip()

    def stop(self):
        self.proc.terminate()
        self.proc.wait(10)
        self.dir.cleanup()


def depth_sample():
    """A 160 x 120 frame of a few boxes (the real camera), as in the bus tests."""
    import trimesh

    from ft_sitl.scenarios.camera import CameraConfig, DepthCamera

    parts = []
    for centre, extents in (((6.0, 0.0, 1.5), (1.0, 4.0, 3.0)),
                            ((4.0, 2.5, 1.0), (1.0, 1.0, 2.0))):
        box = trimesh.creation.box(extents=extents)
        box.apply_translation(centre)
        parts.append(box)
    config = CameraConfig().subsampled(4)
    frame = DepthCamera(config, trimesh.util.concatenate(parts)).capture(
        0, (0.0, 0.0, 1.2), (1.0, 0.0, 0.0, 0.0))
    return frame, config


# --- the subscriber process -----------------------------------------------------------------
def subscriber_main(url: str, kind: str, conn, cap_s: float) -> None:
    """Receive ``kind`` until the publisher's ``bench_end`` event; send back per message
    (receive time us, latency us)."""
    from ft_sitl.bus import BusClient

    async def run():
        records = []
        async with BusClient(url, VEHICLE, kinds=(kind, "events"), queue_size=4096) as c:
            conn.send("ready")
            try:
                async with asyncio.timeout(cap_s):
                    while True:
                        msg = await c.receive()
                        t = now_us()
                        if msg.kind == "events":
                            if msg.data.type == "bench_end":
                                break
                            continue
                        records.append((t, t - msg.data.time_usec))
            except TimeoutError:
                pass
        return records

    conn.send(asyncio.run(run()))
    conn.close()


def start_subscriber(url: str, kind: str, cap_s: float):
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    proc = ctx.Process(target=subscriber_main, args=(url, kind, child, cap_s), daemon=True)
    proc.start()
    if not parent.poll(60.0) or parent.recv() != "ready":
        proc.kill()
        sys.exit("the subscriber process did not start")
    return proc, parent


def finish(pub, conn, proc, cap_s: float):
    """Wait until the publisher's queues are empty, send the end marker, collect."""
    deadline = time.monotonic() + 10.0
    while any(pub.stats().queued.values()) and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(0.2)
    pub.publish_event("bench_end", 0)
    if not conn.poll(cap_s + 30.0):
        proc.kill()
        sys.exit("the subscriber did not report")
    records = conn.recv()
    proc.join(10)
    return records


# --- the measurements -------------------------------------------------------------------------
def bench_depth(url: str, seconds: float, frame, config) -> dict:
    from ft_sitl.bus import BusPublisher, encode_depth

    proc, conn = start_subscriber(url, "depth", seconds + 30.0)
    pub = BusPublisher(url, VEHICLE).start()
    if not pub.wait_connected(20.0):
        sys.exit(f"no connection to {url}: {pub.stats()}")
    calls, offered, accepted = [], 0, 0
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        f = dataclasses.replace(frame, t_us=now_us())
        c0 = time.perf_counter()
        ok = pub.publish_depth(f, config)
        dt_us = (time.perf_counter() - c0) * 1e6
        offered += 1
        if ok:
            accepted += 1
            calls.append(dt_us)  # the calls that encoded and queued a frame
        else:
            time.sleep(0.0005)  # queue full: let the bus thread run
    records = finish(pub, conn, proc, seconds)
    stats = pub.stats()
    pub.close()
    n = len(records)
    span = (records[-1][0] - records[0][0]) * 1e-6 if n > 1 else math.nan
    fps = (n - 1) / span if n > 1 else 0.0
    size = len(encode_depth(frame, config))
    lat_ms = [r[1] / 1000.0 for r in records]
    return {"frames_received": n, "fps": fps, "mb_per_s": fps * size / 1e6,
            "frame_bytes": size, "offered": offered, "accepted": accepted,
            "sent": stats.sent["depth"], "dropped": stats.dropped["depth"],
            "latency_ms_median": statistics.median(lat_ms) if lat_ms else math.nan,
            "latency_ms_p95": percentile(lat_ms, 95),
            "call_us_median": statistics.median(calls) if calls else math.nan,
            "call_us_p99": percentile(calls, 99)}


def bench_telemetry(url: str, samples: int, rate_hz: float) -> dict:
    from ft_sitl.bus import BusPublisher, Telemetry

    proc, conn = start_subscriber(url, "telemetry", samples / rate_hz + 30.0)
    pub = BusPublisher(url, VEHICLE).start()
    if not pub.wait_connected(20.0):
        sys.exit(f"no connection to {url}: {pub.stats()}")
    period = 1.0 / rate_hz
    calls = []
    t_next = time.monotonic()
    for i in range(samples):
        a = 0.001 * i
        c0 = time.perf_counter()
        pub.publish_telemetry(Telemetry(now_us(), (i * 0.01, 2.0, 1.5), (0.5, 0.0, 0.0),
                                        (math.cos(a), 0.0, 0.0, math.sin(a)), (0.0, 0.0, 0.1),
                                        (0.52, 0.48, 0.51, 0.49)))
        calls.append((time.perf_counter() - c0) * 1e6)
        t_next += period
        delay = t_next - time.monotonic()
        if delay > 0:
            time.sleep(delay)
    records = finish(pub, conn, proc, samples / rate_hz)
    stats = pub.stats()
    pub.close()
    lat_ms = [r[1] / 1000.0 for r in records]
    return {"samples": samples, "rate_hz": rate_hz, "received": len(records),
            "dropped": stats.dropped["telemetry"],
            "latency_ms_median": statistics.median(lat_ms) if lat_ms else math.nan,
            "latency_ms_p95": percentile(lat_ms, 95),
            "latency_ms_p99": percentile(lat_ms, 99),
            "latency_ms_max": max(lat_ms) if lat_ms else math.nan,
            "call_us_median": statistics.median(calls), "call_us_p99": percentile(calls, 99)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="short run (smoke test)")
    ap.add_argument("--json", action="store_true", help="print the results as JSON")
    ap.add_argument("--brokers", default="mosquitto,amqtt",
                    help="comma-separated: mosquitto, amqtt (default both)")
    ap.add_argument("--rate", type=float, default=200.0, help="telemetry rate, Hz (wall)")
    args = ap.parse_args(argv)
    brokers = [b.strip() for b in args.brokers.split(",") if b.strip()]
    for b in brokers:
        if b not in ("mosquitto", "amqtt"):
            ap.error(f"unknown broker {b!r} (mosquitto, amqtt)")
    depth_s = 2.0 if args.quick else 8.0
    samples = 300 if args.quick else 2000

    from importlib.metadata import version

    frame, config = depth_sample()
    results = {}
    for name in brokers:
        if name == "mosquitto":
            broker = MosquittoProcess()
            label = f"mosquitto {broker.version}"
        else:
            from ft_sitl.bus import EmbeddedBroker

            broker = EmbeddedBroker().start()
            label = f"amqtt {version('amqtt')} (in-process)"
        try:
            results[name] = {"broker": label,
                             "depth": bench_depth(broker.url, depth_s, frame, config),
                             "telemetry": bench_telemetry(broker.url, samples, args.rate)}
        finally:
            broker.stop()

    info = machine_info(None, aiomqtt=version("aiomqtt"), amqtt=version("amqtt"),
                        paho_mqtt=version("paho-mqtt"))
    if args.json:
        print(json.dumps({"machine": info, "results": results}, indent=2))
        return 0
    print(f"ft_sitl.bus benchmark, {info['date_utc']}, {info['cpu_model']}, "
          f"{info['n_cpus']} CPUs, {info['machine']}, Python {info['python']}, "
          f"aiomqtt {info['aiomqtt']}, paho-mqtt {info['paho_mqtt']}")
    print(f"depth: 160 x 120 frames ({results[brokers[0]]['depth']['frame_bytes']} B), "
          f"offered as fast as the queue takes them for {depth_s:.0f} s; telemetry: "
          f"{samples} samples at {args.rate:g} Hz")
    print()
    head = (f"{'broker':<28} {'depth fps':>9} {'MB/s':>6} {'dropped':>8} "
            f"{'depth lat ms':>12} {'telem lat ms':>12} {'p95':>6} {'p99':>6} {'lost':>5} "
            f"{'call us tel/depth (med)':>24}")
    print(head)
    print("-" * len(head))
    for r in results.values():
        d, t = r["depth"], r["telemetry"]
        print(f"{r['broker']:<28} {d['fps']:>9.0f} {d['mb_per_s']:>6.1f} {d['dropped']:>8d} "
              f"{d['latency_ms_median']:>12.2f} {t['latency_ms_median']:>12.2f} "
              f"{t['latency_ms_p95']:>6.2f} {t['latency_ms_p99']:>6.2f} "
              f"{t['samples'] - t['received']:>5d} "
              f"{t['call_us_median']:>11.1f} / {d['call_us_median']:<10.1f}")
    print()
    print("depth lat: median publish_depth call -> decoded frame in the subscriber (under a "
          "saturated stream, so it includes queueing); telem lat: publish_telemetry call "
          "-> decoded sample; lost: telemetry samples not received; call us: median wall "
          "time of one publish call in the simulation's thread.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
