"""A real MAVSDK 4.x client (the native binding, asyncio API) flying the SITL over UDP."""

import asyncio
import math

import pytest
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

from .mavsdk_util import connect, first
from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)


def test_arm_takeoff_goto_hold_rtl_land_with_telemetry():
    async def fly():
        m, drone = await connect()
        action, tel = ActionAsync(drone), TelemetryAsync(drone)
        health = await first(tel.subscribe_health(), lambda h: h.is_armable)
        assert health.is_global_position_ok and health.is_local_position_ok
        assert health.is_home_position_ok and health.is_accelerometer_calibration_ok
        home = await first(tel.subscribe_home())
        assert home.latitude_deg == pytest.approx(47.397742, abs=1e-6)
        assert home.absolute_altitude_m == pytest.approx(488.0, abs=0.1)
        assert await action.get_takeoff_altitude() == pytest.approx(2.5)
        await action.set_return_to_launch_altitude(5.0)
        assert await action.get_return_to_launch_altitude() == pytest.approx(5.0)
        bat = await first(tel.subscribe_battery())
        assert bat.remaining_percent > 90 and bat.voltage_v > 10
        await action.arm()
        assert await first(tel.subscribe_armed(), lambda a: a)
        await action.takeoff()
        await first(tel.subscribe_in_air(), lambda v: v)
        pos = await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > 2.4)
        assert pos.relative_altitude_m == pytest.approx(2.5, abs=0.2)
        mode = await first(tel.subscribe_flight_mode(), lambda f: f.name == "HOLD")
        assert mode.name == "HOLD"
        # goto 15 m north at 5 m above home
        lat = 47.397742 + 15.0 / 111195.0
        await action.goto_location(lat, 8.545594, 493.0, 0.0)
        await first(tel.subscribe_position(),
                    lambda p: abs(p.latitude_deg - lat) < 2e-6 and p.relative_altitude_m > 4.8)
        await action.hold()
        await action.return_to_launch()
        await first(tel.subscribe_flight_mode(), lambda f: f.name == "RETURN_TO_LAUNCH")
        await first(tel.subscribe_landed_state(), lambda s: s.name == "ON_GROUND", timeout=60)
        landed = await first(tel.subscribe_position())
        assert landed.latitude_deg == pytest.approx(47.397742, abs=5e-6)
        assert not await first(tel.subscribe_armed(), lambda a: not a, timeout=10)
        m.destroy()

    with running_sitl(speed_factor=2.0) as server:
        asyncio.run(fly())
        assert server.bad_packets == 0


def test_land_and_auto_disarm_and_refused_disarm_in_air():
    async def fly():
        m, drone = await connect()
        action, tel = ActionAsync(drone), TelemetryAsync(drone)
        await first(tel.subscribe_health(), lambda h: h.is_armable)
        await action.arm()
        await action.takeoff()
        await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > 2.3)
        with pytest.raises(Exception, match="(?i)denied|fail|reject"):
            await action.disarm()
        await action.land()
        await first(tel.subscribe_landed_state(), lambda s: s.name == "LANDING")
        await first(tel.subscribe_armed(), lambda a: not a, timeout=30)
        assert math.isfinite((await first(tel.subscribe_position())).latitude_deg)
        m.destroy()

    with running_sitl(speed_factor=2.0):
        asyncio.run(fly())


def test_two_vehicles_each_flown_by_its_own_mavsdk_client():
    async def fly(m, drone, alt):
        action, tel = ActionAsync(drone), TelemetryAsync(drone)
        await first(tel.subscribe_health(), lambda h: h.is_armable)
        await action.set_takeoff_altitude(alt)
        await action.arm()
        await action.takeoff()
        pos = await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > alt - 0.1)
        m.destroy()
        return pos

    async def both():
        a = await connect(14542)
        b = await connect(14543)
        return await asyncio.gather(fly(*a, 2.0), fly(*b, 4.0))

    # PX4 SITL instances 2 and 3 (ports 14542/14543): a MAVSDK client of an earlier test
    # in this process can keep 14540 bound after destroy() and swallow the packets
    with running_sitl(instances=2, speed_factor=2.0, base_instance=2) as server:
        p1, p2 = asyncio.run(both())
        assert p1.relative_altitude_m == pytest.approx(2.0, abs=0.2)
        assert p2.relative_altitude_m == pytest.approx(4.0, abs=0.2)
        assert [c.armed for c in server.fleet.commanders] == [True, True]
        # vehicle 2 spawned 2 m north of vehicle 1 (ENU y), so its latitude is larger
        assert p2.latitude_deg > p1.latitude_deg
