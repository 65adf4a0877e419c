"""Setpoint rows for many vehicles at once: row for row the rows of the Setpoint
constructors, and the same values refused."""

import numpy as np
import pytest

from ft_sitl.autopilot.setpoints import (
    Setpoint,
    SetpointError,
    acceleration_rows,
    body_rate_rows,
    motor_rows,
    velocity_rows,
)

RNG = np.random.default_rng(3)
V = RNG.uniform(-5, 5, (6, 3))
R = RNG.uniform(-2, 2, 6)
T = RNG.uniform(0, 1, 6)


def same(a, b):
    assert np.array_equal(a, b, equal_nan=True)


def test_each_row_is_the_constructors_row():
    same(velocity_rows(V, R), np.stack([Setpoint.velocity(v, yaw_rate=r).offboard().row
                                        for v, r in zip(V, R)]))
    same(acceleration_rows(V, R),
         np.stack([Setpoint.acceleration(v, yaw_rate=r).offboard().row for v, r in zip(V, R)]))
    same(body_rate_rows(V, T),
         np.stack([Setpoint.body_rates(v, t).offboard().row for v, t in zip(V, T)]))
    u = RNG.uniform(0, 1, (6, 4))
    same(motor_rows(u), np.stack([Setpoint.motors(x).row for x in u]))


@pytest.mark.parametrize("call,match", [
    (lambda: velocity_rows(np.array([[0, 0, 0], [np.nan, 0, 0]]), [0, 0]),
     r"velocity: row 1 \[nan, 0.0, 0.0\] has non-finite"),
    (lambda: velocity_rows(np.zeros((2, 2)), [0, 0]), r"velocity: needs shape \(N, 3\)"),
    (lambda: acceleration_rows(np.zeros((2, 3)), [0, np.inf]), "yaw_rate: row 1"),
    (lambda: body_rate_rows(np.zeros((2, 3)), [0.5, 1.5]), r"thrust: row 1 \[1.5\] is outside"),
    (lambda: motor_rows(np.array([[0.5] * 4, [0.5, -0.1, 0.5, 0.5]])), "motors: row 1"),
    (lambda: motor_rows(np.zeros(4)), r"motors: needs shape \(N, 1..12\)"),
])
def test_bad_values_are_refused_by_row(call, match):
    with pytest.raises(SetpointError, match=match):
        call()
