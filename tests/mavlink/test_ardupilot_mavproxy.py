"""A MAVProxy session, unmodified (the MAVProxy installed beside ft-sitl, its commands fed
on stdin as a user types them), against the ArduCopter face over SERIAL0's TCP port:
`mode guided`, `arm throttle`, `takeoff 10`, `param set WPNAV_SPEED 800`, `wp load FILE`
(a QGC WPL 110 file, home at 0), `mode auto`, `rtl`. Each step is checked on the
vehicle's own state (mode, arming, altitude, parameters, mission, items reached,
position), not on what MAVProxy prints."""

import math

import pytest

from ft_sitl.mavlink.ardupilot import waypoints

from .ardupilot_harness import free_ardupilot_sitl, mavproxy_session

pytestmark = pytest.mark.e2e  # (tests/lanes.py: a MAVProxy process, TCP)


def test_mavproxy_session_flies_guided_a_waypoints_file_in_auto_and_rtl(tmp_path):
    with free_ardupilot_sitl(speed_factor=4.0) as (server, k):
        agent = server.agents[0]
        c = agent.cmd
        geo = agent.geo
        home = c.home.copy()

        def latlon(east, north):
            lat, lon, _ = geo.to_global((home[0] + east, home[1] + north, home[2]))
            return f"{lat:.8f}\t{lon:.8f}"

        wp_file = tmp_path / "square.waypoints"
        wp_file.write_text(
            "QGC WPL 110\n"
            f"0\t1\t0\t16\t0\t0\t0\t0\t{latlon(0, 0)}\t{geo.alt_m:.2f}\t1\n"
            f"1\t0\t3\t16\t0\t0\t0\t0\t{latlon(0, 20)}\t10\t1\n"
            f"2\t0\t3\t16\t0\t0\t0\t0\t{latlon(20, 20)}\t12\t1\n")
        with mavproxy_session(k, tmp_path) as mp:
            mp.take_off(agent, 10.0)
            assert agent.mode_name == "GUIDED"

            mp.type("param set WPNAV_SPEED 800")
            mp.until(lambda: server.fleet.params[0]["MPC_XY_CRUISE"] == 8.0, 30,
                     "WPNAV_SPEED 800 honoured")

            mp.type(f"wp load {wp_file}")
            mp.until(lambda: len(c.mission) == 2, 30, "the file's two items uploaded")
            p1 = c.mission[0].position
            assert abs(p1[1] - home[1] - 20) < 0.1 and abs(p1[2] - home[2] - 10) < 0.1

            saved = tmp_path / "saved.waypoints"
            mp.type(f"wp save {saved}")
            mp.until(lambda: saved.exists() and len(saved.read_text().splitlines()) == 4, 30,
                     "MAVProxy's download saved")
            back = waypoints.read(saved)
            assert [it.command for it in back] == [16, 16, 16]
            assert [it.current for it in back] == [0, 0, 0]  # (none runs before AUTO)
            lat, lon, _ = geo.to_global(home)
            assert abs(back[0].x - lat * 1e7) <= 1 and abs(back[0].y - lon * 1e7) <= 1
            assert back[2].z == 12

            mp.type("mode auto")
            mp.until(lambda: agent.mode_name == "AUTO", 30, "AUTO")
            mp.until(lambda: 1 in c.reached, 120, "the file's last waypoint reached")
            p = c.position_now()
            assert math.hypot(p[0] - home[0] - 20, p[1] - home[1] - 20) < 3.0

            mp.type("rtl")
            mp.until(lambda: agent.mode_name == "RTL", 30, "RTL")
            mp.until(lambda: not c.armed, 180, "landed at home and disarmed")
            p = c.position_now()
            assert math.hypot(p[0] - home[0], p[1] - home[1]) < 2.0
            assert p[2] - home[2] < 0.5

            # DO_FENCE_ENABLE: FENCE_ENABLE, written through to the geofence's limits
            mp.type("fence enable")
            ap = agent.vehicle.ap_params
            mp.until(lambda: ap["FENCE_ENABLE"] == 1, 30, "the fence enabled")
            assert server.fleet.params[0]["GF_MAX_HOR_DIST"] == ap["FENCE_RADIUS"] > 0
            mp.type("fence disable")
            mp.until(lambda: ap["FENCE_ENABLE"] == 0, 30, "the fence disabled")
            assert server.fleet.params[0]["GF_MAX_HOR_DIST"] == 0
