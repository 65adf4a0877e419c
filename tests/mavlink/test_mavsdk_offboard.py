"""MAVSDK offboard control of the SITL: every setpoint kind MAVSDK sends, PX4 semantics."""

import asyncio
import math

import pytest
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.offboard import (
    Attitude,
    OffboardError,
    PositionNedYaw,
    VelocityBodyYawspeed,
    VelocityNedYaw,
)

from .mavsdk_util import connect, first
from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)


async def pos_ned(tel):
    return (await first(tel.subscribe_position_velocity_ned())).position


def test_offboard_position_velocity_body_posvel_and_attitude():
    async def fly():
        m, drone = await connect()
        action, tel, off = ActionAsync(drone), TelemetryAsync(drone), OffboardAsync(drone)
        await first(tel.subscribe_health(), lambda h: h.is_armable)
        # PX4 refuses offboard before any setpoint has been streamed
        with pytest.raises(OffboardError):
            await off.start()
        await action.arm()
        await off.set_position_ned(PositionNedYaw(0.0, 0.0, -3.0, 0.0))
        await off.start()
        await first(tel.subscribe_flight_mode(), lambda f: f.name == "OFFBOARD")
        await off.set_position_ned(PositionNedYaw(5.0, -2.0, -3.0, 90.0))
        await asyncio.sleep(6.0)
        p = await pos_ned(tel)
        assert (p.north_m, p.east_m, p.down_m) == pytest.approx((5.0, -2.0, -3.0), abs=0.15)
        att = await first(tel.subscribe_attitude_euler())
        assert att.yaw_deg == pytest.approx(90.0, abs=2.0)
        # velocity NED: 2 m/s east
        await off.set_velocity_ned(VelocityNedYaw(0.0, 2.0, 0.0, 90.0))
        await asyncio.sleep(3.0)
        v = (await first(tel.subscribe_position_velocity_ned())).velocity
        assert v.east_m_s == pytest.approx(2.0, abs=0.15) and abs(v.north_m_s) < 0.15
        # velocity body: 1.5 m/s forward while facing east -> east in NED
        await off.set_velocity_body(VelocityBodyYawspeed(1.5, 0.0, 0.0, 0.0))
        await asyncio.sleep(3.0)
        v = (await first(tel.subscribe_position_velocity_ned())).velocity
        assert v.east_m_s == pytest.approx(1.5, abs=0.2) and abs(v.north_m_s) < 0.2
        # body yaw rate 30 deg/s
        await off.set_velocity_body(VelocityBodyYawspeed(0.0, 0.0, 0.0, 30.0))
        await asyncio.sleep(2.0)
        w = await first(tel.subscribe_attitude_angular_velocity_body())
        assert math.degrees(w.yaw_rad_s) == pytest.approx(30.0, abs=4.0)
        # position + velocity feed-forward
        await off.set_position_velocity_ned(PositionNedYaw(0.0, 0.0, -2.0, 0.0),
                                            VelocityNedYaw(0.0, 0.0, 0.0, 0.0))
        await asyncio.sleep(8.0)
        p = await pos_ned(tel)
        assert (p.north_m, p.east_m, p.down_m) == pytest.approx((0.0, 0.0, -2.0), abs=0.15)
        # attitude: 10 deg roll at hover thrust drifts east (right)
        await off.set_attitude(Attitude(10.0, 0.0, 0.0, 0.25))
        await asyncio.sleep(1.0)
        att = await first(tel.subscribe_attitude_euler())
        assert att.roll_deg == pytest.approx(10.0, abs=1.5)
        await off.set_position_ned(PositionNedYaw(0.0, 0.0, -2.0, 0.0))
        await asyncio.sleep(1.0)
        await off.stop()
        mode = await first(tel.subscribe_flight_mode(), lambda f: f.name != "OFFBOARD")
        assert mode.name == "HOLD"
        m.destroy()

    with running_sitl(speed_factor=2.0) as server:
        asyncio.run(fly())
        assert server.bad_packets == 0


def test_offboard_stream_loss_falls_back_to_hold():
    async def fly():
        m, drone = await connect()
        action, tel, off = ActionAsync(drone), TelemetryAsync(drone), OffboardAsync(drone)
        await first(tel.subscribe_health(), lambda h: h.is_armable)
        await action.arm()
        await off.set_position_ned(PositionNedYaw(0.0, 0.0, -2.0, 0.0))
        await off.start()
        await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > 1.9)
        m.destroy()  # the client vanishes: no more setpoints
        return True

    with running_sitl(speed_factor=2.0) as server:
        asyncio.run(fly())
        cmd = server.fleet.commanders[0]
        import time

        deadline = time.time() + 5
        while time.time() < deadline and cmd.mode_name == "OFFBOARD":
            time.sleep(0.1)
        assert cmd.mode_name == "AUTO.LOITER"
        assert any("Offboard signal lost" in t for _, t in cmd.statustexts)
