"""EGO-Planner's optimiser: cost gradients, anchors, rebound optimisation, refinement."""

import numpy as np
import pytest
from scipy.optimize import minimize

from ft_sitl.navigation.optimisers import ego as eo
from ft_sitl.navigation.optimisers import lbfgs
from ft_sitl.navigation.optimisers.ego import (
    Anchors,
    EgoOptimizer,
    EgoParams,
    EgoStatus,
    anchors_for_segment,
    check_end_index,
    colliding_segments,
    collision_cost,
    feasibility_cost,
    first_collision_time,
    fitness_cost,
    smoothness_cost,
)
from ft_sitl.navigation.planners.astar import OccupancyView, search
from ft_sitl.navigation.trajectories.bspline import BSpline, fit_samples

RES = 0.1
INFLATION = 0.1  # one voxel, as the local map inflates
BOX_CENTRE = np.array([3.5, 0.05, 1.0])
BOX_HALF = np.array([0.3, 0.5, 3.0])  # a pillar across the straight path


def _box_world(centre=BOX_CENTRE, half=BOX_HALF):
    """Inflated box plus floor and ceiling, like the local map's view."""

    def occupied(p):
        inside = np.all(np.abs(p - centre) <= half + INFLATION, axis=1)
        return inside | (p[:, 2] < 0.0) | (p[:, 2] > 3.0)

    return OccupancyView(occupied, RES)


START = np.array([0.0, 0.0, 1.0])
GOAL = np.array([7.5, 0.0, 1.0])
SPEED = 3.0
VEL = (GOAL - START) / np.linalg.norm(GOAL - START) * SPEED
ZERO = np.zeros(3)


def _straight_spline(speed=SPEED, vmax=4.0):
    """EGO's initial path: the straight line flown at constant speed, sampled and fitted."""
    duration = np.linalg.norm(GOAL - START) / speed
    vel = (GOAL - START) / duration

    def line(t):
        return START + (GOAL - START) * (np.asarray(t) / duration)[:, None]

    pts, dt = fit_samples(line, duration, vmax)
    return BSpline.fit(pts, dt, vel, vel, ZERO, ZERO), vel


def _numeric_grad(fun, q, h=1e-6):
    g = np.zeros_like(q)
    for i in range(q.shape[0]):
        for d in range(3):
            qp, qm = q.copy(), q.copy()
            qp[i, d] += h
            qm[i, d] -= h
            g[i, d] = (fun(qp) - fun(qm)) / (2 * h)
    return g


def _q(seed, n=14, scale=1.0):
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(size=(n, 3)) * scale, axis=0)


# ---- cost terms -------------------------------------------------------------------------
def test_smoothness_is_the_squared_jerk_differences_with_exact_gradient():
    q = _q(0)
    f, g = smoothness_cost(q)
    jerk = q[3:] - 3 * q[2:-1] + 3 * q[1:-2] - q[:-3]
    assert f == pytest.approx(np.sum(jerk ** 2))
    np.testing.assert_allclose(g, _numeric_grad(lambda x: smoothness_cost(x)[0], q),
                               rtol=1e-6, atol=1e-6)
    line = np.outer(np.arange(10), [1.0, 2.0, 0.5])
    assert smoothness_cost(line)[0] == pytest.approx(0.0, abs=1e-20)


def test_collision_cost_shape_continuity_and_gradient():
    c0 = 0.5
    # one pair on point 0 along +x through the origin: d = x, e = c0 - x
    e = np.linspace(-0.3, 1.5, 1801)
    q = np.zeros((1, 3))
    vals = []
    for ei in e:
        q[0, 0] = c0 - ei
        vals.append(collision_cost(q, np.array([0]), np.zeros((1, 3)), np.array([[1.0, 0, 0]]),
                                   c0)[0])
    vals = np.array(vals)
    want = np.where(e <= 0, 0.0, np.where(e <= c0, e ** 3, 1.5 * e ** 2 - 0.75 * e + 0.125))
    np.testing.assert_allclose(vals, want, atol=1e-14)
    # C2 at the demarcation e = c0 and at e = 0
    for a, b in ((lambda x: x ** 3, lambda x: 1.5 * x ** 2 - 0.75 * x + 0.125),):
        for k, (fa, fb) in enumerate(((a(c0), b(c0)), (3 * c0 ** 2, 3 * c0 - 0.75),
                                      (6 * c0, 3.0))):
            assert fa == pytest.approx(fb), k
    # gradient with several pairs in all three regimes, some on the same point
    q = _q(1, n=8, scale=0.3)
    rng = np.random.default_rng(2)
    idx = np.array([3, 3, 4, 5, 6, 4])
    v = rng.normal(size=(6, 3))
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    offsets = np.array([-0.2, 0.2, 0.8, 0.45, 1.2, 0.05])  # d values -> e = 0.5 - d
    p = q[idx] - offsets[:, None] * v
    f, g = collision_cost(q, idx, p, v, c0)
    assert f > 0
    np.testing.assert_allclose(
        g, _numeric_grad(lambda x: collision_cost(x, idx, p, v, c0)[0], q), rtol=1e-6,
        atol=1e-7)


def test_feasibility_cost_is_zero_within_limits_and_has_exact_gradient():
    dt = 0.12
    q = np.outer(np.arange(12) * dt, [3.0, -2.0, 1.0])  # 3 m/s at most per axis
    f, g = feasibility_cost(q, dt, vmax=4.0, amax=3.0)
    assert f == 0.0 and not g.any()
    q = _q(3, n=12, scale=0.5)
    f, g = feasibility_cost(q, dt, vmax=4.0, amax=3.0)
    vel = np.diff(q, axis=0) / dt
    acc = np.diff(q, 2, axis=0) / dt ** 2
    want = (np.sum(np.maximum(np.abs(vel) - 4.0, 0) ** 2) / dt ** 2
            + np.sum(np.maximum(np.abs(acc) - 3.0, 0) ** 2))
    assert f == pytest.approx(want) and f > 0
    np.testing.assert_allclose(
        g, _numeric_grad(lambda x: feasibility_cost(x, dt, 4.0, 3.0)[0], q, h=1e-7),
        rtol=1e-5, atol=1e-3)


def test_fitness_cost_weights_along_tangent_1_25_and_across_1():
    n = 12
    ref = np.outer(np.arange(n - 2), [0.4, 0.0, 0.0])  # straight reference along x
    spline_knots = BSpline.fit(ref, 0.1, [4, 0, 0], [4, 0, 0], ZERO, ZERO)
    q = np.array(spline_knots.control_points)
    f0, _ = fitness_cost(q, ref)
    assert f0 == pytest.approx(0.0, abs=1e-12)
    along = q + np.array([0.1, 0.0, 0.0])
    across = q + np.array([0.0, 0.1, 0.0])
    n_terms = n - 4
    assert fitness_cost(along, ref)[0] == pytest.approx(n_terms * 0.01 / 25.0)
    assert fitness_cost(across, ref)[0] == pytest.approx(n_terms * 0.01)
    q = _q(4, n=n)
    ref = _q(5, n=n - 2)
    np.testing.assert_allclose(fitness_cost(q, ref)[1],
                               _numeric_grad(lambda x: fitness_cost(x, ref)[0], q),
                               rtol=1e-6, atol=1e-6)


def test_combined_cost_gradient_matches_finite_differences():
    q = _q(6, n=16, scale=0.4)
    idx = np.array([4, 5, 7])
    v = np.array([[0, 1.0, 0], [0, 0.6, 0.8], [1.0, 0, 0]])
    p = q[idx] - np.array([0.1, 0.3, 0.9])[:, None] * v
    w = np.array([1.0, 0.5, 0.1, 1.0])
    ref = _q(7, n=14, scale=0.4)
    tan = eo.fitness_tangents(ref)

    def total(x, mode):
        g = np.zeros_like(x)
        return eo._total_cost(x, g, mode, w, 0.5, 0.12, 4.0, 3.0, idx, p, v, ref, tan, 25.0,
                              1.0), g

    for mode in (0, 1):
        _, g = total(q, mode)
        np.testing.assert_allclose(g, _numeric_grad(lambda x, m=mode: total(x, m)[0], q, h=1e-7),
                                   rtol=1e-5, atol=1e-3)


def test_lbfgs_reaches_scipys_minimum_on_a_convex_problem():
    """Smoothness + fitness (feasibility inactive) is a convex quadratic: our L-BFGS and
    scipy's L-BFGS-B must find the same minimiser."""
    rng = np.random.default_rng(8)
    n = 20
    ref = np.cumsum(rng.normal(size=(n - 2, 3)) * 0.3, axis=0)
    q0 = BSpline.fit(ref, 0.5, ZERO, ZERO, ZERO, ZERO).control_points.copy()
    q0[3:-3] += rng.normal(size=(n - 6, 3)) * 0.3
    w = np.array([1.0, 0.0, 0.1, 1.0])
    args = (1, w, 0.5, 0.5, 100.0, 100.0, np.zeros(0, dtype=np.int64), np.zeros((0, 3)),
            np.zeros((0, 3)), ref, eo.fitness_tangents(ref), 25.0, 1.0)
    ours = q0.copy()
    solver = eo._Lbfgs(ours, 16, 1000, 1e-9, args)
    # converged, or stopped when round-off no longer lets the line search decrease f
    assert solver.run() in (lbfgs.CONVERGED, lbfgs.LINE_SEARCH)

    def fun(x):
        q = q0.copy()
        q[3:-3] = x.reshape(-1, 3)
        g = np.zeros_like(q)
        f = eo._total_cost(q, g, *args)
        return f, g[3:-3].ravel()

    ref_res = minimize(fun, q0[3:-3].ravel(), jac=True, method="L-BFGS-B",
                       options={"maxcor": 16, "maxiter": 5000, "gtol": 1e-12, "ftol": 1e-15})
    np.testing.assert_allclose(ours[3:-3].ravel(), ref_res.x, atol=1e-5)
    np.testing.assert_array_equal(ours[:3], q0[:3])  # ends fixed
    np.testing.assert_array_equal(ours[-3:], q0[-3:])


# ---- anchors ----------------------------------------------------------------------------
def test_check_end_index_is_egos_first_two_thirds():
    assert check_end_index(24) == 21 - 18 // 3
    assert check_end_index(7) == 4 - 1 // 3


def test_colliding_segments_bracket_the_obstacle():
    sp, _ = _straight_spline()
    q = np.array(sp.control_points)
    grid = _box_world()
    segs = colliding_segments(q, grid)
    assert len(segs) == 1
    a, b = segs[0]
    lo_x = BOX_CENTRE[0] - BOX_HALF[0] - INFLATION
    hi_x = BOX_CENTRE[0] + BOX_HALF[0] + INFLATION
    assert q[a, 0] < lo_x < q[a + 1, 0]  # the last point before the obstacle
    assert q[b - 1, 0] < hi_x < q[b, 0]  # the first point after it
    far = _box_world(centre=np.array([3.5, 5.0, 1.0]))
    assert colliding_segments(q, far) == []


def test_obstacle_beyond_the_checked_two_thirds_is_ignored():
    sp, _ = _straight_spline()
    q = np.array(sp.control_points)
    late = _box_world(centre=np.array([6.8, 0.0, 1.0]), half=np.array([0.1, 0.5, 3.0]))
    assert q[check_end_index(len(q)), 0] < 6.6
    assert colliding_segments(q, late) == []


def test_anchor_pairs_point_out_of_the_obstacle_from_its_surface():
    sp, _ = _straight_spline()
    q = np.array(sp.control_points)
    grid = _box_world()
    (a, b), = colliding_segments(q, grid)
    path = search(q[a], q[b], grid).path
    anchors = Anchors(len(q))
    assert anchors_for_segment(q, (a, b), path, grid, anchors) >= 1
    for j in range(a, b + 1):
        pairs = anchors.of(j)
        assert len(pairs) == 1, j  # every point of the stretch got one pair
        p, v = pairs[0]
        assert np.linalg.norm(v) == pytest.approx(1.0)
        assert abs(v[1]) > 0.95  # out of the pillar sideways, toward the A* detour
        assert np.sign(v[1]) == np.sign(np.mean(path[:, 1]))
        assert not grid.is_occupied(p[None])[0]
    # where the ray met the obstacle, p is one voxel short of the first occupied sample
    met = [pv for j in range(a + 1, b) for pv in anchors.of(j)
           if grid.is_occupied((pv[0] - RES * pv[1])[None])[0]]
    assert met
    for p, v in met:
        # ... and that is the obstacle's (inflated) surface: |y| just beyond the box edge
        edge = BOX_CENTRE[1] + np.sign(v[1]) * (BOX_HALF[1] + INFLATION)
        assert abs(p[1] - edge) <= RES + 1e-9


# ---- the optimiser ----------------------------------------------------------------------
def _raw_box_clearance(points):
    return np.linalg.norm(np.maximum(np.abs(points - BOX_CENTRE) - BOX_HALF, 0.0), axis=1)


def test_optimiser_removes_a_collision_from_a_straight_path_through_a_box():
    sp, vel = _straight_spline()
    grid = _box_world()
    assert first_collision_time(sp, grid) is not None
    opt = EgoOptimizer(grid, EgoParams(max_vel=4.0, max_acc=3.0))
    res = opt.optimize(sp, vel, vel, ZERO, ZERO)
    assert res.status is EgoStatus.SUCCESS and res.success
    out = res.spline
    q = out.control_points
    assert not grid.is_occupied(q).any()  # control points clear of the inflated box
    t = np.linspace(0.0, out.duration, 3000)
    assert not grid.is_occupied(out.position(t)).any()  # and the whole curve
    assert _raw_box_clearance(out.position(t)).min() > 0.2
    assert res.feasibility.ok
    # ends untouched, shape smooth: small jerk, no kinks
    np.testing.assert_array_equal(q[:3], sp.control_points[:3])
    np.testing.assert_array_equal(q[-3:], sp.control_points[-3:])
    assert smoothness_cost(q)[0] < 0.05
    assert np.abs(out.acceleration(t)).max() <= 3.0 * 1.05 + 1e-3
    # it went around the pillar on one side
    assert np.abs(out.position(t)[:, 1]).max() > BOX_HALF[1] + INFLATION


def test_collision_free_input_stays_unchanged():
    sp, vel = _straight_spline()
    grid = _box_world(centre=np.array([3.5, 5.0, 1.0]))
    res = EgoOptimizer(grid).optimize(sp, vel, vel, ZERO, ZERO)
    assert res.success and res.anchors == 0 and res.astar_calls == 0 and not res.refined
    np.testing.assert_allclose(res.spline.control_points, sp.control_points, atol=1e-9)


def test_gently_curved_free_input_moves_little():
    sp, vel = _straight_spline()
    q = np.array(sp.control_points)
    q[:, 1] += 0.3 * np.sin(np.linspace(0, np.pi, len(q)))
    curved = sp.with_control_points(q)
    res = EgoOptimizer(_box_world(centre=np.array([3.5, 5.0, 1.0]))).optimize(
        curved, vel, vel, ZERO, ZERO)
    assert res.success and res.anchors == 0
    assert np.abs(res.spline.control_points - q).max() < 0.3


def test_a_second_obstacle_next_to_the_detour_triggers_rebound():
    boxes = [(BOX_CENTRE, BOX_HALF), (np.array([3.5, -1.1, 1.0]), np.array([0.3, 0.2, 3.0]))]

    def occupied(p):
        out = (p[:, 2] < 0.0) | (p[:, 2] > 3.0)
        for c, h in boxes:
            out |= np.all(np.abs(p - c) <= h + INFLATION, axis=1)
        return out

    grid = OccupancyView(occupied, RES)
    sp, vel = _straight_spline()
    res = EgoOptimizer(grid).optimize(sp, vel, vel, ZERO, ZERO)
    assert res.success
    assert res.rebounds >= 1 and res.astar_calls >= 2
    t = np.linspace(0.0, res.spline.duration * 2 / 3, 2000)
    assert not grid.is_occupied(res.spline.position(t)).any()


def test_collision_in_the_first_span_fails():
    sp, vel = _straight_spline()
    grid = _box_world(centre=np.array([0.2, 0.0, 1.0]), half=np.array([0.05, 1.0, 3.0]))
    res = EgoOptimizer(grid).rebound(sp)
    assert not res.success
    assert res.status in (EgoStatus.COLLISION_AT_START, EgoStatus.STILL_COLLIDING)


def test_refine_retimes_an_infeasible_trajectory():
    sp, vel = _straight_spline(speed=6.0, vmax=6.0)  # 6 m/s against a 4 m/s cap
    grid = _box_world(centre=np.array([3.5, 5.0, 1.0]))
    opt = EgoOptimizer(grid, EgoParams(max_vel=4.0, max_acc=3.0))
    assert not sp.feasibility(4.0, 3.0, 0.05).ok
    ratio = sp.feasibility(4.0, 3.0).ratio
    v_end = vel * 4.0 / 6.0
    res = opt.refine(sp, v_end, v_end, ZERO, ZERO)
    assert res.success and res.refined
    assert res.spline.dt == pytest.approx(sp.dt * ratio)
    assert res.spline.duration == pytest.approx(sp.duration * ratio)
    assert res.feasibility.ok, res.feasibility
    # the geometry is kept: it still runs along the line start -> goal
    t = np.linspace(0, res.spline.duration, 200)
    assert np.abs(res.spline.position(t)[:, 1:] - START[1:]).max() < 1e-6
    np.testing.assert_allclose(res.spline.position(res.spline.duration), GOAL, atol=0.05)
    # optimize() = rebound (nothing to do) + refine because infeasible
    full = opt.optimize(sp, v_end, v_end, ZERO, ZERO)
    assert full.success and full.refined and full.feasibility.ok


def test_params_are_validated():
    with pytest.raises(ValueError):
        EgoParams(max_vel=0.0)
    with pytest.raises(ValueError):
        EgoParams(max_rounds=0)
    with pytest.raises(ValueError):
        EgoParams(w_collision=-1.0)
    with pytest.raises(TypeError):
        EgoOptimizer(lambda p: np.zeros(len(p), bool))
    sp, _ = _straight_spline()
    with pytest.raises(ValueError):
        EgoOptimizer(_box_world()).rebound(sp.derivative())


def test_a_local_trajectory_past_one_obstacle_takes_one_solve_of_at_most_350_evaluations():
    # (how long it takes, target well under 20 ms, is measured in bench/bench_search.py)
    sp, vel = _straight_spline()
    assert 20 <= sp.num_control_points <= 25
    grid = _box_world()
    opt = EgoOptimizer(grid, EgoParams(max_vel=4.0, max_acc=3.0))
    res = opt.optimize(sp, vel, vel, ZERO, ZERO)
    assert res.success and res.feasibility.ok
    t = np.linspace(0.0, res.spline.duration, 3000)
    assert not grid.is_occupied(res.spline.position(t)).any()
    # the work, deterministic: one A* call, one L-BFGS solve, no rebound, no refinement;
    # the solve ran 200 iterations (its cap) and 262 cost evaluations on 2026-11-26
    assert (res.astar_calls, res.rounds, res.rebounds, res.refined) == (1, 1, 0, False)
    assert res.evaluations <= 350, res.evaluations
    # a second call on the same optimiser does the same work
    again = opt.optimize(sp, vel, vel, ZERO, ZERO)
    assert (again.iterations, again.evaluations) == (res.iterations, res.evaluations)
    np.testing.assert_array_equal(again.spline.control_points, res.spline.control_points)
