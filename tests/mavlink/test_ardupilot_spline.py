"""Spline waypoints on the ArduCopter face, flown by pymavlink over SERIAL0's TCP: a mission
of MAV_CMD_NAV_SPLINE_WAYPOINT items bends before its corners (it leaves the straight
chords between the waypoints by metres: 5.3 m when written, against 1.3 m for the straight
legs' overshoot after each corner), passes each waypoint within WPNAV_RADIUS and
lands at the last; the same mission of NAV_WAYPOINT items keeps to the chords."""

import math
import os
import time

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil, mavwp  # noqa: E402

from .ardupilot_harness import (  # noqa: E402
    free_ardupilot_sitl,
    serial0,
    upload_mission,
    wait_armed,
    wait_for,
)

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

#: the corners, metres north and east of where the vehicle starts, at 5 m
CORNERS = [(0.0, 20.0), (20.0, 20.0), (20.0, 0.0)]
ALT_M = 5.0


def _fly(conn, command: int, home, start_ned) -> tuple[np.ndarray, list]:
    """Upload home, TAKEOFF, the corners as ``command`` items and LAND, fly it in AUTO
    from GUIDED's arming; the positions flown (north, east, up from the start, and the
    mission item then current) and the items reached."""
    mav = mavutil.mavlink
    lat0, lon0 = home.lat * 1e-7, home.lon * 1e-7
    per_m_north = 1 / 111320.0
    per_m_east = 1 / (111320.0 * math.cos(math.radians(lat0)))
    rel = mav.MAV_FRAME_GLOBAL_RELATIVE_ALT
    loader = mavwp.MAVWPLoader(target_system=conn.target_system,
                               target_component=conn.target_component)

    def item(seq, cmd, lat=0.0, lon=0.0, alt=0.0, frame=rel):
        return mav.MAVLink_mission_item_message(conn.target_system, conn.target_component,
                                                seq, frame, cmd, 0, 1, 0, 0, 0, 0, lat, lon,
                                                alt)

    loader.add(item(0, mav.MAV_CMD_NAV_WAYPOINT, lat0, lon0, frame=mav.MAV_FRAME_GLOBAL))
    loader.add(item(1, mav.MAV_CMD_NAV_TAKEOFF, alt=ALT_M))
    for k, (n, e) in enumerate(CORNERS):
        loader.add(item(2 + k, command, lat0 + (n + start_ned[0]) * per_m_north,
                        lon0 + (e + start_ned[1]) * per_m_east, ALT_M))
    loader.add(item(5, mav.MAV_CMD_NAV_LAND))
    assert upload_mission(conn, loader) == mav.MAV_MISSION_ACCEPTED
    conn.set_mode("GUIDED")
    wait_for(conn, lambda m: m.custom_mode == 4, 10.0, type="HEARTBEAT")
    conn.arducopter_arm()
    wait_armed(conn)
    conn.set_mode("AUTO")
    path, reached, current = [], [], 0
    armed = mav.MAV_MODE_FLAG_SAFETY_ARMED
    deadline = time.monotonic() + 300.0  # (a liveness deadline: the flight ends or fails)
    while time.monotonic() < deadline:
        m = conn.recv_match(type=["LOCAL_POSITION_NED", "MISSION_ITEM_REACHED", "HEARTBEAT",
                                  "MISSION_CURRENT"], blocking=True, timeout=1.0)
        if m is None:
            continue
        if m.get_type() == "LOCAL_POSITION_NED":
            path.append((m.x - start_ned[0], m.y - start_ned[1], -(m.z - start_ned[2]),
                         current))
        elif m.get_type() == "MISSION_CURRENT":
            current = m.seq
        elif m.get_type() == "MISSION_ITEM_REACHED":
            if not reached or reached[-1] != m.seq:
                reached.append(m.seq)
        elif m.get_srcSystem() == conn.target_system and reached and \
                not m.base_mode & armed:
            break
    return np.array(path), reached


def _off_chords(path: np.ndarray) -> float:
    """How far the legs between the corners (items 3 and 4, their first and last 4 m
    left out) go from the straight chords joining them (m, horizontally)."""
    off = 0.0
    for seq, (a, b) in ((3, (CORNERS[0], CORNERS[1])), (4, (CORNERS[1], CORNERS[2]))):
        a, b = np.array(a), np.array(b)
        u = (b - a) / np.linalg.norm(b - a)
        leg = path[path[:, 3] == seq]
        d = leg[:, :2] - a
        along = d @ u
        inner = (along > 4.0) & (along < np.linalg.norm(b - a) - 4.0)
        assert inner.sum() > 5, f"too few positions on item {seq}'s leg"
        off = max(off, float(np.max(np.abs(d[inner, 0] * u[1] - d[inner, 1] * u[0]))))
    return off


def test_spline_waypoints_fly_a_curve_through_each_waypoint_and_straight_ones_do_not():
    mavutil.set_dialect("ardupilotmega")
    mav = mavutil.mavlink
    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        with serial0(k) as conn:
            conn.mav.request_data_stream_send(conn.target_system, conn.target_component,
                                              mav.MAV_DATA_STREAM_ALL, 50, 1)
            home = wait_for(conn, lambda m: True, 10.0, type="GLOBAL_POSITION_INT")
            start = wait_for(conn, lambda m: True, 10.0, type="LOCAL_POSITION_NED")
            start_ned = (start.x, start.y, start.z)
            radius = server.agents[0].vehicle.ap_params["WPNAV_RADIUS"] / 100.0

            curve, reached = _fly(conn, mav.MAV_CMD_NAV_SPLINE_WAYPOINT, home, start_ned)
            assert reached == [1, 2, 3, 4, 5], reached
            corners = np.array(CORNERS)
            for c in corners:  # through each waypoint, within WPNAV_RADIUS
                closest = np.min(np.linalg.norm(curve[:, :2] - c, axis=1))
                assert closest < radius, (c, closest)
            assert np.linalg.norm(curve[-1, :2] - corners[-1]) < radius  # landed there
            # it bends round the corners: metres off the straight chords between them
            # (the straight legs: only their overshoot after each corner)
            curve_off = _off_chords(curve)

            straight, reached = _fly(conn, mav.MAV_CMD_NAV_WAYPOINT, home, start_ned)
            assert reached == [1, 2, 3, 4, 5], reached
            straight_off = _off_chords(straight)
            assert straight_off < 2.0 < 3.0 < curve_off, (straight_off, curve_off)
