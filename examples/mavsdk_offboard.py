#!/usr/bin/env python3
"""Fly an offboard square with MAVSDK (the native 4.x binding), as against PX4 SITL.

    ft-sitl sitl &                      # or PX4 SITL: the script does not care
    python examples/mavsdk_offboard.py [udpin://0.0.0.0:14540]
"""

import asyncio
import sys

from mavsdk import ComponentType
from mavsdk.asyncio import Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.offboard import PositionNedYaw, VelocityNedYaw


async def arrived(telemetry: TelemetryAsync, north: float, east: float, down: float,
                  within_m: float = 0.3) -> None:
    """Wait until the vehicle is within `within_m` of the point and nearly still: waiting
    on telemetry, not on a fixed sleep, works at any simulation speed factor."""
    async for pv in telemetry.subscribe_position_velocity_ned():
        p, v = pv.position, pv.velocity
        off = ((p.north_m - north) ** 2 + (p.east_m - east) ** 2 + (p.down_m - down) ** 2) ** 0.5
        if off < within_m and (v.north_m_s ** 2 + v.east_m_s ** 2) ** 0.5 < 0.3:
            return


async def main(url: str) -> None:
    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    await mavsdk.add_any_connection(url)
    drone = await mavsdk.first_autopilot(timeout_s=10.0)
    if drone is None:
        raise SystemExit(f"no autopilot found on {url}")
    action, offboard, telemetry = ActionAsync(drone), OffboardAsync(drone), TelemetryAsync(drone)

    async for health in telemetry.subscribe_health():
        if health.is_armable and health.is_global_position_ok:
            break
    print("-- arming")
    await action.arm()
    print("-- starting offboard")
    await offboard.set_position_ned(PositionNedYaw(0.0, 0.0, 0.0, 0.0))
    await offboard.start()

    for north, east, yaw in ((0, 0, 0), (5, 0, 0), (5, 5, 90), (0, 5, 180), (0, 0, 270)):
        print(f"-- go to {north} m north, {east} m east, 3 m up, yaw {yaw}")
        await offboard.set_position_ned(PositionNedYaw(north, east, -3.0, yaw))
        await arrived(telemetry, north, east, -3.0)
    print("-- climb at 1 m/s for 2 s")
    await offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, -1.0, 0.0))
    await asyncio.sleep(2)
    async for pos in telemetry.subscribe_position():
        print(f"-- at {pos.latitude_deg:.7f}, {pos.longitude_deg:.7f}, "
              f"{pos.relative_altitude_m:.2f} m above home")
        break
    await offboard.stop()
    print("-- landing")
    await action.land()
    async for armed in telemetry.subscribe_armed():
        if not armed:
            break
    print("-- landed and disarmed")
    mavsdk.destroy()


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1] if len(sys.argv) > 1 else "udpin://0.0.0.0:14540"))
