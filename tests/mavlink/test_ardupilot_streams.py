"""The ArduCopter face's streams as ArduPilot sends them, asked for with pymavlink's
REQUEST_DATA_STREAM and SET_MESSAGE_INTERVAL over SERIAL0's TCP port: AHRS2 (EXTRA1),
NAV_CONTROLLER_OUTPUT and SYS_STATUS (EXTENDED_STATUS), SERVO_OUTPUT_RAW and RC_CHANNELS
(RC_CHANNELS, with RC_CHANNELS_OVERRIDE),
EKF_STATUS_REPORT (EXTRA3); their content checked against the vehicle's state (presence
only, no timing)."""

import math
import os
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from ft_sitl.mavlink.ardupilot.server import tcp_ports  # noqa: E402
from ft_sitl.mavlink.ardupilot.streams import GROUP_MESSAGES  # noqa: E402

from .ardupilot_harness import (  # noqa: E402
    command_ack,
    free_ardupilot_sitl,
    wait_armed,
    wait_disarmed,
    wait_for,
)

pytestmark = pytest.mark.e2e  # (tests/lanes.py)
_m = mavutil.mavlink


_wait, _ack = wait_for, command_ack  # (ardupilot_harness)
EKF_HEALTHY = (_m.EKF_ATTITUDE | _m.EKF_VELOCITY_HORIZ | _m.EKF_VELOCITY_VERT
               | _m.EKF_POS_HORIZ_REL | _m.EKF_POS_HORIZ_ABS | _m.EKF_POS_VERT_ABS
               | _m.EKF_PRED_POS_HORIZ_REL | _m.EKF_PRED_POS_HORIZ_ABS)


def test_the_groups_hold_ardupilots_messages():
    """Copter's GCS_Mavlink.cpp stream lists: each message in its group."""
    where = {m: g for g, ids in GROUP_MESSAGES.items() for m in ids}
    assert where[_m.MAVLINK_MSG_ID_AHRS2] == "EXTRA1"
    assert where[_m.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT] == "EXT_STAT"
    assert where[_m.MAVLINK_MSG_ID_FENCE_STATUS] == "EXT_STAT"
    assert where[_m.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW] == "RC_CHAN"
    assert where[_m.MAVLINK_MSG_ID_RC_CHANNELS] == "RC_CHAN"
    assert where[_m.MAVLINK_MSG_ID_EKF_STATUS_REPORT] == "EXTRA3"


def _until(what, timeout_s: float, describe: str) -> None:
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        if what():
            return
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {describe}")


def _stream(conn, stream_id, hz=5, start=1):
    conn.mav.request_data_stream_send(conn.target_system, conn.target_component, stream_id,
                                      hz, start)


def test_streams_carry_ahrs2_ekf_servo_outputs_and_nav_controller_output():
    mavutil.set_dialect("ardupilotmega")
    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        agent = server.agents[0]
        geo, home = agent.geo, agent.cmd.home.copy()
        conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{tcp_ports(k)[0]}",
                                          source_system=250)
        try:
            conn.wait_heartbeat(timeout=30)
            for s in (_m.MAV_DATA_STREAM_EXTRA1, _m.MAV_DATA_STREAM_EXTENDED_STATUS,
                      _m.MAV_DATA_STREAM_RC_CHANNELS, _m.MAV_DATA_STREAM_EXTRA3,
                      _m.MAV_DATA_STREAM_POSITION):
                _stream(conn, s)

            m = _wait(conn, lambda m: True, 30.0, type="AHRS2")
            lat, lon, alt = geo.to_global(home)
            assert abs(m.lat - lat * 1e7) < 50 and abs(m.lng - lon * 1e7) < 50
            assert abs(m.altitude - alt) < 0.5 and abs(m.roll) < 0.05 and abs(m.pitch) < 0.05
            m = _wait(conn, lambda m: True, 30.0, type="EKF_STATUS_REPORT")
            assert m.flags == EKF_HEALTHY
            assert 0 <= m.velocity_variance < 1 and 0 <= m.pos_horiz_variance < 1
            conn.param_set_send("SIM_GPS_DISABLE", 1)  # no GPS: no horizontal position
            _wait(conn, lambda m: m.flags == _m.EKF_ATTITUDE | _m.EKF_VELOCITY_VERT
                  | _m.EKF_POS_VERT_ABS | _m.EKF_CONST_POS_MODE, 30.0,
                  type="EKF_STATUS_REPORT")
            conn.param_set_send("SIM_GPS_DISABLE", 0)
            _wait(conn, lambda m: m.flags == EKF_HEALTHY, 30.0, type="EKF_STATUS_REPORT")
            m = _wait(conn, lambda m: True, 30.0, type="SERVO_OUTPUT_RAW")
            assert [m.servo1_raw, m.servo2_raw, m.servo3_raw, m.servo4_raw] == [1000] * 4
            assert m.servo5_raw == 0
            # RC_CHANNELS: ArduPilot SITL's radio (1500, throttle at RC3_MIN), then the
            # channels overridden
            m = _wait(conn, lambda m: True, 30.0, type="RC_CHANNELS")
            assert m.chancount == 16 and (m.chan1_raw, m.chan3_raw, m.chan16_raw) == \
                (1500, 1100, 1500)
            conn.param_set_send("SYSID_MYGCS", 250)  # (overrides only from the GCS)
            _wait(conn, lambda m: m.param_id == "SYSID_MYGCS" and m.param_value == 250, 10.0,
                  type="PARAM_VALUE")
            conn.mav.rc_channels_override_send(conn.target_system, conn.target_component,
                                               1600, 65535, 1300, 65535, 65535, 65535, 65535,
                                               1700)
            m = _wait(conn, lambda m: m.chan1_raw == 1600, 30.0, type="RC_CHANNELS")
            assert (m.chan2_raw, m.chan3_raw, m.chan8_raw) == (1500, 1300, 1700)
            conn.mav.rc_channels_override_send(conn.target_system, conn.target_component,
                                               0, 65535, 0, 65535, 65535, 65535, 65535, 0)
            _wait(conn, lambda m: (m.chan1_raw, m.chan3_raw, m.chan8_raw) ==
                  (1500, 1100, 1500), 30.0, type="RC_CHANNELS")
            m = _wait(conn, lambda m: True, 30.0, type="NAV_CONTROLLER_OUTPUT")
            assert m.wp_dist == 0 and m.target_bearing == 0  # (no target disarmed)
            m = _wait(conn, lambda m: True, 30.0, type="SYS_STATUS")
            bit = _m.MAV_SYS_STATUS_GEOFENCE
            # FENCE_TYPE 7 configures the altitude and circle kinds: present; off; healthy
            assert (m.onboard_control_sensors_present & bit,
                    m.onboard_control_sensors_enabled & bit,
                    m.onboard_control_sensors_health & bit) == (bit, 0, bit)

            conn.set_mode("GUIDED")
            _wait(conn, lambda m: m.custom_mode == 4, 10.0, type="HEARTBEAT")
            conn.arducopter_arm()
            wait_armed(conn)
            conn.mav.command_long_send(conn.target_system, conn.target_component,
                                       _m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 10)
            assert _ack(conn, 22).result == _m.MAV_RESULT_ACCEPTED
            _wait(conn, lambda m: m.relative_alt > 9500, 60.0, type="GLOBAL_POSITION_INT")
            # hovering: the four motors alike, between idle and full
            m = _wait(conn, lambda m: True, 10.0, type="SERVO_OUTPUT_RAW")
            pwm = [m.servo1_raw, m.servo2_raw, m.servo3_raw, m.servo4_raw]
            assert all(1150 < p < 1950 for p in pwm) and max(pwm) - min(pwm) < 100, pwm
            w = server.fleet.rotor_speed_commands(0)
            w_max = server.fleet.sim.platforms[0].rotor_speed_max_rad_s
            assert abs(pwm[0] - (1000 + 1000 * w[0] / w_max)) < 100

            # a destination 30 m north: bearing 0, the distance falling, no cross-track
            conn.mav.set_position_target_local_ned_send(
                0, conn.target_system, conn.target_component, _m.MAV_FRAME_LOCAL_NED, 3576,
                30.0, 0.0, -10.0, 0, 0, 0, 0, 0, 0, 0, 0)
            m = _wait(conn, lambda m: 10 <= m.wp_dist <= 25, 60.0,
                      type="NAV_CONTROLLER_OUTPUT")
            assert min(m.target_bearing, 360 - m.target_bearing) <= 5, m
            assert abs(m.alt_error) < 1.5 and abs(m.xtrack_error) < 2.0, m
            assert math.isfinite(m.nav_roll) and abs(m.nav_pitch) < 45

            # SET_MESSAGE_INTERVAL keeps AHRS2 going when its group is stopped
            conn.mav.command_long_send(conn.target_system, conn.target_component,
                                       _m.MAV_CMD_SET_MESSAGE_INTERVAL, 0,
                                       _m.MAVLINK_MSG_ID_AHRS2, 250000, 0, 0, 0, 0, 0)
            assert _ack(conn, _m.MAV_CMD_SET_MESSAGE_INTERVAL).result == \
                _m.MAV_RESULT_ACCEPTED
            _stream(conn, _m.MAV_DATA_STREAM_EXTRA1, start=0)
            rates = agent.streams.rates[0]
            _until(lambda: rates[_m.MAVLINK_MSG_ID_ATTITUDE] == 0.0, 30.0, "EXTRA1 stopped")
            assert rates[_m.MAVLINK_MSG_ID_AHRS2] == pytest.approx(4.0)
            assert server.agents[0].vehicle.ap_params["SR0_EXTRA1"] == 0
            _wait(conn, lambda m: True, 10.0, type="AHRS2")

            conn.set_mode("LAND")
            wait_disarmed(conn)
        finally:
            conn.close()
