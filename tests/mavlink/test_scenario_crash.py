"""A vehicle served in a scenario world crashes into what it flies into, seen over MAVLink."""

import asyncio

import numpy as np
import pytest
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.action import ActionError
from mavsdk.plugins.offboard import PositionNedYaw, VelocityNedYaw
from mavsdk.plugins.telemetry import StatusTextType

from ft_sitl.frames import enu_to_ned
from ft_sitl.scenarios.families import build_scenario

from .mavsdk_util import connect, first
from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)


def test_mavsdk_flight_into_a_tree_crashes_then_a_reboot_respawns():
    sc = build_scenario("forest", 2)
    start_ned = enu_to_ned(sc.start - sc.takeoff)  # local origin = the takeoff point
    heading = np.degrees(np.pi / 2 - sc.start_yaw)  # NED yaw of the start direction
    u = enu_to_ned((sc.goal - sc.start) / np.linalg.norm(sc.goal - sc.start))

    async def fly(server):
        m, drone = await connect(14544)  # instance 4: away from earlier tests' clients
        action, tel, off = ActionAsync(drone), TelemetryAsync(drone), OffboardAsync(drone)
        texts = []

        async def collect():
            async for t in tel.subscribe_status_text():
                texts.append(t)
        collector = asyncio.ensure_future(collect())
        await first(tel.subscribe_health(), lambda h: h.is_armable)
        p0 = (await first(tel.subscribe_position_velocity_ned())).position
        assert abs(p0.north_m) < 0.05 and abs(p0.east_m) < 0.05
        await action.arm()
        target = PositionNedYaw(*[float(v) for v in start_ned], float(heading))
        await off.set_position_ned(target)
        await off.start()
        await asyncio.sleep(6.0)
        await off.set_velocity_ned(VelocityNedYaw(*[float(3.0 * v) for v in u], float(heading)))
        await first(tel.subscribe_armed(), lambda a: not a, timeout=30.0)
        await asyncio.sleep(0.5)
        crash = [t for t in texts if t.text.startswith("Collision: hit tree")]
        assert crash, [t.text for t in texts]
        assert crash[0].type == StatusTextType.EMERGENCY
        # it fell at the trunk instead of flying through it
        await first(tel.subscribe_in_air(), lambda a: not a, timeout=10.0)
        p = (await first(tel.subscribe_position_velocity_ned())).position
        ev = [e for e in server.fleet.events if e.kind == "collision"][0]
        hit_ned = enu_to_ned(ev.position - sc.takeoff)
        assert np.hypot(p.north_m - hit_ned[0], p.east_m - hit_ned[1]) < 0.3
        # a long status text arrives whole (MAVLink 2 chunks, reassembled by MAVSDK)
        long_text = "A status text longer than fifty characters " * 3
        server.fleet.commanders[0].text(4, long_text.strip())
        await asyncio.sleep(1.0)
        assert long_text.strip() in [t.text for t in texts]
        # arming is refused until a reboot, which puts the vehicle back on its spawn point
        with pytest.raises(ActionError):
            await action.arm()
        await action.reboot()
        await asyncio.sleep(1.0)
        p = (await first(tel.subscribe_position_velocity_ned())).position
        assert abs(p.north_m) < 0.05 and abs(p.east_m) < 0.05 and abs(p.down_m) < 0.05
        await action.arm()
        await action.disarm()
        collector.cancel()
        m.destroy()

    with running_sitl(speed_factor=3.0, scenario=sc, base_instance=4) as server:
        asyncio.run(fly(server))
        assert server.bad_packets == 0
