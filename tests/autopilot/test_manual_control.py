"""Manual control in-process: the stick modes, arming with the sticks, manual control loss."""

import math

import numpy as np
import pytest

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import LandedState, Result
from ft_sitl.physics.catalog import catalog
from ft_sitl.sim.fleet import Fleet

P = catalog()["0.98kg-EGO Planner DIY"]


def texts(c):
    return [t for _, t in c.statustexts]


def fly(f, seconds, sticks, hz=20):
    """Send the sticks at hz while running seconds of simulation."""
    for _ in range(round(seconds * hz)):
        f.manual_control(0, *sticks)
        f.run(1.0 / hz)


def airborne(mode=cm.MAIN_POSCTL, alt=3.0):
    """Armed in POSCTL with the sticks, climbed to about alt m, then switched to mode."""
    f = Fleet(P)
    c = f.commanders[0]
    f.manual_control(0, 0, 0, 0.5, 0)
    assert c.arm() == Result.ACCEPTED
    fly(f, 0.5, (0, 0, 0.5, 0))
    assert c.landed_state == LandedState.ON_GROUND  # centred throttle: no take-off
    while f.state(0).position[2] < alt:
        fly(f, 0.1, (0, 0, 0.9, 0))
        assert f.sim.time_us < 20e6
    c.set_mode(mode)
    fly(f, 2.0, (0, 0, 0.5, 0))
    return f, c


def test_posctl_sticks_fly_body_velocity_climb_rate_and_hold():
    f, c = airborne()
    assert c.landed_state == LandedState.IN_AIR
    z0 = f.state(0).position[2]
    # full forward stick: 4 m/s forward (MPC_VEL_MANUAL 10 capped by MPC_XY_VEL_MAX 4),
    # altitude held
    yaw = f.state(0).yaw
    fly(f, 4.0, (1.0, 0, 0.5, 0))
    v = f.state(0).velocity
    fwd = np.array([math.cos(yaw), math.sin(yaw)])
    assert float(v[:2] @ fwd) == pytest.approx(4.0, abs=0.2)
    assert abs(f.state(0).position[2] - z0) < 0.3
    # half right stick: 0.5 -> (0.5 - 0.1) / 0.9 of 4 m/s to the right
    fly(f, 4.0, (0, 0.5, 0.5, 0))
    right = np.array([math.sin(yaw), -math.cos(yaw)])
    assert float(f.state(0).velocity[:2] @ right) == pytest.approx(4.0 * 0.4 / 0.9, abs=0.2)
    # centred: stops and holds
    fly(f, 4.0, (0, 0, 0.5, 0))
    p = f.state(0).position.copy()
    fly(f, 3.0, (0.05, -0.05, 0.52, 0.05))  # within MPC_HOLD_DZ: still centred
    assert np.linalg.norm(f.state(0).position - p) < 0.2
    # full throttle: MPC_Z_VEL_MAX_UP; low: MPC_Z_VEL_MAX_DN
    fly(f, 3.0, (0, 0, 1.0, 0))
    assert f.state(0).velocity[2] == pytest.approx(3.0, abs=0.2)
    fly(f, 3.0, (0, 0, 0.0, 0))
    assert f.state(0).velocity[2] == pytest.approx(-1.5, abs=0.15)
    # yaw stick right: clockwise at MPC_MAN_Y_MAX (150 deg/s) x (0.5 - 0.1) / 0.9
    fly(f, 1.0, (0, 0, 0.5, 0.5))
    y0 = f.state(0).yaw
    fly(f, 0.5, (0, 0, 0.5, 0.5))
    turned = -math.remainder(f.state(0).yaw - y0, 2 * math.pi)
    assert math.degrees(turned) / 0.5 == pytest.approx(150 * 0.4 / 0.9, rel=0.1)


def test_altctl_sticks_tilt_and_hold_altitude():
    f, c = airborne(cm.MAIN_ALTCTL)
    z0 = f.state(0).position[2]
    fly(f, 0.8, (0.5, 0, 0.5, 0))  # half forward: (0.4 / 0.9) x 35 deg of tilt
    tilt = math.degrees(f.state(0).tilt)
    assert tilt == pytest.approx(35 * 0.4 / 0.9, abs=2.5)
    assert abs(f.state(0).position[2] - z0) < 0.3
    fwd = np.array([math.cos(f.state(0).yaw), math.sin(f.state(0).yaw)])
    assert float(f.state(0).velocity[:2] @ fwd) > 1.0


def test_stabilized_attitude_and_direct_throttle():
    f, c = airborne(cm.MAIN_STABILIZED)
    # mid throttle is hover thrust: roughly level flight; high throttle climbs
    fly(f, 1.0, (0, -0.6, 0.5, 0))
    assert math.degrees(f.state(0).tilt) == pytest.approx(35 * 0.5 / 0.9, abs=2.5)
    fly(f, 0.5, (0, 0, 0.5, 0))  # level at mid throttle (hover thrust): no vertical acc.
    v1 = f.state(0).velocity[2]
    fly(f, 1.0, (0, 0, 0.5, 0))
    assert abs(f.state(0).velocity[2] - v1) < 0.3
    fly(f, 0.5, (0, 0, 0.6, 0))  # above hover thrust: it accelerates up
    assert f.state(0).velocity[2] > 1.0
    # the stick at the bottom: MPC_MANTHR_MIN (0.08), far below hover: it falls
    v0 = f.state(0).velocity[2]
    fly(f, 0.5, (0, 0, 0.0, 0))
    assert (f.state(0).velocity[2] - v0) / 0.5 < -0.5 * 9.81
    assert c.main_mode == cm.MAIN_STABILIZED


def test_arming_needs_low_throttle_and_posctl_takes_off_only_on_climb_stick():
    f = Fleet(P)
    c = f.commanders[0]
    f.manual_control(0, 0, 0, 0.7, 0)
    assert c.arm() == Result.DENIED and texts(c)[-1] == "Arming denied: throttle above center"
    c.set_mode(cm.MAIN_STABILIZED)
    f.manual_control(0, 0, 0, 0.3, 0)
    assert c.arm() == Result.DENIED and texts(c)[-1] == "Arming denied: high throttle"
    f.manual_control(0, 0, 0, 0.0, 0)
    assert c.arm() == Result.ACCEPTED
    c.disarm()
    c.set_mode(cm.MAIN_POSCTL)
    f.manual_control(0, 0, 0, 0.5, 0)
    assert c.arm() == Result.ACCEPTED
    fly(f, 1.0, (0, 0, 0.6, 0))  # above centre but not 65 %: stays on the ground
    assert c.landed_state == LandedState.ON_GROUND
    fly(f, 2.0, (0, 0, 0.8, 0))
    assert c.landed_state == LandedState.IN_AIR and f.state(0).velocity[2] > 0.3


@pytest.mark.parametrize("action,mode", [(1, "AUTO.LOITER"), (2, "AUTO.RTL"),
                                         (3, "AUTO.LAND"), (6, None)])
def test_manual_control_loss_takes_nav_rcl_act(action, mode):
    f, c = airborne()
    c.params.set("NAV_RCL_ACT", action)
    c.params.set("COM_FAIL_ACT_T", 0.0)
    f.run(0.4)
    assert c.mode_name == "POSCTL"  # within COM_RC_LOSS_T (0.5 s)
    f.run(0.3)
    assert "Manual control lost" in texts(c)
    if mode is None:
        assert not c.armed and "Disarmed by failsafe" in texts(c)
    else:
        assert c.mode_name == mode
    if action in (1, 3):  # the sticks back: back to POSCTL (PX4 clears hold and land)
        f.manual_control(0, 0, 0, 0.5, 0)
        f.run(0.1)
        assert c.mode_name == "POSCTL"
        assert any(t.startswith("Manual control regained") for t in texts(c))


def test_loss_holds_for_com_fail_act_t_then_returns_and_the_exceptions():
    f, c = airborne()
    f.run(0.7)
    assert c.mode_name == "AUTO.LOITER"
    assert "Failsafe activated: entering Hold for 5 seconds" in texts(c)
    f.run(4.0)
    assert c.mode_name == "AUTO.LOITER"
    f.run(1.5)
    assert c.mode_name == "AUTO.RTL"  # NAV_RCL_ACT 2 (PX4's default)
    f.manual_control(0, 0, 0, 0.5, 0)
    f.run(0.2)
    assert c.mode_name == "AUTO.RTL"  # a return goes on until the user changes mode
    # exempt: hold with COM_RCL_EXCEPT bit 1
    c.params.set("COM_RCL_EXCEPT", 2)
    c.hold()
    fly(f, 0.5, (0, 0, 0.5, 0))
    f.run(2.0)
    assert c.mode_name == "AUTO.LOITER" and c.armed


def test_no_sticks_at_arming_no_loss_failsafe_and_bad_input_refused():
    f = Fleet(P)
    c = f.commanders[0]
    assert not f.manual_control(0, math.nan, 0, 0.5, 0)
    assert not f.manual_control(0, 0, 0, math.inf, 0)
    assert c.manual.t_us is None
    assert f.manual_control(0, 32.767, -40, 99, 1e9)  # clamped
    assert c.sticks == (1.0, -1.0, 1.0, 1.0)
    f.run(1.0)  # stale before arming: the loss is ignored until the sticks come back
    c.arm()
    c.takeoff()
    f.run(5.0)
    assert c.mode_name == "AUTO.LOITER" and "Failsafe" not in " ".join(texts(c))
    c.params.set("COM_RC_IN_MODE", 4)  # stick input disabled
    assert not f.manual_control(0, 0, 0, 0.5, 0)
