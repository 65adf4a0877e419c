"""MAVSDK's follow_me example against the SITL: set_config, start, set_target_location in
a loop, stop. The vehicle enters AUTO.FOLLOW_TARGET (MAVSDK's FOLLOW_ME), keeps the
configured distance and height from the target (behind it: FLW_TGT_FA 180 of a target
whose course is still north), faces it, and stop() leaves it holding. Bad FOLLOW_TARGET
fixes are ignored."""

import asyncio
import math

import numpy as np
import pytest
from mavsdk.asyncio.plugins.action import ActionAsync
from mavsdk.asyncio.plugins.follow_me import FollowMeAsync
from mavsdk.asyncio.plugins.telemetry import TelemetryAsync
from mavsdk.plugins.follow_me import Config, TargetLocation
from mavsdk.plugins.telemetry import FlightMode
from pymavlink import mavutil
from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.mavlink.agent import VehicleAgent
from ft_sitl.physics.catalog import catalog
from ft_sitl.sim.fleet import Fleet

from .mavsdk_util import connect, first
from .sitl_harness import running_sitl

pytestmark = pytest.mark.e2e  # (tests/lanes.py)

INSTANCE = 50  # ports 14590 (MAVSDK) and 14630 (the vehicle's API link)
LAT0, LON0 = 47.397742, 8.545594
M_PER_DEG_LAT = 111195.0


BAD = [  # (lat, lon degE7, alt AMSL, vel NED): what a vehicle must not use as it is
    (0, 0, 488.0, [0.0] * 3),  # no position
    (2_000_000_000, int(LON0 * 1e7), 488.0, [0.0] * 3),  # 200 deg
    (None, None, math.nan, [math.nan] * 3),  # NaN altitude and velocity: position only
    (None, None, 1e12, [1e9, 0.0, 0.0]),  # absurd altitude and velocity: position only
    (None, None, -math.inf, [math.inf] * 3),
]


def follow_target(lat, lon, alt, vel, cap=3):
    nan3 = [math.nan] * 3
    return mav.MAVLink_follow_target_message(0, cap, lat, lon, alt, vel, nan3,
                                             [1.0, 0.0, 0.0, 0.0], nan3, nan3, 0)


def bad_fixes(port, lat, lon):
    """The BAD fixes, the partly usable ones at (lat, lon) degE7."""
    c = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=245,
                                   source_component=190)
    for la, lo, alt, vel in BAD:
        c.mav.send(follow_target(lat if la is None else la, lon if lo is None else lo, alt,
                                 vel))
    c.close()


def test_bad_follow_target_fixes_are_ignored_or_used_in_part():
    f = Fleet(catalog()["0.98kg-EGO Planner DIY"])
    agent = VehicleAgent(f, 0, frames.GeoReference(*frames.PX4_SITL_HOME), 2,
                         ["onboard", "normal"])
    calls = []
    agent.cmd.follow_target_measurement = lambda t, p, v: calls.append((p, v))
    lat, lon = int(LAT0 * 1e7) + 900, int(LON0 * 1e7)  # 10 m north of home
    for la, lo, alt, vel in BAD:
        m = follow_target(lat if la is None else la, lon if lo is None else lo, alt, vel)
        assert agent.handle(m, 0, None, 0) == []
    assert len(calls) == 3  # the two without a position are dropped
    for p, v in calls:  # the others: the position, no altitude, no velocity
        assert p[:2] == pytest.approx([0.0, 10.0], abs=0.01) and math.isnan(p[2]) and v is None
    calls.clear()
    # a good one: altitude AMSL to local, NED velocity to ENU; MAVSDK's zeros are unknown
    agent.handle(follow_target(lat, lon, 498.0, [1.0, 2.0, 0.0]), 0, None, 0)
    agent.handle(follow_target(lat, lon, 498.0, [0.0, 0.0, 0.0], cap=1), 0, None, 0)
    assert calls[0][0] == pytest.approx([0.0, 10.0, 10.0], abs=0.01)
    assert calls[0][1] == pytest.approx([2.0, 1.0, 0.0]) and calls[1][1] is None


def test_mavsdk_follow_me_example_sequence():
    async def run(server):
        m, drone = await connect(14540 + INSTANCE)
        action, tel, follow = ActionAsync(drone), TelemetryAsync(drone), FollowMeAsync(drone)
        await first(tel.subscribe_health(), lambda h: h.is_armable and h.is_global_position_ok)
        await action.set_takeoff_altitude(8.0)
        await action.arm()
        await action.takeoff()
        await first(tel.subscribe_position(), lambda p: p.relative_altitude_m > 7.5, timeout=30)
        await follow.set_config(Config(follow_height_m=8.0, follow_distance_m=5.0,
                                       responsiveness=0.1, follow_angle_deg=180.0))
        await follow.start()
        await first(tel.subscribe_flight_mode(), lambda fm: fm == FlightMode.FOLLOW_ME)
        # MAVSDK's follow-me plugin marks itself active from the same heartbeat in its own
        # handler, which may run after telemetry's callback has already woken this test: a
        # target set in between is refused NOT_ACTIVE (seen once in CI under load)
        for _ in range(100):
            if await follow.is_active():
                break
            await asyncio.sleep(0.05)
        assert await follow.is_active()
        # the example's fake locations: a few steps north of home, 2 s apart (8 s simulated)
        north = 0.0
        for _ in range(4):
            north += 1.0
            await follow.set_target_location(TargetLocation(
                LAT0 + north / M_PER_DEG_LAT, LON0, 488.0, 0.0, 0.0, 0.0))
            await asyncio.sleep(2.0)
        bad_fixes(14580 + INSTANCE, round((LAT0 + north / M_PER_DEG_LAT) * 1e7),
                  round(LON0 * 1e7))
        await asyncio.sleep(0.5)
        st = server.fleet.true_state(0)
        cmd = server.fleet.commanders[0]
        est = cmd.follow_target.estimate(server.fleet.time_us)[0]
        await follow.stop()
        await first(tel.subscribe_flight_mode(), lambda fm: fm == FlightMode.HOLD)
        m.destroy()
        return st, est, north

    with running_sitl(speed_factor=4.0, base_instance=INSTANCE) as server:
        cmd = server.fleet.commanders[0]
        fixes = []
        measure = cmd.follow_target_measurement
        cmd.follow_target_measurement = lambda t, p, v: (fixes.append(p), measure(t, p, v))
        st, est, north = asyncio.run(run(server))
        params = server.fleet.params[0]
        assert (params["FLW_TGT_DST"], params["FLW_TGT_HT"]) == (5.0, 8.0)
    # MAVSDK's fixes (sent once a second), then the three usable bad ones, nothing else
    assert len(fixes) >= 4 + 3 and all(np.all(np.isfinite(p[:2])) for p in fixes)
    assert sum(math.isnan(p[2]) for p in fixes) == 3
    target = np.array([0.0, north])
    assert est[:2] == pytest.approx(target, abs=0.2)  # the bad fixes changed nothing
    rel = st.position[:2] - target
    assert np.hypot(*rel) == pytest.approx(5.0, rel=0.12)
    assert abs(math.atan2(rel[1], rel[0]) + math.pi / 2) < math.radians(15)  # south of it
    assert st.position[2] == pytest.approx(8.0, abs=0.5)
    to_target = math.atan2(-rel[1], -rel[0])
    assert abs(math.remainder(st.yaw - to_target, 2 * math.pi)) < math.radians(15)
