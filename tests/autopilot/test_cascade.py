"""The control cascade flying every catalog platform: hover, steps, limits, determinism."""

import math

import numpy as np
import pytest

from ft_sitl.autopilot.params import ParamError, ParamSet
from ft_sitl.autopilot.setpoints import Setpoint, SetpointError
from ft_sitl.physics.catalog import catalog
from ft_sitl.physics.quaternion import tilt_angle
from ft_sitl.sim.lockstep import Simulation

PLATFORMS = list(catalog().values())


def settle_time(t, err, tol):
    bad = np.flatnonzero(err > tol)
    return 0.0 if bad.size == 0 else float(t[bad[-1]])


def test_every_platform_takes_off_and_holds_a_2m_hover_within_5cm():
    sim = Simulation(PLATFORMS)
    for i in range(sim.n):
        sim.place(i, [0.0, 0.0, 0.0])
        sim.set_setpoint(i, Setpoint.position([0.0, 0.0, 2.0], yaw=0.0))
    sim.run(8.0)  # take off from the ground and settle
    rec = sim.run(10.0, record_hz=100)
    for i, p in enumerate(PLATFORMS):
        err = np.linalg.norm(rec.positions(i) - [0.0, 0.0, 2.0], axis=1)
        assert err.max() < 0.05, f"{p.name}: hover error {err.max():.3f} m"
        assert not sim.on_ground(i)


def test_position_step_settles_on_every_platform():
    sim = Simulation(PLATFORMS)
    for i in range(sim.n):
        sim.start_hovering(i, [0.0, 0.0, 2.0])
        sim.set_setpoint(i, Setpoint.position([1.0, 0.0, 3.0], yaw=0.0))
    rec = sim.run(12.0, record_hz=100)
    for i, p in enumerate(PLATFORMS):
        err = np.linalg.norm(rec.positions(i) - [1.0, 0.0, 3.0], axis=1)
        assert settle_time(rec.t_s, err, 0.05) < 8.0, p.name
        assert err[-100:].max() < 0.02, p.name
        assert np.abs(rec.positions(i)).max() < 4.0, f"{p.name} diverged"


def test_yaw_step_settles_and_low_agility_platforms_are_slower():
    sim = Simulation(PLATFORMS)
    for i in range(sim.n):
        sim.start_hovering(i, [0.0, 0.0, 2.0])
        sim.set_setpoint(i, Setpoint.position([0.0, 0.0, 2.0], yaw=math.pi / 2))
    rec = sim.run(10.0, record_hz=200)
    rise = {}
    for i, p in enumerate(PLATFORMS):
        yaw = rec.eulers(i)[:, 2]
        err = np.abs(yaw - math.pi / 2)
        assert settle_time(rec.t_s, err, math.radians(2.0)) < 6.0, p.name
        assert err[-200:].max() < math.radians(1.0), p.name
        rise[p.name] = float(rec.t_s[np.argmax(yaw >= 0.9 * math.pi / 2)])
    by_agility = sorted(PLATFORMS, key=lambda p: p.indicators().alpha_z_max_rad_s2)
    slow = np.mean([rise[p.name] for p in by_agility[:6]])
    fast = np.mean([rise[p.name] for p in by_agility[-6:]])
    assert slow > 1.5 * fast, (slow, fast)


def test_velocity_and_tilt_limits_are_obeyed():
    params = ParamSet({"MPC_XY_VEL_MAX": 4.0, "MPC_TILTMAX_AIR": 30.0, "MPC_ACC_HOR_MAX": 10.0})
    plats = [catalog()["0.55kg-UAV 1"], catalog()["2.00kg-T-MOTOR"]]
    sim = Simulation(plats, params=params)
    for i in range(sim.n):
        sim.start_hovering(i, [0.0, 0.0, 5.0])
        sim.set_setpoint(i, Setpoint.velocity([20.0, 5.0, 0.0], yaw=0.0))
    rec = sim.run(6.0, record_hz=200)
    for i in range(sim.n):
        speed_xy = np.linalg.norm(rec.x[:, i, 3:5], axis=1)
        assert speed_xy.max() < 4.0 * 1.05
        assert speed_xy[-1] == pytest.approx(4.0, abs=0.1)
        tilt = np.degrees([tilt_angle(q) for q in rec.x[:, i, 6:10]])
        assert tilt.max() < 30.0 + 3.0  # transients within a few degrees of the limit


def test_acceleration_setpoint_is_limited_by_mpc_acc_hor_max():
    from ft_sitl.autopilot import cascade as c

    sim = Simulation(catalog()["0.98kg-EGO Planner DIY"])
    sim.start_hovering(0, [0.0, 0.0, 5.0])
    sim.set_setpoint(0, Setpoint.acceleration([8.0, 0.0, 0.0], yaw=0.0))
    sim.run(0.3)  # tilt established
    acc_sp = sim.ctrl[0, c.C_ACC_SP:c.C_ACC_SP + 3]
    assert acc_sp[0] == pytest.approx(3.0, rel=1e-9)  # MPC_ACC_HOR_MAX default
    v0 = sim.velocity(0)[0]
    sim.run(0.3)
    assert (sim.velocity(0)[0] - v0) / 0.3 == pytest.approx(3.0, rel=0.06)  # minus drag


@pytest.mark.parametrize("name,twr", [("1.00kg-SunnySky", 6.0), ("1.20kg-JFRC", 1.4)])
def test_offboard_acceleration_is_bounded_by_tilt_and_thrust_not_mpc_acc(name, twr):
    """PX4 parity: a 10 m/s^2 offboard acceleration setpoint is not clamped to
    MPC_ACC_HOR_MAX (3 m/s^2); it is followed up to the tilt limit (45 deg), and a weak
    platform (TWR 1.4: g sqrt(TWR^2 - 1) = 9.6 m/s^2 with no thrust to spare) saturates its
    motors getting there while a strong one (TWR 6) does not."""
    from ft_sitl.autopilot import cascade as c

    p = catalog()[name]
    assert p.indicators().twr_max == pytest.approx(twr, abs=0.05)
    sim = Simulation(p)
    sim.start_hovering(0, [0.0, 0.0, 5.0])
    sp = Setpoint.trajectory(position=[math.nan, math.nan, 5.0],
                             acceleration=[10.0, 0.0, 0.0], yaw=0.0).offboard()
    sim.set_setpoint(0, sp)
    sim.run(0.3)
    saturated = sim.ctrl[0, c.C_SAT_STEPS] / sim.steps
    v0 = sim.velocity(0)[0]
    sim.run(0.5)
    achieved = (sim.velocity(0)[0] - v0) / 0.5
    ax, _, az = sim.ctrl[0, c.C_ACC_SP:c.C_ACC_SP + 3]
    assert math.degrees(math.atan2(ax, az + 9.80665)) == pytest.approx(45.0, abs=0.5)
    assert achieved > 8.0  # (drag takes a little)
    if twr > 3:
        assert saturated == 0.0
    else:
        assert saturated > 0.5


def test_offboard_acceleration_clamp_of_protocol_1():
    """FT_OFFB_ACC_LIM = 1 (protocol 1) clamps offboard setpoints to MPC_ACC_HOR_MAX too."""
    from ft_sitl.autopilot import cascade as c

    sim = Simulation(catalog()["1.00kg-SunnySky"], params=ParamSet({"FT_OFFB_ACC_LIM": 1}))
    sim.start_hovering(0, [0.0, 0.0, 5.0])
    sim.set_setpoint(0, Setpoint.acceleration([10.0, 0.0, 0.0], yaw=0.0).offboard())
    sim.run(0.3)
    assert sim.ctrl[0, c.C_ACC_SP] == pytest.approx(3.0, rel=1e-9)


def test_attitude_setpoint_tracks_roll():
    from ft_sitl.physics.quaternion import qfrom_euler

    p = catalog()["1.80kg-SunnySky"]
    sim = Simulation(p)
    sim.start_hovering(0, [0.0, 0.0, 20.0])
    hover = p.mass_kg * 9.80665 / p.thrust_max_n
    sim.set_setpoint(0, Setpoint.attitude(qfrom_euler(math.radians(10), 0.0, 0.0), hover))
    sim.run(2.0)
    roll, pitch, yaw = sim.euler(0)
    assert math.degrees(roll) == pytest.approx(10.0, abs=0.5)
    assert abs(pitch) < 0.01 and abs(yaw) < 0.01


def test_same_inputs_give_bit_identical_trajectories():
    def fly():
        sim = Simulation(catalog()["3.00kg-T-MOTOR"])
        sim.place(0, [0.0, 0.0, 0.0])
        sim.set_setpoint(0, Setpoint.position([3.0, -2.0, 2.5], yaw=1.0))
        return sim.run(6.0, record_hz=1000).x

    a, b = fly(), fly()
    assert a.tobytes() == b.tobytes()


def test_batch_of_n_equals_n_single_runs():
    plats = PLATFORMS[::5]
    targets = [[i * 0.5, -1.0, 1.5 + 0.1 * i] for i in range(len(plats))]
    batch = Simulation(plats)
    for i, tgt in enumerate(targets):
        batch.place(i, [0.0, 0.0, 0.0])
        batch.set_setpoint(i, Setpoint.position(tgt, yaw=0.3 * i))
    rb = batch.run(5.0, record_hz=100).x
    for i, (p, tgt) in enumerate(zip(plats, targets)):
        single = Simulation(p)
        single.place(0, [0.0, 0.0, 0.0])
        single.set_setpoint(0, Setpoint.position(tgt, yaw=0.3 * i))
        rs = single.run(5.0, record_hz=100).x
        assert rs[:, 0].tobytes() == rb[:, i].tobytes(), p.name


@pytest.mark.parametrize(
    "make, message",
    [
        (lambda: Setpoint.position([1.0, float("nan"), 2.0]), "position: .*non-finite"),
        (lambda: Setpoint.position([1.0, 2.0, float("inf")]), "non-finite"),
        (lambda: Setpoint.position([1.0, 2.0]), "needs 3 components"),
        (lambda: Setpoint.position("up"), "not a 3-vector"),
        (lambda: Setpoint.velocity([1.0, 0.0, 0.0], yaw=float("nan")), "yaw: nan is not finite"),
        (lambda: Setpoint.velocity(None), "velocity: required"),
        (lambda: Setpoint.attitude([1.0, 0.0, 0.0, 0.0], 1.5), r"thrust: 1.5 is outside"),
        (lambda: Setpoint.attitude([2.0, 0.0, 0.0, 0.0], 0.5), "norm 2.000000 is not 1"),
        (lambda: Setpoint.attitude([1.0, 0.0, float("nan"), 0.0], 0.5), "not a finite quat"),
        (lambda: Setpoint.body_rates([0.0, 0.0, 0.0], float("nan")), "thrust: nan"),
        (lambda: Setpoint.trajectory(position=[1.0, float("nan"), 2.0]),
         "axis y has no position, velocity or acceleration"),
    ],
)
def test_bad_setpoints_are_rejected_with_a_named_error(make, message):
    with pytest.raises(SetpointError, match=message):
        make()


def test_vehicle_keeps_its_last_valid_setpoint_after_a_rejected_one():
    sim = Simulation(catalog()["0.90kg-DJI"])
    sim.start_hovering(0, [0.0, 0.0, 2.0])
    sim.set_setpoint(0, Setpoint.position([1.0, 1.0, 2.0], yaw=0.0))
    with pytest.raises(SetpointError):
        sim.set_setpoint(0, Setpoint.position([float("nan"), 0.0, 2.0]))
    sim.run(10.0)
    assert sim.position(0) == pytest.approx([1.0, 1.0, 2.0], abs=0.02)
    assert np.all(np.isfinite(sim.w_cmd))


def test_per_axis_trajectory_mix_position_xy_velocity_z():
    sim = Simulation(catalog()["1.05kg-UAV 4"])
    sim.start_hovering(0, [0.0, 0.0, 2.0])
    nan = float("nan")
    sim.set_setpoint(0, Setpoint.trajectory(position=[2.0, 0.0, nan], velocity=[nan, nan, 0.5]))
    sim.run(4.0)
    assert sim.position(0)[:2] == pytest.approx([2.0, 0.0], abs=0.15)
    assert sim.velocity(0)[2] == pytest.approx(0.5, abs=0.02)


def test_params_are_bounded_and_named():
    ps = ParamSet()
    with pytest.raises(ParamError, match="MPC_XY_VEL_MAX: 25.0 m/s is outside"):
        ps.set("MPC_XY_VEL_MAX", 25.0)
    with pytest.raises(ParamError, match="did you mean 'MPC_XY_VEL_MAX'"):
        ps.set("MPC_XY_VEL_MX", 3.0)
    with pytest.raises(ParamError, match="not finite"):
        ps.set("MC_ROLL_P", float("nan"))
    with pytest.raises(ParamError, match="must be an integer"):
        ps.set("FT_GAIN_MODE", 0.5)
    assert ps.get("MPC_XY_VEL_MAX") == 4.0


def test_normalised_gain_mode_flies_a_mid_range_platform():
    """PX4's default normalised rate gains suit a platform of ordinary agility."""
    sim = Simulation(catalog()["1.80kg-SunnySky"], params=ParamSet({"FT_GAIN_MODE": 1}))
    sim.place(0, [0.0, 0.0, 0.0])
    sim.set_setpoint(0, Setpoint.position([1.0, 0.0, 2.0], yaw=0.5))
    sim.run(12.0)
    assert sim.position(0) == pytest.approx([1.0, 0.0, 2.0], abs=0.05)
    assert sim.euler(0)[2] == pytest.approx(0.5, abs=0.02)


def test_landing_is_soft_and_a_motor_cut_in_flight_is_a_hard_impact():
    sim = Simulation([catalog()["2.50kg-HLY"]] * 2)
    for i in range(2):
        sim.start_hovering(i, [0.0, 0.0, 3.0])
    sim.set_setpoint(0, Setpoint.velocity([0.0, 0.0, -0.8], yaw=0.0))
    sim.set_setpoint(1, Setpoint.off())
    sim.run(6.0)
    assert sim.on_ground(0) and sim.on_ground(1)
    assert sim.max_impact_speed(0) == pytest.approx(0.8, abs=0.1)
    assert not sim.hard_impact(0)
    assert sim.hard_impact(1) and sim.max_impact_speed(1) > 6.0
    assert sim.position(1)[2] == 0.0


def test_a_plus_layout_user_platform_flies(tmp_path):
    from ft_sitl.physics.catalog import load_platform_file

    f = tmp_path / "plus.toml"
    f.write_text('[platform]\nname = "plus"\nlayout = "quad_plus"\nmass_kg = 1.3\n'
                 "twr_max = 2.8\nalpha_xy_max_rad_s2 = 180\nalpha_z_max_rad_s2 = 12\n")
    (p,) = load_platform_file(f)
    sim = Simulation(p)
    sim.place(0, [0.0, 0.0, 0.0])
    sim.set_setpoint(0, Setpoint.position([2.0, -1.0, 2.0], yaw=1.0))
    sim.run(12.0)
    assert sim.position(0) == pytest.approx([2.0, -1.0, 2.0], abs=0.03)
    assert sim.euler(0)[2] == pytest.approx(1.0, abs=0.02)


def test_without_airmode_the_collective_is_never_raised_for_roll():
    p = catalog()["1.50kg-DJI"]
    for airmode in (0, 1):
        sim = Simulation(p, params=ParamSet({"MC_AIRMODE": airmode, "FT_RATE_BW_RP": 200}))
        sim.start_hovering(0, [0.0, 0.0, 50.0])
        sim.set_setpoint(0, Setpoint.body_rates([3.0, 0.0, 0.0], 0.02))  # thrust near idle
        sim.step(1)
        thrust = p.thrust_coefficient * sim.w_cmd[0] ** 2
        if airmode == 0:
            assert thrust.sum() <= 0.02 * p.thrust_max_n + 4 * p.rotor_thrust_min_n
        else:
            assert thrust.max() > 0.2 * p.rotor_thrust_max_n


def test_a_platform_that_cannot_descend_under_mpc_thr_min_is_refused():
    from ft_sitl.physics.synthesis import synthesise

    p = synthesise("rocket", 0.6, 7.9, 800.0, 40.0)
    with pytest.raises(ParamError, match="hovers at 12.7% .* MPC_THR_MIN"):
        Simulation(p, params=ParamSet({"MPC_THR_MIN": 0.15}))
    Simulation(p)  # the default 12 % leaves it controllable
