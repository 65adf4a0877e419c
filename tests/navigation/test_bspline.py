"""B-splines, both evaluations (matrix form and de Boor): against scipy and finite
differences, against each other, fitting, re-timing."""

import numpy as np
import pytest
from scipy.interpolate import BSpline as ScipyBSpline

from ft_sitl.navigation.trajectories.bspline import (
    BSpline,
    Evaluation,
    basis_matrix,
    fit_samples,
)

BOTH = list(Evaluation)


def _random_spline(degree=3, n=12, dt=0.3, seed=0, evaluation=Evaluation.MATRIX):
    rng = np.random.default_rng(seed)
    return BSpline(rng.normal(size=(n, 3)) * 2.0, dt, degree, evaluation=evaluation)


def test_cubic_basis_matrix_is_the_textbook_one():
    expected = np.array([[1, 4, 1, 0], [-3, 0, 3, 0], [3, -6, 3, 0], [-1, 3, -3, 1]]) / 6.0
    np.testing.assert_allclose(basis_matrix(3), expected, atol=1e-15)


@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_basis_is_a_partition_of_unity(degree):
    s = np.linspace(0, 1, 11)
    powers = s[:, None] ** np.arange(degree + 1)[None, :]
    w = powers @ basis_matrix(degree)
    np.testing.assert_allclose(w.sum(axis=1), 1.0, atol=1e-12)
    assert np.all(w >= -1e-12)


@pytest.mark.parametrize("evaluation", BOTH)
@pytest.mark.parametrize("degree", [1, 2, 3, 4, 5])
def test_evaluation_matches_scipy_bspline_with_the_same_knots(degree, evaluation):
    sp = _random_spline(degree=degree, n=10, dt=0.25, seed=degree, evaluation=evaluation)
    n = sp.num_control_points
    knots = (np.arange(n + degree + 1) - degree) * sp.dt
    ref = ScipyBSpline(knots, np.array(sp.control_points), degree)
    t = np.concatenate([np.linspace(0, sp.duration, 97), sp.knot_times()])
    assert sp.duration == pytest.approx((n - degree) * 0.25)
    for order in range(degree + 1):
        want = ref(t, nu=order) if order else ref(t)
        np.testing.assert_allclose(sp.evaluate(t, order), want, atol=1e-9, rtol=1e-9)
    np.testing.assert_allclose(sp.to_scipy()(t), ref(t), atol=1e-12)


@pytest.mark.parametrize("evaluation", BOTH)
def test_scalar_and_vector_evaluation_agree_and_domain_is_clamped(evaluation):
    sp = _random_spline(evaluation=evaluation)
    t = np.array([0.0, 0.41, 1.7, sp.duration])
    vec = sp.position(t)
    for i, ti in enumerate(t):
        assert sp.position(ti).shape == (3,)
        np.testing.assert_allclose(sp.position(ti), vec[i])
    np.testing.assert_allclose(sp.position(-1.0), sp.position(0.0))
    np.testing.assert_allclose(sp.position(sp.duration + 5), sp.position(sp.duration))
    assert np.all(sp.evaluate(t, 4) == 0.0)


@pytest.mark.parametrize("evaluation", BOTH)
@pytest.mark.parametrize("degree", [1, 2, 3, 5])
def test_pva_is_evaluate_of_orders_0_to_2_at_one_time(degree, evaluation):
    sp = _random_spline(degree=degree, n=9, dt=0.37, seed=10 + degree, evaluation=evaluation)
    # inside, on the knots, and clamped outside the domain
    times = np.concatenate([np.linspace(-0.5, sp.duration + 0.5, 41), sp.knot_times()])
    for t in times:
        p, v, a = sp.pva(float(t))
        for order, got in enumerate((p, v, a)):
            np.testing.assert_allclose(got, sp.evaluate(t, order), rtol=0, atol=1e-12)
    if degree == 1:
        assert np.all(sp.pva(0.1)[2] == 0.0)  # above the degree: zero


@pytest.mark.parametrize("evaluation", BOTH)
def test_derivatives_match_central_finite_differences(evaluation):
    sp = _random_spline(seed=3, evaluation=evaluation)
    h = 1e-5
    # stay away from the knots, where the third derivative jumps
    t = (np.arange(sp.num_segments) + 0.37) * sp.dt
    for order, fn in ((1, sp.velocity), (2, sp.acceleration), (3, sp.jerk)):
        lower = sp.evaluate(t, order - 1)
        fd = (sp.evaluate(t + h, order - 1) - sp.evaluate(t - h, order - 1)) / (2 * h)
        np.testing.assert_allclose(fn(t), fd, rtol=1e-5, atol=1e-5 * (1 + np.abs(lower).max()))


@pytest.mark.parametrize("evaluation", BOTH)
def test_derivative_spline_has_difference_control_points_and_same_domain(evaluation):
    sp = _random_spline(seed=4, evaluation=evaluation)
    vel = sp.derivative()
    acc = sp.derivative(2)
    np.testing.assert_allclose(vel.control_points, np.diff(sp.control_points, axis=0) / sp.dt)
    np.testing.assert_allclose(acc.control_points, sp.acceleration_control_points())
    assert vel.degree == 2 and acc.degree == 1
    assert vel.evaluation is acc.evaluation is evaluation
    assert vel.duration == pytest.approx(sp.duration) == pytest.approx(acc.duration)
    t = np.linspace(0, sp.duration, 41)
    np.testing.assert_allclose(vel.position(t), sp.velocity(t), atol=1e-10)
    np.testing.assert_allclose(acc.position(t), sp.acceleration(t), atol=1e-9)
    # scipy's derivative has the same coefficients
    ref = sp.to_scipy().derivative()
    np.testing.assert_allclose(ref.c[:vel.num_control_points], vel.control_points, atol=1e-10)


def test_velocity_control_points_bound_the_curve_velocity_per_axis():
    sp = _random_spline(seed=5)
    t = np.linspace(0, sp.duration, 500)
    vmax_curve = np.abs(sp.velocity(t)).max(axis=0)
    vmax_ctrl = np.abs(sp.velocity_control_points()).max(axis=0)
    assert np.all(vmax_curve <= vmax_ctrl + 1e-12)


def test_fit_recovers_a_spline_from_its_own_knots_and_end_derivatives():
    sp = _random_spline(seed=6, n=15, dt=0.2)
    T = sp.duration
    fit = BSpline.fit(sp.knot_points(), sp.dt, sp.velocity(0.0), sp.velocity(T),
                             sp.acceleration(0.0), sp.acceleration(T))
    np.testing.assert_allclose(fit.control_points, sp.control_points, atol=1e-9)


def test_fit_of_a_constant_speed_line_is_that_line():
    v = np.array([2.0, -1.0, 0.5])
    pts = np.array([1.0, 2.0, 3.0]) + np.arange(9)[:, None] * 0.1 * v
    sp = BSpline.fit(pts, 0.1, v, v, np.zeros(3), np.zeros(3))
    assert sp.num_control_points == 9 + 2
    t = np.linspace(0, sp.duration, 30)
    np.testing.assert_allclose(sp.velocity(t), np.tile(v, (30, 1)), atol=1e-9)
    np.testing.assert_allclose(sp.knot_points(), pts, atol=1e-9)


def test_fit_is_the_least_squares_solution_of_the_sample_and_end_equations():
    """Built independently from scipy's basis functions: K position rows at the knots plus
    velocity and acceleration rows at both ends, solved in the least-squares sense."""
    rng = np.random.default_rng(9)
    pts = np.cumsum(rng.normal(size=(8, 3)), axis=0)
    v0, v1, a0, a1 = rng.normal(size=(4, 3))
    dt, k = 0.4, 3
    n = len(pts) + 2
    knots = (np.arange(n + k + 1) - k) * dt
    T = (n - k) * dt
    t = np.arange(len(pts)) * dt

    def basis(j, order, at):
        c = np.zeros(n)
        c[j] = 1.0
        b = ScipyBSpline(knots, c, k)
        return (b.derivative(order) if order else b)(at)

    rows = [[basis(j, 0, ti) for j in range(n)] for ti in t]
    rows += [[basis(j, o, at) for j in range(n)] for o, at in ((1, 0.0), (1, T), (2, 0.0),
                                                                 (2, T))]
    rhs = np.vstack([pts, v0, v1, a0, a1])
    want, *_ = np.linalg.lstsq(np.array(rows), rhs, rcond=None)
    sp = BSpline.fit(pts, dt, v0, v1, a0, a1)
    np.testing.assert_allclose(sp.control_points, want, atol=1e-9)


def test_stretch_time_scales_velocity_and_acceleration():
    sp = _random_spline(seed=7)
    st = sp.stretch_time(1.5)
    t = np.linspace(0, sp.duration, 23)
    assert st.duration == pytest.approx(1.5 * sp.duration)
    np.testing.assert_allclose(st.position(1.5 * t), sp.position(t), atol=1e-12)
    np.testing.assert_allclose(st.velocity(1.5 * t), sp.velocity(t) / 1.5, atol=1e-12)
    np.testing.assert_allclose(st.acceleration(1.5 * t), sp.acceleration(t) / 2.25, atol=1e-10)


def test_feasibility_ratio_makes_a_stretched_spline_feasible():
    sp = _random_spline(seed=8, dt=0.1)
    f = sp.feasibility(vmax=2.0, amax=3.0)
    assert not f.ok and f.ratio > 1.0
    vel = sp.velocity_control_points()
    acc = sp.acceleration_control_points()
    assert f.max_vel == pytest.approx(np.abs(vel).max())
    assert f.max_acc == pytest.approx(np.abs(acc).max())
    assert f.ratio == pytest.approx(max(f.max_vel / 2.0, np.sqrt(f.max_acc / 3.0)))
    g = sp.stretch_time(f.ratio).feasibility(vmax=2.0, amax=3.0)
    assert g.ok and g.ratio == pytest.approx(1.0)
    # the tolerance admits 5 % more
    tight = sp.stretch_time(f.ratio / 1.04).feasibility(2.0, 3.0, tolerance=0.05)
    assert tight.ok


def test_fit_samples_follows_ego_spacing_rules_and_ends_on_the_end_point():
    start, end = np.zeros(3), np.array([7.5, 0.0, 0.0])
    duration = 2.5

    def line(t):
        return start + (end - start) * (np.asarray(t) / duration)[:, None]

    pts, dt = fit_samples(line, duration, max_vel=4.0)
    nominal = 0.4 / 4.0 * 1.2
    assert dt <= nominal + 1e-12
    assert len(pts) >= 7
    np.testing.assert_allclose(pts[-1], end)
    assert np.linalg.norm(np.diff(pts, axis=0), axis=1).max() <= 0.6 + 1e-12
    # a faster path forces shorter spans (the too-far rule)
    pts2, dt2 = fit_samples(line, duration, max_vel=1.0)
    assert np.linalg.norm(np.diff(pts2, axis=0), axis=1).max() <= 0.6 + 1e-12
    assert dt2 < 0.4 / 1.0 * 1.2
    # short path: at least 7 samples
    pts3, _ = fit_samples(line, 0.2, max_vel=4.0)
    assert len(pts3) == 7


def test_invalid_inputs_are_rejected():
    with pytest.raises(ValueError):
        BSpline(np.zeros((3, 3)), 0.1, 3)
    with pytest.raises(ValueError):
        BSpline(np.zeros((5, 3, 1)), 0.1, 3)
    with pytest.raises(ValueError):
        BSpline(np.zeros((5, 3)), 0.0, 3)
    with pytest.raises(ValueError):
        BSpline.fit(np.zeros((1, 3)), 0.1, *np.zeros((4, 3)))
    with pytest.raises(ValueError):
        _random_spline().stretch_time(-1.0)
    sp = _random_spline()
    with pytest.raises(ValueError):
        sp.control_points[0, 0] = 1.0  # read-only
    with pytest.raises(ValueError):
        sp.knots[0] = 1.0
    # dt or knots, not both, not neither; the matrix form needs uniform knots
    with pytest.raises(ValueError):
        BSpline(np.zeros((5, 3)), 0.1, knots=np.arange(9.0))
    with pytest.raises(ValueError):
        BSpline(np.zeros((5, 3)))
    with pytest.raises(ValueError):
        BSpline(np.zeros((5, 3)), knots=np.arange(9.0), evaluation=Evaluation.MATRIX)
    with pytest.raises(ValueError):
        BSpline(np.zeros((5, 3)), knots=[0, 1, 2, 2, 3, 4, 5, 6, 7])  # not increasing
    with pytest.raises(ValueError):
        BSpline(np.zeros((5, 3)), knots=np.arange(8.0))  # one short
    with pytest.raises(ValueError):
        BSpline(np.zeros((5, 3)), knots=np.arange(9.0)).stretch_time(2.0)  # no single dt
    with pytest.raises(ValueError):
        _random_spline(degree=4).reallocate_time(1.0, 1.0)  # Fast-Planner's: cubic only
    with pytest.raises(ValueError):
        _random_spline(degree=2).lengthen_time(1.5)
    with pytest.raises(ValueError):
        _random_spline().lengthen_time(0.0)


@pytest.mark.parametrize("degree", [1, 2, 3, 4])
def test_the_two_evaluations_are_the_same_curve(degree):
    """Matrix form and de Boor agree to rounding on uniform knots (not bit for bit: they
    are different operations, which is why the choice is the constructor's)."""
    mat = _random_spline(degree=degree, n=11, dt=0.21, seed=20 + degree)
    boor = mat.with_evaluation(Evaluation.DE_BOOR)
    assert boor.evaluation is Evaluation.DE_BOOR and mat.evaluation is Evaluation.MATRIX
    assert boor.duration == mat.duration and boor.uniform and boor.dt == mat.dt
    np.testing.assert_array_equal(boor.knots, mat.knots)
    t = np.concatenate([np.linspace(-0.2, mat.duration + 0.2, 53), mat.knot_times()])
    for order in range(degree + 2):
        np.testing.assert_allclose(boor.evaluate(t, order), mat.evaluate(t, order),
                                   rtol=1e-9, atol=1e-9)
    for order in range(degree + 1):
        np.testing.assert_allclose(boor.derivative_control_points(order),
                                   mat.derivative_control_points(order), rtol=1e-12,
                                   atol=1e-9)
    for ti in t[::7]:
        for a, b in zip(boor.pva(float(ti)), mat.pva(float(ti))):
            np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
    # operations keep the evaluation they were asked for
    assert boor.stretch_time(1.5).evaluation is Evaluation.DE_BOOR
    assert boor.with_control_points(mat.control_points * 2).evaluation is Evaluation.DE_BOOR
    assert mat.stretch_time(1.5).evaluation is Evaluation.MATRIX


def test_any_dimension_and_non_uniform_knots():
    rng = np.random.default_rng(7)
    knots = np.cumsum(rng.uniform(0.1, 0.5, 12))
    yaw = BSpline(rng.normal(size=8), knots=knots)  # 1-D: one column
    assert yaw.control_points.shape == (8, 1) and yaw.dim == 1
    assert yaw.evaluation is Evaluation.DE_BOOR and not yaw.uniform
    assert yaw.duration == pytest.approx(knots[8] - knots[3])
    ref = ScipyBSpline(knots, yaw.control_points, 3)
    t = np.linspace(0, yaw.duration, 31)
    np.testing.assert_allclose(yaw.position(t), ref(t + knots[3]), atol=1e-12)
    np.testing.assert_allclose(yaw.knot_times(), knots[3:9] - knots[3])
    # derivative control points from knot differences bound the velocity (convex hull)
    v = yaw.velocity(np.linspace(0, yaw.duration, 400))
    assert np.abs(v).max() <= np.abs(yaw.velocity_control_points()).max() + 1e-12
    vel = yaw.derivative()
    np.testing.assert_allclose(vel.position(t), yaw.velocity(t), atol=1e-10)
    plane = BSpline(rng.normal(size=(9, 2)), 0.2)  # 2-D, matrix form
    assert plane.position(0.3).shape == (2,) and plane.pva(0.3)[2].shape == (2,)


def test_lengthen_time_keeps_the_shape_and_the_end_speeds():
    sp = _random_spline(seed=8, n=14, dt=0.2)
    out = sp.lengthen_time(1.4)
    assert out.evaluation is Evaluation.DE_BOOR
    np.testing.assert_array_equal(out.control_points, sp.control_points)
    # the duration grows by 0.4 of the stretched spans' (all but the first two and last two)
    assert out.duration == pytest.approx(sp.duration + 0.4 * (sp.num_segments - 4) * sp.dt)
    np.testing.assert_allclose(out.velocity(0.0), sp.velocity(0.0), atol=1e-9)
    np.testing.assert_allclose(out.velocity(out.duration), sp.velocity(sp.duration),
                               atol=1e-9)
    np.testing.assert_allclose(out.position(out.duration), sp.position(sp.duration),
                               atol=1e-9)
    # too few knots to keep the ends: a uniform stretch
    short = _random_spline(seed=9, n=7, dt=0.2).lengthen_time(2.0)
    assert short.duration == pytest.approx(2.0 * 4 * 0.2)
