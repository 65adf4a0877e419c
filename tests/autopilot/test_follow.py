"""Follow-target (PX4's AUTO.FOLLOW_TARGET) in-process: a target fed to the commander as
FOLLOW_TARGET fixes would be, the vehicle keeping FLW_TGT_DST / FLW_TGT_FA / FLW_TGT_HT
from it and facing it, holding when the target stops or is lost."""

import math

import numpy as np
import pytest

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import Result
from ft_sitl.autopilot.follow import TargetEstimator
from ft_sitl.physics.catalog import catalog
from ft_sitl.sim.fleet import Fleet
from tests.autopilot.test_commander import _flying as airborne
from tests.autopilot.test_commander import texts

P = catalog()["0.98kg-EGO Planner DIY"]




def fly(f, c, seconds, target, vel, step=0.02, feed=True, with_vel=True):
    """Run, moving the target at vel (ENU) and feeding it every step (50 Hz)."""
    for _ in range(round(seconds / step)):
        target += vel * step
        if feed:
            c.follow_target_measurement(f.time_us, target.copy(),
                                        vel.copy() if with_vel else None)
        f.run(step)
    return target


def offset_of(f, target):
    p = f.state(0).position
    rel = p[:2] - target[:2]
    return p, float(np.hypot(*rel)), math.atan2(rel[1], rel[0])


def facing_error(f, target):
    p, yaw = f.state(0).position, f.state(0).yaw
    return abs(math.remainder(yaw - math.atan2(target[1] - p[1], target[0] - p[0]),
                              2 * math.pi))


@pytest.mark.parametrize("with_vel", [True, False])
def test_follows_behind_a_moving_target_faces_it_and_holds_when_it_stops(with_vel):
    f, c = airborne({"FLW_TGT_DST": 6.0, "FLW_TGT_HT": 8.0})
    assert c.set_mode(cm.MAIN_AUTO, cm.SUB_FOLLOW_TARGET) == Result.ACCEPTED
    assert c.mode_name == "AUTO.FOLLOW_TARGET"
    target, vel = np.array([0.0, 5.0, 0.0]), np.array([2.0, 0.0, 0.0])  # east at 2 m/s
    target = fly(f, c, 20.0, target, vel, with_vel=with_vel)
    samples = []
    for _ in range(10):
        target = fly(f, c, 0.5, target, vel, with_vel=with_vel)
        p, dist, angle = offset_of(f, target)
        samples.append((p[2], dist, angle, facing_error(f, target), f.state(0).velocity))
    # behind (FLW_TGT_FA 180: west of an eastbound target), 6 m away, 8 m above home
    assert np.mean([s[1] for s in samples]) == pytest.approx(6.0, rel=0.1)
    assert all(abs(math.remainder(s[2] - math.pi, 2 * math.pi)) < math.radians(10)
               for s in samples)
    assert all(s[0] == pytest.approx(8.0, abs=0.5) for s in samples)
    assert all(s[3] < math.radians(10) for s in samples)
    assert np.mean([s[4][0] for s in samples]) == pytest.approx(2.0, rel=0.1)
    # the target stops: the vehicle stops behind it and holds
    target = fly(f, c, 10.0, target, np.zeros(3), with_vel=with_vel)
    p0 = f.state(0).position.copy()
    target = fly(f, c, 3.0, target, np.zeros(3), with_vel=with_vel)
    assert np.linalg.norm(f.state(0).position - p0) < 0.3
    assert offset_of(f, target)[1] == pytest.approx(6.0, rel=0.1)
    assert c.mode_name == "AUTO.FOLLOW_TARGET"


def test_follow_angle_and_target_height_and_a_lost_target():
    f, c = airborne({"FLW_TGT_FA": 90.0, "FLW_TGT_ALT_M": 2, "FLW_TGT_HT": 9.0})
    c.set_mode(cm.MAIN_AUTO, cm.SUB_FOLLOW_TARGET)
    target, vel = np.array([0.0, 0.0, 1.0]), np.array([0.0, 2.0, 0.0])  # north, 1 m up
    target = fly(f, c, 25.0, target, vel)
    p, dist, angle = offset_of(f, target)
    assert dist == pytest.approx(8.0, rel=0.1)  # FLW_TGT_DST's default
    assert abs(math.remainder(angle - 0.0, 2 * math.pi)) < math.radians(10)  # right: east
    assert p[2] == pytest.approx(10.0, abs=0.5)  # 9 m above the target
    assert facing_error(f, target) < math.radians(10)
    # no more fixes: after 3 s the estimate stops, the vehicle holds, a status text says so
    fly(f, c, 3.5, target, vel, feed=False)
    assert "Follow target lost: holding" in texts(c)
    f.run(3.0)
    p0 = f.state(0).position.copy()
    f.run(3.0)
    assert np.linalg.norm(f.state(0).position - p0) < 0.3
    assert c.mode_name == "AUTO.FOLLOW_TARGET"
    assert np.all(np.isfinite(f.state(0).position))


def test_mode_rules_as_px4():
    f = Fleet(P)
    c = f.commanders[0]
    # selectable on the ground (PX4), but not a mode to arm in
    assert c.set_mode(cm.MAIN_AUTO, cm.SUB_FOLLOW_TARGET) == Result.ACCEPTED
    assert c.arm() == Result.DENIED and "not suitable for arming" in texts(c)[-1]
    c.hold()
    c.arm()
    c.takeoff()
    assert f.run_until(lambda: c.mode_name == "AUTO.LOITER", 15)
    p0 = f.state(0).position.copy()
    c.set_mode(cm.MAIN_AUTO, cm.SUB_FOLLOW_TARGET)  # no target yet: holds
    f.run(3.0)
    assert np.linalg.norm(f.state(0).position - p0) < 0.2
    c.land()
    assert f.run_until(lambda: not c.armed, 20)


def test_estimator_tracks_position_fixes_and_extrapolates():
    est = TargetEstimator()
    for k in range(21):  # 1 Hz fixes of a target moving north at 3 m/s, no velocity
        est.measure(k * 1_000_000, np.array([0.0, 3.0 * k, math.nan]), None, 0.1)
    pos, vel = est.estimate(20_500_000)
    assert vel[1] == pytest.approx(3.0, abs=0.05) and pos[1] == pytest.approx(61.5, abs=0.2)
    assert math.isnan(pos[2])  # altitude never known
    pos, vel = est.estimate(30_000_000)  # lost after 3 s: stands where it was
    assert pos[1] == pytest.approx(69.0, abs=0.3) and np.all(vel == 0)
