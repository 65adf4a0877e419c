"""PGO (Fast-Planner's topological replanning): the roadmap on synthetic maps, shortcut,
equivalence, the path-guided optimisation, the navigator's logic and one real trial."""

import math
import tracemalloc

import numpy as np
import pytest
import trimesh

from ft_sitl.autopilot.cascade import SP_POS
from ft_sitl.missions.trial import TrialSpec, run_trial
from ft_sitl.navigation.maps.esdf import EsdfGrid
from ft_sitl.navigation.maps.mapping import LocalMap
from ft_sitl.navigation.planners.astar import OccupancyView
from ft_sitl.navigation.planners.pgo import (
    PgoParams,
    PgoPlanner,
    esdf_centre,
    first_collision_time,
    guide_phase,
    jerk_cost,
    lengthen_time,
    near_occupied,
    normal_cost,
    plan_segment,
)
from ft_sitl.navigation.planners.topo import (
    discretize_path,
    find_topo_paths,
    path_length,
    prune_equivalent,
    same_topo_path,
    shortcut_path,
)
from ft_sitl.navigation.trajectories.bspline import BSpline
from ft_sitl.scenarios.camera import CameraConfig, DepthCamera

from .planner_util import obs_at, open_task

AGILE = "0.98kg-EGO Planner DIY"
RES = 0.1
S = np.array([2.0, 0.0, 1.5])
E = np.array([8.0, 0.0, 1.5])


def _world(pillars=(), walls=(), lo=(-3.0, -7.0, -0.5), hi=(13.0, 7.0, 3.5)) -> EsdfGrid:
    """A synthetic planning map: vertical pillars (x, y, radius) and wall boxes
    (x0, x1, y0, y1), inflated by one voxel, with the floor (z < 0) and ceiling (z >= 3)."""
    o = np.floor(np.array(lo) / RES).astype(int)
    n = np.floor(np.array(hi) / RES).astype(int) - o
    c = (np.stack(np.meshgrid(*[np.arange(k) for k in n], indexing="ij"), -1) + o + 0.5) * RES
    occ = (c[..., 2] < 0.0) | (c[..., 2] >= 3.0)
    for x, y, r in pillars:
        occ |= np.hypot(c[..., 0] - x, c[..., 1] - y) <= r + RES
    for x0, x1, y0, y1 in walls:
        occ |= ((c[..., 0] >= x0 - RES) & (c[..., 0] <= x1 + RES)
                & (c[..., 1] >= y0 - RES) & (c[..., 1] <= y1 + RES))
    return EsdfGrid.from_occupancy(occ, o, RES)


def _dense_free(grid: EsdfGrid, path, step=0.01) -> bool:
    pts = discretize_path(path, max(int(path_length(path) / step), 2))
    return not grid.occupied(pts).any()


def _side(path, x=5.0) -> float:
    """Mean lateral offset of the path where it passes x."""
    pts = discretize_path(path, 600)
    return float(np.mean(pts[np.abs(pts[:, 0] - x) < 0.3, 1]))


PILLAR = _world(pillars=[(5.0, 0.0, 0.5)])


# ---- the roadmap -------------------------------------------------------------------------
@pytest.mark.slow
def test_the_roadmap_goes_both_ways_around_a_pillar():
    for seed in (0, 1):
        found = find_topo_paths(S, E, [S], [E], PILLAR, np.random.default_rng(seed))
        assert len(found.paths) >= 2
        assert {math.copysign(1.0, _side(p)) for p in found.paths} == {-1.0, 1.0}
        for p in found.paths:
            assert np.allclose(p[0], S) and np.allclose(p[-1], E)
            assert _dense_free(PILLAR, p)
            assert path_length(p) < 1.2 * np.linalg.norm(E - S)  # shortcut tight around it
    # the same generator state gives the same search
    a = find_topo_paths(S, E, [S], [E], PILLAR, np.random.default_rng(3))
    b = find_topo_paths(S, E, [S], [E], PILLAR, np.random.default_rng(3))
    assert len(a.paths) == len(b.paths)
    assert all(np.array_equal(p, q) for p, q in zip(a.paths, b.paths))


def test_a_wall_with_one_gap_leaves_one_path():
    grid = _world(walls=[(5.0, 5.2, -20.0, -1.0), (5.0, 5.2, 1.0, 20.0)])
    start = np.array([2.0, 0.5, 1.5])
    for seed in (0, 1):
        found = find_topo_paths(start, E, [start], [E], grid, np.random.default_rng(seed))
        assert len(found.raw_paths) >= 1
        assert len(found.paths) == 1
        assert abs(_side(found.paths[0], 5.1)) < 0.9 and _dense_free(grid, found.paths[0])
    # closed: nothing
    closed = _world(walls=[(5.0, 5.2, -20.0, 20.0)])
    found = find_topo_paths(start, E, [start], [E], closed, np.random.default_rng(0))
    assert found.paths == []


def test_shortcut_keeps_paths_collision_free_and_never_longer():
    grid = _world(pillars=[(4.0, 0.3, 0.4), (5.5, -0.6, 0.5), (6.5, 1.0, 0.3), (5.0, 2.0, 0.4)])
    found = find_topo_paths(S, E, [S], [E], grid, np.random.default_rng(0))
    assert len(found.raw_paths) >= 3
    for raw in found.raw_paths:
        assert _dense_free(grid, raw)
        for passes in (1, 5):
            short = shortcut_path(raw, grid, passes)
            assert _dense_free(grid, short)
            assert path_length(short) <= path_length(raw) + 1e-9
            assert np.allclose(short[0], raw[0]) and np.allclose(short[-1], raw[-1])
    # a detour around the pillar is pulled tight
    detour = np.array([S, [3.0, 2.5, 1.5], [5.0, 3.0, 1.5], [7.0, 2.5, 1.5], E])
    short = shortcut_path(detour, PILLAR, 5)
    assert _dense_free(PILLAR, short)
    assert path_length(short) < 0.9 * path_length(detour)
    assert _side(short) > 0.5  # still on the left


def test_equivalence_merges_paths_on_the_same_side_only():
    def around(y):
        return np.array([S, [5.0, y, 1.5], E])

    left_near, left_far, right = around(1.0), around(2.5), around(-1.2)
    assert same_topo_path(left_near, left_far, PILLAR)
    assert not same_topo_path(left_near, right, PILLAR)
    kept = prune_equivalent([left_near, left_far, right], PILLAR)
    assert len(kept) == 2 and kept[0] is left_near and kept[1] is right


# ---- the optimisation --------------------------------------------------------------------
def _straight(speed=3.0, a=(0.0, 0.0, 1.5), b=(7.0, 0.0, 1.5)):
    a, b = np.array(a), np.array(b)
    duration = float(np.linalg.norm(b - a)) / speed
    vel = (b - a) / duration

    def resample(n):
        return a + (b - a) * np.linspace(0.0, 1.0, n + 1)[:, None], duration / n

    derivs = (vel, vel, np.zeros(3), np.zeros(3))
    pts, dt = resample(23)
    return BSpline.fit(pts, dt, *derivs), resample, derivs


@pytest.mark.slow
def test_path_guided_optimisation_avoids_the_pillar():
    grid = _world(pillars=[(3.5, 0.0, 0.5)])
    init, resample, derivs = _straight()
    assert first_collision_time(init, grid) is not None
    params = PgoParams()
    plan = plan_segment(init, resample, derivs, grid, np.random.default_rng(0), params)
    assert plan.success and plan.status == "topo"
    assert len(plan.search.paths) >= 2 and len(plan.candidates) == len(plan.search.paths)
    out = plan.spline
    assert first_collision_time(out, grid) is None
    t = np.linspace(0.0, out.duration, 400)
    assert grid.distance(out.position(t)).min() > 0.0
    # it starts where the segment starts (up to the least-squares fit)
    np.testing.assert_allclose(out.position(0.0), init.position(0.0), atol=0.1)
    np.testing.assert_allclose(out.velocity(0.0), derivs[0], atol=0.5)
    # the lowest-jerk collision-free candidate was chosen
    free = [c for c in plan.candidates if first_collision_time(c, grid) is None]
    if not plan.refined:
        assert jerk_cost(out) == pytest.approx(min(jerk_cost(c) for c in free))
    # a free segment is only optimised
    clear, resample, derivs = _straight()
    plan = plan_segment(clear, resample, derivs, _world(), np.random.default_rng(0), params)
    assert plan.status == "free" and plan.search is None


def _one_shot_first_collision(spline, grid):
    """The candidate check as it was before the blockwise evaluation (all samples at once)."""
    length = float(np.sum(np.linalg.norm(np.diff(spline.control_points, axis=0), axis=1)))
    t = np.linspace(0.0, spline.duration, max(math.ceil(2.0 * length / grid.resolution), 1) + 1)
    hit = np.flatnonzero(near_occupied(grid.occupied, grid.resolution, spline.position(t)))
    return float(t[hit[0]]) if hit.size else None


def test_the_check_of_a_diverged_candidate_stays_small_in_memory():
    # trial 8b3c40a7 (PGO, 2.50kg-HLY, urban 1, protocol 5): a diverged fit left a candidate
    # whose control polygon was 9.5e6 m long; the check sampled it every half voxel at once
    # (1.9e8 samples, > 20 GB with the 8 corner voxels). Here a 1e5 m polygon (2e6 samples,
    # ~0.5 GB at once) swinging through the pillar.
    grid = _world(pillars=[(5.0, 0.0, 0.5)])
    q = np.array([[5.0, 1500.0 * (-1) ** i, 1.5] for i in range(36)])
    spline = BSpline(q, 0.1)
    tracemalloc.start()
    try:
        t = first_collision_time(spline, grid)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert t is not None and t < 0.1  # the first swing crosses the pillar
    assert peak < 64e6


@pytest.mark.parametrize("into_pillar", [False, True])
def test_the_blockwise_check_gives_the_one_shot_result(into_pillar):
    # ~160k samples (3 blocks): back and forth in free space, then (or not) into the pillar
    grid = _world(pillars=[(5.0, 0.0, 0.5)])
    q = [[1.0, 2.0 * (-1) ** i, 1.5] for i in range(2000)]
    q += [[5.0, 0.0, 1.5]] * 4 if into_pillar else [[1.0, 0.0, 1.5]] * 4
    spline = BSpline(np.array(q), 0.05)
    expected = _one_shot_first_collision(spline, grid)
    assert (expected is not None) == into_pillar
    assert first_collision_time(spline, grid) == expected


def test_time_lengthening_keeps_the_shape_and_the_end_speeds():
    init, _, derivs = _straight()
    curve = BSpline(init.control_points + np.column_stack(
        [np.zeros(init.num_control_points), np.sin(np.arange(init.num_control_points)),
         np.zeros(init.num_control_points)]), init.dt)
    for ratio in (1.4, 0.8):
        pts, dt = lengthen_time(curve, ratio)
        assert len(pts) == curve.num_segments + 1
        # the two knot spans at each end keep their duration, the others scale
        inner = curve.duration - 4 * curve.dt
        assert dt * curve.num_segments == pytest.approx(curve.duration + (ratio - 1) * inner)
        np.testing.assert_allclose(pts[[0, -1]], curve.position([0.0, curve.duration]),
                                   atol=1e-9)
        fitted = BSpline.fit(pts, dt, *derivs)
        np.testing.assert_allclose(fitted.velocity(0.0), derivs[0], atol=0.2)


def test_guide_phase_and_normal_cost():
    rng = np.random.default_rng(0)
    q = np.cumsum(rng.normal(size=(12, 3)), axis=0)
    guide = q[3:-3] + rng.normal(size=(6, 3))
    out = guide_phase(q, guide, 10.0, 1.5)
    np.testing.assert_array_equal(out[:3], q[:3])
    np.testing.assert_array_equal(out[-3:], q[-3:])
    # stationary: the gradient of the quadratic vanishes on the free points
    jd = np.zeros((9, 12))
    for i in range(9):
        jd[i, i:i + 4] = (-1.0, 3.0, -3.0, 1.0)
    grad = 20.0 * jd.T @ (jd @ out) + 3.0 * np.vstack([np.zeros((3, 3)), out[3:-3] - guide,
                                                      np.zeros((3, 3))])
    assert np.abs(grad[3:-3]).max() < 1e-8
    # the normal cost's gradient against finite differences (near the pillar, feasibility on)
    spline = BSpline(np.column_stack([np.linspace(2.0, 5.0, 12), 0.2 * np.sin(
        np.arange(12.0)) + 0.6, np.full(12, 1.5)]), 0.05)
    params = PgoParams(w_feasibility=1e-3)
    f, g = normal_cost(spline, PILLAR, params)
    q = np.array(spline.control_points)
    for i, d in ((4, 0), (5, 1), (7, 2), (8, 1)):
        h = 1e-6
        qp, qm = q.copy(), q.copy()
        qp[i, d] += h
        qm[i, d] -= h
        num = (normal_cost(spline.with_control_points(qp), PILLAR, params)[0]
               - normal_cost(spline.with_control_points(qm), PILLAR, params)[0]) / (2 * h)
        assert g[i, d] == pytest.approx(num, rel=1e-4, abs=1e-6)


def test_the_esdf_snapshot_reads_the_local_map_like_the_map():
    cam_cfg = CameraConfig().subsampled(4)
    box = trimesh.creation.box(extents=[0.6, 0.6, 3.0])
    box.apply_translation([3.0, 0.3, 1.5])
    m = LocalMap(None, 3.0, camera=cam_cfg)
    cam = DepthCamera(cam_cfg, box)
    p = np.array([0.05, 0.05, 1.55])
    for k in range(8):
        m.fuse(cam.capture(k * 50_000, p, np.array([1.0, 0.0, 0.0, 0.0])))
    grid = EsdfGrid.from_map(m)
    pts = np.random.default_rng(0).uniform([-1.0, -3.0, -0.2], [6.0, 3.0, 3.2], (4000, 3))
    d, g = grid.evaluate(pts)
    d_map, g_map = m.esdf(pts)
    np.testing.assert_allclose(d, d_map, atol=1e-12)
    np.testing.assert_allclose(g, g_map, atol=1e-9)
    assert m.occupied_inflated(pts).any()
    np.testing.assert_array_equal(grid.occupied(pts), m.occupied_inflated(pts))


def test_the_esdf_box_of_a_segment_beyond_the_window_is_moved_onto_it():
    # A replan whose segment lies beyond the window (seen in the paper campaign: Urban
    # configuration 3, 52 s into a flight) raised "the ESDF box does not overlap the
    # window", which failed the trial as a navigator error.
    m = LocalMap(None, 3.0, center_m=(0.0, 0.0))
    lo, hi = m.window_min_m, m.window_max_m
    inside = np.array([0.5, -1.0, 1.5])
    np.testing.assert_array_equal(esdf_centre(m, inside, 5.5), inside)
    # a box centred off the window but still overlapping it stays where it was
    near = np.array([hi[0] + 3.0, 0.0, 1.5])
    np.testing.assert_array_equal(esdf_centre(m, near, 5.5), near)
    EsdfGrid.from_map(m, near, 5.5)
    far = np.array([hi[0] + 9.0, lo[1] - 7.0, 1.5])
    with pytest.raises(ValueError, match="does not overlap"):
        EsdfGrid.from_map(m, far, 5.5)
    c = esdf_centre(m, far, 5.5)
    assert c[0] == pytest.approx(hi[0]) and c[1] == pytest.approx(lo[1]) and c[2] == 1.5
    grid = EsdfGrid.from_map(m, c, 5.5)
    assert grid.field.shape[0] >= 2 and grid.field.shape[1] >= 2
    d, _ = grid.evaluate(np.array([[hi[0] - 1.0, lo[1] + 1.0, 1.5]]))
    assert np.isfinite(d).all()


# ---- the navigator -----------------------------------------------------------------------
def test_parameters_are_checked():
    nav = PgoPlanner(latency_s=0.02, camera="d435")
    assert nav.name == "pgo" and nav.rate_hz == 100.0 and nav.latency == 0.02
    assert (nav.camera.width, nav.camera.height, nav.camera.rate_hz) == (320, 240, 30.0)
    for bad in ({"latency_s": -1}, {"local_segment_m": 0.5}, {"replan_period_s": True}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            PgoPlanner(**bad)
    with pytest.raises(ValueError):
        PgoParams(w_smooth=-1.0)


def test_a_plan_acts_only_after_its_latency_and_replans_every_half_second():
    nav = PgoPlanner(latency_s=0.2)
    nav.reset(open_task())
    sp0 = nav.step(obs_at(0.0))
    assert nav.pending is not None and nav.traj is None  # planned, not yet in force
    assert sp0.row[SP_POS:SP_POS + 3] == pytest.approx([0.0, 0.0, 1.5])  # holds meanwhile
    nav.step(obs_at(0.19))
    assert nav.traj is None
    nav.step(obs_at(0.2))
    assert nav.traj is not None and nav.traj.t0 == pytest.approx(0.2)
    assert nav.replans == 1 and nav.last_plan.status == "free"
    nav.step(obs_at(0.69))
    assert nav.replans == 1
    nav.step(obs_at(0.7))  # 0.5 s after the trajectory started
    assert nav.replans == 2 and nav.pending is not None


def test_the_safety_check_replans_or_stops():
    nav = PgoPlanner(latency_s=0.0)
    nav.reset(open_task())
    nav.step(obs_at(0.0))
    nav.step(obs_at(0.01))
    assert nav.traj is not None

    def wall_at(x):
        return OccupancyView(lambda p: np.abs(p[:, 0] - x) < 0.15, RES)

    nav.view = wall_at(3.0)  # ahead: replan, keep flying
    nav.next_check = 0.0
    nav.step(obs_at(0.05))
    assert nav.stop_at is None and nav.stats["safety_replans"] == 1
    assert nav.replans == 2 and nav.pending is not None
    nav.step(obs_at(0.06))
    nav.view = wall_at(0.3)  # within 0.5 m: emergency stop, hover there, plan from rest
    nav.next_check = 0.0
    sp = nav.step(obs_at(0.1, p=(0.1, 0.0, 1.5)))
    assert nav.stats["stops"] == 1 and nav.traj is None
    assert sp.row[SP_POS:SP_POS + 3] == pytest.approx([0.1, 0.0, 1.5])
    assert nav.replans == 3 and nav.pending is not None
    np.testing.assert_allclose(nav.pending.spline.position(0.0), [0.1, 0.0, 1.5], atol=1e-3)
    np.testing.assert_allclose(nav.pending.spline.velocity(0.0), 0.0, atol=1e-2)


def test_never_commands_nan():
    nav = PgoPlanner(latency_s=0.0)
    nav.reset(open_task())
    nav.step(obs_at(0.0))
    nav.yaw = math.nan
    with pytest.raises(FloatingPointError):
        nav.step(obs_at(0.01))


@pytest.mark.slow
def test_flies_a_forest_configuration_to_the_goal():
    nav = PgoPlanner()
    row = run_trial(TrialSpec(algorithm="straight", platform=AGILE, family="forest",
                              scenario_index=2), navigator=nav).row
    assert row["reason"] == "success", row["detail"]
    assert row["replans"] > 10 and nav.stats["topo"] >= 1
    assert row["max_speed_m_s"] < 4.5 and row["path_length_m"] / row["time_to_goal_s"] > 2.0
