"""ArduCopter's modes and safety on the face, flown by a real pymavlink client over
SERIAL0's TCP port as the ground station SYSID_MYGCS (255): RC overrides in ALT_HOLD and
LOITER (and their timeout), RTL with RTL_ALT, RTL_SPEED, RTL_LOIT_TIME and RTL_ALT_FINAL,
BRAKE and LAND_SPEED, ArduCopter's arming checks and their texts, the GCS and battery
failsafes. Every wait has a generous liveness deadline; nothing asserts a duration."""

import math
import os
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from ft_sitl import frames  # noqa: E402
from ft_sitl.autopilot import commander as cm  # noqa: E402
from ft_sitl.autopilot.commander import Result  # noqa: E402
from ft_sitl.mavlink.ardupilot import modes, prearm  # noqa: E402
from ft_sitl.mavlink.ardupilot.agent import ArduCopterVehicle  # noqa: E402
from ft_sitl.mavlink.ardupilot.server import tcp_ports  # noqa: E402
from ft_sitl.physics.catalog import get_platform  # noqa: E402
from ft_sitl.sim.fleet import Fleet  # noqa: E402

from .ardupilot_harness import free_ardupilot_sitl  # noqa: E402
from .sitl_harness import PLATFORM  # noqa: E402

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

GCS = 255  # ArduCopter's SYSID_MYGCS
ARMED = mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED


class Gcs:
    """A pymavlink ground station: what it sends while it waits (its heartbeat, the RC
    overrides it holds) goes out at 10 Hz of wall time."""

    def __init__(self, port: int):
        mavutil.set_dialect("ardupilotmega")
        self.conn = mavutil.mavlink_connection(f"tcp:127.0.0.1:{port}", source_system=GCS)
        self.rc: list[int] | None = None
        self.heartbeat = True
        self._sent = 0.0

    def pump(self, now_please: bool = False) -> None:
        now = time.time()
        if now - self._sent < 0.1 and not now_please:
            return
        self._sent = now
        c = self.conn
        if self.heartbeat:
            c.mav.heartbeat_send(mavutil.mavlink.MAV_TYPE_GCS,
                                 mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        if self.rc is not None:
            c.mav.rc_channels_override_send(c.target_system, c.target_component, *self.rc)

    def wait(self, what, timeout_s=90.0, **match):
        deadline = time.time() + timeout_s
        while time.time() < deadline:
            self.pump()
            m = self.conn.recv_match(blocking=True, timeout=0.1, **match)
            if m is not None and what(m):
                return m
        raise AssertionError(f"timed out waiting for {match}")

    def samples(self, n: int, **match) -> list:
        """The next n messages of a kind."""
        return [self.wait(lambda m: True, 30.0, **match) for _ in range(n)]

    def ack(self, command: int) -> int:
        return self.wait(lambda m: m.command == command, 15.0, type="COMMAND_ACK").result

    def text(self, start: str, timeout_s=60.0):
        return self.wait(lambda m: m.text.startswith(start), timeout_s, type="STATUSTEXT")

    def mode(self, name: str) -> None:
        number = self.conn.mode_mapping()[name]
        self.conn.set_mode(number)
        self.wait(lambda m: m.custom_mode == number, 15.0, type="HEARTBEAT")

    def param(self, name: str, value: float) -> None:
        self.conn.param_set_send(name, value)
        m = self.wait(lambda m: m.param_id == name, 15.0, type="PARAM_VALUE")
        assert m.param_value == pytest.approx(value), (name, m.param_value)

    def arm(self, force: bool = False) -> int:
        c = self.conn
        c.mav.command_long_send(c.target_system, c.target_component,
                                mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1,
                                2989 if force else 0, 0, 0, 0, 0, 0)
        return self.ack(mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM)

    def armed(self, yes: bool = True, timeout_s=90.0) -> None:
        self.wait(lambda m: bool(m.base_mode & ARMED) == yes, timeout_s, type="HEARTBEAT")

    def takeoff(self, alt_m: float) -> None:
        self.mode("GUIDED")
        assert self.arm() == mavutil.mavlink.MAV_RESULT_ACCEPTED
        self.armed()
        c = self.conn
        c.mav.command_long_send(c.target_system, c.target_component,
                                mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0,
                                alt_m)
        assert self.ack(mavutil.mavlink.MAV_CMD_NAV_TAKEOFF) == \
            mavutil.mavlink.MAV_RESULT_ACCEPTED
        self.wait(lambda m: m.relative_alt > (alt_m - 0.5) * 1000, 90.0,
                  type="GLOBAL_POSITION_INT")

    def goto(self, north: float, east: float, up: float) -> None:
        """A GUIDED destination in LOCAL_NED (ArduPilot's position-only mask)."""
        c = self.conn
        c.mav.set_position_target_local_ned_send(
            0, c.target_system, c.target_component, mavutil.mavlink.MAV_FRAME_LOCAL_NED,
            3576, north, east, -up, 0, 0, 0, 0, 0, 0, 0, 0)

    def close(self) -> None:
        self.conn.close()


def _session(test):
    """Run ``test(gcs, server)`` against a fresh face at speed factor 4."""
    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        gcs = Gcs(tcp_ports(k)[0])
        try:
            gcs.conn.wait_heartbeat(timeout=30)
            gcs.conn.mav.request_data_stream_send(
                gcs.conn.target_system, gcs.conn.target_component,
                mavutil.mavlink.MAV_DATA_STREAM_ALL, 10, 1)
            gcs.wait(lambda m: True, 15.0, type="GLOBAL_POSITION_INT")
            test(gcs, server)
        finally:
            gcs.close()


def test_boots_in_stabilize_and_takes_any_mode_while_disarmed():
    """ArduCopter boots in STABILIZE; disarmed, Copter::set_mode takes every mode, AUTO
    without a mission too (a hold until there is one); armed, AUTO needs a mission; an
    unknown mode and an unarmable one are named in the texts (the parity run's wording)."""
    fleet = Fleet([get_platform(PLATFORM)])
    v = ArduCopterVehicle(fleet, 0, frames.GeoReference(*frames.PX4_SITL_HOME))
    c, m = v.cmd, v.modes
    assert m.number == modes.STABILIZE and (c.main_mode, c.sub_mode) == (cm.MAIN_STABILIZED, 0)
    assert m.set(99) == Result.FAILED and c.statustexts[-1][1] == "No such mode 99"
    assert m.number == modes.STABILIZE
    assert not c.mission
    assert m.set(modes.AUTO) == Result.ACCEPTED and m.number == modes.AUTO
    assert (c.main_mode, c.sub_mode) == (cm.MAIN_AUTO, cm.SUB_LOITER)
    assert prearm.arm_failure(v) == "Arm: AUTO mode not armable"
    assert m.set(modes.LAND) == Result.ACCEPTED
    assert prearm.arm_failure(v) == "Arm: LAND mode not armable"
    assert m.set(modes.GUIDED) == Result.ACCEPTED and c.arm() == Result.ACCEPTED
    assert m.set(modes.AUTO) == Result.FAILED and m.number == modes.GUIDED


def _horizontal(m0, m1) -> float:
    return math.hypot(m1.x - m0.x, m1.y - m0.y)


def test_rc_overrides_fly_alt_hold_and_loiter_and_time_out():
    def flight(gcs: Gcs, server):
        gcs.param("RC_OVERRIDE_TIME", 30)  # (a loaded machine must not time them out)
        gcs.takeoff(10)
        gcs.rc = [1500, 1500, 1500, 1500, 65535, 65535, 65535, 65535]
        gcs.mode("ALT_HOLD")
        # throttle high climbs ...
        gcs.rc[2] = 1800
        gcs.wait(lambda m: m.relative_alt > 16000, type="GLOBAL_POSITION_INT")
        # ... and mid stick holds the altitude it settles at
        gcs.rc[2] = 1500
        gcs.wait(lambda m: abs(m.vz) < 20, type="GLOBAL_POSITION_INT")
        held = [m.relative_alt for m in gcs.samples(30, type="GLOBAL_POSITION_INT")]
        assert max(held) - min(held) < 1000, held
        assert min(held) > 15000

        # LOITER: the pitch stick forward (below trim) flies the way the nose points
        gcs.mode("LOITER")
        start = gcs.wait(lambda m: True, type="LOCAL_POSITION_NED")
        yaw = gcs.wait(lambda m: True, type="ATTITUDE").yaw
        gcs.rc[1] = 1300
        moved = gcs.wait(lambda m: _horizontal(start, m) > 12.0, type="LOCAL_POSITION_NED")
        along = (moved.x - start.x) * math.cos(yaw) + (moved.y - start.y) * math.sin(yaw)
        assert along > 10.0, (along, yaw)
        assert abs(moved.z - start.z) < 2.0
        # pitch released (0: back to the radio, centred), the others left as they are
        # (UINT16_MAX: ignored, the throttle's override stands): it stops and holds
        gcs.rc = [65535, 0, 65535, 65535, 65535, 65535, 65535, 65535]
        gcs.wait(lambda m: math.hypot(m.vx, m.vy) < 0.2, type="LOCAL_POSITION_NED")
        assert gcs.conn.messages["HEARTBEAT"].custom_mode == 5

        # the overrides stop: after RC_OVERRIDE_TIME the throttle is the radio's (low)
        # and LOITER descends, as on ArduPilot SITL
        gcs.param("RC_OVERRIDE_TIME", 1)
        alt = gcs.wait(lambda m: True, type="GLOBAL_POSITION_INT").relative_alt
        gcs.rc = None
        gcs.wait(lambda m: m.relative_alt < alt - 3000, type="GLOBAL_POSITION_INT")
        assert gcs.conn.messages["HEARTBEAT"].custom_mode == 5
    _session(flight)


def test_rtl_climbs_to_rtl_alt_returns_loiters_then_holds_at_alt_final_or_lands():
    def flight(gcs: Gcs, server):
        for name, value in (("RTL_ALT", 2500), ("RTL_SPEED", 600), ("RTL_LOIT_TIME", 2000),
                            ("RTL_ALT_FINAL", 600)):
            gcs.param(name, value)
        assert server.fleet.params[0]["RTL_RETURN_ALT"] == 25.0
        gcs.takeoff(10)
        gcs.goto(30, 0, 10)
        gcs.wait(lambda m: m.x > 29.0 and abs(m.vx) < 0.3, type="LOCAL_POSITION_NED")
        gcs.mode("RTL")
        # the climb to RTL_ALT comes before the return
        top = gcs.wait(lambda m: m.z < -24.0, type="LOCAL_POSITION_NED")
        assert top.x > 27.0, top
        # back over home at RTL_ALT, then down to RTL_ALT_FINAL, where it holds in RTL
        over = gcs.wait(lambda m: math.hypot(m.x, m.y) < 1.0, type="LOCAL_POSITION_NED")
        assert over.z < -23.0
        gcs.wait(lambda m: abs(m.z + 6.0) < 0.3 and abs(m.vz) < 0.1, type="LOCAL_POSITION_NED")
        hb = gcs.wait(lambda m: True, type="HEARTBEAT")
        assert hb.custom_mode == 6 and hb.base_mode & ARMED
        assert max(abs(m.z + 6.0) for m in gcs.samples(20, type="LOCAL_POSITION_NED")) < 0.5

        # RTL_ALT_FINAL 0: the same return ends in a landing at home and disarms
        gcs.param("RTL_ALT_FINAL", 0)
        gcs.mode("GUIDED")
        gcs.goto(0, 20, 10)
        gcs.wait(lambda m: m.y > 19.0 and abs(m.vy) < 0.3, type="LOCAL_POSITION_NED")
        gcs.mode("RTL")
        gcs.wait(lambda m: m.z < -24.0, type="LOCAL_POSITION_NED")
        gcs.armed(False, 180.0)
        end = gcs.wait(lambda m: True, type="LOCAL_POSITION_NED")
        assert math.hypot(end.x, end.y) < 1.0 and end.z > -0.5
        assert gcs.conn.messages["HEARTBEAT"].custom_mode == 6
    _session(flight)


def test_brake_stops_and_holds_and_land_descends_at_land_speed():
    def flight(gcs: Gcs, server):
        gcs.param("LAND_SPEED", 100)
        assert server.fleet.params[0]["MPC_LAND_SPEED"] == 1.0
        gcs.takeoff(10)
        gcs.goto(80, 0, 10)
        gcs.wait(lambda m: m.vx > 3.0 and m.x > 15.0, type="LOCAL_POSITION_NED")
        gcs.mode("BRAKE")
        stop = gcs.wait(lambda m: math.hypot(m.vx, m.vy) < 0.1, type="LOCAL_POSITION_NED")
        assert stop.x < 40.0  # it did not fly on to the destination
        gcs.samples(20, type="LOCAL_POSITION_NED")  # (settling on the stopping point)
        held = gcs.samples(30, type="LOCAL_POSITION_NED")
        assert max(_horizontal(stop, m) for m in held) < 2.0
        assert max(_horizontal(held[0], m) for m in held) < 1.0
        assert gcs.conn.messages["HEARTBEAT"].custom_mode == 17

        gcs.mode("LAND")
        descent = [m.vz for m in gcs.samples(200, type="LOCAL_POSITION_NED")
                   if -6.0 < m.z < -2.0]
        assert descent, "no samples in the last metres"
        descent.sort()
        assert descent[len(descent) // 2] == pytest.approx(1.0, abs=0.2)
        gcs.armed(False)
    _session(flight)


def test_arming_checks_answer_arducopter_texts_and_force_arm_bypasses():
    def flight(gcs: Gcs, server):
        failed, ok = (mavutil.mavlink.MAV_RESULT_FAILED,
                      mavutil.mavlink.MAV_RESULT_ACCEPTED)
        gcs.mode("RTL")
        assert gcs.arm() == failed
        gcs.text("Arm: RTL mode not armable")

        # no GPS (SITL's SIM_GPS_DISABLE): a mode that needs a position is refused
        gcs.mode("GUIDED")
        gcs.param("SIM_GPS_DISABLE", 1)
        assert gcs.arm() == failed
        gcs.text("PreArm: Need Position Estimate")
        gcs.param("SIM_GPS_DISABLE", 0)

        # throttle up in a manual-throttle mode
        gcs.mode("STABILIZE")
        gcs.rc = [1500, 1500, 1600, 1500, 65535, 65535, 65535, 65535]
        gcs.pump(now_please=True)
        assert gcs.arm() == failed
        gcs.text("Arm: Throttle too high")
        gcs.rc[2] = 1100
        gcs.pump(now_please=True)
        assert gcs.arm() == ok
        gcs.armed()
        gcs.conn.arducopter_disarm()
        gcs.armed(False)
        gcs.rc = None

        # the battery below BATT_LOW_VOLT; ARMING_CHECK without the battery bit passes it
        gcs.mode("GUIDED")
        gcs.param("BATT_LOW_VOLT", 90.0)
        assert gcs.arm() == failed
        gcs.text("PreArm: Battery 1 low voltage failsafe")
        gcs.param("ARMING_CHECK", 64)
        assert gcs.arm() == ok
        gcs.armed()
        gcs.conn.arducopter_disarm()
        gcs.armed(False)
        gcs.param("ARMING_CHECK", 1)
        gcs.param("BATT_LOW_VOLT", 10.5)

        # outside an enabled fence (the circle around home): refused, forced arming is not
        here = gcs.wait(lambda m: True, type="GLOBAL_POSITION_INT")
        c = gcs.conn
        c.mav.command_long_send(  # home 60 m east of the vehicle
            c.target_system, c.target_component, mavutil.mavlink.MAV_CMD_DO_SET_HOME, 0, 0,
            0, 0, 0, here.lat * 1e-7,
            here.lon * 1e-7 + 60.0 / (111320.0 * math.cos(math.radians(here.lat * 1e-7))),
            here.alt * 1e-3)
        assert gcs.ack(mavutil.mavlink.MAV_CMD_DO_SET_HOME) == ok
        gcs.param("FENCE_RADIUS", 30.0)
        gcs.param("FENCE_TYPE", 2)
        gcs.param("FENCE_ENABLE", 1)
        assert gcs.arm() == failed
        gcs.text("PreArm: vehicle outside fence")
        assert gcs.arm(force=True) == ok
        gcs.armed()
    _session(flight)


def test_gcs_failsafe_lands_and_clears_and_battery_failsafe_returns_then_lands():
    def flight(gcs: Gcs, server):
        gcs.takeoff(8)
        gcs.param("FS_GCS_TIMEOUT", 5)  # (ArduCopter's default: a stalled client is not silence)
        gcs.param("FS_GCS_ENABLE", 5)  # land
        gcs.heartbeat = False  # the ground station falls silent
        gcs.text("GCS Failsafe", 60.0)
        gcs.wait(lambda m: m.custom_mode == 9, 30.0, type="HEARTBEAT")
        gcs.armed(False)
        # disarmed and still silent: arming is refused while the failsafe is on
        gcs.mode("GUIDED")
        assert gcs.arm() == mavutil.mavlink.MAV_RESULT_FAILED
        gcs.text("PreArm: GCS failsafe on")
        gcs.heartbeat = True
        gcs.text("GCS Failsafe Cleared")
        gcs.param("FS_GCS_ENABLE", 0)

        # battery: low voltage for BATT_LOW_TIMER returns, critical capacity lands
        gcs.takeoff(8)
        gcs.goto(15, 0, 8)
        gcs.wait(lambda m: m.x > 14.0, type="LOCAL_POSITION_NED")
        for name, value in (("BATT_LOW_TIMER", 1), ("BATT_FS_LOW_ACT", 2),
                            ("BATT_FS_CRT_ACT", 1), ("BATT_LOW_VOLT", 90.0)):
            gcs.param(name, value)
        low = gcs.text("Battery 1 is low ")
        assert "V used " in low.text and low.text.endswith(" mAh")
        gcs.text("Battery Failsafe")
        gcs.wait(lambda m: m.custom_mode == 6, 30.0, type="HEARTBEAT")
        gcs.param("BATT_CRT_MAH", 3300)
        gcs.text("Battery 1 is critical ")
        gcs.wait(lambda m: m.custom_mode == 9, 30.0, type="HEARTBEAT")
        gcs.armed(False)
    _session(flight)
