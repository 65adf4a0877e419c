"""Minimum-snap piecewise polynomials: interpolation, continuity, optimality, EGO helpers."""

import numpy as np
import pytest

from ft_sitl.navigation.trajectories.minsnap import (
    PiecewisePolynomial,
    ego_time_allocation,
    ego_waypoints,
    global_reference,
    min_snap,
    one_segment_time,
)


def _segment_derivative(pp: PiecewisePolynomial, i: int, s: float, order: int) -> np.ndarray:
    """d^order p / dt^order on segment i at normalised time s, straight from coefficients."""
    c = pp.coeffs[i]
    out = np.zeros(3)
    for k in range(order, c.shape[0]):
        fall = np.prod(np.arange(k - order + 1, k + 1)) if order else 1.0
        out += fall * s ** (k - order) * c[k]
    return out / pp.durations[i] ** order


def _random_problem(seed, m=5):
    rng = np.random.default_rng(seed)
    w = np.cumsum(rng.normal(size=(m + 1, 3)) * 3.0, axis=0)
    T = rng.uniform(0.6, 2.5, size=m)
    return w, T


@pytest.mark.parametrize("order", [3, 4])
def test_passes_through_the_waypoints(order):
    w, T = _random_problem(0)
    pp = min_snap(w, T, order=order)
    assert pp.degree == 2 * order - 1
    np.testing.assert_allclose(pp.waypoints(), w, atol=1e-9)
    np.testing.assert_allclose(pp.segment_times, np.concatenate([[0], np.cumsum(T)]))


@pytest.mark.parametrize("order", [3, 4])
def test_derivatives_are_continuous_at_the_waypoints(order):
    w, T = _random_problem(1)
    pp = min_snap(w, T, order=order)
    scale = np.abs(pp.coeffs).max()
    for i in range(pp.num_segments - 1):
        for m in range(0, 2 * order - 1):  # 0 .. 2r-2
            left = _segment_derivative(pp, i, 1.0, m)
            right = _segment_derivative(pp, i + 1, 0.0, m)
            np.testing.assert_allclose(left, right, atol=1e-8 * scale * 10 ** m, err_msg=m)
    # the (2r-1)-th derivative is generically not continuous: only the optimum is C^{2r-2}
    jumps = [np.abs(_segment_derivative(pp, i, 1.0, 2 * order - 1)
                    - _segment_derivative(pp, i + 1, 0.0, 2 * order - 1)).max()
             for i in range(pp.num_segments - 1)]
    assert max(jumps) > 1e-3


def test_end_conditions_are_met():
    w, T = _random_problem(2)
    v0, a0, v1, a1 = np.array([1.0, -2, 0.5]), np.array([0.3, 0, -1]), np.zeros(3), np.zeros(3)
    pp = min_snap(w, T, v0=v0, a0=a0, v1=v1, a1=a1, order=4)
    np.testing.assert_allclose(pp.velocity(0.0), v0, atol=1e-9)
    np.testing.assert_allclose(pp.acceleration(0.0), a0, atol=1e-9)
    np.testing.assert_allclose(pp.velocity(pp.duration), v1, atol=1e-9)
    np.testing.assert_allclose(pp.acceleration(pp.duration), a1, atol=1e-9)
    np.testing.assert_allclose(pp.evaluate(0.0, 3), 0.0, atol=1e-8)  # jerk fixed to 0
    np.testing.assert_allclose(pp.evaluate(pp.duration, 3), 0.0, atol=1e-8)


def test_one_segment_rest_to_rest_closed_forms():
    p0, p1, T = np.array([1.0, 2.0, 3.0]), np.array([4.0, -2.0, 5.0]), 2.0
    t = np.linspace(0, T, 41)
    s = t / T
    snap = min_snap(np.stack([p0, p1]), [T], order=4)
    shape7 = 35 * s ** 4 - 84 * s ** 5 + 70 * s ** 6 - 20 * s ** 7
    np.testing.assert_allclose(snap.position(t), p0 + np.outer(shape7, p1 - p0), atol=1e-12)
    dshape7 = (140 * s ** 3 - 420 * s ** 4 + 420 * s ** 5 - 140 * s ** 6) / T
    np.testing.assert_allclose(snap.velocity(t), np.outer(dshape7, p1 - p0), atol=1e-11)
    jerk = min_snap(np.stack([p0, p1]), [T], order=3)
    shape5 = 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5
    np.testing.assert_allclose(jerk.position(t), p0 + np.outer(shape5, p1 - p0), atol=1e-12)


def test_first_variation_vanishes_at_the_solution():
    """Optimality: for an admissible perturbation (zero at all waypoints, C^{r-1}, zero
    r-1 derivatives at its support's ends) spanning an interior waypoint,
    int p^(r) . delta^(r) dt = 0."""
    r = 4
    w, T = _random_problem(3, m=4)
    pp = min_snap(w, T, order=r)
    t0, t1, t2 = pp.segment_times[1:4]
    x, wq = np.polynomial.legendre.leggauss(20)

    def delta_r(t):
        # delta(t) = ((t - t0)(t2 - t))^r (t - t1): zero at t0, t1, t2, smooth across t1
        poly = np.polynomial.Polynomial([-t0, 1]) ** r * np.polynomial.Polynomial([t2, -1]) \
            ** r * np.polynomial.Polynomial([-t1, 1])
        return poly.deriv(r)(t)

    total = np.zeros(3)
    for a, b in ((t0, t1), (t1, t2)):
        tt = 0.5 * (b - a) * x + 0.5 * (a + b)
        # evaluate strictly inside each segment
        total += 0.5 * (b - a) * np.sum(
            (wq * delta_r(tt))[:, None] * pp.evaluate(tt, r), axis=0)
    scale = 0.5 * (t2 - t0) * np.abs(delta_r(np.linspace(t0, t2, 50))).max() * \
        np.abs(pp.evaluate(np.linspace(t0, t2, 50), r)).max()
    np.testing.assert_allclose(total, 0.0, atol=1e-9 * scale)


def test_ego_waypoints_every_4_m_and_time_allocation():
    w = ego_waypoints([0, 0, 1], [30, 0, 1])
    assert len(w) == 9  # floor(30 / 4) + 1 = 8 pieces
    np.testing.assert_allclose(np.diff(w[:, 0]), 3.75)
    assert len(ego_waypoints([0, 0, 1], [3, 0, 1])) == 2
    assert len(ego_waypoints([0, 0, 1], [8, 0, 1])) == 4  # floor(2) + 1 = 3 pieces
    T = ego_time_allocation(w, vmax=4.0)
    np.testing.assert_allclose(T, [2 * 3.75 / 4] + [3.75 / 4] * 6 + [2 * 3.75 / 4])
    np.testing.assert_allclose(ego_time_allocation(w[[0, -1]], 4.0), [4 * 30 / 4.0])


def test_one_segment_time_is_egos_formula():
    assert one_segment_time(2.0, vmax=4.0, amax=2.0) == pytest.approx(1.0)  # sqrt(d / a)
    assert one_segment_time(20.0, 4.0, 2.0) == pytest.approx((20 - 8) / 4 + 4)


def test_global_reference_is_a_straight_line_ending_at_rest():
    start, goal = np.array([0.0, 0.0, 1.0]), np.array([30.0, 10.0, 1.5])
    ref = global_reference(start, goal, vmax=4.0)
    t = np.linspace(0, ref.duration, 400)
    p = ref.position(t)
    u = (goal - start) / np.linalg.norm(goal - start)
    off = (p - start) - np.outer((p - start) @ u, u)
    assert np.abs(off).max() < 1e-8
    np.testing.assert_allclose(ref.position(ref.duration), goal, atol=1e-9)
    np.testing.assert_allclose(ref.velocity(ref.duration), 0.0, atol=1e-9)
    np.testing.assert_allclose(ref.velocity(0.0), 0.0, atol=1e-9)
    assert ref.length == pytest.approx(np.linalg.norm(goal - start), rel=1e-4)


def test_arc_length_helpers():
    ref = global_reference([0, 0, 1], [20, 0, 1], vmax=4.0)
    assert ref.arc_length(ref.duration) == pytest.approx(20.0, rel=1e-4)
    t5 = ref.time_at_arc_length(5.0)
    assert ref.position(t5)[0] == pytest.approx(5.0, abs=1e-3)
    t, p = ref.point_ahead(t5, 7.5)
    assert p[0] == pytest.approx(12.5, abs=1e-3) and t > t5
    t, p = ref.point_ahead(t5, 100.0)  # clamped at the goal
    np.testing.assert_allclose(p, [20, 0, 1], atol=1e-9)


def test_local_target_is_75_m_ahead_then_the_goal():
    ref = global_reference([0, 0, 1], [30, 0, 1], vmax=4.0)
    here = np.array([0.0, 0.0, 1.0])
    lt = ref.local_target(here, 0.0, horizon=7.5, vmax=4.0, amax=3.0)
    d = np.linalg.norm(lt.point - here)
    assert 7.5 <= d < 7.5 + 4.0 * (7.5 / 20 / 4.0) + 1e-9  # first sample beyond the horizon
    assert not lt.at_goal
    np.testing.assert_allclose(lt.velocity, ref.velocity(lt.time_s))
    assert lt.velocity[0] > 0
    # near the end: the goal itself, arriving at rest
    t_late = ref.time_at_arc_length(25.0)
    lt = ref.local_target(ref.position(t_late), t_late, 7.5, 4.0, 3.0)
    assert lt.at_goal and lt.time_s == pytest.approx(ref.duration)
    np.testing.assert_allclose(lt.point, [30, 0, 1])
    np.testing.assert_allclose(lt.velocity, 0.0)
    # goal within the braking distance v^2 / 2a of the target -> zero velocity
    t_mid = ref.time_at_arc_length(21.0)
    lt = ref.local_target(ref.position(t_mid), t_mid, 7.5, 4.0, 3.0)
    assert not lt.at_goal and np.linalg.norm([30, 0, 1] - lt.point) < 16 / 6
    np.testing.assert_allclose(lt.velocity, 0.0)
    t_far = ref.time_at_arc_length(16.0)  # goal 6.5 m beyond the target: keep the speed
    lt = ref.local_target(ref.position(t_far), t_far, 7.5, 4.0, 3.0)
    assert lt.velocity[0] > 1.0


def test_invalid_inputs_are_rejected():
    with pytest.raises(ValueError):
        min_snap(np.zeros((1, 3)), [])
    with pytest.raises(ValueError):
        min_snap(np.zeros((3, 3)), [1.0, -1.0])
    with pytest.raises(ValueError):
        min_snap(np.zeros((3, 3)), [1.0])
    with pytest.raises(ValueError):
        global_reference([0, 0, 0], [0, 0, 0], 4.0)
