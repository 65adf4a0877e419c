"""The ArduCopter face flown by pymavlink's ArduPilot helpers, unmodified, over a real TCP
connection to SERIAL0 (ArduPilot SITL's 5760 + 10 x instance): mode_mapping, set_mode,
arducopter_arm, motors_armed_wait, a GUIDED take-off to 10 m, a SET_POSITION_TARGET_LOCAL_NED
goto, LAND until disarmed; REQUEST_DATA_STREAM; parameters by ArduCopter's names."""

import os
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from ft_sitl.mavlink.ardupilot.server import ArduPilotServer, tcp_port_free, tcp_ports  # noqa: E402,E501
from ft_sitl.mavlink.instances import free_instances  # noqa: E402

from .sitl_harness import _running_sitl  # noqa: E402

pytestmark = pytest.mark.e2e  # (tests/lanes.py)


def _free(k: int) -> bool:
    return all(tcp_port_free("127.0.0.1", p) for p in tcp_ports(k))


def _wait(conn, what, timeout_s=60.0, **match):
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        m = conn.recv_match(blocking=True, timeout=1.0, **match)
        if m is not None and what(m):
            return m
    raise AssertionError(f"timed out waiting for {match}")


def _ack(conn, command):
    return _wait(conn, lambda m: m.command == command, 10.0, type="COMMAND_ACK")


def test_pymavlink_arducopter_helpers_fly_guided_takeoff_goto_land():
    mavutil.set_dialect("ardupilotmega")
    with free_instances(1, _free) as k, \
            _running_sitl(1, speed_factor=4.0, server_class=ArduPilotServer,
                          base_instance=k) as server:
        conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{tcp_ports(k)[0]}",
                                          source_system=250)
        try:
            hb = conn.wait_heartbeat(timeout=30)
            assert hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
            assert hb.type == mavutil.mavlink.MAV_TYPE_QUADROTOR
            modes = conn.mode_mapping()
            assert modes["GUIDED"] == 4 and modes["LAND"] == 9 and modes["LOITER"] == 5
            # nothing streams until asked (ArduCopter's SRn_* default 0), then it does
            conn.mav.request_data_stream_send(conn.target_system, conn.target_component,
                                              mavutil.mavlink.MAV_DATA_STREAM_ALL, 10, 1)
            _wait(conn, lambda m: True, 10.0, type="GLOBAL_POSITION_INT")

            # arming in a mode that does not allow it: ArduCopter's text, FAILED
            conn.set_mode("LAND")
            _wait(conn, lambda m: m.custom_mode == 9, 10.0, type="HEARTBEAT")
            conn.arducopter_arm()
            assert _ack(conn, 400).result == mavutil.mavlink.MAV_RESULT_FAILED
            _wait(conn, lambda m: m.text.startswith("Arm: Mode not armable"), 10.0,
                  type="STATUSTEXT")

            conn.set_mode("GUIDED")
            assert _ack(conn, 176).result == mavutil.mavlink.MAV_RESULT_ACCEPTED
            _wait(conn, lambda m: m.custom_mode == 4, 10.0, type="HEARTBEAT")
            conn.arducopter_arm()
            conn.motors_armed_wait()
            conn.mav.command_long_send(conn.target_system, conn.target_component,
                                       mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0,
                                       0, 10)
            assert _ack(conn, 22).result == mavutil.mavlink.MAV_RESULT_ACCEPTED
            _wait(conn, lambda m: m.relative_alt > 9500, 60.0, type="GLOBAL_POSITION_INT")
            assert conn.messages["HEARTBEAT"].custom_mode == 4  # still GUIDED

            # a position target: ArduPilot's mask (3576: position only), local NED
            conn.mav.set_position_target_local_ned_send(
                0, conn.target_system, conn.target_component,
                mavutil.mavlink.MAV_FRAME_LOCAL_NED, 3576, 15.0, -5.0, -10.0,
                0, 0, 0, 0, 0, 0, 0, 0)
            m = _wait(conn, lambda m: abs(m.x - 15) < 0.5 and abs(m.y + 5) < 0.5, 60.0,
                      type="LOCAL_POSITION_NED")
            assert abs(m.z + 10) < 1.0

            conn.set_mode("LAND")
            conn.motors_disarmed_wait()
            m = _wait(conn, lambda m: True, 10.0, type="GLOBAL_POSITION_INT")
            assert m.relative_alt < 300
            assert server.agents[0].mode_name == "LAND"
        finally:
            conn.close()


def test_parameters_by_arducopter_names_honoured_and_refused():
    mavutil.set_dialect("ardupilotmega")
    with free_instances(1, _free) as k, \
            _running_sitl(1, server_class=ArduPilotServer, base_instance=k) as server:
        conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{tcp_ports(k)[0]}",
                                          source_system=250)
        try:
            conn.wait_heartbeat(timeout=30)
            conn.param_fetch_one("WPNAV_SPEED")
            m = _wait(conn, lambda m: m.param_id == "WPNAV_SPEED", 10.0, type="PARAM_VALUE")
            assert m.param_value == 1000.0
            conn.param_set_send("WPNAV_SPEED", 750)
            m = _wait(conn, lambda m: m.param_id == "WPNAV_SPEED", 10.0, type="PARAM_VALUE")
            assert m.param_value == 750.0
            assert server.fleet.params[0]["MPC_XY_CRUISE"] == 7.5  # honoured
            conn.param_set_send("ANGLE_MAX", 9000, mavutil.mavlink.MAV_PARAM_TYPE_INT16)
            m = _wait(conn, lambda m: m.param_id == "ANGLE_MAX", 10.0, type="PARAM_VALUE")
            assert m.param_value == 3000.0 and m.param_type == 4  # refused, echoed as INT16
            _wait(conn, lambda m: m.text == "Param write denied (ANGLE_MAX)", 10.0,
                  type="STATUSTEXT")
            _wait(conn, lambda m: "[1000, 8000] cdeg" in m.text, 10.0, type="STATUSTEXT")
        finally:
            conn.close()
