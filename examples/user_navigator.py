#!/usr/bin/env python3
"""A user navigator in its own process: the form a campaign's ``command`` algorithm takes.

ft-sitl starts this script once per trial with the trial in environment variables
(docs/wire.md) and judges the flight itself; the script only flies. It uses nothing from
ft-sitl: MAVSDK for the flight controller and, if it wants them, aiomqtt for the bus.

    FT_SITL_CONNECT      MAVSDK URL of the vehicle, e.g. udpin://0.0.0.0:14560
    FT_SITL_START_NED    start, local NED metres ("n,e,d"), reached after take-off
    FT_SITL_GOAL_NED     goal, local NED metres
    FT_SITL_START_YAW_DEG  heading to hold at the start (deg, 0 = north)
    FT_SITL_MAX_SPEED    the benchmark's speed cap, m/s

What it does (on PX4, or on ArduPilot after asking for its telemetry's rates): arm, take
off to the start altitude, hold the start, then fly toward the goal at ``SPEED`` with
position + velocity setpoints, a little higher than the start (a crude "climb over it"
strategy), then hold the goal. Campaign entry:

    [[algorithms]]
    label = "user-climb"
    command = "python examples/user_navigator.py"
"""

import asyncio
import math
import os

from mavsdk import ComponentType
from mavsdk.asyncio import Autopilot, Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.offboard import PositionNedYaw, VelocityNedYaw

RATE_HZ = 20.0


def vec(name):
    return [float(x) for x in os.environ[name].split(",")]


async def main() -> None:
    url = os.environ.get("FT_SITL_CONNECT", "udpin://0.0.0.0:14540")
    start, goal = vec("FT_SITL_START_NED"), vec("FT_SITL_GOAL_NED")
    yaw = float(os.environ.get("FT_SITL_START_YAW_DEG", "0"))
    speed = min(2.0, float(os.environ.get("FT_SITL_MAX_SPEED", "4")))
    speed_factor = float(os.environ.get("FT_SITL_SPEED_FACTOR", "1"))

    mavsdk = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    await mavsdk.add_any_connection(url)
    drone = await mavsdk.first_autopilot(timeout_s=30.0)
    if drone is None:
        raise SystemExit(f"no autopilot at {url}")
    action, off, tel = ActionAsync(drone), OffboardAsync(drone), TelemetryAsync(drone)
    if await drone.autopilot_type() == Autopilot.ARDUPILOT:
        # ArduPilot streams nothing but HEARTBEAT until asked (PX4 streams unasked)
        for rate in (tel.set_rate_health, tel.set_rate_home, tel.set_rate_position,
                     tel.set_rate_position_velocity_ned, tel.set_rate_attitude_euler):
            await rate(10.0)
    async for health in tel.subscribe_health():
        if health.is_armable:
            break
    await action.set_takeoff_altitude(-start[2])
    await action.arm()
    await action.takeoff()
    async for pv in tel.subscribe_position_velocity_ned():
        if abs(pv.position.down_m - start[2]) < 0.3:
            break
    hold = PositionNedYaw(start[0], start[1], start[2], yaw)
    await off.set_position_ned(hold)
    await off.start()
    for _ in range(int(3.0 * RATE_HZ)):  # settle at the start (ft-sitl starts the clock)
        await off.set_position_ned(hold)
        await asyncio.sleep(1.0 / RATE_HZ / speed_factor)

    # fly: a reference point moving toward the goal at `speed`, 0.5 m above the start
    d = [g - s for g, s in zip(goal, start)]
    length = math.sqrt(d[0] ** 2 + d[1] ** 2)
    u = [d[0] / length, d[1] / length]
    heading = math.degrees(math.atan2(d[1], d[0]))
    altitude = start[2] - 0.5
    s = 0.0
    while True:
        s = min(s + speed / RATE_HZ, length)
        moving = s < length
        await off.set_position_velocity_ned(
            PositionNedYaw(start[0] + s * u[0], start[1] + s * u[1], altitude, heading),
            VelocityNedYaw(speed * u[0] if moving else 0.0, speed * u[1] if moving else 0.0,
                           0.0, heading))
        await asyncio.sleep(1.0 / RATE_HZ / speed_factor)


if __name__ == "__main__":
    asyncio.run(main())
