"""Spline waypoints (ft_sitl.autopilot.spline): the Hermite leg's ends and tangents, the
speed limits along it, ArduCopter's tangent rule between legs, and a mission flown
in-process through the flight controller (no sockets): the path bends before each corner,
passes each waypoint within the acceptance radius, the legs join with one tangent, and a
mission of straight waypoints flies as before."""

import math

import numpy as np
import pytest

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import MissionItem, MissionState, Result
from ft_sitl.autopilot.spline import (
    HermiteLeg,
    SplineLimits,
    curve_point,
    end_speed_max,
    kinematic_limit,
)
from ft_sitl.physics.catalog import catalog
from ft_sitl.sim.fleet import Fleet

P = catalog()["0.98kg-EGO Planner DIY"]
LIM = SplineLimits(speed_xy=5.0, speed_up=2.5, speed_down=1.5, accel_xy=2.5, accel_z=1.0)
nan = math.nan


def test_a_leg_starts_and_ends_at_its_points_with_the_derivatives_asked():
    o, d = np.array([0.0, 0.0, 5.0]), np.array([20.0, 0.0, 5.0])
    v0, v1 = np.array([10.0, 0.0, 0.0]), np.array([20.0, 20.0, 0.0])
    leg = HermiteLeg.between(o, d, v0, v1)
    p0, dp0, _, _ = leg.at(0.0)
    p1, dp1, _, _ = leg.at(1.0)
    assert p0 == pytest.approx(o) and p1 == pytest.approx(d)
    assert dp0 == pytest.approx(v0) and dp1 == pytest.approx(v1)
    # the curve bends toward the end tangent: it leaves the chord (y = 0) on the far side
    ys = [leg.at(t)[0][1] for t in np.linspace(0, 1, 21)]
    assert min(ys) < -1.0 and ys[-1] == pytest.approx(0.0, abs=1e-9)


def test_end_derivatives_longer_than_four_chords_are_scaled_down_together():
    o, d = np.zeros(3), np.array([2.0, 0.0, 0.0])
    v0, v1 = np.array([6.0, 0.0, 0.0]), np.array([0.0, 6.0, 0.0])  # 12 > 4 * 2
    leg = HermiteLeg.between(o, d, v0, v1)
    _, dp0, _, _ = leg.at(0.0)
    _, dp1, _, _ = leg.at(1.0)
    assert np.linalg.norm(dp0) + np.linalg.norm(dp1) == pytest.approx(8.0)
    assert dp0 == pytest.approx(v0 * 8 / 12) and dp1 == pytest.approx(v1 * 8 / 12)
    assert leg.at(1.0)[0] == pytest.approx(d)


def test_kinematic_limit_takes_the_tighter_of_the_horizontal_and_vertical_caps():
    assert kinematic_limit(np.array([1.0, 0, 0]), 5.0, 2.5, 1.5) == pytest.approx(5.0)
    assert kinematic_limit(np.array([0, 0, 1.0]), 5.0, 2.5, 1.5) == pytest.approx(2.5)
    assert kinematic_limit(np.array([0, 0, -1.0]), 5.0, 2.5, 1.5) == pytest.approx(1.5)
    # 45 deg up: the climb cap binds (2.5 / sin 45 < 5 / cos 45)
    assert kinematic_limit(np.array([1.0, 0, 1.0]), 5.0, 2.5, 1.5) == \
        pytest.approx(2.5 * math.sqrt(2))
    assert kinematic_limit(np.zeros(3), 5.0, 2.5, 1.5) == 0.0


def test_speed_along_a_leg_is_capped_by_speed_curvature_and_the_distance_to_stop():
    straight = HermiteLeg.between(np.zeros(3), np.array([100.0, 0, 0]),
                                  np.array([100.0, 0, 0]), np.array([100.0, 0, 0]))
    mid = curve_point(straight, 0.5, LIM, 0.0)
    assert mid.speed_max == pytest.approx(LIM.speed_xy)  # far from the end: WPNAV_SPEED
    assert mid.accel_max == pytest.approx(0.5 * LIM.accel_xy)
    near = curve_point(straight, 0.99, LIM, 0.0)  # 1 m left, stopping with 1.25 m/s^2
    assert near.speed_max == pytest.approx(math.sqrt(2 * 1.25 * 1.0), rel=1e-6)
    # a tight bend: the lateral acceleration at the capped speed is half WPNAV_ACCEL
    bend = HermiteLeg.between(np.zeros(3), np.array([4.0, 4.0, 0]), np.array([16.0, 0, 0]),
                              np.array([0.0, 16.0, 0]))
    pt = curve_point(bend, 0.5, LIM, 5.0)
    curvature = float(np.linalg.norm(pt.normal_accel))
    assert pt.speed_max < LIM.speed_xy
    assert pt.speed_max ** 2 * curvature == pytest.approx(0.5 * LIM.accel_xy, rel=1e-6)
    assert end_speed_max(bend, LIM) > 0.0
    assert end_speed_max(HermiteLeg.between(np.zeros(3), np.ones(3), np.ones(3),
                                            np.zeros(3)), LIM) == 0.0


def _fly(items, dt=0.05, limit_s=200.0):
    """Fly ``items`` in AUTO from the ground; the positions, the legs the spline flew
    (in order) and the commander."""
    f = Fleet(P)
    c = f.commanders[0]
    c.set_mission(items)
    assert c.arm() == Result.ACCEPTED
    assert c.set_mode(cm.MAIN_AUTO, cm.SUB_MISSION) == Result.ACCEPTED
    path, legs = [], []
    for _ in range(int(limit_s / dt)):
        f.run(dt)
        path.append((c.mission_seq, *f.state(0).position))
        fl = c.mission_exec.spline.flight
        if fl is not None and (not legs or legs[-1] is not fl.leg):
            legs.append(fl.leg)
        if c.mission_state == MissionState.COMPLETE and not c.armed:
            break
    return np.array(path), legs, c


SQUARE = [(20.0, 0.0, 5.0), (20.0, 20.0, 5.0), (0.0, 20.0, 5.0)]


def _square(spline: bool):
    return ([MissionItem(cm.CMD_NAV_TAKEOFF, (nan, nan, 5.0))] +
            [MissionItem(cm.CMD_NAV_WAYPOINT, w, spline=spline) for w in SQUARE] +
            [MissionItem(cm.CMD_NAV_LAND, (nan, nan, nan))])


def test_a_spline_mission_flies_curves_through_its_waypoints_with_one_tangent():
    path, legs, c = _fly(_square(True))
    assert list(c.reached) == [0, 1, 2, 3, 4] and not c.armed
    radius = c.params["NAV_ACC_RAD"]
    for w in SQUARE:  # through each waypoint, within WPNAV_RADIUS
        assert np.min(np.linalg.norm(path[:, 1:4] - w, axis=1)) < radius
    # it bends before the corner at (20, 0): on the first leg it leaves the chord y = 0,
    # on the second (20, 0) -> (20, 20) the chord x = 20
    first, second = path[path[:, 0] == 1], path[path[:, 0] == 2]
    assert np.max(np.abs(first[:, 2])) > 1.5
    assert np.max(np.abs(second[:, 1] - 20.0)) > 1.5
    # ArduCopter's tangents: from rest after the take-off; toward the next spline, the
    # chord from this leg's origin to the next destination; the last one stops (LAND)
    assert len(legs) == 3
    a, b, last = legs
    assert not np.any(a.v0)
    assert a.v1 == pytest.approx(np.array(SQUARE[1]) - a.origin)
    assert b.v1 == pytest.approx(np.array(SQUARE[2]) - b.origin)
    assert not np.any(last.v1)
    for x, y in ((a, b), (b, last)):  # joined: same point, same derivative
        assert y.origin == pytest.approx(x.destination)
        assert y.v0 == pytest.approx(x.v1)
        assert y.at(0.0)[1] == pytest.approx(x.at(1.0)[1])
    assert np.linalg.norm(path[-1, 1:3] - [0.0, 20.0]) < radius  # landed at the last one


def test_tangent_rules_for_a_delay_a_straight_neighbour_and_a_return():
    """A straight waypoint before a spline gives its direction as v0; a spline before a
    straight waypoint leaves parallel to the next leg (n - d); a delay stops the leg
    (v1 = 0); a spline before RTL stops too (RTL has no location)."""
    items = [MissionItem(cm.CMD_NAV_TAKEOFF, (nan, nan, 5.0)),
             MissionItem(cm.CMD_NAV_WAYPOINT, (10.0, 0.0, 5.0)),
             MissionItem(cm.CMD_NAV_WAYPOINT, (20.0, 6.0, 5.0), spline=True),
             MissionItem(cm.CMD_NAV_WAYPOINT, (20.0, 16.0, 5.0)),
             MissionItem(cm.CMD_NAV_WAYPOINT, (10.0, 16.0, 5.0), spline=True, hold_s=1.0),
             MissionItem(cm.CMD_NAV_WAYPOINT, (0.0, 10.0, 5.0), spline=True),
             MissionItem(cm.CMD_NAV_RETURN_TO_LAUNCH)]
    path, legs, c = _fly(items, limit_s=300.0)
    assert list(c.reached) == [0, 1, 2, 3, 4, 5, 6] and not c.armed
    first, held, last = legs
    takeoff_point = np.array([0.0, 0.0, 5.0])
    assert first.origin == pytest.approx([10.0, 0.0, 5.0])
    assert first.v0[:2] == pytest.approx((first.origin - takeoff_point)[:2], abs=0.3)
    assert first.v1 == pytest.approx([0.0, 10.0, 0.0])  # parallel to the next leg
    assert not np.any(held.v1)  # the delay: it stops there
    assert not np.any(last.v0) and not np.any(last.v1)  # after a stop; before RTL
    assert np.min(np.linalg.norm(path[:, 1:4] - [10.0, 16.0, 5.0], axis=1)) < 0.5


def test_a_mission_of_straight_waypoints_keeps_its_straight_legs():
    path, legs, c = _fly(_square(False))
    assert list(c.reached) == [0, 1, 2, 3, 4] and legs == []
    first = path[path[:, 0] == 1]
    assert np.max(np.abs(first[:, 2])) < 0.5  # on the chord y = 0
