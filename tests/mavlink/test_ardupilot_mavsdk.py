"""MAVSDK 4.x (the native binding, asyncio API) against the ArduCopter face over SERIAL0's
TCP port (``tcpout://``), with what MAVSDK supports for ArduPilot: telemetry once its
rates are asked for (ArduPilot streams nothing but HEARTBEAT until a client asks: the
set_rate_* calls), arm, set_takeoff_altitude and takeoff (GUIDED and NAV_TAKEOFF),
goto_location, land, return_to_launch, and offboard (MAVSDK's offboard is GUIDED with
SET_POSITION_TARGET_LOCAL_NED on ArduPilot). Each step is checked on the vehicle itself."""

import asyncio
import math

import pytest
from mavsdk import ComponentType
from mavsdk.asyncio import Configuration, Mavsdk
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync, VelocityNedYaw
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync

from ft_sitl.mavlink.ardupilot.server import tcp_ports

from .ardupilot_harness import free_ardupilot_sitl, until
from .mavsdk_util import first

pytestmark = pytest.mark.e2e  # (tests/lanes.py: TCP)

HOME = (47.397742, 8.545594, 488.0)
#: the telemetry MAVSDK is asked for (Hz)
RATES = ("position", "battery", "in_air", "attitude_euler", "gps_info", "home",
         "landed_state", "velocity_ned", "health")


async def _connect(port: int):
    m = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    await m.add_any_connection(f"tcpout://127.0.0.1:{port}")
    drone = await m.first_autopilot(timeout_s=60.0)
    assert drone is not None, "no autopilot discovered"
    tel = TelemetryAsync(drone)
    for name in RATES:
        await getattr(tel, f"set_rate_{name}")(4.0)
    return m, drone, tel


async def _take_off(action, tel, alt: float) -> None:
    await first(tel.subscribe_health(), lambda h: h.is_armable, 60)
    await action.set_takeoff_altitude(alt)
    assert await action.get_takeoff_altitude() == pytest.approx(alt)
    await action.arm()
    assert await first(tel.subscribe_armed(), lambda a: a, 30)
    await action.takeoff()
    await first(tel.subscribe_in_air(), lambda v: v, 60)
    pos = await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > alt - 0.3,
                      120)
    assert pos.relative_altitude_m < alt + 0.5


def test_telemetry_takeoff_goto_rtl():
    async def fly(server, port):
        m, drone, tel = await _connect(port)
        action = ActionAsync(drone)
        agent = server.agents[0]
        health = await first(tel.subscribe_health(), lambda h: h.is_armable, 60)
        assert health.is_global_position_ok and health.is_home_position_ok
        home = await first(tel.subscribe_home(), timeout=30)
        assert home.latitude_deg == pytest.approx(HOME[0], abs=1e-6)
        assert home.absolute_altitude_m == pytest.approx(HOME[2], abs=0.1)
        bat = await first(tel.subscribe_battery(), timeout=30)
        assert bat.remaining_percent > 90 and bat.voltage_v > 10
        gps = await first(tel.subscribe_gps_info(), timeout=30)
        assert gps.num_satellites > 0 and gps.fix_type.name == "FIX_3D"
        assert not await first(tel.subscribe_armed(), timeout=30)

        await _take_off(action, tel, 8.0)
        assert agent.mode_name == "GUIDED"
        mode = await first(tel.subscribe_flight_mode(), timeout=30)
        assert mode.name in ("OFFBOARD", "HOLD")  # (MAVSDK's names for GUIDED)
        await action.hold()  # (out of GUIDED: goto_location's CHANGE_MODE flag brings it back)
        until(lambda: agent.mode_name != "GUIDED", 30, "a mode other than GUIDED")
        lat = HOME[0] + 15.0 / 111195.0
        await action.goto_location(lat, HOME[1], HOME[2] + 10.0, 0.0)
        await first(tel.subscribe_position(), lambda p: abs(p.latitude_deg - lat) < 3e-6
                    and abs(p.relative_altitude_m - 10.0) < 0.3, 120)
        assert agent.mode_name == "GUIDED"

        await action.return_to_launch()
        await first(tel.subscribe_flight_mode(), lambda f: f.name == "RETURN_TO_LAUNCH", 30)
        assert agent.mode_name == "RTL"
        await first(tel.subscribe_armed(), lambda a: not a, 300)
        landed = await first(tel.subscribe_position(), timeout=30)
        assert landed.relative_altitude_m < 0.5
        assert abs(landed.latitude_deg - HOME[0]) * 111195.0 < 2.0
        m.destroy()

    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        asyncio.run(fly(server, tcp_ports(k)[0]))


def test_offboard_velocity_then_land():
    async def fly(server, port):
        m, drone, tel = await _connect(port)
        action, offboard = ActionAsync(drone), OffboardAsync(drone)
        agent = server.agents[0]
        await _take_off(action, tel, 6.0)
        start = await first(tel.subscribe_position(), timeout=30)
        await offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
        await offboard.start()
        assert agent.mode_name == "GUIDED"
        await offboard.set_velocity_ned(VelocityNedYaw(0.0, 2.0, 0.0, 90.0))  # east

        def east_of_start(p):
            return (p.longitude_deg - start.longitude_deg) * 111195.0 * \
                math.cos(math.radians(start.latitude_deg))

        pos = await first(tel.subscribe_position(), lambda p: east_of_start(p) > 10.0, 120)
        assert abs(pos.latitude_deg - start.latitude_deg) * 111195.0 < 2.0
        await offboard.set_velocity_ned(VelocityNedYaw(0.0, 0.0, 0.0, 90.0))
        await offboard.stop()

        await action.land()
        await first(tel.subscribe_flight_mode(), lambda f: f.name == "LAND", 30)
        assert agent.mode_name == "LAND"
        await first(tel.subscribe_armed(), lambda a: not a, 300)
        landed = await first(tel.subscribe_position(), timeout=30)
        assert landed.relative_altitude_m < 0.5 and east_of_start(landed) > 9.0
        m.destroy()

    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        asyncio.run(fly(server, tcp_ports(k)[0]))
