"""Kinodynamic A* (Fast-Planner's front end) at its boundaries, on synthetic occupancy maps."""


import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import minimize, minimize_scalar

from ft_sitl.navigation.planners.kino_astar import (
    KinoAstarParams,
    KinodynamicAstar,
    KinoStatus,
    VoxelOccupancy,
    obvp_coefficients,
    obvp_cost,
)

FLOOR, CEILING = 0.1, 3.0
BOUNDS = (np.array([-2.0, -6.0, -0.5]), np.array([12.0, 6.0, 3.5]))


def boxes_map(*boxes, floor=FLOOR, ceiling=CEILING):
    """occupied(points) for closed axis-aligned boxes (lo, hi), a floor and a ceiling."""

    def occupied(points):
        p = np.asarray(points, dtype=float)
        occ = (p[:, 2] < floor) | (p[:, 2] > ceiling)
        for lo, hi in boxes:
            occ |= np.all((p >= lo) & (p <= hi), axis=1)
        return occ

    return occupied


def depth_in_boxes(points, boxes):
    """How deep each point lies inside the boxes (0 outside)."""
    d = np.zeros(len(points))
    for lo, hi in boxes:
        inside = np.minimum(points - lo, hi - points).min(axis=1)
        d = np.maximum(d, np.clip(inside, 0.0, None))
    return d


def shell(center, inner_half, thickness=0.8):
    """Six boxes forming a closed hollow cube. The walls are thick: at 3 m/s the check points
    of a primitive are up to 0.36 m apart, so a search can tunnel through thin walls (as
    Fast-Planner's can)."""
    c = np.asarray(center, dtype=float)
    out = inner_half + thickness
    boxes = []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            lo = c - out
            hi = c + out
            if sign < 0:
                hi = hi.copy()
                hi[axis] = c[axis] - inner_half
            else:
                lo = lo.copy()
                lo[axis] = c[axis] + inner_half
            boxes.append((lo, hi))
    return boxes


def check_points(result, n=5):
    """The points where the search checked each primitive."""
    pts = []
    for x0, u, tau in zip(result.states[:-1], result.inputs, result.durations):
        for k in range(1, n + 1):
            t = tau * k / n
            pts.append(x0[:3] + x0[3:] * t + 0.5 * u * t * t)
    return np.array(pts).reshape(-1, 3)


WALL = [(np.array([2.9, -2.1, -10.0]), np.array([3.4, 2.1, 10.0]))]


def voxelize(occupied, lo, hi, res=0.1):
    """The same map as a VoxelOccupancy grid (voxel centres sampled)."""
    n = np.ceil((hi - lo) / res).astype(int)
    idx = np.stack(np.meshgrid(*[np.arange(k) for k in n], indexing="ij"), -1).reshape(-1, 3)
    return VoxelOccupancy(occupied(lo + (idx + 0.5) * res).reshape(n), lo, res)


@pytest.fixture(scope="module")
def wall_planner():
    return KinodynamicAstar(boxes_map(*WALL), 0.1, bounds=BOUNDS,
                            params=KinoAstarParams(max_vel=3.0))


# --- searches -------------------------------------------------------------------------


@pytest.mark.parametrize("vmax", [3.0, 4.0])
def test_path_around_a_wall_is_free_and_within_the_speed_limit(vmax):
    occ = boxes_map(*WALL)
    planner = KinodynamicAstar(occ, 0.1, bounds=BOUNDS, params=KinoAstarParams(max_vel=vmax))
    start, goal = np.array([0.0, 0.0, 1.5]), np.array([6.0, 0.0, 1.5])
    r = planner.search(start, [0, 0, 0], [0, 0, 0], goal)
    assert r.status is KinoStatus.REACHED_GOAL
    assert len(r.durations) > 3 and r.shot_coeffs is not None
    # the search guarantees its check points (and the shot's) are free and in bounds
    assert not occ(check_points(r)).any()
    s = r.sample(0.005)
    assert not occ(r.evaluate(np.linspace(r.duration - r.shot_duration, r.duration,
                                          11)).position).any()
    assert np.all(s.position > BOUNDS[0]) and np.all(s.position < BOUNDS[1])
    # between check points (0.12 s apart) the path may graze an inflated corner, not more
    assert depth_in_boxes(s.position, WALL).max() < 0.15
    # it goes around the wall (|y| beyond its edge when passing it)
    passing = (s.position[:, 0] > 2.9) & (s.position[:, 0] < 3.4)
    assert passing.any() and np.all(np.abs(s.position[passing, 1]) > 2.0)
    assert np.all(np.abs(s.velocity) <= vmax + 1e-9)
    np.testing.assert_allclose(s.position[0], start)
    np.testing.assert_allclose(s.position[-1], goal, atol=1e-9)
    np.testing.assert_allclose(s.velocity[-1], 0.0, atol=1e-9)
    # continuity: no jumps between samples
    assert np.max(np.linalg.norm(np.diff(s.position, axis=0), axis=1)) <= vmax * 2 * 0.005


def test_far_goal_stops_at_the_horizon(wall_planner):
    start = np.array([0.0, 0.0, 1.5])
    r = wall_planner.search(start, [2.0, 0, 0], [0, 0, 0], [11.0, 1.0, 1.5])
    assert r.status is KinoStatus.REACHED_HORIZON and r.stop_reason == "horizon"
    assert r.shot_coeffs is None
    assert np.linalg.norm(r.states[-1, :3] - start) >= 7.0
    assert np.linalg.norm(r.states[-2, :3] - start) < 7.0 + 3.0 * 0.6 * np.sqrt(3)
    assert not boxes_map(*WALL)(check_points(r)).any()
    assert np.all(np.abs(r.states[:, 3:]) <= 3.0 + 1e-9)


def test_close_free_goal_is_reached_by_the_analytic_shot():
    planner = KinodynamicAstar(boxes_map(), 0.1, params=KinoAstarParams())
    start, goal = np.array([0.0, 0.0, 1.0]), np.array([0.7, -0.4, 1.3])
    r = planner.search(start, [0.5, 0, 0], [0, 0, 0], goal)
    assert r.status is KinoStatus.REACHED_GOAL and r.stop_reason == "goal"
    assert len(r.durations) == 0 and r.expansions == 0  # the start node itself shoots
    _, t_opt = obvp_cost(r.start_state, r.goal_state)
    assert r.shot_duration == pytest.approx(t_opt)
    np.testing.assert_allclose(r.end_state, np.r_[goal, 0, 0, 0], atol=1e-12)


def test_goal_a_few_metres_away_primitives_then_shot_ends_exactly_at_goal_state():
    planner = KinodynamicAstar(boxes_map(), 0.1, params=KinoAstarParams())
    goal, goal_vel = np.array([4.0, 2.0, 1.5]), np.array([1.0, 0.5, 0.0])
    r = planner.search([0, 0, 1.5], [0, 0, 0], [0, 0, 0], goal, goal_vel=goal_vel)
    assert r.status is KinoStatus.REACHED_GOAL
    assert len(r.durations) >= 1
    np.testing.assert_allclose(r.end_state, np.r_[goal, goal_vel], atol=1e-9)
    # the shot starts where the last primitive ends
    last = r.states[-1]
    np.testing.assert_allclose(r.shot_coeffs[0], last[:3])
    np.testing.assert_allclose(r.shot_coeffs[1], last[3:])
    # primitives chain: each node state is the previous one propagated
    for k, (u, tau) in enumerate(zip(r.inputs, r.durations)):
        x0 = r.states[k]
        np.testing.assert_allclose(r.states[k + 1, :3], x0[:3] + x0[3:] * tau + 0.5 * u * tau**2)
        np.testing.assert_allclose(r.states[k + 1, 3:], x0[3:] + u * tau)


def test_inputs_are_the_125_input_set_for_0_6_s():
    planner = KinodynamicAstar(boxes_map(), 0.1, params=KinoAstarParams(max_acc=2.0))
    r = planner.search([0, 0, 1.5], [0, 0, 0], [0, 0, 0], [6.0, -3.0, 2.0])
    assert r.status is KinoStatus.REACHED_GOAL
    assert r.attempts == 2 and not r.kept_start_acc  # hovering: the first try finds nothing
    assert np.all(r.durations == 0.6)
    assert set(np.unique(r.inputs)) <= {-2.0, -1.0, 0.0, 1.0, 2.0}


def test_first_primitive_keeps_the_current_acceleration():
    planner = KinodynamicAstar(boxes_map(), 0.1, params=KinoAstarParams())
    acc = np.array([1.0, 0.3, 0.0])
    r = planner.search([0, 0, 1.5], [1.5, 0, 0], acc, [6.0, 1.0, 1.5])
    assert r.found and r.attempts == 1 and r.kept_start_acc
    np.testing.assert_array_equal(r.inputs[0], acc)
    k = r.durations[0] / 0.04
    assert 0.04 - 1e-12 <= r.durations[0] <= 0.8 + 1e-12 and k == pytest.approx(round(k))
    assert np.all(r.durations[1:] == 0.6)


def test_goal_inside_an_obstacle_ends_near_it():
    block = [(np.array([5.5, -0.5, 1.0]), np.array([6.5, 0.5, 2.0]))]
    planner = KinodynamicAstar(boxes_map(*block), 0.1, bounds=BOUNDS, params=KinoAstarParams())
    r = planner.search([0, 0, 1.5], [0, 0, 0], [0, 0, 0], [6.0, 0.0, 1.5])
    assert r.status is KinoStatus.NEAR_GOAL and r.shot_coeffs is None
    vox = np.floor((r.states[-1, :3] - BOUNDS[0]) / 0.1)
    goal_vox = np.floor((np.array([6.0, 0.0, 1.5]) - BOUNDS[0]) / 0.1)
    assert np.all(np.abs(vox - goal_vox) <= 10)
    assert not boxes_map(*block)(check_points(r)).any()
    # from a start already within 1 m, a failed shot is NO_PATH (as the original)
    r2 = planner.search([5.3, 0.8, 1.5], [0, 0, 0], [0, 0, 0], [6.0, 0.0, 1.5])
    assert r2.status is KinoStatus.NO_PATH and r2.stop_reason == "start_shot_failed"


def test_enclosed_start_has_no_path_and_ends_by_exhausting_the_space():
    walls = shell([0.0, 0.0, 1.5], inner_half=0.8)
    params = KinoAstarParams()
    planner = KinodynamicAstar(boxes_map(*walls), 0.1, bounds=BOUNDS, params=params)
    r = planner.search([0, 0, 1.5], [0, 0, 0], [0, 0, 0], [6.0, 0.0, 1.5])
    # it ran out of reachable states, well before the expansion cap (work, not time)
    assert r.expansions < params.max_expansions
    assert r.status is KinoStatus.NO_PATH and r.stop_reason == "exhausted"
    assert not r.found and r.attempts == 2 and r.expansions > 10
    assert len(r.durations) == 0 and r.states.shape == (1, 6)
    s = r.sample(0.1)
    assert len(s.t) == 1


def test_enclosed_goal_stops_at_the_expansion_cap():
    walls = shell([4.0, 0.0, 1.5], inner_half=1.3)
    small = (np.array([-1.0, -3.0, 0.0]), np.array([5.9, 3.0, 3.0]))  # horizon unreachable
    params = KinoAstarParams(max_expansions=1500)
    planner = KinodynamicAstar(boxes_map(*walls), 0.1, bounds=small, params=params)
    r = planner.search([0, 0, 1.5], [0, 0, 0], [0, 0, 0], [4.0, 0.0, 1.5])
    assert r.status is KinoStatus.NO_PATH and r.stop_reason == "expansion_cap"
    assert r.stats["per_attempt"][-1]["expansions"] == 1500


@pytest.mark.parametrize("grid", [False, True])
def test_wall_clock_cap_ends_the_search_after_its_deadline(grid):
    walls = shell([4.0, 0.0, 1.5], inner_half=1.3)
    small = (np.array([-1.0, -3.0, 0.0]), np.array([5.9, 3.0, 3.0]))
    params = KinoAstarParams(max_expansions=10**6, max_nodes=10**6, max_time_s=0.05)
    occ = voxelize(boxes_map(*walls), *small) if grid else boxes_map(*walls)
    planner = KinodynamicAstar(occ, 0.1, bounds=small, params=params)
    r = planner.search([0, 0, 1.5], [0, 0, 0], [0, 0, 0], [4.0, 0.0, 1.5])
    assert r.status is KinoStatus.NO_PATH and r.stop_reason == "time_cap"
    # stopped by the clock, not before its deadline and not by a cap (how far past the
    # deadline it stops depends on the machine's load: not asserted)
    assert r.search_time_s > 0.05
    assert 0 < r.expansions < 10**6 and r.nodes < 10**6


def test_node_pool_cap():
    params = KinoAstarParams(max_nodes=200)
    planner = KinodynamicAstar(boxes_map(*WALL), 0.1, bounds=BOUNDS, params=params)
    r = planner.search([0, 0, 1.5], [0, 0, 0], [0, 0, 0], [6.0, 0.0, 1.5])
    assert r.status is KinoStatus.NO_PATH and r.stop_reason == "node_cap"
    assert r.nodes <= 2 * 200


def test_same_inputs_same_result(wall_planner):
    args = ([0, 0, 1.5], [0.5, 0.2, 0], [0.2, 0, 0], [6.0, 0.3, 1.5])
    a = wall_planner.search(*args)
    wall_planner.search([0, 0, 1.0], [0, 0, 0], [0, 0, 0], [2.0, -3.0, 1.0])  # in between
    b = wall_planner.search(*args)
    c = KinodynamicAstar(boxes_map(*WALL), 0.1, bounds=BOUNDS,
                         params=KinoAstarParams(max_vel=3.0)).search(*args)
    for other in (b, c):
        assert other.status is a.status and other.stop_reason == a.stop_reason
        assert (other.expansions, other.nodes, other.attempts) == (a.expansions, a.nodes,
                                                                   a.attempts)
        np.testing.assert_array_equal(other.states, a.states)
        np.testing.assert_array_equal(other.inputs, a.inputs)
        np.testing.assert_array_equal(other.durations, a.durations)
        np.testing.assert_array_equal(other.shot_coeffs, a.shot_coeffs)


@pytest.mark.parametrize("start_vel, goal", [([0, 0, 0], [6.0, 0.0, 1.5]),
                                             ([1.0, 0.5, 0], [11.0, 2.0, 1.5])])
def test_voxel_grid_in_the_compiled_loop_gives_the_same_search(start_vel, goal):
    grid = voxelize(boxes_map(*WALL), *BOUNDS)
    fast = KinodynamicAstar(grid, 0.1, bounds=BOUNDS, params=KinoAstarParams(max_vel=3.0))
    slow = KinodynamicAstar(lambda p: grid(p), 0.1, bounds=BOUNDS,
                            params=KinoAstarParams(max_vel=3.0))
    a = fast.search([0, 0, 1.5], start_vel, [0, 0, 0], goal)
    b = slow.search([0, 0, 1.5], start_vel, [0, 0, 0], goal)
    assert a.found and a.status is b.status
    assert (a.expansions, a.nodes) == (b.expansions, b.nodes) and a.expansions > 50
    np.testing.assert_array_equal(a.states, b.states)
    np.testing.assert_array_equal(a.inputs, b.inputs)
    assert not grid(check_points(a)).any()


def test_voxel_occupancy_lookup():
    grid = np.zeros((4, 5, 6), bool)
    grid[1, 2, 3] = True
    occ = VoxelOccupancy(grid, np.array([-1.0, 0.0, 2.0]), 0.5)
    pts = np.array([[-0.5, 1.0, 3.5], [-0.01, 1.49, 3.99], [-0.51, 1.0, 3.5], [10, 10, 10],
                    [-5, -5, -5]])
    np.testing.assert_array_equal(occ(pts), [True, True, False, False, False])
    grid[1, 2, 3] = False  # the grid is read, not copied
    assert not occ(pts).any()
    with pytest.raises(ValueError):
        VoxelOccupancy(np.zeros((4, 5)), np.zeros(3), 0.1)
    with pytest.raises(ValueError):
        VoxelOccupancy(np.zeros((4, 5, 6)), np.zeros(3), 0.1)  # float grid
    with pytest.raises(ValueError):
        VoxelOccupancy(np.zeros((4, 5, 6), bool), np.zeros(3), 0.0)


def test_typical_wall_search_reaches_the_goal_within_2000_expansions(wall_planner):
    # (how long it takes, tens of ms, is measured in bench/bench_search.py, not asserted)
    args = ([0, 0, 1.5], [0, 0, 0], [0, 0, 0], [6.0, 0.0, 1.5])
    r = wall_planner.search(*args)
    assert r.status is KinoStatus.REACHED_GOAL and r.found
    assert not boxes_map(*WALL)(check_points(r)).any()
    # the work, deterministic: the kept start acceleration finds nothing (1 expansion), the
    # retry with the full inputs 1,482 expansions and 4,336 nodes in all (2026-11-26)
    assert r.attempts == 2 and r.stats["per_attempt"][0]["expansions"] == 1
    assert r.expansions <= 2000 and r.nodes <= 6000, (r.expansions, r.nodes)


def test_bspline_samples_cover_the_path(wall_planner):
    r = wall_planner.search([0, 0, 1.5], [1.0, 0, 0], [0, 0, 0], [6.0, 0.0, 1.5])
    ts, pts, v0, v1, a0, a1 = r.bspline_samples(0.5 / 3.0)
    assert len(pts) >= 9
    assert ts == pytest.approx(r.duration / (len(pts) - 1))
    np.testing.assert_allclose(pts[0], r.start_state[:3])
    np.testing.assert_allclose(pts[-1], r.end_state[:3], atol=1e-9)
    np.testing.assert_allclose(v0, [1.0, 0, 0])
    np.testing.assert_allclose(v1, r.goal_state[3:])
    np.testing.assert_allclose(a0, r.inputs[0])
    np.testing.assert_allclose(a1, r.evaluate(np.array([r.duration])).acceleration[0])


@pytest.mark.parametrize("bad", [dict(max_vel=0.0), dict(max_acc=-1.0), dict(check_num=0),
                                 dict(lambda_heu=float("nan")), dict(max_time_s=0.0),
                                 dict(max_expansions=1.5)])
def test_bad_parameters_are_rejected(bad):
    with pytest.raises(ValueError):
        KinoAstarParams(**bad)


def test_bad_inputs_are_rejected():
    with pytest.raises(ValueError):
        KinodynamicAstar(boxes_map(), 0.0)
    with pytest.raises(ValueError):
        KinodynamicAstar(boxes_map(), 0.1, bounds=(np.zeros(3), np.zeros(3)))
    planner = KinodynamicAstar(boxes_map(), 0.1)
    with pytest.raises(ValueError):
        planner.search([0, 0], [0, 0, 0], [0, 0, 0], [1, 1, 1])
    with pytest.raises(ValueError):
        KinodynamicAstar(lambda p: np.zeros(1, bool), 0.1).search(
            [0, 0, 1.5], [0, 0, 0], [0, 0, 0], [5, 0, 1.5])


# --- the two-point problem (heuristic and shot) ----------------------------------------


def _cost_formula(x0, x1, t, rho):
    dp, v0, v1 = x1[:3] - x0[:3], x0[3:], x1[3:]
    return (12 * dp @ dp / t**3 - 12 * (v0 + v1) @ dp / t**2
            + 4 * (v0 @ v0 + v0 @ v1 + v1 @ v1) / t + rho * t)


def _reference_obvp(x0, x1, rho, vmax):
    """The original's recipe with numpy.roots: real roots of the quartic and T_bar."""
    dp, v0, v1 = x1[:3] - x0[:3], x0[3:], x1[3:]
    c1 = -36 * dp @ dp
    c2 = 24 * (v0 + v1) @ dp
    c3 = -4 * (v0 @ v0 + v0 @ v1 + v1 @ v1)
    roots = np.roots([rho, 0.0, c3, c2, c1])
    t_bar = np.max(np.abs(dp)) / (0.5 * vmax)
    cands = [r.real for r in roots if abs(r.imag) < 1e-9 * max(1.0, abs(r)) and r.real >= t_bar]
    cands.append(t_bar)
    costs = [_cost_formula(x0, x1, t, rho) if t > 0 else np.inf for t in cands]
    i = int(np.argmin(costs))
    return costs[i], cands[i], t_bar


def _random_states(rng, n):
    for _ in range(n):
        x0 = np.r_[rng.uniform(-5, 5, 3), rng.uniform(-3, 3, 3)]
        x1 = np.r_[rng.uniform(-5, 5, 3), rng.uniform(-3, 3, 3) * rng.integers(0, 2)]
        yield x0, x1


def test_obvp_cost_matches_the_quartic_solved_by_numpy_roots():
    rng = np.random.default_rng(1)
    for x0, x1 in _random_states(rng, 300):
        rho, vmax = rng.choice([1.0, 10.0, 50.0]), rng.choice([2.0, 3.0, 4.0])
        cost, t = obvp_cost(x0, x1, rho, vmax)
        ref_cost, ref_t, _ = _reference_obvp(x0, x1, rho, vmax)
        assert cost == pytest.approx(ref_cost, rel=1e-9, abs=1e-9)
        assert t == pytest.approx(ref_t, rel=1e-6)


def test_obvp_cost_is_the_minimum_over_durations_found_numerically():
    rng = np.random.default_rng(2)
    for x0, x1 in _random_states(rng, 40):
        cost, t = obvp_cost(x0, x1, 10.0, 3.0)
        t_bar = np.max(np.abs(x1[:3] - x0[:3])) / 1.5
        res = minimize_scalar(lambda s, a=x0, b=x1: _cost_formula(a, b, s, 10.0),
                              bounds=(max(t_bar, 1e-3), 60.0), method="bounded",
                              options={"xatol": 1e-10})
        grid = np.linspace(max(t_bar, 1e-3), 60.0, 20001)
        best_grid = min(_cost_formula(x0, x1, s, 10.0) for s in grid[::10])
        assert cost <= min(res.fun, best_grid) + 1e-6 * max(1.0, abs(cost))
        assert cost == pytest.approx(min(res.fun, best_grid), rel=1e-5, abs=1e-6)


def test_obvp_cost_is_the_effort_and_time_of_the_cubic():
    rng = np.random.default_rng(3)
    for x0, x1 in _random_states(rng, 10):
        cost, t = obvp_cost(x0, x1, 10.0, 3.0)
        c = obvp_coefficients(x0, x1, t)
        effort = quad(lambda s, c=c: float(np.sum((2 * c[2] + 6 * c[3] * s) ** 2)), 0.0, t)[0]
        assert effort + 10.0 * t == pytest.approx(cost, rel=1e-9)


def test_the_cubic_minimises_effort_among_curves_with_the_same_ends():
    """Add t^2 (T-t)^2 q(t) (keeps both end states) and minimise int ||a||^2 numerically:
    the optimum is the cubic itself (q = 0)."""
    rng = np.random.default_rng(4)
    nodes, weights = np.polynomial.legendre.leggauss(12)
    for x0, x1 in _random_states(rng, 5):
        t_f = rng.uniform(0.5, 4.0)
        c = obvp_coefficients(x0, x1, t_f)
        s = 0.5 * t_f * (nodes + 1.0)
        w = 0.5 * t_f * weights

        def effort(q, c=c, s=s, w=w, t_f=t_f):
            q = q.reshape(3, 3)  # per axis: q0 + q1 t + q2 t^2
            base = 2 * c[2][None, :] + 6 * c[3][None, :] * s[:, None]
            # second derivative of t^2 (T - t)^2 (q0 + q1 t + q2 t^2), by polynomial algebra
            acc = np.empty((len(s), 3))
            for a in range(3):
                bump = np.polynomial.Polynomial([0, 0, t_f**2, -2 * t_f, 1])
                poly = bump * np.polynomial.Polynomial(q[a])
                acc[:, a] = poly.deriv(2)(s)
            return float(np.sum(w[:, None] * (base + acc) ** 2))

        res = minimize(effort, rng.normal(size=9), method="BFGS", options={"gtol": 1e-10})
        assert res.fun == pytest.approx(effort(np.zeros(9)), rel=1e-6, abs=1e-9)
        assert np.abs(res.x).max() < 1e-3 * max(1.0, np.abs(c).max())


def test_obvp_cubic_hits_both_end_states_exactly():
    rng = np.random.default_rng(5)
    for x0, x1 in _random_states(rng, 50):
        t_f = rng.uniform(0.2, 5.0)
        c = obvp_coefficients(x0, x1, t_f)
        p = c[0] + c[1] * t_f + c[2] * t_f**2 + c[3] * t_f**3
        v = c[1] + 2 * c[2] * t_f + 3 * c[3] * t_f**2
        np.testing.assert_allclose(c[0], x0[:3])
        np.testing.assert_allclose(c[1], x0[3:])
        np.testing.assert_allclose(p, x1[:3], atol=1e-10)
        np.testing.assert_allclose(v, x1[3:], atol=1e-10)


def test_obvp_degenerate_cases():
    x = np.array([1.0, 2.0, 3.0, 0.0, 0.0, 0.0])
    assert obvp_cost(x, x) == (0.0, 0.0)  # already there, at rest
    x1 = x.copy()
    x1[3] = 1.0  # same place, other velocity: T = sqrt(4 |v|^2 / rho)
    cost, t = obvp_cost(x, x1, 10.0, 3.0)
    assert t == pytest.approx(np.sqrt(0.4)) and cost == pytest.approx(2 * np.sqrt(4.0 * 10.0))
