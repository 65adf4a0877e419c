"""ArduCopter's fence and rally points on the face.

A MAVProxy session, unmodified (as tests/mavlink/test_ardupilot_mavproxy.py runs it): with
the fence off MAVProxy reports the fence present (FENCE_TYPE's kinds) and no breach;
`fence load FILE` uploads an inclusion polygon and an exclusion circle over the mission
protocol's FENCE list, stored but not flown while FENCE_ENABLE is 0; `fence list` reads
them back; `fence enable` puts them in force; `rally load FILE` / `rally list` a rally point; a
GUIDED flight out of the polygon breaches it, FENCE_ACTION 1 returns the vehicle (to the
rally point, nearer than home) and MAVProxy says "fence breach".

Rally points uploaded with pymavlink (MAV_MISSION_TYPE_RALLY) and RTL's choice among them
and home by RALLY_INCL_HOME / RALLY_LIMIT_KM (AP_Rally's rule)."""

import math
import os

import numpy as np
import pytest

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from ft_sitl import frames  # noqa: E402
from ft_sitl.autopilot import commander as cm  # noqa: E402
from ft_sitl.autopilot.geofence import Fence, polygon  # noqa: E402
from ft_sitl.autopilot.params import ParamSet  # noqa: E402
from ft_sitl.mavlink.ardupilot.agent import ArduCopterVehicle  # noqa: E402
from ft_sitl.mavlink.ardupilot.params import ApParamSet  # noqa: E402
from ft_sitl.mavlink.ardupilot.rally import RallyRule  # noqa: E402
from ft_sitl.physics.catalog import get_platform  # noqa: E402
from ft_sitl.sim.fleet import Fleet  # noqa: E402

from .ardupilot_harness import (  # noqa: E402
    command_ack,
    free_ardupilot_sitl,
    mavproxy_session,
    serial0,
    wait_armed,
    wait_disarmed,
    wait_for,
)
from .sitl_harness import PLATFORM  # noqa: E402

_m = mavutil.mavlink


_wait, _ack = wait_for, command_ack  # (ardupilot_harness)


def test_rally_rule_is_ap_rallys():
    ap = ApParamSet(ParamSet(), sysid=1)
    rule = RallyRule(ap)
    home = np.zeros(3)
    near, far = np.array([0.0, 60.0, 5.0]), np.array([0.0, 500.0, 5.0])
    assert np.array_equal(rule([0, 50, 10], home, []), home)  # none: home
    assert np.array_equal(rule([0, 50, 10], home, [near, far]), near)  # nearest
    assert np.array_equal(rule([0, 20, 10], home, [near]), home)  # home nearer (INCL_HOME)
    ap.set("RALLY_INCL_HOME", 0)
    assert np.array_equal(rule([0, 20, 10], home, [near]), near)  # the rally point anyway
    assert np.array_equal(rule([0, 450, 10], home, [far]), far)  # 50 m: within 0.3 km
    assert np.array_equal(rule([0, -350, 10], home, [far]), home)  # 850 m: past the limit
    ap.set("RALLY_LIMIT_KM", 0)
    assert np.array_equal(rule([0, -350, 10], home, [far]), far)  # no limit


def _bits(v):
    g = _m.MAV_SYS_STATUS_GEOFENCE
    p, e, h = v.fence.sys_status_bits(0, 0, 0)
    return bool(p & g), bool(e & g), bool(h & g)


def test_fence_kinds_gate_the_uploaded_areas_and_set_ac_fences_sys_status_bits():
    fleet = Fleet([get_platform(PLATFORM)])
    v = ArduCopterVehicle(fleet, 0, frames.GeoReference(*frames.PX4_SITL_HOME))
    ap, c = v.ap_params, v.cmd
    assert _bits(v) == (True, False, True)  # FENCE_TYPE 7: altitude, circle; off; healthy
    assert v.fence.status() is None  # FENCE_ENABLE 0: no FENCE_STATUS (send_fence_status)
    ap.set("FENCE_ENABLE", 1)
    assert v.fence.status() is not None
    ap.set("FENCE_ENABLE", 0)
    ap.set("FENCE_TYPE", 4)
    assert _bits(v) == (False, False, True)  # polygons, none uploaded: absent, healthy
    area = Fence([polygon([(-30, -30), (30, -30), (30, 30), (-30, 30)], True, "test")])
    v.fence.upload(area)
    assert _bits(v) == (True, False, True) and c.fence.empty  # stored, not flown
    ap.set("FENCE_ENABLE", 1)
    assert _bits(v) == (True, True, True) and c.fence is area  # in force
    assert fleet.params[0]["GF_MAX_HOR_DIST"] == 0  # (no circle kind)
    ap.set("FENCE_ACTION", 0)
    assert _bits(v) == (True, False, True)  # report only: not "enabled"
    c.failsafes.fence_breached = True
    assert _bits(v) == (True, False, False)  # breached: unhealthy
    st = v.fence.status()
    assert st.breach_status == 1
    ap.set("FENCE_TYPE", 2)
    assert c.fence.empty and fleet.params[0]["GF_MAX_HOR_DIST"] == ap["FENCE_RADIUS"]
    ap.set("FENCE_TYPE", 0)
    assert _bits(v)[0] is False and _bits(v)[2] is True and v.fence.status() is None


@pytest.mark.e2e  # (tests/lanes.py: a MAVProxy process, TCP)
def test_mavproxy_fence_load_list_enable_and_a_breach_returns(tmp_path):
    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        agent = server.agents[0]
        v, c, geo = agent.vehicle, agent.cmd, agent.geo
        home = c.home.copy()

        def latlon(east, north):
            lat, lon, _ = geo.to_global((home[0] + east, home[1] + north, home[2]))
            return f"{lat:.8f}\t{lon:.8f}"

        square = [(-30, -30), (30, -30), (30, 30), (-30, 30)]
        fence_file = tmp_path / "fence.waypoints"
        fence_file.write_text("QGC WPL 110\n" + "".join(
            f"{i}\t0\t0\t5001\t4\t0\t0\t0\t{latlon(e, n)}\t0\t1\n"
            for i, (e, n) in enumerate(square))
            + f"4\t0\t0\t5004\t5\t0\t0\t0\t{latlon(15, 0)}\t0\t1\n")
        with mavproxy_session(k, tmp_path) as mp:
            # FENCE_TYPE 7 configures the altitude and circle kinds: present, not enabled,
            # healthy (MAVProxy printed "fence breach" when the health bit was missing)
            mp.until(lambda: "fence present" in mp.output(), 30, "fence present")
            assert "fence breach" not in mp.output()

            mp.type(f"fence load {fence_file}")
            mp.until(lambda: len(v.fence.uploaded.areas) == 2, 30, "the fence uploaded")
            assert c.fence.empty  # FENCE_ENABLE 0: stored, not flown
            mp.type("fence list")
            mp.until(lambda: mp.output().count("\n5001 ") == 4, 30, "fence list")
            assert mp.output().count("\n5004 0 ") == 1

            # a rally point 20 m north, loaded and listed with MAVProxy's rally module
            rally_file = tmp_path / "rally.waypoints"
            rally_file.write_text("QGC WPL 110\n"
                                  f"0\t0\t3\t5100\t0\t0\t0\t0\t{latlon(0, 20)}\t15\t1\n")
            mp.type(f"rally load {rally_file}")
            mp.until(lambda: len(c.rally) == 1, 30, "the rally point uploaded")
            assert abs(c.rally[0][1] - home[1] - 20) < 0.1
            mp.type("rally list")
            mp.until(lambda: "\n5100 3 " in mp.output(), 30, "rally list")

            mp.type("fence enable")
            mp.until(lambda: c.fence is v.fence.uploaded, 30, "the fence in force")
            mp.until(lambda: "fence enabled" in mp.output(), 30, "fence enabled")

            mp.take_off(agent, 10.0)
            assert not c.fence_events
            lat, lon = latlon(0, 45).split("\t")
            mp.type(f"guided {lat} {lon} 10")
            mp.until(lambda: c.fence_events, 60, "the breach")
            assert c.fence_events[0][1:] == ("outside the fence", "return")
            assert (c.main_mode, c.sub_mode) == (cm.MAIN_AUTO, cm.SUB_RTL)
            # RTL returns to the rally point, nearer than home (RALLY_INCL_HOME 1)
            assert math.hypot(*(c.auto.rtl_dest[:2] - c.rally[0][:2])) < 1e-6
            mp.until(lambda: "fence breach" in mp.output(), 30, "MAVProxy's breach")
            st = agent.telemetry.build(_m.MAVLINK_MSG_ID_FENCE_STATUS)
            assert st.breach_count == 1 and st.breach_type == _m.FENCE_BREACH_BOUNDARY
            p = c.position_now()
            assert 30 < p[1] - home[1] < 45  # (turned back where it crossed)


def _upload_rally(conn, points) -> int:
    """The mission protocol's RALLY upload as a ground station drives it."""
    conn.mav.mission_count_send(conn.target_system, conn.target_component, len(points),
                                _m.MAV_MISSION_TYPE_RALLY)
    while True:
        m = _wait(conn, lambda m: getattr(m, "mission_type", 0) == _m.MAV_MISSION_TYPE_RALLY,
                  10.0, type=["MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"])
        if m.get_type() == "MISSION_ACK":
            return m.type
        lat, lon, alt = points[m.seq]
        conn.mav.mission_item_int_send(
            conn.target_system, conn.target_component, m.seq,
            _m.MAV_FRAME_GLOBAL_RELATIVE_ALT, _m.MAV_CMD_NAV_RALLY_POINT, 0, 1, 0, 0, 0, 0,
            int(round(lat * 1e7)), int(round(lon * 1e7)), alt, _m.MAV_MISSION_TYPE_RALLY)


@pytest.mark.e2e  # (tests/lanes.py: TCP)
def test_rtl_returns_to_the_rally_point_or_home_as_rally_params_say():
    mavutil.set_dialect("ardupilotmega")
    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        agent = server.agents[0]
        c, geo = agent.cmd, agent.geo
        home = c.home.copy()
        with serial0(k) as conn:
            rally = geo.to_global((home[0], home[1] + 50.0, home[2]))
            assert _upload_rally(conn, [(rally[0], rally[1], 15.0)]) == \
                _m.MAV_MISSION_ACCEPTED
            assert len(c.rally) == 1

            conn.set_mode("GUIDED")
            _wait(conn, lambda m: m.custom_mode == 4, 10.0, type="HEARTBEAT")
            conn.arducopter_arm()
            wait_armed(conn)
            conn.mav.command_long_send(conn.target_system, conn.target_component,
                                       _m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 0, 10)
            assert _ack(conn, 22).result == _m.MAV_RESULT_ACCEPTED
            conn.mav.request_data_stream_send(conn.target_system, conn.target_component,
                                              _m.MAV_DATA_STREAM_POSITION, 10, 1)
            _wait(conn, lambda m: m.relative_alt > 9500, 60.0, type="GLOBAL_POSITION_INT")
            conn.mav.set_position_target_local_ned_send(
                0, conn.target_system, conn.target_component, _m.MAV_FRAME_LOCAL_NED, 3576,
                35.0, 0.0, -10.0, 0, 0, 0, 0, 0, 0, 0, 0)
            _wait(conn, lambda m: abs(m.x - 35) < 1.0 and abs(m.z + 10) < 1.0, 60.0,
                  type="LOCAL_POSITION_NED")

            def rtl_dest():
                conn.set_mode("RTL")
                _wait(conn, lambda m: m.custom_mode == 6, 10.0, type="HEARTBEAT")
                dest = c.auto.rtl_dest.copy()
                conn.set_mode("GUIDED")
                _wait(conn, lambda m: m.custom_mode == 4, 10.0, type="HEARTBEAT")
                return dest

            # 35 m north: the rally point (15 m away) is nearer than home (35 m)
            dest = rtl_dest()
            assert math.hypot(dest[0] - home[0], dest[1] - home[1] - 50.0) < 0.1
            # RALLY_LIMIT_KM 0.01: the rally point is beyond 10 m, home it is
            conn.param_set_send("RALLY_LIMIT_KM", 0.01)
            _wait(conn, lambda m: m.param_id == "RALLY_LIMIT_KM", 10.0, type="PARAM_VALUE")
            dest = rtl_dest()
            assert math.hypot(dest[0] - home[0], dest[1] - home[1]) < 0.1
            conn.set_mode("LAND")
            wait_disarmed(conn)
