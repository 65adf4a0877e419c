"""MAV_CMD_DO_ORBIT as PX4 SITL answers MAVSDK's do_orbit: the vehicle circles the given
centre at the commanded radius and speed (within 10 %), facing the centre, in PX4's
orbit sub mode of POSCTL, and ORBIT_EXECUTION_STATUS reports the orbit; a radius out of
range and an orbit on the ground are refused."""

import asyncio
import math

import numpy as np
import pytest
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.action import ActionError, OrbitYawBehavior
from pymavlink.dialects.v20 import common as mav

from ft_sitl.autopilot import commander as cm

from .mavsdk_util import connect, first
from .sitl_harness import running_sitl
from .test_pymavlink_and_robustness import client, wait_msg

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

INSTANCE = 63  # (ports of its own: a test's leftover client cannot starve the next)

LAT0, LON0 = 47.397742, 8.545594
M_PER_DEG_LAT = 111195.0


def test_do_orbit_circles_at_the_commanded_radius_and_speed():
    center_lat = LAT0 + 10.0 / M_PER_DEG_LAT  # 10 m north of home

    async def run(server):
        m, drone = await connect(14540 + INSTANCE)
        action, tel = ActionAsync(drone), TelemetryAsync(drone)
        await first(tel.subscribe_health(), lambda h: h.is_armable)
        with pytest.raises(ActionError):  # on the ground: refused
            await action.do_orbit(5.0, 2.0, OrbitYawBehavior.HOLD_FRONT_TO_CIRCLE_CENTER,
                                  center_lat, LON0, 488.0 + 4.0)
        await action.set_takeoff_altitude(4.0)
        await action.arm()
        await action.takeoff()
        await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > 3.8,
                    timeout=30)
        await action.do_orbit(5.0, 2.0, OrbitYawBehavior.HOLD_FRONT_TO_CIRCLE_CENTER,
                              center_lat, LON0, 488.0 + 4.0)
        await asyncio.sleep(6.0)  # onto the circle
        fleet = server.fleet
        samples = []
        for _ in range(30):  # about 2 laps at 3x
            await asyncio.sleep(0.1)
            st = fleet.true_state(0)
            samples.append((st.position.copy(), st.velocity.copy(), st.yaw))
        await action.land()
        await first(tel.subscribe_armed(), lambda a: not a, timeout=40)
        m.destroy()
        return samples

    with running_sitl(speed_factor=3.0, base_instance=INSTANCE) as server:
        samples = asyncio.run(run(server))
        cmd = server.fleet.commanders[0]
        assert any(t.startswith("Orbit denied: not flying") for _, t in cmd.statustexts)
    center = np.array([0.0, 10.0])
    radii = [np.linalg.norm(p[:2] - center) for p, _, _ in samples]
    speeds = [np.linalg.norm(v[:2]) for _, v, _ in samples]
    assert np.mean(radii) == pytest.approx(5.0, rel=0.1) and max(radii) < 5.5
    assert all(abs(p[2] - 4.0) < 0.3 for p, _, _ in samples)  # at the commanded altitude
    assert np.mean(speeds) == pytest.approx(2.0, rel=0.1)
    for p, v, yaw in samples:  # clockwise seen from above (positive radius), facing in
        r = np.append(p[:2] - center, 0.0)
        assert np.cross(r, np.append(v[:2], 0.0))[2] < 0
        to_center = math.atan2(-r[1], -r[0])
        assert abs(math.remainder(yaw - to_center, 2 * math.pi)) < math.radians(15)


def test_orbit_status_and_refusals_over_pymavlink():
    with running_sitl(base_instance=INSTANCE) as server:
        c = client(14540 + INSTANCE)
        cmd = server.fleet.commanders[0]
        fleet = server.fleet
        c.mav.command_long_send(1, 1, mav.MAV_CMD_DO_ORBIT, 0, 3.0, 1.0, 0, 0, math.nan,
                                math.nan, math.nan)
        assert wait_msg(c, "COMMAND_ACK", lambda m: m.command == mav.MAV_CMD_DO_ORBIT) \
            .result == mav.MAV_RESULT_TEMPORARILY_REJECTED
        fleet.sim.start_hovering(0, [0.0, 0.0, 3.0])
        cmd.armed, cmd.landed_state = True, cm.LandedState.IN_AIR
        for radius, result in ((5000.0, mav.MAV_RESULT_DENIED), (math.nan,
                                                                 mav.MAV_RESULT_DENIED),
                               (-3.0, mav.MAV_RESULT_ACCEPTED)):
            c.mav.command_long_send(1, 1, mav.MAV_CMD_DO_ORBIT, 0, radius, 1.0, 0, 0,
                                    math.nan, math.nan, math.nan)
            assert wait_msg(c, "COMMAND_ACK", lambda m: m.command == mav.MAV_CMD_DO_ORBIT) \
                .result == result
        hb = wait_msg(c, "HEARTBEAT", lambda m: m.custom_mode == (3 << 16 | 1 << 24))
        assert hb.custom_mode >> 16 & 0xFF == cm.MAIN_POSCTL
        st = wait_msg(c, "ORBIT_EXECUTION_STATUS")
        assert st.radius == pytest.approx(-3.0) and st.frame == mav.MAV_FRAME_GLOBAL_INT
        assert st.x == pytest.approx(LAT0 * 1e7, abs=2) and st.y == pytest.approx(LON0 * 1e7,
                                                                                  abs=2)
