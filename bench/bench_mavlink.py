"""Benchmark: the MAVLink SITL server.

1. Vehicles one core serves at real time with PX4's default streams: CPU seconds the
   server spends per simulated second per vehicle (run CPU-bound at a high speed factor,
   no client), inverted; then checked by serving that many vehicles at speed factor 1.
2. The speed factor one vehicle reaches with a MAVSDK client attached (MAVSDK in its own
   process, subscribed to position and attitude, server asked for 1000x).
3. Latency from an offboard setpoint packet's arrival to the first physics step that uses
   it, in wall time (distribution over many packets) and in simulated time.

    .venv/bin/python bench/bench_mavlink.py            # ~1.5 minutes
    .venv/bin/python bench/bench_mavlink.py --quick    # ~30 s
    .venv/bin/python bench/bench_mavlink.py --json

Timings are never asserted: this is a script, not a test.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import textwrap
import threading
import time

from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.mavlink.server import SitlServer
from ft_sitl.physics.catalog import get_platform
from ft_sitl.sim.fleet import Fleet

PLATFORM = "0.98kg-EGO Planner DIY"
GEO = frames.GeoReference(*frames.PX4_SITL_HOME)


def make_server(n: int, speed: float) -> SitlServer:
    fleet = Fleet([get_platform(PLATFORM)] * n, spawn=[[0.0, 2.0 * i, 0.0] for i in range(n)])
    return SitlServer(fleet, GEO, speed_factor=speed)


def serve(server: SitlServer, seconds: float) -> tuple[float, float]:
    """Serve for seconds of wall time; returns (achieved speed factor, CPU share)."""
    async def main():
        await server.start()
        try:
            await server.run(duration_s=seconds)
        finally:
            server.close()

    c0, w0 = time.process_time(), time.perf_counter()
    asyncio.run(main())
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    return server.achieved_speed_factor, cpu / wall


def cost_per_vehicle(n: int, seconds: float) -> float:
    """CPU seconds per simulated second per vehicle, CPU-bound (speed factor 1000)."""
    server = make_server(n, 1000.0)
    c0 = time.process_time()
    achieved, _ = serve(server, seconds)
    cpu = time.process_time() - c0
    return cpu / (server.fleet.time_us * 1e-6) / n


MAVSDK_CLIENT = textwrap.dedent("""
    import asyncio, sys, time
    from mavsdk import ComponentType
    from mavsdk.asyncio import Configuration, Mavsdk
    from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
    async def main(seconds):
        m = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
        await m.add_any_connection("udpin://0.0.0.0:14540")
        drone = await m.first_autopilot(timeout_s=10.0)
        tel = TelemetryAsync(drone)
        n = 0
        end = time.time() + seconds
        async for _ in tel.subscribe_position():
            n += 1
            if time.time() > end:
                break
        print(n)
        m.destroy()
    asyncio.run(main(float(sys.argv[1])))
""")


def speed_with_mavsdk(seconds: float) -> dict:
    server = make_server(1, 1000.0)
    client = subprocess.Popen([sys.executable, "-c", MAVSDK_CLIENT, str(seconds)],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    achieved, share = serve(server, seconds + 3.0)
    out, _ = client.communicate(timeout=30)
    return {"achieved_speed_factor": achieved, "server_cpu_share": share,
            "positions_received_by_mavsdk": int(out.strip() or 0)}


def setpoint_latency(n_packets: int) -> dict:
    """Wall and simulated time from a setpoint's arrival to the next physics step."""
    server = make_server(1, 1.0)
    fleet = server.fleet
    arrivals: list[tuple[float, int]] = []
    latencies_wall: list[float] = []
    latencies_sim: list[int] = []
    orig_dgram = server.on_datagram
    orig_run = fleet.run_us

    def on_datagram(link, data, addr):
        orig_dgram(link, data, addr)
        if len(data) > 10 and data[7] == mav.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED:
            arrivals.append((time.perf_counter(), fleet.time_us))

    def run_us(duration_us):
        now = time.perf_counter()
        while arrivals:
            t_wall, t_sim = arrivals.pop()
            latencies_wall.append(now - t_wall)
            latencies_sim.append(fleet.time_us - t_sim)
        orig_run(duration_us)

    server.on_datagram = on_datagram
    fleet.run_us = run_us
    fleet.commanders[0].arm()

    def sender():
        import socket

        time.sleep(0.5)
        enc = mav.MAVLink(None, 246, 191)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        for _ in range(n_packets):
            msg = mav.MAVLink_set_position_target_local_ned_message(
                0, 1, 1, mav.MAV_FRAME_LOCAL_NED, 0b110111111000, 0.0, 0.0, -2.0,
                0, 0, 0, 0, 0, 0, 0.0, 0.0)
            sock.sendto(msg.pack(enc), ("127.0.0.1", 14580))
            time.sleep(0.05)

    th = threading.Thread(target=sender, daemon=True)
    th.start()
    serve(server, 0.5 + n_packets * 0.05 + 0.5)
    lw = sorted(latencies_wall)

    def pct(p):
        return lw[min(len(lw) - 1, int(p * len(lw)))] * 1e3 if lw else float("nan")

    return {"packets": len(lw), "wall_ms_median": statistics.median(lw) * 1e3 if lw else None,
            "wall_ms_p95": pct(0.95), "wall_ms_max": lw[-1] * 1e3 if lw else None,
            "sim_us_max": max(latencies_sim) if latencies_sim else None}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    secs = 4.0 if args.quick else 10.0
    results: dict = {"date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                     "cpus": os.cpu_count(), "python": sys.version.split()[0]}
    costs = {n: cost_per_vehicle(n, secs) for n in (1, 4, 16)}
    results["cpu_s_per_sim_s_per_vehicle"] = costs
    per_core = 1.0 / costs[16]
    results["vehicles_per_core_estimate"] = per_core
    n_check = max(1, int(per_core * 0.9))
    achieved, share = serve(make_server(n_check, 1.0), secs)
    results["real_time_check"] = {"vehicles": n_check, "achieved_speed_factor": achieved,
                                  "cpu_share": share}
    results["one_vehicle_with_mavsdk"] = speed_with_mavsdk(secs)
    results["setpoint_latency"] = setpoint_latency(40 if args.quick else 150)
    if args.json:
        print(json.dumps(results, indent=2))
        return
    print(f"# ft-sitl MAVLink benchmark {results['date']} ({results['cpus']} CPUs, "
          f"Python {results['python']})")
    for n, c in costs.items():
        print(f"- {n:2d} vehicles: {c * 1e3:.1f} ms CPU per simulated second per vehicle "
              f"-> {1 / c:.0f} vehicles per core at real time")
    rc = results["real_time_check"]
    print(f"- check: {rc['vehicles']} vehicles at speed factor 1 achieved "
          f"{rc['achieved_speed_factor']:.3f} using {rc['cpu_share']:.0%} of a core")
    mv = results["one_vehicle_with_mavsdk"]
    print(f"- one vehicle, MAVSDK attached: {mv['achieved_speed_factor']:.0f}x real time "
          f"({mv['positions_received_by_mavsdk']} positions received)")
    sl = results["setpoint_latency"]
    print(f"- setpoint arrival -> first physics step using it: median "
          f"{sl['wall_ms_median']:.2f} ms, p95 {sl['wall_ms_p95']:.2f} ms, max "
          f"{sl['wall_ms_max']:.2f} ms wall; {sl['sim_us_max']} us simulated at most "
          f"({sl['packets']} packets)")


if __name__ == "__main__":
    main()
