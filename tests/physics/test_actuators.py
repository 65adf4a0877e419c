"""Imperfect actuators (ft_sitl.physics.actuators): a failed motor stops and shows in the
allocation's saturation while the vehicle tumbles and falls; a degraded motor makes the
others work harder; added lag slows the motors; command noise is seeded; nominal
actuators change nothing; bad settings are named."""

import numpy as np
import pytest

from ft_sitl.physics import dynamics as d
from ft_sitl.physics.actuators import Actuators
from ft_sitl.physics.catalog import catalog
from ft_sitl.schema import SchemaError
from ft_sitl.sim.lockstep import Simulation

PLATFORM = "1.00kg-SunnySky"


def _hover(settings=None, seed=0):
    sim = Simulation(catalog()[PLATFORM])
    sim.start_hovering(0, [0.0, 0.0, 5.0])
    sim.run(1.0)
    sim.set_actuators(0, settings, seed=seed)
    return sim


def test_a_failed_motor_stops_and_saturates_the_allocation():
    sim = _hover({"fail_motor": 2, "fail_at_s": 0.5})
    sat0 = sim.saturation_fraction(0) * sim.steps
    sim.run(0.5)
    before = sim.saturation_fraction(0) * sim.steps
    assert before == pytest.approx(sat0)  # hovering: nothing at a limit yet
    assert np.linalg.norm(sim.velocity(0)) < 0.05
    sim.run(1.0)
    w = sim.rotor_speeds(0)
    assert w[1] < 1.0  # motor 2 (index 1) has spun down
    assert all(w[j] > 100.0 for j in (0, 2, 3))
    after = sim.saturation_fraction(0) * sim.steps
    assert after - before > 100  # the others sit at their limits for over 0.1 s of 1 s
    # a quadrotor without one motor cannot hold its attitude: it tumbles and falls
    assert np.abs(sim.x[0, d.X_OMEGA:d.X_OMEGA + 2]).max() > 2.0
    assert sim.position(0)[2] < 4.0


def test_a_degraded_motor_makes_the_others_work_and_lag_slows_the_motors():
    nominal = _hover()
    weak = _hover({"degraded_motor": 1, "degraded_efficiency": 0.7})
    for sim in (nominal, weak):
        sim.run(3.0)
    wn, ww = nominal.rotor_speeds(0), weak.rotor_speeds(0)
    assert ww[0] > wn[0] * 1.1  # the weak motor spins faster for its share
    assert np.linalg.norm(weak.position(0) - [0.0, 0.0, 5.0]) < 0.1  # and it still hovers
    p = catalog()[PLATFORM]
    slow = _hover({"lag_s": 0.05})
    assert slow.plant.prm[0, d.P_TAU_UP] == pytest.approx(p.motor_tau_up_s + 0.05)
    assert slow.plant.prm[0, d.P_TAU_DN] == pytest.approx(p.motor_tau_down_s + 0.05)
    slow.set_actuators(0, None)  # back to the platform's own
    assert slow.plant.prm[0, d.P_TAU_UP] == p.motor_tau_up_s


def test_command_noise_is_seeded_and_nominal_actuators_change_nothing():
    a, b, c = (_hover({"noise": 0.02}, seed=s) for s in (4, 4, 5))
    for sim in (a, b, c):
        sim.run(1.0)
    assert np.array_equal(a.x, b.x) and not np.array_equal(a.x, c.x)
    plain, nominal = _hover(), _hover({"efficiency": 1.0, "lag_s": 0.0})
    for sim in (plain, nominal):
        sim.run(1.0)
    assert np.array_equal(plain.x, nominal.x)
    assert Actuators().nominal and not Actuators({"noise": 0.01}).nominal


@pytest.mark.parametrize("values,message", [
    ({"efficiency": 1.5}, "efficiency: must be a number 0.05..1"),
    ({"fail_motor": 5}, "fail_motor: 5 must be within 0..4 (the platform's motors)"),
    ({"noise": -0.1}, "noise: must be a number 0..0.2"),
    ({"lag": 0.1}, "has no parameter 'lag'; did you mean 'lag_s'?"),
])
def test_bad_actuator_settings_are_named(values, message):
    with pytest.raises(SchemaError) as exc:
        Actuators(values, n_rotors=4)
    assert message in str(exc.value)
