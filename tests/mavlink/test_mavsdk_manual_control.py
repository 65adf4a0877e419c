"""MAVSDK's manual control plugin (a virtual joystick) flying POSCTL, then stopping."""

import asyncio
import math
import time

import pytest
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.manual_control import ManualControlAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from pymavlink import mavutil

from ft_sitl.autopilot.params import ParamSet

from .mavsdk_util import connect, first
from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

INSTANCE = 43  # ports of PX4 SITL instance 43 (API 14583), clear of other tests


def test_mavsdk_sticks_fly_posctl_and_their_loss_lands():
    sticks = [0.0, 0.0, 0.5, 0.0]
    streaming = [True]

    async def stream(manual):
        while streaming[0]:
            await manual.set_manual_control_input(*sticks)
            await asyncio.sleep(0.05)  # 20 Hz, as a joystick app sends

    async def fly(server):
        m, drone = await connect(14540 + INSTANCE)
        action, tel, manual = ActionAsync(drone), TelemetryAsync(drone), ManualControlAsync(drone)
        await first(tel.subscribe_health(), lambda h: h.is_armable)
        task = asyncio.ensure_future(stream(manual))
        await asyncio.sleep(0.3)
        await manual.start_position_control()
        await first(tel.subscribe_flight_mode(), lambda f: f.name == "POSCTL")
        await action.arm()
        sticks[2] = 0.85  # climb
        await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > 3.0)
        sticks[2] = 0.5
        yaw = math.radians((await first(tel.subscribe_attitude_euler())).yaw_deg)
        sticks[0] = 1.0  # full forward: along the heading at MPC_XY_VEL_MAX (4 m/s)
        await asyncio.sleep(3.0)
        v = (await first(tel.subscribe_position_velocity_ned())).velocity
        fwd = v.north_m_s * math.cos(yaw) + v.east_m_s * math.sin(yaw)
        side = -v.north_m_s * math.sin(yaw) + v.east_m_s * math.cos(yaw)
        assert fwd == pytest.approx(4.0, abs=0.3) and abs(side) < 0.3
        sticks[0] = 0.0  # centred: stops and holds where it is
        await asyncio.sleep(3.0)
        p1 = (await first(tel.subscribe_position_velocity_ned())).position
        await asyncio.sleep(1.0)
        pv = await first(tel.subscribe_position_velocity_ned())
        assert math.hypot(pv.velocity.north_m_s, pv.velocity.east_m_s) < 0.2
        assert math.hypot(pv.position.north_m - p1.north_m,
                          pv.position.east_m - p1.east_m) < 0.2
        assert (pv.position.north_m * math.cos(yaw) + pv.position.east_m * math.sin(yaw)) > 5.0
        # the joystick stops: COM_RC_LOSS_T, Hold for COM_FAIL_ACT_T, then NAV_RCL_ACT
        streaming[0] = False
        await task
        await first(tel.subscribe_flight_mode(), lambda f: f.name == "HOLD", timeout=5)
        await first(tel.subscribe_flight_mode(), lambda f: f.name == "LAND", timeout=5)
        await first(tel.subscribe_armed(), lambda a: not a, timeout=30)
        texts = [t for _, t in server.fleet.commanders[0].statustexts]
        assert "Manual control lost" in texts
        m.destroy()

    params = ParamSet({"NAV_RCL_ACT": 3, "COM_FAIL_ACT_T": 1.0})
    with running_sitl(speed_factor=2.0, params=[params], base_instance=INSTANCE) as server:
        asyncio.run(fly(server))


def test_bad_manual_control_values_are_clamped():
    with running_sitl(speed_factor=2.0, base_instance=INSTANCE + 1) as server:
        link = mavutil.mavlink_connection(f"udpout:127.0.0.1:{14580 + INSTANCE + 1}",
                                          source_system=245, source_component=190)
        link.mav.heartbeat_send(6, 8, 0, 0, 0)
        for x, y, z, r in ((32767, -32768, 32767, 32767), (-32768, 32767, -32768, -32768)):
            link.mav.manual_control_send(1, x, y, z, r, 0)
        link.mav.manual_control_send(7, 0, 0, 0, 0, 0)  # another system's: ignored
        c = server.fleet.commanders[0]
        for _ in range(50):
            if c.sticks == (-1.0, 1.0, 0.0, -1.0):
                break
            time.sleep(0.05)
        assert c.sticks == (-1.0, 1.0, 0.0, -1.0)
        link.close()
