"""Failure injection over the wire, as PX4 SITL does it: MAV_CMD_INJECT_FAILURE is
refused until SYS_FAILURE_EN is 1; with MAVSDK's Failure plugin, a motor failed
mid-offboard is flown by the physics (the vehicle falls); a MAVLink signal failure starves
offboard, and "ok" brings the link back; a GPS failure shows in GPS_RAW_INT and
SYS_STATUS."""

import asyncio

import pytest
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.failure import FailureAsync
from mavsdk.asyncio.plugins.offboard import OffboardAsync
from mavsdk.asyncio.plugins.param import ParamAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.failure import FailureType, FailureUnit
from mavsdk.plugins.offboard import VelocityNedYaw
from pymavlink.dialects.v20 import common as mav

from ft_sitl.autopilot.params import ParamSet

from .mavsdk_util import connect, first
from .sitl_harness import running_sitl
from .test_pymavlink_and_robustness import ack_of, client, wait_msg

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

INSTANCE = 61  # (ports of its own: a test's leftover client cannot starve the next)


def test_a_motor_failed_mid_offboard_brings_the_vehicle_down():
    async def run():
        m, drone = await connect(14540 + INSTANCE)
        failure, param = FailureAsync(drone), ParamAsync(drone)
        action, tel, off = ActionAsync(drone), TelemetryAsync(drone), OffboardAsync(drone)
        assert await param.get_param_int("SYS_FAILURE_EN") == 1
        await first(tel.subscribe_health(), lambda h: h.is_armable)
        await action.set_takeoff_altitude(4.0)
        await action.arm()
        await action.takeoff()
        await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > 3.8,
                    timeout=30)
        await off.set_velocity_ned(VelocityNedYaw(1.0, 0.0, 0.0, 0.0))
        await off.start()
        await asyncio.sleep(1.0)
        await failure.inject(FailureUnit.SYSTEM_MOTOR, FailureType.OFF, 1)
        low = await first(tel.subscribe_position(), lambda p: p.relative_altitude_m < 1.0,
                          timeout=20)
        m.destroy()
        return low

    with running_sitl(speed_factor=3.0, params=[ParamSet({"SYS_FAILURE_EN": 1})],
                      base_instance=INSTANCE) as server:
        asyncio.run(run())
        cmd = server.fleet.commanders[0]
        assert cmd.failures == {"motor": ("off", 1)}
        assert server.fleet.sim.rotor_speeds(0)[0] < 1.0
        assert any("Failure injection: motor 1 off" in t for _, t in cmd.statustexts)


def test_signal_and_gps_failures_over_pymavlink():
    with running_sitl(base_instance=INSTANCE) as server:
        c = client(14540 + INSTANCE)

        def inject(unit, ftype, instance=0):
            c.mav.command_long_send(1, 1, mav.MAV_CMD_INJECT_FAILURE, 0, unit, ftype,
                                    instance, 0, 0, 0, 0)
            return ack_of(c, mav.MAV_CMD_INJECT_FAILURE).result

        assert inject(mav.FAILURE_UNIT_SENSOR_GPS, mav.FAILURE_TYPE_OFF) == \
            mav.MAV_RESULT_DENIED  # SYS_FAILURE_EN 0
        c.mav.param_set_send(1, 1, b"SYS_FAILURE_EN", 1.4e-45, mav.MAV_PARAM_TYPE_INT32)
        wait_msg(c, "PARAM_VALUE", lambda m: m.param_id == "SYS_FAILURE_EN")

        assert inject(mav.FAILURE_UNIT_SENSOR_GPS, mav.FAILURE_TYPE_OFF) == \
            mav.MAV_RESULT_ACCEPTED
        gps = wait_msg(c, "GPS_RAW_INT", lambda m: m.fix_type == mav.GPS_FIX_TYPE_NO_FIX)
        assert gps.satellites_visible == 0
        st = wait_msg(c, "SYS_STATUS", lambda m: not m.onboard_control_sensors_health
                      & mav.MAV_SYS_STATUS_SENSOR_GPS)
        assert st.onboard_control_sensors_present & mav.MAV_SYS_STATUS_SENSOR_GPS
        assert inject(mav.FAILURE_UNIT_SENSOR_GPS, mav.FAILURE_TYPE_OK) == \
            mav.MAV_RESULT_ACCEPTED
        wait_msg(c, "GPS_RAW_INT", lambda m: m.fix_type == mav.GPS_FIX_TYPE_3D_FIX)
        assert inject(mav.FAILURE_UNIT_SYSTEM_MAVLINK_SIGNAL, mav.FAILURE_TYPE_OFF) == \
            mav.MAV_RESULT_ACCEPTED
        cmd = server.fleet.commanders[0]
        n = cmd._offboard_t_us
        for _ in range(5):  # offboard setpoints are dropped now
            c.mav.set_position_target_local_ned_send(0, 1, 1, mav.MAV_FRAME_LOCAL_NED,
                                                     0b110111000111, 0, 0, 0, 0, 0, 0,
                                                     0, 0, 0, 0, 0)
        wait_msg(c, "HEARTBEAT")
        assert cmd._offboard_t_us == n
        assert inject(mav.FAILURE_UNIT_SYSTEM_MAVLINK_SIGNAL, mav.FAILURE_TYPE_OK) == \
            mav.MAV_RESULT_ACCEPTED
        assert inject(mav.FAILURE_UNIT_SYSTEM_RC_SIGNAL, mav.FAILURE_TYPE_OFF) == \
            mav.MAV_RESULT_UNSUPPORTED
        assert cmd.failures == {}
