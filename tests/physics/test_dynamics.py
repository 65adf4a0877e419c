"""The plant at its boundaries: what comes out for what goes in."""

import math

import numpy as np
import pytest

from ft_sitl import G
from ft_sitl.autopilot.params import ParamSet
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.physics import dynamics as d
from ft_sitl.physics.catalog import catalog
from ft_sitl.sim.lockstep import Simulation

PLATFORMS = list(catalog().values())


def plant_for(platforms):
    return d.PlantBatch.from_platforms(platforms)


def step(plant, w_cmd, n, dt=1e-3):
    for _ in range(n):
        d.plant_step(plant.x, w_cmd, plant.prm, plant.alloc, plant.env, plant.status, dt)


def test_free_fall_with_motors_stopped_follows_quadratic_drag():
    plant = plant_for(PLATFORMS[:3])
    plant.x[:, d.X_POS + 2] = 100.0
    plant.x[:, d.X_ROTOR:] = 0.0
    step(plant, np.zeros((3, 4)), 1000)
    for i, p in enumerate(PLATFORMS[:3]):
        v_terminal = math.sqrt(p.mass_kg * G / p.body_drag_coefficient[2])
        expect = -v_terminal * math.tanh(G * 1.0 / v_terminal)
        assert plant.x[i, d.X_VEL + 2] == pytest.approx(expect, rel=2e-3)
        assert plant.x[i, d.X_VEL + 2] > -G * 1.0


def test_motor_lag_time_constants_up_and_down():
    p = catalog()["2.00kg-T-MOTOR"]
    plant = plant_for([p])
    plant.x[0, d.X_POS + 2] = 50.0
    w0, w1 = p.rotor_speed_min_rad_s, p.rotor_speed_max_rad_s
    plant.x[0, d.X_ROTOR:] = w0
    n_up = round(p.motor_tau_up_s / 1e-3)
    step(plant, np.full((1, 4), w1), n_up)
    frac = (plant.x[0, d.X_ROTOR] - w0) / (w1 - w0)
    assert frac == pytest.approx(1 - math.exp(-n_up * 1e-3 / p.motor_tau_up_s), abs=1e-9)
    assert frac == pytest.approx(0.632, abs=0.01)
    plant.x[0, d.X_ROTOR:] = w1
    n_dn = round(p.motor_tau_down_s / 1e-3)
    step(plant, np.full((1, 4), w0), n_dn)
    frac = (w1 - plant.x[0, d.X_ROTOR]) / (w1 - w0)
    assert frac == pytest.approx(0.632, abs=0.01)


def test_commands_saturate_at_the_rotor_speed_limits():
    p = catalog()["0.60kg-EMAX"]
    plant = plant_for([p])
    plant.x[0, d.X_POS + 2] = 50.0
    step(plant, np.full((1, 4), 10 * p.rotor_speed_max_rad_s), 500)
    assert plant.x[0, d.X_ROTOR:] == pytest.approx(p.rotor_speed_max_rad_s, rel=1e-6)
    step(plant, np.full((1, 4), 1.0), 500)  # positive but below idle: idles
    assert plant.x[0, d.X_ROTOR:] == pytest.approx(p.rotor_speed_min_rad_s, rel=1e-6)


def test_ground_holds_the_vehicle_and_reports_impacts():
    p = catalog()["1.50kg-DJI"]
    plant = plant_for([p])
    plant.x[0, d.X_POS + 2] = 5.0
    plant.x[0, d.X_ROTOR:] = 0.0
    step(plant, np.zeros((1, 4)), 3000)
    assert plant.x[0, d.X_POS + 2] == 0.0
    assert np.all(plant.x[0, d.X_VEL:d.X_VEL + 3] == 0.0)
    assert plant.status[0, d.S_CONTACT] == 1.0
    impact = plant.status[0, d.S_IMPACT_MAX]
    v_t2 = p.mass_kg * G / p.body_drag_coefficient[2]  # terminal speed squared
    assert impact == pytest.approx(math.sqrt(v_t2 * (1 - math.exp(-2 * G * 5.0 / v_t2))), rel=0.01)
    # resting on raised ground (a rooftop) with rotors at idle: stays there
    plant.env[0, d.E_GROUND_Z] = 2.0
    plant.x[0, d.X_POS + 2] = 2.0
    step(plant, np.full((1, 4), p.rotor_speed_min_rad_s), 2000)
    assert plant.x[0, d.X_POS + 2] == 2.0


def saturated_command(p, row):
    """Rotor speeds of a full-saturation command about one allocation row."""
    b = p.allocation()[row]
    return np.where(b > 0, p.rotor_speed_max_rad_s, p.rotor_speed_min_rad_s)[None, :]


def measured_accelerations(p, w_cmd, wait_s, with_speed=False):
    """Start in hover, apply a rotor command, wait for the motors, then differentiate."""
    plant = plant_for([p])
    plant.x[0, d.X_POS + 2] = 500.0
    plant.x[0, d.X_ROTOR:] = p.hover_rotor_speed_rad_s
    step(plant, w_cmd, math.ceil(wait_s / 1e-3))
    w0 = plant.x[0, d.X_OMEGA:d.X_OMEGA + 3].copy()
    v0 = plant.x[0, d.X_VEL:d.X_VEL + 3].copy()
    step(plant, w_cmd, 5)
    out = ((plant.x[0, d.X_OMEGA:d.X_OMEGA + 3] - w0) / 5e-3,
           (plant.x[0, d.X_VEL:d.X_VEL + 3] - v0) / 5e-3)
    return (*out, 0.5 * (v0[2] + plant.x[0, d.X_VEL + 2])) if with_speed else out


@pytest.mark.parametrize("name", [p.name for p in PLATFORMS])
def test_full_saturation_reaches_the_platform_limits(name):
    """Saturated rotor commands in, accelerations out, against the paper's indicators."""
    p = catalog()[name]
    ind = p.indicators()
    settle = 7 * p.motor_tau_down_s  # both lag directions within 0.1 %
    alpha, _ = measured_accelerations(p, saturated_command(p, 1), settle)
    assert alpha[0] == pytest.approx(ind.alpha_xy_max_rad_s2, rel=0.03)
    assert abs(alpha[1]) < 1e-6 * ind.alpha_xy_max_rad_s2
    alpha, _ = measured_accelerations(p, saturated_command(p, 2), settle)
    assert alpha[1] == pytest.approx(ind.alpha_pitch_max_rad_s2, rel=0.03)
    alpha, _ = measured_accelerations(p, saturated_command(p, 3), settle)
    assert alpha[2] == pytest.approx(ind.alpha_z_max_rad_s2, rel=0.03)
    full = np.full((1, 4), p.rotor_speed_max_rad_s)
    _, acc, vz = measured_accelerations(p, full, 7 * p.motor_tau_up_s, with_speed=True)
    # the climb has begun by then: quadratic body drag, known from the platform, opposes it
    drag = p.body_drag_coefficient[2] * vz * abs(vz) / p.mass_kg
    assert acc[2] + drag == pytest.approx((ind.twr_max - 1) * G, rel=0.03)
    assert drag < 0.05 * acc[2]


@pytest.mark.parametrize("name", ["0.55kg-UAV 1", "2.00kg-T-MOTOR", "5.45kg-JFRC"])
def test_cascade_at_full_demand_commands_exactly_the_saturated_rotors(name):
    """A rate demand far beyond reach makes the allocator output the saturation pattern.

    With airmode the collective re-centres so both sides of the frame saturate; PX4's
    default (MC_AIRMODE 0) only lowers thrust and gives up some roll authority here.
    """
    p = catalog()[name]
    params = ParamSet({"MC_ROLLRATE_MAX": 1800, "MC_YAWRATE_MAX": 1800,
                       "FT_RATE_BW_RP": 200, "FT_RATE_BW_Y": 100, "MC_AIRMODE": 1})
    mid = 0.5 * (1 + (p.rotor_speed_min_rad_s / p.rotor_speed_max_rad_s) ** 2)
    for rates, row in (([30.0, 0, 0], 1), ([0, 0, 30.0], 3)):
        sim = Simulation(p, params=params)
        sim.start_hovering(0, [0.0, 0.0, 100.0])
        sim.set_setpoint(0, Setpoint.body_rates(rates, mid))
        sim.step(1)
        assert sim.w_cmd[0] == pytest.approx(saturated_command(p, row)[0], rel=1e-9)


def test_quaternion_stays_unit_through_violent_tumbling():
    p = catalog()["0.75kg-UAV 2"]
    plant = plant_for([p])
    plant.x[0, d.X_POS + 2] = 1e4
    cmd = np.array([[p.rotor_speed_max_rad_s, p.rotor_speed_min_rad_s,
                     p.rotor_speed_max_rad_s, p.rotor_speed_min_rad_s]])
    step(plant, cmd, 5000)
    q = plant.x[0, d.X_QUAT:d.X_QUAT + 4]
    assert np.linalg.norm(q) == pytest.approx(1.0, abs=1e-12)
    assert np.all(np.isfinite(plant.x))


def test_rotor_energy_is_shaft_power_integrated():
    p = catalog()["1.20kg-JFRC"]
    plant = plant_for([p])
    plant.x[0, d.X_POS + 2] = 100.0
    w = p.hover_rotor_speed_rad_s
    plant.x[0, d.X_ROTOR:] = w
    step(plant, np.full((1, 4), w), 1000)
    power = 4 * p.torque_thrust_ratio_m * p.thrust_coefficient * w**3
    assert plant.status[0, d.S_ENERGY] == pytest.approx(power * 1.0, rel=1e-9)
