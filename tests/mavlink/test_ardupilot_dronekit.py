"""DroneKit (the maintained fork, PyPI ``dronekit2``, imported as ``dronekit``) against
``ft-sitl sitl --autopilot ardupilot`` in a process of its own, over SERIAL0's TCP port:
our own scripts following the flows of DroneKit's four classic examples (vehicle_state,
simple_goto, mission_basic, guided_set_speed_yaw), each asserting that the vehicle did
what was asked (attributes, parameters, home, modes, positions reached, disarmed at the
end). Waits are liveness deadlines that fail naming what was awaited, never timings."""

import math
import time

import pytest
from dronekit import Command, LocationGlobal, LocationGlobalRelative, VehicleMode, connect
from pymavlink import mavutil

from .ardupilot_harness import ardupilot_sitl_process, until

pytestmark = pytest.mark.e2e  # (tests/lanes.py: a SITL process, TCP)

MAV = mavutil.mavlink
#: metres per degree of latitude (and of longitude at the home's latitude, below)
M_PER_DEG = 111319.5


def _offset(loc, north_m: float, east_m: float, alt=None):
    """A LocationGlobalRelative north_m / east_m from loc (flat earth, fine over 100 m)."""
    lat = loc.lat + north_m / M_PER_DEG
    lon = loc.lon + east_m / (M_PER_DEG * math.cos(math.radians(loc.lat)))
    return LocationGlobalRelative(lat, lon, loc.alt if alt is None else alt)


def _ne(vehicle, origin) -> tuple[float, float]:
    """The vehicle's (north, east) metres from origin."""
    here = vehicle.location.global_frame
    return ((here.lat - origin.lat) * M_PER_DEG,
            (here.lon - origin.lon) * M_PER_DEG * math.cos(math.radians(origin.lat)))


def _near(vehicle, target, within_m: float) -> bool:
    n, e = _ne(vehicle, target)
    alt = vehicle.location.global_relative_frame.alt
    return math.hypot(n, e) < within_m and abs(alt - target.alt) < within_m


@pytest.fixture
def vehicle():
    """A DroneKit Vehicle connected to a fresh ArduCopter SITL (speed factor 4)."""
    with ardupilot_sitl_process("--speed-factor", "4") as info:
        v = connect(info["vehicles"][0]["serial"][0], wait_ready=True, timeout=120,
                    heartbeat_timeout=120)
        try:
            yield v
        finally:
            v.close()


def _arm_and_take_off(v, alt: float) -> None:
    """As DroneKit's examples do it: wait until armable, GUIDED, arm, simple_takeoff, wait
    for 95 % of the altitude."""
    until(lambda: v.is_armable, 60, "vehicle.is_armable")
    v.mode = VehicleMode("GUIDED")
    until(lambda: v.mode.name == "GUIDED", 30, "GUIDED")
    v.armed = True
    until(lambda: v.armed, 30, "armed")
    v.simple_takeoff(alt)
    until(lambda: v.location.global_relative_frame.alt >= 0.95 * alt, 120,
          f"the climb to {alt} m")


def _land_disarmed(v, mode: str, home, within_m: float) -> None:
    v.mode = VehicleMode(mode)
    until(lambda: not v.armed, 300, f"disarmed after {mode}")
    assert v.mode.name in (mode, "LAND"), v.mode.name
    assert v.location.global_relative_frame.alt < 0.5
    n, e = _ne(v, home)
    assert math.hypot(n, e) < within_m, (n, e)


def test_vehicle_state(vehicle):
    """Attributes, parameters (read, observed, written and read back), home location (read
    from the mission download, set, read back), mode and arming changes."""
    v = vehicle
    v.wait_ready("autopilot_version", timeout=60)  # (asked for after the first heartbeat)
    assert v.version.autopilot_type == MAV.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert (v.version.major, v.version.minor) == (4, 5)
    assert v.capabilities.mission_int and v.capabilities.command_int
    assert v.capabilities.set_attitude_target_local_ned and not v.capabilities.ftp
    here = v.location.global_frame
    assert abs(here.lat - 47.397742) < 1e-5 and abs(here.lon - 8.545594) < 1e-5
    assert abs(v.location.global_relative_frame.alt) < 0.2
    assert v.location.local_frame.north is not None
    assert all(math.isfinite(x) for x in (v.attitude.pitch, v.attitude.roll, v.attitude.yaw))
    assert v.velocity == pytest.approx([0, 0, 0], abs=0.1)
    assert v.gps_0.fix_type >= 3 and v.gps_0.satellites_visible > 0
    assert v.battery.voltage > 10 and v.battery.level > 50
    assert 0 <= v.heading < 360 and v.groundspeed < 0.2
    assert v.last_heartbeat < 5
    until(lambda: v.is_armable, 60, "vehicle.is_armable")
    assert v.ekf_ok
    assert v.system_status.state == "STANDBY" and not v.armed

    # home: read with the mission download (item 0), set, read back
    cmds = v.commands
    cmds.download()
    cmds.wait_ready(timeout=60)
    home = v.home_location
    # (MISSION_ITEM carries float32 degrees: some 1e-6)
    assert abs(home.lat - here.lat) < 1e-5 and abs(home.lon - here.lon) < 1e-5
    new_home = LocationGlobal(home.lat + 10 / M_PER_DEG, home.lon, home.alt + 1.0)
    v.home_location = new_home
    v._home_location = None  # (read it again from the vehicle, not DroneKit's cache)
    until(lambda: (cmds.download(), cmds.wait_ready(timeout=60))
          and v.home_location is not None
          and abs(v.home_location.lat - new_home.lat) < 1e-5, 60, "the new home")
    assert abs(v.home_location.alt - new_home.alt) < 0.1

    # parameters: all read at connection, one observed while it is written
    assert len(v.parameters) > 50 and v.parameters["WPNAV_SPEED"] == 1000
    assert set(v.parameters.keys()) >= {"RTL_ALT", "ANGLE_MAX", "FENCE_ENABLE"}
    seen = []
    v.parameters.add_attribute_listener("RTL_ALT", lambda _p, name, value: seen.append(value))
    v.parameters["RTL_ALT"] = 2500
    until(lambda: 2500 in seen, 30, "the RTL_ALT observer")
    assert v.parameters["RTL_ALT"] == 2500

    # mode and arming
    v.mode = VehicleMode("GUIDED")
    until(lambda: v.mode.name == "GUIDED", 30, "GUIDED")
    v.armed = True
    until(lambda: v.armed, 30, "armed")
    assert v.system_status.state == "ACTIVE"
    v.armed = False
    until(lambda: not v.armed, 30, "disarmed")
    v.mode = VehicleMode("STABILIZE")
    until(lambda: v.mode.name == "STABILIZE", 30, "STABILIZE")


def test_simple_goto(vehicle):
    """GUIDED, arm, simple_takeoff, simple_goto twice (an airspeed, then a groundspeed),
    RTL: each point reached, the speeds asked for flown, disarmed at home."""
    v = vehicle
    home = v.location.global_frame
    _arm_and_take_off(v, 10)
    speeds = []
    v.add_attribute_listener("groundspeed", lambda _v, _n, value: speeds.append(value))

    v.airspeed = 1.5
    p1 = _offset(home, 30, 0, 20)
    v.simple_goto(p1)
    until(lambda: _near(v, p1, 1.0), 120, "the first point (30 m north, 20 m up)")
    slow = max(speeds)
    speeds.clear()

    p2 = _offset(home, 30, 40, 20)
    v.simple_goto(p2, groundspeed=3.5)
    until(lambda: _near(v, p2, 1.0), 120, "the second point (40 m east of the first)")
    fast = max(speeds)
    assert v.mode.name == "GUIDED"
    # (ArduCopter's DO_CHANGE_SPEED sets the horizontal speed of both legs; this platform
    # flies 4 m/s at most, MPC_XY_VEL_MAX)
    assert 1.0 < slow < 2.0 and 3.0 < fast < 4.0, (slow, fast)

    _land_disarmed(v, "RTL", home, 2.0)


def test_mission_basic(vehicle):
    """A mission through vehicle.commands (home kept at 0): cleared, a take-off and four
    waypoints and a dummy uploaded, flown in AUTO from GUIDED; commands.next advances and
    is moved on past the third waypoint; at the dummy, RTL to a disarmed landing."""
    v = vehicle
    home = v.location.global_frame
    cmds = v.commands
    cmds.download()
    cmds.wait_ready(timeout=60)
    cmds.clear()
    rel = MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT

    def cmd(command, loc=None, alt=0.0):
        lat, lon = (loc.lat, loc.lon) if loc is not None else (0, 0)
        return Command(0, 0, 0, rel, command, 0, 0, 0, 0, 0, 0, lat, lon, alt)

    square = [_offset(home, n, e, alt) for n, e, alt in
              ((25, -25, 11), (25, 25, 12), (-25, 25, 13), (-25, -25, 14))]
    cmds.add(cmd(MAV.MAV_CMD_NAV_TAKEOFF, alt=10))
    for p in square:
        cmds.add(cmd(MAV.MAV_CMD_NAV_WAYPOINT, p, p.alt))
    cmds.add(cmd(MAV.MAV_CMD_NAV_WAYPOINT, square[3], 14))  # the dummy: the end marker
    cmds.upload(timeout=60)
    cmds.download()
    cmds.wait_ready(timeout=60)
    assert cmds.count == 6 and cmds[0].command == MAV.MAV_CMD_NAV_TAKEOFF
    assert abs(cmds[2].x - square[1].lat) < 1e-5 and cmds[2].z == 12  # (float32 degrees)

    _arm_and_take_off(v, 10)
    cmds.next = 0  # (ArduPilot: home cannot be current, item 1 is)
    v.mode = VehicleMode("AUTO")
    until(lambda: v.mode.name == "AUTO", 30, "AUTO")
    seen, far = [], 0.0
    visited_third = False

    def progressed():
        nonlocal far, visited_third
        nxt = cmds.next
        if not seen or seen[-1] != nxt:
            seen.append(nxt)
        if nxt == 4:  # ArduPilot's numbering: 1 take-off, 2..5 the square, 6 the dummy
            cmds.next = 5  # skip the third waypoint
        if _near(v, square[2], 3.0):
            visited_third = True
        far = max(far, math.hypot(*_ne(v, home)))
        return nxt == 6

    until(progressed, 300, "commands.next reaching the dummy item")
    assert seen[0] in (1, 2) and 3 in seen and 5 in seen, seen
    assert seen == sorted(seen), seen  # it only ever moved on
    assert not visited_third and far > 30
    n, e = _ne(v, home)
    assert abs(n + 25) < 3 and abs(e + 25) < 3  # at the fourth waypoint
    _land_disarmed(v, "RTL", home, 2.0)


def _send_until(v, msg, done, timeout_s: float, describe: str) -> None:
    """Send ``msg`` every 0.1 s until ``done()`` (a velocity target must be repeated
    within GUID_TIMEOUT; the examples send theirs once a second at 1x)."""
    deadline = time.monotonic() + timeout_s
    while not done():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s:g} s waiting for {describe}")
        v.send_mavlink(msg)
        time.sleep(0.1)


def _heading_near(v, deg: float, within: float = 5.0) -> bool:
    return abs((v.heading - deg + 180) % 360 - 180) < within


def test_guided_set_speed_yaw(vehicle):
    """SET_POSITION_TARGET_GLOBAL_INT and _LOCAL_NED positions and velocities as DroneKit's
    guided_set_speed_yaw example sends them, CONDITION_YAW (absolute and relative),
    DO_CHANGE_SPEED, DO_SET_ROI; LAND to a disarmed landing."""
    v = vehicle
    home = v.location.global_frame
    f = v.message_factory
    _arm_and_take_off(v, 5)

    # a global position target (type_mask: positions only), at a changed speed
    v.groundspeed = 4
    p = _offset(home, 20, 0, 8)
    v.send_mavlink(f.set_position_target_global_int_encode(
        0, 0, 0, MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0b0000111111111000,
        int(p.lat * 1e7), int(p.lon * 1e7), p.alt, 0, 0, 0, 0, 0, 0, 0, 0))
    until(lambda: _near(v, p, 1.0), 120, "the global position target")
    # a local position target (LOCAL_NED: from the origin, down negative up)
    v.send_mavlink(f.set_position_target_local_ned_encode(
        0, 0, 0, MAV.MAV_FRAME_LOCAL_NED, 0b0000111111111000, 20, 20, -6,
        0, 0, 0, 0, 0, 0, 0, 0))
    q = _offset(home, 20, 20, 6)
    until(lambda: _near(v, q, 1.0), 120, "the local position target")

    # CONDITION_YAW, absolute then relative (clockwise), while holding there
    def condition_yaw(heading, relative):
        v.send_mavlink(f.command_long_encode(0, 0, MAV.MAV_CMD_CONDITION_YAW, 0, heading,
                                             0, 1, 1 if relative else 0, 0, 0, 0))
    condition_yaw(0, False)
    until(lambda: _heading_near(v, 0), 60, "heading 0 (north)")
    condition_yaw(90, False)
    until(lambda: _heading_near(v, 90), 60, "heading 90 (east)")
    condition_yaw(45, True)
    until(lambda: _heading_near(v, 135), 60, "heading 135 (90 + 45 relative)")

    # DO_SET_ROI: the nose turns to a point 30 m west of where it holds
    roi = _offset(q, 0, -30, 0)
    v.send_mavlink(f.command_long_encode(0, 0, MAV.MAV_CMD_DO_SET_ROI, 0, 0, 0, 0, 0,
                                         roi.lat, roi.lon, 0))
    until(lambda: _heading_near(v, 270), 60, "heading 270 (facing the ROI)")

    # velocities, local NED (velocities only), then global
    def ned_velocity(vn, ve, vd):
        return f.set_position_target_local_ned_encode(
            0, 0, 0, MAV.MAV_FRAME_LOCAL_NED, 0b0000111111000111, 0, 0, 0, vn, ve, vd,
            0, 0, 0, 0, 0)

    for (vn, ve), name in (((2, 0), "north"), ((0, -2), "west"), ((-2, 0), "south")):
        a = _ne(v, home)
        _send_until(v, ned_velocity(vn, ve, 0),
                    lambda a=a, vn=vn, ve=ve: (_ne(v, home)[0] - a[0]) * vn / 2 +
                    (_ne(v, home)[1] - a[1]) * ve / 2 > 8, 120, f"8 m {name}")
        b = _ne(v, home)
        across = (b[1] - a[1]) if vn else (b[0] - a[0])
        assert abs(across) < 2.0, (name, a, b)
    assert v.mode.name == "GUIDED"
    a = _ne(v, home)
    _send_until(v, f.set_position_target_global_int_encode(
        0, 0, 0, MAV.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, 0b0000111111000111, 0, 0, 0,
        0, 2, 0, 0, 0, 0, 0, 0), lambda: _ne(v, home)[1] - a[1] > 8, 120,
        "8 m east (global velocity)")
    v.mode = VehicleMode("LAND")
    until(lambda: not v.armed, 300, "disarmed after LAND")
    assert v.location.global_relative_frame.alt < 0.5
