#!/usr/bin/env python3
"""Arm, take off, fly a 5 m offboard square, land: and check every corner was reached.

The acceptance flight of autopilot-in-the-loop (docs/autopilot-in-the-loop.md), usable
against any PX4: ft-sitl's own SITL, or a real PX4 SITL flying ft-sitl's physics through
`ft-sitl bridge px4`. Waits for each corner (within 0.3 m) instead of sleeping, so it works
at any simulation speed. Prints one line per leg and exits 0 only if every leg and the
landing succeeded.

    python examples/mavsdk_square_check.py [udpin://0.0.0.0:14540] [--side 5] [--alt 3]
"""

import argparse
import asyncio
import math
import sys
import time

from mavsdk import ComponentType
from mavsdk.asyncio import Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.offboard import PositionNedYaw

TOLERANCE_M = 0.3
LEG_TIMEOUT_S = 120.0


async def first(gen, pred, timeout):
    async def scan():
        async for v in gen:
            if pred(v):
                return v
    return await asyncio.wait_for(scan(), timeout)


async def main(url: str, side: float, alt: float) -> int:
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    await mavsdk.add_any_connection(url)
    drone = await mavsdk.first_autopilot(timeout_s=60.0)
    if drone is None:
        print(f"no autopilot on {url}")
        return 2
    action, off, tel = ActionAsync(drone), OffboardAsync(drone), TelemetryAsync(drone)
    await first(tel.subscribe_health(), lambda h: h.is_armable and h.is_global_position_ok,
                180.0)
    ok = True
    await action.arm()
    print("armed")
    await off.set_position_ned(PositionNedYaw(0.0, 0.0, 0.0, 0.0))
    await off.start()
    t0 = time.monotonic()
    legs = [(0.0, 0.0, 0.0), (side, 0.0, 0.0), (side, side, 90.0), (0.0, side, 180.0),
            (0.0, 0.0, 270.0)]
    for north, east, yaw in legs:
        target = PositionNedYaw(north, east, -alt, yaw)
        await off.set_position_ned(target)
        try:
            pv = await first(tel.subscribe_position_velocity_ned(),
                             lambda p, n=north, e=east: math.dist(
                                 (p.position.north_m, p.position.east_m, p.position.down_m),
                                 (n, e, -alt)) < TOLERANCE_M
                             and math.hypot(p.velocity.north_m_s, p.velocity.east_m_s) < 0.3,
                             LEG_TIMEOUT_S)
            # then the heading (a low-agility platform turns slowly)
            try:
                att = await first(tel.subscribe_attitude_euler(),
                                  lambda a, y=yaw: abs((a.yaw_deg - y + 180.0) % 360.0
                                                       - 180.0) < 5.0, LEG_TIMEOUT_S)
            except TimeoutError:
                att = await first(tel.subscribe_attitude_euler(), lambda a: True, 10.0)
            yaw_err = abs((att.yaw_deg - yaw + 180.0) % 360.0 - 180.0)
            p = pv.position
            print(f"corner N {north:4.1f} E {east:4.1f} up {alt:.1f} yaw {yaw:5.1f}: reached "
                  f"({p.north_m:+.2f}, {p.east_m:+.2f}, {p.down_m:+.2f}), yaw error "
                  f"{yaw_err:.1f} deg, {time.monotonic() - t0:.1f} s wall")
            ok = ok and yaw_err < 10.0
        except TimeoutError:
            print(f"corner N {north} E {east}: NOT reached within {LEG_TIMEOUT_S:g} s")
            ok = False
    await off.stop()
    await action.land()
    try:
        await first(tel.subscribe_armed(), lambda armed: not armed, 180.0)
        print("landed and disarmed")
    except TimeoutError:
        print("did not land and disarm")
        ok = False
    mavsdk.destroy()
    print("SQUARE OK" if ok else "SQUARE FAILED")
    return 0 if ok else 1


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("url", nargs="?", default="udpin://0.0.0.0:14540")
    ap.add_argument("--side", type=float, default=5.0)
    ap.add_argument("--alt", type=float, default=3.0)
    a = ap.parse_args()
    sys.exit(asyncio.run(main(a.url, a.side, a.alt)))
