"""The ArduCopter face flown by pymavlink's ArduPilot helpers, unmodified, over a real TCP
connection to SERIAL0 (ArduPilot SITL's 5760 + 10 x instance): mode_mapping, set_mode,
arducopter_arm, motors_armed_wait, a GUIDED take-off to 10 m, a SET_POSITION_TARGET_LOCAL_NED
goto, LAND until disarmed; REQUEST_DATA_STREAM; parameters by ArduCopter's names."""

import os
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from .ardupilot_harness import (  # noqa: E402
    command_ack,
    free_ardupilot_sitl,
    serial0,
    upload_mission,
    wait_armed,
    wait_disarmed,
    wait_for,
)

pytestmark = pytest.mark.e2e  # (tests/lanes.py)


_wait, _ack = wait_for, command_ack  # (ardupilot_harness)


def test_pymavlink_arducopter_helpers_fly_guided_takeoff_goto_land():
    mavutil.set_dialect("ardupilotmega")
    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        with serial0(k) as conn:
            hb = conn.messages["HEARTBEAT"]
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
            _wait(conn, lambda m: m.text == "Arm: LAND mode not armable", 10.0,
                  type="STATUSTEXT")

            conn.set_mode("GUIDED")
            assert _ack(conn, 176).result == mavutil.mavlink.MAV_RESULT_ACCEPTED
            _wait(conn, lambda m: m.custom_mode == 4, 10.0, type="HEARTBEAT")
            conn.arducopter_arm()
            wait_armed(conn)
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
            wait_disarmed(conn)
            m = _wait(conn, lambda m: True, 10.0, type="GLOBAL_POSITION_INT")
            assert m.relative_alt < 300
            assert server.agents[0].mode_name == "LAND"


def test_parameters_by_arducopter_names_honoured_and_refused():
    mavutil.set_dialect("ardupilotmega")
    with free_ardupilot_sitl() as (server, k):
        with serial0(k) as conn:
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
            _wait(conn, lambda m: m.text == "ANGLE_MAX: 9000 not in 1000..8000 cdeg", 10.0,
                  type="STATUSTEXT")  # (the reason in one STATUSTEXT)


def test_auto_mission_with_home_at_zero_flies_to_the_land_and_disarms():
    """A mission built with pymavlink's MAVWPLoader (item 0 a placeholder for home):
    TAKEOFF, DO_CHANGE_SPEED, a waypoint with a delay, LOITER_TIME, DO_JUMP back once,
    LAND; armed in GUIDED, flown in AUTO; reached items and MISSION_CURRENT in ArduPilot's
    numbering, home read back as item 0."""
    from pymavlink import mavwp

    mavutil.set_dialect("ardupilotmega")
    mav = mavutil.mavlink
    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        with serial0(k) as conn:
            conn.mav.request_data_stream_send(conn.target_system, conn.target_component,
                                              mav.MAV_DATA_STREAM_ALL, 10, 1)
            home = _wait(conn, lambda m: True, 10.0, type="GLOBAL_POSITION_INT")
            lat0, lon0 = home.lat * 1e-7, home.lon * 1e-7
            north, east = 1 / 111320.0, 1 / (111320.0 * 0.9)  # (deg per m, roughly)
            rel = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT

            def item(seq, command, p1=0, p2=0, lat=0.0, lon=0.0, alt=0.0, frame=rel):
                return mav.MAVLink_mission_item_message(
                    conn.target_system, conn.target_component, seq, frame, command, 0, 1,
                    p1, p2, 0, 0, lat, lon, alt)

            loader = mavwp.MAVWPLoader(target_system=conn.target_system,
                                       target_component=conn.target_component)
            for w in (item(0, mav.MAV_CMD_NAV_WAYPOINT, lat=lat0, lon=lon0,
                           frame=mav.MAV_FRAME_GLOBAL),
                      item(1, mav.MAV_CMD_NAV_TAKEOFF, alt=10),
                      item(2, mav.MAV_CMD_DO_CHANGE_SPEED, 1, 8),
                      item(3, mav.MAV_CMD_NAV_WAYPOINT, 1, lat=lat0 + 25 * north, lon=lon0,
                           alt=10),
                      item(4, mav.MAV_CMD_NAV_LOITER_TIME, 2, lat=lat0 + 25 * north,
                           lon=lon0 + 20 * east, alt=12),
                      item(5, mav.MAV_CMD_DO_JUMP, 3, 1),
                      item(6, mav.MAV_CMD_NAV_LAND, lat=lat0, lon=lon0 + 20 * east)):
                loader.add(w)
            assert upload_mission(conn, loader) == mav.MAV_MISSION_ACCEPTED
            assert len(server.fleet.commanders[0].mission) == 6  # (home is not flown)

            # read back: item 0 is home as the vehicle holds it, the rest as uploaded
            conn.waypoint_request_list_send()
            assert _wait(conn, lambda m: True, 10.0, type="MISSION_COUNT").count == 7
            for seq in (0, 1, 2, 5):
                conn.waypoint_request_send(seq)
                m = _wait(conn, lambda m, seq=seq: m.seq == seq, 10.0,
                          type=["MISSION_ITEM", "MISSION_ITEM_INT"])
                assert m.current == 0  # (AP_Mission: nothing runs before AUTO starts it)
                if seq == 0:
                    x = m.x if m.get_type() == "MISSION_ITEM" else m.x * 1e-7
                    assert abs(x - lat0) < 1e-5 and m.command == mav.MAV_CMD_NAV_WAYPOINT
                elif seq == 1:  # a command with a location keeps its frame
                    assert m.command == mav.MAV_CMD_NAV_TAKEOFF and m.frame == rel
                elif seq == 2:  # one without comes back in frame 0, GLOBAL
                    assert m.command == mav.MAV_CMD_DO_CHANGE_SPEED and m.frame == 0
                else:
                    assert m.command == mav.MAV_CMD_DO_JUMP and m.param1 == 3
                    assert m.frame == 0
            conn.mav.mission_ack_send(conn.target_system, conn.target_component, 0)

            conn.set_mode("GUIDED")
            _wait(conn, lambda m: m.custom_mode == 4, 10.0, type="HEARTBEAT")
            conn.arducopter_arm()
            wait_armed(conn)
            conn.set_mode("AUTO")
            _wait(conn, lambda m: m.custom_mode == 3, 10.0, type="HEARTBEAT")
            reached = []
            deadline = time.time() + 240
            while time.time() < deadline:
                m = conn.recv_match(type=["MISSION_ITEM_REACHED", "HEARTBEAT"],
                                    blocking=True, timeout=1.0)
                if m is None:
                    continue
                if m.get_type() == "MISSION_ITEM_REACHED":
                    if not reached or reached[-1] != m.seq:
                        reached.append(m.seq)
                elif reached and not m.base_mode & mav.MAV_MODE_FLAG_SAFETY_ARMED:
                    break
            # DO_JUMP 3 once: 3 and 4 twice, then the jump is spent (5), then LAND (6)
            assert reached == [1, 2, 3, 4, 3, 4, 5, 6], reached
            m = _wait(conn, lambda m: True, 10.0, type="GLOBAL_POSITION_INT")
            assert m.relative_alt < 300
            assert abs((m.lon * 1e-7 - lon0) / east - 20) < 2.0  # landed at item 6
            assert abs((m.lat * 1e-7 - lat0) / north) < 2.0
            mc = _wait(conn, lambda m: True, 10.0, type="MISSION_CURRENT")
            assert mc.seq == 6 and mc.total == 7
            # MISSION_CLEAR_ALL leaves nothing, home's item neither (AP_Mission::clear)
            conn.waypoint_clear_all_send()
            assert _wait(conn, lambda m: True, 10.0, type="MISSION_ACK").type == \
                mav.MAV_MISSION_ACCEPTED
            conn.waypoint_request_list_send()
            assert _wait(conn, lambda m: True, 10.0, type="MISSION_COUNT").count == 0
            conn.waypoint_request_send(0)  # home can still be read (DroneKit asks for it)
            m = _wait(conn, lambda m: m.seq == 0, 10.0, type=["MISSION_ITEM", "MISSION_ITEM_INT"])
            assert m.command == mav.MAV_CMD_NAV_WAYPOINT and m.frame == 0


def test_auto_mission_return_to_launch_item_lands_at_home_and_disarms():
    """TAKEOFF, a spline waypoint 20 m east, NAV_RETURN_TO_LAUNCH: the vehicle comes back, lands
    at home and disarms; MISSION_SET_CURRENT and MISSION_CURRENT in ArduPilot's numbering."""
    from pymavlink import mavwp

    mavutil.set_dialect("ardupilotmega")
    mav = mavutil.mavlink
    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        with serial0(k) as conn:
            conn.mav.request_data_stream_send(conn.target_system, conn.target_component,
                                              mav.MAV_DATA_STREAM_ALL, 10, 1)
            home = _wait(conn, lambda m: True, 10.0, type="GLOBAL_POSITION_INT")
            rel = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT
            east = 20 / (111320.0 * 0.67)  # (20 m at about 47.4 deg north)
            loader = mavwp.MAVWPLoader(target_system=conn.target_system,
                                       target_component=conn.target_component)
            for seq, (command, lon, alt) in enumerate(
                    ((mav.MAV_CMD_NAV_WAYPOINT, 0.0, 0), (mav.MAV_CMD_NAV_TAKEOFF, 0.0, 8),
                     (mav.MAV_CMD_NAV_SPLINE_WAYPOINT, home.lon * 1e-7 + east, 8),
                     (mav.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0.0, 0))):
                lat = home.lat * 1e-7 if lon else 0.0
                loader.add(mav.MAVLink_mission_item_message(
                    conn.target_system, conn.target_component, seq, rel, command, 0, 1,
                    0, 0, 0, 0, lat, lon, alt))
            assert upload_mission(conn, loader) == mav.MAV_MISSION_ACCEPTED
            conn.waypoint_set_current_send(1)
            mc = _wait(conn, lambda m: True, 10.0, type="MISSION_CURRENT")
            assert mc.seq == 1 and mc.total == 4
            conn.set_mode("GUIDED")
            conn.arducopter_arm()
            wait_armed(conn)
            conn.set_mode("AUTO")
            _wait(conn, lambda m: m.seq == 2, 120.0, type="MISSION_ITEM_REACHED")
            far = _wait(conn, lambda m: True, 10.0, type="LOCAL_POSITION_NED")
            assert far.y > 15  # out east before returning
            wait_disarmed(conn)
            c = server.agents[0].cmd
            p = c.position_now()
            assert abs(p[0] - c.home[0]) < 2.0 and abs(p[1] - c.home[1]) < 2.0
            assert p[2] - c.home[2] < 0.5
            assert 2 in c.reached  # (the commander's index of item 3, RTL)
