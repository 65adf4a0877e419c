"""Moving obstacles on the wire: one ADSB_VEHICLE per mover (PX4 forwards its traffic
receiver's reports so), streamed on both links and recorded in the telemetry log."""

import time

import numpy as np
import pytest
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.mavlink.agent import VehicleAgent
from ft_sitl.mavlink.traffic import TRAFFIC_HZ
from ft_sitl.physics.catalog import get_platform
from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.io import load_scenario
from ft_sitl.sim.fleet import Fleet

from .sitl_harness import PLATFORM, running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

INSTANCE = 66  # (ports of its own)
GEO = frames.GeoReference(*frames.PX4_SITL_HOME)


def _walkers(tmp_path):
    """A 30 x 30 m yard (one box far off) with a person walking east along y = 9 from
    x = 10 at 1 m/s and a cart going round a loop."""
    import trimesh

    trimesh.creation.box(bounds=[[26, 26, 0], [28, 28, 3]]).export(tmp_path / "yard.ply")
    spec = tmp_path / "yard.yaml"
    spec.write_text(
        "name: yard\nmesh: yard.ply\nstart: [15.0, 5.0, 1.5]\ngoal: [15.0, 25.0, 1.5]\n"
        "bounds_min: [0, 0, 0]\nbounds_max: [30, 30, 5]\nmovers:\n"
        "  - {shape: person, radius_m: 0.4, height_m: 1.8, points: [[10, 9], [20, 9]],"
        " speed_m_s: 1.0}\n"
        "  - {shape: box, length_m: 2, width_m: 1, height_m: 1.5, loop: true,"
        " points: [[3, 20], [8, 20], [8, 25]], speed_m_s: 2.0}\n")
    return load_scenario(spec)


def test_tlog_holds_every_movers_state_as_adsb_vehicle(tmp_path):
    sc = _walkers(tmp_path)
    log = tmp_path / "flight.tlog"
    with running_sitl(speed_factor=4.0, scenario=sc, base_instance=INSTANCE,
                      tlog=log) as server:
        t0 = server.fleet.time_us
        deadline = time.monotonic() + 60
        while server.fleet.time_us < t0 + 4_000_000 and time.monotonic() < deadline:
            time.sleep(0.05)
        t1 = server.fleet.time_us
    assert t1 >= t0 + 4_000_000, "the server did not simulate 4 s"
    r = mavutil.mavlink_connection(str(log))
    t_ms = None  # the simulated time of the latest message that carries it
    person, box = [], []
    while True:
        m = r.recv_match()
        if m is None:
            break
        if hasattr(m, "time_boot_ms"):
            t_ms = m.time_boot_ms
        if m.get_type() == "ADSB_VEHICLE" and t_ms is not None:
            (person if m.ICAO_address == 0xFE0001 else box).append((t_ms, m))
    span_s = (t1 - t0) * 1e-6
    # 2 Hz on each of the two links, each sent packet logged once
    for got in (person, box):
        assert abs(len(got) - 2 * TRAFFIC_HZ * span_s) <= 4 * TRAFFIC_HZ, len(got)
    for t, m in person:
        assert (m.callsign, m.emitter_type) == ("PERSON1", mav.ADSB_EMITTER_TYPE_POINT_OBSTACLE)
        assert m.flags & mav.ADSB_FLAGS_SIMULATED and m.flags & mav.ADSB_FLAGS_VALID_COORDS
        assert m.altitude_type == mav.ADSB_ALTITUDE_TYPE_GEOMETRIC
        p = GEO.to_local(m.lat * 1e-7, m.lon * 1e-7, m.altitude * 1e-3)
        # walking east from (10, 9) at 1 m/s since t = 0; its centre at half its height
        # (the time is that of a message up to 10 ms earlier; degE7 is ~1 cm)
        np.testing.assert_allclose(p, [10.0 + t * 1e-3, 9.0, 0.9], atol=0.04)
        # east at 1 m/s (still at simulation time 0, the field's start)
        assert (m.heading, m.hor_velocity, m.ver_velocity) == (9000, 100 if t else 0, 0)
    for t, m in box:
        assert (m.callsign, m.emitter_type) == ("BOX1", mav.ADSB_EMITTER_TYPE_SERVICE_SURFACE)
        assert m.hor_velocity == (200 if t else 0)
        p = GEO.to_local(m.lat * 1e-7, m.lon * 1e-7, m.altitude * 1e-3)
        on_loop = (abs(p[1] - 20.0) < 0.02 and 3.0 - 0.02 <= p[0] <= 8.02) or \
            (abs(p[0] - 8.0) < 0.02 and 19.98 <= p[1] <= 25.02) or \
            abs(np.cross([5.0, 5.0], [p[0] - 3.0, p[1] - 20.0])) / np.hypot(5, 5) < 0.02
        assert on_loop, p
    assert len({m.heading for _, m in box}) >= 2  # it turns at the loop's corners


def test_no_traffic_without_movers():
    p = get_platform(PLATFORM)
    sc = build_scenario("forest", 1)
    for fleet in (Fleet([p]), Fleet([p], spawn=[sc.takeoff], scenario=sc)):
        agent = VehicleAgent(fleet, 0, GEO, 2, ["onboard", "normal"])
        assert agent.traffic() == []
        assert not [o for o in agent.due_telemetry(0) + agent.due_telemetry(1)
                    if o.msg.get_type() == "ADSB_VEHICLE"]
