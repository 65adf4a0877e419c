"""The estimator stage (ft_sitl.autopilot.estimator): latency delays the controller's
response by exactly the configured time; a bias moves the hover by the bias (the
controller holds its estimate on the setpoint) while the flight controller reports the
estimate; the noise has the configured variance and correlation; the truth as estimate
changes nothing; bad settings are named."""

import math

import numpy as np
import pytest

from ft_sitl.autopilot.estimator import Estimator
from ft_sitl.physics import dynamics as d
from ft_sitl.physics.catalog import catalog
from ft_sitl.physics.quaternion import qto_euler
from ft_sitl.schema import SchemaError
from ft_sitl.sim.fleet import Fleet
from ft_sitl.sim.lockstep import Simulation

PLATFORM = "1.00kg-SunnySky"
HOVER = [0.0, 0.0, 5.0]


def _hover(settings=None, seed=0, settle_s=1.0):
    sim = Simulation(catalog()[PLATFORM])
    sim.start_hovering(0, HOVER)
    sim.run(settle_s)
    if settings is not None:
        sim.set_estimator(0, settings, seed=seed)
    return sim


def _commands_after_a_push(sim, n):
    """Push the vehicle 1 m east (the truth jumps); the rotor commands of the next n steps."""
    sim.plant.x[0, d.X_POS] += 1.0
    out = []
    for _ in range(n):
        sim.step(1)
        out.append(sim.w_cmd[0].copy())
    return np.array(out)


def test_latency_delays_the_controllers_response_by_exactly_the_latency():
    lag_steps = 40  # 40 ms at 1 kHz
    truth = _hover()
    late = _hover({"position_latency_s": 0.040, "velocity_latency_s": 0.040,
                   "attitude_latency_s": 0.040, "rate_latency_s": 0.040})
    hover_cmd = truth.w_cmd[0].copy()
    w_truth = _commands_after_a_push(truth, 100)
    w_late = _commands_after_a_push(late, 100)

    def first_response(w):
        return int(np.flatnonzero(np.abs(w - hover_cmd).max(axis=1) > 0.5)[0])

    assert first_response(w_truth) == 0  # the step right after the push
    assert first_response(w_late) == lag_steps  # exactly the latency later
    # and the late controller's first reaction is the prompt one's, delayed
    np.testing.assert_allclose(w_late[lag_steps], w_truth[0], rtol=1e-9)


def test_a_bias_moves_the_vehicle_and_the_flight_controller_reports_its_estimate():
    fleet = Fleet(catalog()[PLATFORM], spawn=[[0.0, 0.0, 0.0]])
    fleet.sim.start_hovering(0, HOVER)
    bias = np.array([0.8, -0.5, 0.3])
    fleet.sim.set_estimator(0, {"position_bias_m": bias.tolist(),
                                "attitude_bias_deg": [0.0, 0.0, 10.0]})
    fleet.sim.run(8.0)
    believed, true = fleet.state(0), fleet.true_state(0)
    # the controller holds its estimate on the setpoint: the truth sits off by the bias
    np.testing.assert_allclose(believed.position, HOVER, atol=0.01)
    np.testing.assert_allclose(true.position, np.array(HOVER) - bias, atol=0.01)
    assert math.degrees(believed.yaw) == pytest.approx(0.0, abs=0.2)
    assert math.degrees(true.yaw) == pytest.approx(-10.0, abs=0.2)


@pytest.mark.parametrize("tau", [0.0, 0.05])
def test_the_noise_has_the_configured_deviation_and_correlation(tau):
    sigma = 0.2
    sim = _hover({"position_noise_m": sigma, "noise_correlation_s": tau}, seed=7)
    err = []
    for _ in range(20_000):
        sim.step(1)
        err.append(sim.xe[0, d.X_POS:d.X_POS + 3] - sim.x[0, d.X_POS:d.X_POS + 3])
    e = np.array(err)  # (steps, 3): the estimate's error, the noise alone
    assert e.std(axis=0) == pytest.approx([sigma] * 3, rel=0.1 if tau else 0.03)
    lag = max(1, round(tau / sim.dt))
    rho = np.mean([np.corrcoef(e[:-lag, j], e[lag:, j])[0, 1] for j in range(3)])
    assert rho == pytest.approx(math.exp(-1.0) if tau else 0.0, abs=0.06)
    # seeded: the same seed, the same noise; another seed, other noise
    again = _hover({"position_noise_m": sigma, "noise_correlation_s": tau}, seed=7)
    other = _hover({"position_noise_m": sigma, "noise_correlation_s": tau}, seed=8)
    for s in (again, other):
        s.step(20_000)
    assert np.array_equal(again.x, sim.x) and not np.array_equal(other.x, sim.x)


def test_the_truth_as_estimate_changes_nothing():
    plain = _hover()
    for settings in ({}, Estimator(), None):
        sim = _hover()
        sim.set_estimator(0, settings)
        assert not sim.estimating(0)
        for s in (plain, sim):
            s.run(0.5)
        assert np.array_equal(sim.x, plain.x)
        plain = _hover()
    assert np.allclose(qto_euler(plain.attitude(0)), 0.0, atol=1e-6)


@pytest.mark.parametrize("settings,named", [
    ({"position_latency_s": 2.0}, "position_latency_s: must be a number 0..1"),
    ({"position_bias_m": [1.0, 2.0]}, "position_bias_m: must be 3 numbers"),
    ({"attitude_noise_deg": -1.0}, "attitude_noise_deg"),
    ({"rate_noise": 0.1}, "rate_noise"),
])
def test_bad_settings_are_named(settings, named):
    with pytest.raises(SchemaError, match=named):
        Estimator(settings)
