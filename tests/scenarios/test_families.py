"""The seven scenario families: the paper's facts, determinism, obstacles on the straight
line, and a proof that every configuration is solvable for the largest catalog platform."""

from __future__ import annotations

import functools
import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh

from ft_sitl import __version__
from ft_sitl.navigation.maps.mapping import MapConfig
from ft_sitl.physics.catalog import catalog, largest_platform
from ft_sitl.rotations import matrix_from_quat
from ft_sitl.scenarios.camera import DepthCamera, camera_config
from ft_sitl.scenarios.collision import BodyProbe, CollisionWorld
from ft_sitl.scenarios.families import (
    FAMILIES,
    LINE_CORRIDOR_M,
    OPEN_FAMILIES,
    REGISTRY,
    build_scenario,
    mockamap_noise,
    perlin3,
    resolve_family,
    start_altitude,
    voxel_boxes,
)
from ft_sitl.scenarios.scenario import Scenario, ScenarioError
from ft_sitl.scenarios.solvability import (
    body_path,
    find_path,
    occupancy_grid,
    polyline_clearance,
    scenario_path,
    segment_mesh_distance,
    segment_triangles_distance,
)

R_MAX = max(p.collision_radius_m for p in catalog().values())
INDICES = range(1, 11)


def perlin_slow(cases):
    """Parameters of a test over families; Perlin's take seconds each to build and to
    solve, so they are in the slow lane (tests/lanes.py)."""
    def case(c):
        values = c if isinstance(c, tuple) else (c,)
        return pytest.param(*values, marks=pytest.mark.slow) if values[0] == "perlin" else c

    return [case(c) for c in cases]


ALL = perlin_slow([(f, i) for f in FAMILIES for i in INDICES])

# family: (width, length, ceiling, category) -- benchmark-protocol.md, paper Sec. III-B
PAPER = {
    "forest": (40.0, 60.0, 3.0, "classic"),
    "urban": (60.0, 60.0, 10.0, "classic"),
    "random_angle_cylinder": (40.0, 60.0, 3.0, "classic"),
    "narrow_gap": (50.0, 50.0, 4.0, "theoretical"),
    "sudden_drop": (50.0, 50.0, 4.0, "theoretical"),
    "maze": (25.0, 40.0, 2.0, "theoretical"),
    "perlin": (40.0, 50.0, 4.0, "theoretical"),
}


@functools.cache
def built(family: str, index: int, seed: int = 0) -> Scenario:
    return build_scenario(family, index, seed)


def test_largest_platform_radius():
    assert 0.38 < R_MAX < 0.39


@pytest.mark.slow
def test_registry_is_the_papers_seven_families():
    assert list(FAMILIES) == list(PAPER)
    for name, fn in FAMILIES.items():
        sc = fn(1, 0)
        assert sc.family == name and sc.category == PAPER[name][3]


# ---- every configuration ---------------------------------------------------------------


@pytest.mark.parametrize("family,index", ALL)
def test_configuration(family, index):
    sc = built(family, index)
    width, length, ceiling, category = PAPER[family]
    assert (sc.family, sc.index, sc.seed, sc.category) == (family, index, 0, category)
    np.testing.assert_array_equal(sc.bounds_min, [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(sc.bounds_max, [width, length, ceiling])
    assert sc.floor == 0.0 and sc.ceiling == ceiling
    # takeoff on the floor near the short side y = 0, start above it, goal across
    alt = 2.5 if family == "sudden_drop" else start_altitude(ceiling)
    assert sc.takeoff[2] == 0.0 and sc.takeoff[1] < 0.1 * length
    np.testing.assert_array_equal(sc.start, [sc.takeoff[0], sc.takeoff[1], alt])
    assert sc.goal[2] == alt and sc.goal[1] > 0.9 * length
    assert sc.goal[0] == pytest.approx(width / 2) and sc.start[0] == pytest.approx(width / 2)
    d = sc.goal - sc.start
    assert sc.start_yaw == pytest.approx(math.atan2(d[1], d[0]))
    assert sc.goal_radius_m == 2.0
    # provenance
    prov = sc.provenance
    assert prov["generator"].endswith(family) and prov["seed"] == 0 and prov["index"] == index
    assert prov["ft_sitl_version"] == __version__ and isinstance(prov["parameters"], dict)
    json.dumps(sc.summary())
    # obstacles: closed, outward-facing, on the straight line
    assert sc.obstacle_count > 0
    assert sc.mesh.is_watertight and sc.mesh.is_winding_consistent and sc.mesh.volume > 0
    if family in OPEN_FAMILIES or family == "narrow_gap":
        # on the line, or beside it by less than the corridor (Narrow-Gap: a gap on the line)
        assert sc.line_blocked(LINE_CORRIDOR_M), "no obstacle along the start->goal segment"
    else:
        assert sc.line_blocked(0.0), "no obstacle crosses the straight start->goal segment"
        assert sc.line_blocked(R_MAX)


@pytest.mark.parametrize("family,index", ALL)
def test_solvable_for_the_largest_platform(family, index):
    """The grid search finds a path; an exact segment-to-triangle check confirms it."""
    sc = built(family, index)
    path = scenario_path(sc, R_MAX)
    assert path is not None, f"{sc.name}: no path for radius {R_MAX:.3f} m"
    np.testing.assert_array_equal(path[0], sc.start)
    np.testing.assert_array_equal(path[-1], sc.goal)
    assert polyline_clearance(sc.mesh, path, cutoff=R_MAX) >= R_MAX
    assert np.all(path >= sc.bounds_min + R_MAX - 1e-9)
    assert np.all(path <= sc.bounds_max - R_MAX + 1e-9)


@pytest.mark.parametrize("family,index", perlin_slow([(f, i) for f in FAMILIES for i in (1, 10)]))
def test_solvable_for_the_largest_body_at_the_start_yaw(family, index):
    """Protocol 5's vehicle is its body: the largest platform's, held level at the start
    yaw, has a path; an exact fcl check of the body along it confirms the grid."""
    sc = built(family, index)
    big = largest_platform()
    found = body_path(sc, big.body(), yaws_deg=(0.0,))
    assert found is not None, f"{sc.name}: no path for {big.name}'s body"
    path, yaw = found
    world = CollisionWorld(sc.mesh, sc.bounds_min, sc.bounds_max)
    probe = BodyProbe(big.body())
    rot = matrix_from_quat([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    for a, b in zip(path[:-1], path[1:]):
        for t in np.linspace(0.0, 1.0, max(2, int(np.linalg.norm(b - a) / 0.05) + 1)):
            p = a + t * (b - a)
            assert world.body_distance(probe, p, rot) > 0.0, (sc.name, p)


def test_narrow_gap_needs_the_largest_body_along_the_passage():
    """An X frame is 2.56 d wide across its nose and 3.15 d along its arms: the largest
    platform (d = 0.2956 m) passes a 0.85 m gap nose first and not yawed 45 degrees."""
    sc = built("narrow_gap", 1)
    big = largest_platform()
    assert body_path(sc, big.body(), yaws_deg=(0.0,)) is not None
    assert body_path(sc, big.body(), yaws_deg=(45.0,)) is None


@pytest.mark.parametrize("family", perlin_slow(list(FAMILIES)))
def test_deterministic(family):
    a, b = built(family, 4), build_scenario(family, 4, 0)
    assert a.mesh_digest() == b.mesh_digest()
    assert a.mesh.vertices.tobytes() == b.mesh.vertices.tobytes()
    assert a.mesh.faces.tobytes() == b.mesh.faces.tobytes()
    assert json.dumps(a.summary()) == json.dumps(b.summary())
    # seed and index both change the layout
    assert build_scenario(family, 4, 1).mesh_digest() != a.mesh_digest()
    assert built(family, 5).mesh_digest() != a.mesh_digest()


def test_no_global_rng():
    np.random.seed(123)
    state = np.random.get_state()[1].copy()
    a = build_scenario("forest", 2, 7)
    assert np.array_equal(np.random.get_state()[1], state)
    np.random.seed(999)
    assert build_scenario("forest", 2, 7).mesh_digest() == a.mesh_digest()


@pytest.mark.slow
def test_other_seeds_build_and_are_solvable():
    for family in FAMILIES:
        sc = build_scenario(family, 7, 3)
        open_line = family in OPEN_FAMILIES or family == "narrow_gap"
        assert sc.line_blocked(LINE_CORRIDOR_M if open_line else 0.0)
        assert scenario_path(sc, R_MAX) is not None, sc.name


# ---- family facts ----------------------------------------------------------------------


def test_counts_rise_with_index():
    gaps = [built("narrow_gap", i).provenance["parameters"]["gap_count"] for i in INDICES]
    assert gaps == list(INDICES)
    assert [len(built("narrow_gap", i).provenance["layout"]["walls"]) for i in INDICES] == gaps
    drops = [built("sudden_drop", i).obstacle_count for i in INDICES]
    assert drops == sorted(drops) and len(set(drops)) == 10


def test_forest():
    for i in INDICES:
        sc = built("forest", i)
        trees = np.array(sc.provenance["layout"]["trees_xyrh"])
        assert len(trees) == round(40 * 60 / 49) == sc.obstacle_count
        assert sc.provenance["parameters"]["density_per_m2"] == 1 / 49
        assert np.all((trees[:, 2] >= 0.15) & (trees[:, 2] <= 0.30))
        assert np.all(trees[:, 3] > sc.ceiling)
        assert sc.mesh.bounds[0][2] == 0.0


def test_random_angle_cylinder():
    tilts = []
    for i in INDICES:
        sc = built("random_angle_cylinder", i)
        cyl = sc.provenance["layout"]["cylinders"]
        assert len(cyl) == round(40 * 60 / 36) == sc.obstacle_count
        assert all(0.25 <= c["r"] <= 0.5 for c in cyl)
        tilts += [c["tilt_deg"] for c in cyl]
    assert 0.0 <= min(tilts) < 10.0 and 170.0 < max(tilts) <= 180.0


def test_urban_version_1():
    for i in INDICES:
        sc = build_scenario("urban", i, version=1)
        lay = sc.provenance["layout"]
        assert lay["buildings_lo_hi"] and lay["walls_lo_hi"]
        assert sc.obstacle_count == len(lay["buildings_lo_hi"]) + len(lay["walls_lo_hi"])
        assert max(b[5] for b in lay["buildings_lo_hi"]) > sc.ceiling


# ---- Urban, version 2: the line runs along a street -----------------------------------


@functools.cache
def urban_v2(index: int, seed: int = 0) -> Scenario:
    return build_scenario("urban", index, seed, version=2)


def _pieces(sc: Scenario) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(name, lower corner, upper corner) of each obstacle piece, from the mesh itself."""
    ends = list(sc.piece_first_face[1:]) + [len(sc.mesh.faces)]
    out = []
    for name, a, b in zip(sc.piece_names, sc.piece_first_face, ends):
        v = sc.mesh.vertices[sc.mesh.faces[a:b].ravel()]
        out.append((name, v.min(axis=0), v.max(axis=0)))
    return out


def _on_route(lo, hi, sc) -> bool:
    return lo[1] < sc.goal[1] and hi[1] > sc.start[1]


@pytest.mark.parametrize("index", INDICES)
def test_urban_v2_keeps_the_papers_area_and_ceiling(index):
    sc = urban_v2(index)
    assert sc.provenance["generator_version"] == 2
    np.testing.assert_array_equal(sc.bounds_min, [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(sc.bounds_max, [60.0, 60.0, 10.0])
    par = sc.provenance["parameters"]
    assert par["size_m"] == [60.0, 60.0] and par["ceiling_m"] == 10.0
    np.testing.assert_array_equal(sc.start, [30.0, 3.0, 2.0])
    np.testing.assert_array_equal(sc.goal, [30.0, 57.0, 2.0])
    names = {n.rsplit(" ", 1)[0] for n in sc.piece_names}
    assert {"building", "wall", "low wall"} <= names
    heights = [hi[2] for n, _, hi in _pieces(sc) if n.startswith("building")]
    assert min(heights) < sc.ceiling < max(heights)  # some to fly over, some far above


@pytest.mark.parametrize("index", INDICES)
def test_urban_v2_line_runs_along_a_street_lined_with_buildings(index):
    """No building stands on the line: the nearest is >= 5.5 m beside it (the avenue's
    half width), and buildings line the avenue on both sides."""
    sc = urban_v2(index)
    x = sc.start[0]
    buildings = [(lo, hi) for n, lo, hi in _pieces(sc) if n.startswith("building")]
    assert len(buildings) >= 8
    gaps = [max(lo[0] - x, x - hi[0]) for lo, hi in buildings]
    assert min(gaps) >= 5.5
    west, east = sc.provenance["layout"]["avenue_x_m"]
    assert x - west >= 5.5 and east - x >= 5.5
    assert not [lo for lo, hi in buildings if hi[0] > west and lo[0] < east]
    assert any(hi[0] > west - 2.0 for lo, hi in buildings if hi[0] <= west)
    assert any(lo[0] < east + 2.0 for lo, hi in buildings if lo[0] >= east)


@pytest.mark.parametrize("index", INDICES)
def test_urban_v2_has_obstacles_beside_and_across_the_line(index):
    """Beside the line: a truck or wall within 2.5 m of it that does not cross it, the
    nearest within LINE_CORRIDOR_M; across it: a low wall under the flight altitude in
    every configuration, and trucks or walls at flight altitude, as many as the index says,
    each crossed >= 0.6 m from its ends and leaving passages on both sides."""
    sc = urban_v2(index)
    x, alt = sc.start[0], sc.start[2]
    pieces = [(n, lo, hi) for n, lo, hi in _pieces(sc) if _on_route(lo, hi, sc)]
    across = [(n, lo, hi) for n, lo, hi in pieces if lo[0] < x < hi[0]]
    beside = [max(lo[0] - x, x - hi[0]) for n, lo, hi in pieces
              if not lo[0] < x < hi[0] and hi[2] > alt]
    assert beside and min(beside) < 2.5
    assert any(n.startswith("low wall") and hi[2] < alt - 0.5 for n, lo, hi in across)
    blocking = [(n, lo, hi) for n, lo, hi in across if lo[2] < alt < hi[2]]
    expected = [0, 0, 0, 1, 1, 2, 2, 3, 3, 4][index - 1]
    assert len(blocking) == expected == sc.provenance["parameters"]["barrier_count"]
    west, east = sc.provenance["layout"]["avenue_x_m"]
    for n, lo, hi in blocking:
        assert n.split()[0] in ("truck", "wall")
        if n.startswith("wall"):
            assert hi[2] <= 3.0 + 5.0 * (index - 1) / 9 + 1e-9
        assert min(x - lo[0], hi[0] - x) >= 0.6 - 1e-9  # no platform slips past its end
        passages = sorted([lo[0] - west, east - hi[0]])
        assert passages[0] >= 2.5 - 1e-9 and passages[1] >= 4.0 - 1e-9
    ys = sorted((lo[1] + hi[1]) / 2 for _, lo, hi in blocking)
    assert all(b - a >= 7.0 for a, b in zip(ys, ys[1:]))
    if expected:
        assert sc.line_distance() == 0.0
    else:  # only the obstacle beside it: a vehicle narrower than the gap flies the line
        assert 0.0 < sc.line_distance() < LINE_CORRIDOR_M
        assert min(beside) == pytest.approx(sc.line_distance())
    # the first 10 m of the avenue after the start are clear
    assert all(lo[1] >= sc.start[1] + 10.0 for n, lo, hi in pieces
               if hi[0] > west and lo[0] < east)


def test_urban_v2_difficulty_rises_with_the_index():
    counts = [urban_v2(i).provenance["parameters"]["barrier_count"] for i in INDICES]
    assert counts == sorted(counts) and counts[0] == 0 and counts[-1] == 4
    tallest = {i: max([it["hi"][2] for s in range(4) for it in urban_v2(i, s).provenance
                       ["layout"]["avenue_obstacles"]
                       if it["role"] == "across" and it["kind"] == "wall"], default=0.0)
               for i in (4, 10)}
    assert tallest[4] <= 3.0 + 5.0 / 3 < tallest[10] <= 8.0


@pytest.mark.parametrize("index", INDICES)
def test_urban_v2_is_solvable_for_the_largest_body_at_flight_altitude(index):
    """The largest platform's body, held level at the start yaw, has a path that stays
    below 3 m (no climbing: NavRL holds its altitude); an exact fcl check confirms it."""
    sc = urban_v2(index)
    big = max(catalog().values(), key=lambda p: p.body().bounding_radius_m)
    low = replace(sc, bounds_max=(60.0, 60.0, 3.0))
    found = body_path(low, big.body(), yaws_deg=(0.0,))
    assert found is not None, f"{sc.name}: no level path for {big.name}'s body"
    path, yaw = found
    assert path[:, 2].max() < 3.0
    world = CollisionWorld(sc.mesh, sc.bounds_min, sc.bounds_max)
    probe = BodyProbe(big.body())
    rot = matrix_from_quat([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    for a, b in zip(path[:-1], path[1:]):
        for t in np.linspace(0.0, 1.0, max(2, int(np.linalg.norm(b - a) / 0.1) + 1)):
            assert world.body_distance(probe, a + t * (b - a), rot) > 0.0


def test_urban_v2_other_seeds():
    for seed in (1, 2, 3):
        for index in (1, 6, 10):
            sc = urban_v2(index, seed)
            assert sc.line_blocked(LINE_CORRIDOR_M)
            assert scenario_path(sc, R_MAX) is not None, sc.name


def test_narrow_gap_version_1():
    """Version 1 (kept for its results): full-width walls, gaps 4-18 m off the line on
    alternating sides."""
    for i in INDICES:
        sc = build_scenario("narrow_gap", i, version=1)
        walls = sc.provenance["layout"]["walls"]
        assert all(0.85 <= w["gap_width_m"] <= 0.90 for w in walls)
        offsets = [w["gap_centre_x_m"] - 25.0 for w in walls]
        assert all(abs(o) >= 4.0 for o in offsets)
        assert all(a * b < 0 for a, b in zip(offsets, offsets[1:])), "gaps alternate sides"
        assert sc.mesh.bounds[1][2] > sc.ceiling
        np.testing.assert_allclose(sc.mesh.bounds[:, 0], [0.0, 50.0])
        # 2 r_max = 0.768 m fits through 0.85 m; a 0.46 m radius fits through no gap
        assert scenario_path(sc, 0.46) is None


def _free_spans(sc, y, z, lo=0.0, hi=50.0, step=0.001):
    """The free x-intervals of the segment x in [lo, hi] at (y, z), from the mesh."""
    x = np.linspace(lo, hi, round((hi - lo) / step) + 1)
    inside = sc.mesh.contains(np.column_stack([x, np.full_like(x, y), np.full_like(x, z)]))
    edges = np.flatnonzero(np.diff(inside.astype(int))) + 1
    bounds = np.concatenate([[0], edges, [len(x)]])
    return [(x[a], x[b - 1]) for a, b in zip(bounds[:-1], bounds[1:]) if not inside[a]]


def test_narrow_gap():
    """Version 2 (the default): the paper's numbers read off the mesh -- 50 x 50 m, ceiling
    4 m, one 0.85-0.90 m gap per wall, index walls -- and the placement rule: each gap
    centred on the start->goal line or 1-2 m beside it."""
    kinds = set()
    for i in INDICES:
        sc = built("narrow_gap", i)
        prov = sc.provenance
        assert prov["generator_version"] == 2
        assert prov["parameters"]["gap_width_m"] == [0.85, 0.9]
        walls = prov["layout"]["walls"]
        assert len(walls) == i == prov["parameters"]["gap_count"] == sc.obstacle_count
        ys = [w["y_m"] for w in walls]
        assert ys == sorted(ys) and 8.0 < ys[0] and ys[-1] < 42.0
        assert sc.mesh.bounds[1][2] > sc.ceiling  # no way over
        np.testing.assert_allclose(sc.mesh.bounds[:, 0], [0.0, 50.0])  # nor around
        for w in walls:
            # every wall's only opening, measured on the mesh at the flight altitude
            for y in (w["y_m"] - 0.14, w["y_m"] + 0.14):
                coarse = _free_spans(sc, y, sc.start[2], 0.01, 49.99, 0.05)
                assert len(coarse) == 1 and coarse[0][1] - coarse[0][0] < 0.9, coarse
                (span,) = _free_spans(sc, y, sc.start[2], coarse[0][0] - 0.1,
                                      coarse[0][1] + 0.1)
                assert 0.85 - 0.002 <= span[1] - span[0] <= 0.90
                assert (span[0] + span[1]) / 2 == pytest.approx(w["gap_centre_x_m"], abs=2e-3)
            off = abs(w["gap_centre_x_m"] - 25.0)
            assert w["on_line"] == (off == 0.0)
            assert off == 0.0 or 1.0 <= off <= 2.0
            kinds.add((w["on_line"], np.sign(w["gap_centre_x_m"] - 25.0)))
    assert kinds == {(True, 0.0), (False, 1.0), (False, -1.0)}


def test_narrow_gap_places_gaps_on_the_line_with_its_declared_probability():
    """Over many configurations (seeds 0-29), 40 % of the gaps are on the line and the rest
    fall either side, their offsets spread over 1-2 m."""
    walls = [w for seed in range(30) for i in INDICES
             for w in build_scenario("narrow_gap", i, seed).provenance["layout"]["walls"]]
    off = np.array([w["gap_centre_x_m"] - 25.0 for w in walls])
    on = np.array([w["on_line"] for w in walls])
    assert len(walls) == 30 * 55
    assert abs(on.mean() - 0.4) < 0.05  # 4 standard deviations
    side = np.sign(off[~on])
    assert abs((side > 0).mean() - 0.5) < 0.06
    assert np.all((np.abs(off[~on]) >= 1.0) & (np.abs(off[~on]) <= 2.0))
    assert np.quantile(np.abs(off[~on]), [0.1, 0.9]) == pytest.approx([1.1, 1.9], abs=0.06)


def test_narrow_gap_straight_flight_passes_only_gaps_on_the_line():
    """A body flown along the start->goal line, nose first, passes a configuration's walls
    exactly when all its gaps lie on the line -- the largest platform's (0.76 m across)
    included; a gap beside the line blocks it even for the smallest (0.30 m across). The
    paper's configurations hold both kinds."""
    bodies = sorted((p.body() for p in catalog().values()), key=lambda b: b.half_span_m)
    probes = [BodyProbe(bodies[0]), BodyProbe(bodies[-1])]
    straight = []
    for i in INDICES:
        sc = built("narrow_gap", i)
        world = CollisionWorld(sc.mesh, sc.bounds_min, sc.bounds_max)
        rot = matrix_from_quat([math.cos(sc.start_yaw / 2), 0.0, 0.0,
                                math.sin(sc.start_yaw / 2)])
        walls = sc.provenance["layout"]["walls"]
        # sample the line densely through each wall (0.02 m steps across +-0.8 m)
        ys = np.concatenate([w["y_m"] + np.arange(-0.8, 0.81, 0.02) for w in walls])
        for probe in probes:
            clear = all(world.body_distance(probe, np.array([25.0, y, sc.start[2]]), rot) > 0
                        for y in ys)
            assert clear == all(w["on_line"] for w in walls), (sc.name, probe.body)
        straight.append(all(w["on_line"] for w in walls))
    assert any(straight) and not all(straight)


def test_narrow_gap_every_gap_beside_the_line_is_mapped_whole_from_the_line():
    """From a stretch of the line at least 0.75 m long before each wall, the planners'
    camera (field of view) and map (obstacles marked within max_ray_length_m) take in both
    edges of a gap beside the line. Ray casts against the mesh confirm it from the middle
    of that stretch: the wall either side of the gap is hit within range, the ray through
    the gap's middle passes the wall. Only where walls stand closer than that stretch (8
    or more walls) may the previous wall be in the way."""
    cfg = camera_config("benchmark", None, None, None)
    half_fov = math.radians(cfg.fov_deg[0] / 2)
    reach = MapConfig().max_ray_length_m
    seen, hidden = 0, set()
    for i in INDICES:
        sc = built("narrow_gap", i)
        cam = DepthCamera(cfg, sc.mesh)
        half_t = sc.provenance["parameters"]["wall_thickness_m"] / 2
        walls = sc.provenance["layout"]["walls"]
        for j, w in enumerate(walls):
            if w["on_line"]:
                continue
            face = w["y_m"] - half_t
            c, half = w["gap_centre_x_m"], w["gap_width_m"] / 2
            far = abs(c - 25.0) + half + 0.02  # the wall just beyond the far edge
            # distances before the face from which it is in view and in range
            d_lo, d_hi = far / math.tan(half_fov), math.sqrt(reach ** 2 - far ** 2)
            assert d_hi - d_lo >= 0.75, (sc.name, w)
            if j > 0:  # not from behind the previous wall
                d_hi = min(d_hi, face - (walls[j - 1]["y_m"] + half_t))
            if d_hi <= d_lo:
                hidden.add(i)
                continue
            eye = np.array([25.0, face - (d_lo + d_hi) / 2, sc.start[2]])
            targets = np.array([[c - half - 0.02, face, eye[2]], [c + half + 0.02, face, eye[2]],
                                [c, face, eye[2]]])
            dirs = targets - eye
            dist = np.linalg.norm(dirs, axis=1)
            dirs /= dist[:, None]
            assert np.all(np.abs(np.arctan2(dirs[:, 0], dirs[:, 1])) <= half_fov)
            hit = cam.cast(eye, dirs)
            np.testing.assert_allclose(hit[:2], dist[:2], atol=1e-6)
            assert np.all(hit[:2] <= reach)
            assert hit[2] > dist[2] + 2 * half_t  # through the gap
            seen += 1
    assert seen > 20 and min(hidden, default=10) >= 8, (seen, hidden)


def test_sudden_drop():
    for i in INDICES:
        sc = built("sudden_drop", i)
        lo, hi = sc.mesh.bounds
        assert lo[2] == 1.5 and hi[2] == 14.0  # lowest obstacle point; 14 m volume
        assert sc.start[2] == 2.5 and sc.ceiling == 4.0
        assert sc.provenance["parameters"]["size_m"] == [50.0, 50.0, 14.0]
        path = scenario_path(sc, R_MAX)
        assert path[:, 2].min() < 1.5 - R_MAX  # the vehicle has to drop below the blocks


def test_maze_version_1():
    for i in INDICES:
        sc = build_scenario("maze", i, version=1)
        p = sc.provenance
        assert p["parameters"]["corridor_width_m"] >= 2.0
        assert p["layout"]["dead_ends"] > 0
        east, north = np.array(p["layout"]["east_passages"]), np.array(
            p["layout"]["north_passages"])
        nx, ny = p["parameters"]["cells"]
        assert east.sum() + north.sum() == nx * ny - 1  # a perfect maze is a spanning tree
        assert sc.mesh.bounds[1][2] > sc.ceiling


# Maze, version 2 (issue 20): what the paper fixes, the start, loops and dead ends read
# from the mesh itself, and a route the largest body can fly well within 90 s
BIG_BODY = max(catalog().values(), key=lambda p: p.body().bounding_radius_m)
MAZE_ROUTE_FACTOR, MAZE_TURNS, MAZE_STOP_AND_GO_S = 1.8, 12, 45.0  # the generator's bounds


@functools.cache
def maze_v2(index: int) -> Scenario:
    return build_scenario("maze", index, version=2)


def _maze_cells(sc: Scenario):
    """(nx, ny), the cell size and the centre of cell (i, j) at the flight altitude."""
    nx, ny = sc.provenance["parameters"]["cells"]
    cw, ch = sc.provenance["parameters"]["cell_m"]
    return (nx, ny), (cw, ch), lambda i, j: np.array([(i + 0.5) * cw, (j + 0.5) * ch,
                                                     sc.start[2]])


def _maze_passages(sc: Scenario) -> dict:
    """Which neighbouring cells the mesh joins: the segment between their centres is clear
    of the walls by more than the largest body's bounding radius (True), or it crosses a
    wall (False); anything in between fails. Keys ((i, j), (i2, j2))."""
    (nx, ny), _, centre = _maze_cells(sc)
    out = {}
    for i in range(nx):
        for j in range(ny):
            for i2, j2 in ((i + 1, j), (i, j + 1)):
                if i2 < nx and j2 < ny:
                    d = segment_mesh_distance(sc.mesh, centre(i, j), centre(i2, j2))
                    assert d == 0.0 or d > BIG_BODY.body().bounding_radius_m, (sc.name, i, j)
                    out[(i, j), (i2, j2)] = d > 0.0
    return out


def _stop_and_go_s(points, speed=4.0, acc=3.0) -> float:
    """Flying a polyline from rest to rest on every straight leg (the vehicle stops at
    every corner) at most at ``speed`` with ``acc``."""
    pts = np.asarray(points, dtype=float)
    legs, heading = [], None
    for a, b in zip(pts[:-1], pts[1:]):
        d = b - a
        n = float(np.linalg.norm(d))
        if heading is not None and np.allclose(d / n, heading):
            legs[-1] += n
        else:
            legs.append(n)
            heading = d / n
    return sum(d / speed + speed / acc if d >= speed**2 / acc else 2 * math.sqrt(d / acc)
               for d in legs)


@pytest.mark.parametrize("index", INDICES)
def test_maze_v2_is_the_papers_labyrinth(index):
    """25 x 40 m, flight height limited to 2 m (walls above it), closed all round; the
    start cell opens towards the goal; dead ends and loops (not a perfect maze)."""
    sc = maze_v2(index)
    assert sc.provenance["generator_version"] == 2
    np.testing.assert_array_equal(sc.bounds_max, [25.0, 40.0, 2.0])
    assert sc.start[2] == sc.goal[2] == 1.0
    lo, hi = sc.mesh.bounds
    np.testing.assert_allclose([lo[0], lo[1], hi[0], hi[1]], [-0.1, -0.1, 25.1, 40.1])
    assert lo[2] == 0.0 and hi[2] > sc.ceiling
    assert sc.line_blocked(0.0)
    (nx, ny), (cw, ch), centre = _maze_cells(sc)
    assert min(cw, ch) - 0.2 > 3.0  # corridors
    # the start cell opens towards the goal: a whole cell ahead is clear for the body
    ahead = sc.start + np.array([0.0, ch, 0.0])
    assert segment_mesh_distance(sc.mesh, sc.start, ahead) > BIG_BODY.body().bounding_radius_m
    # the passages as the mesh has them: connected, more than a spanning tree, dead ends
    passages = _maze_passages(sc)
    edges = [e for e, open_ in passages.items() if open_]
    graph = {(i, j): set() for i in range(nx) for j in range(ny)}
    for a, b in edges:
        graph[a].add(b)
        graph[b].add(a)
    seen, todo = {(nx // 2, 0)}, [(nx // 2, 0)]
    while todo:
        for n in graph[todo.pop()] - seen:
            seen.add(n)
            todo.append(n)
    assert len(seen) == nx * ny  # every cell reachable
    loops = len(edges) - (nx * ny - 1)
    assert loops >= 6 and loops == sc.provenance["layout"]["loops"]
    dead_ends = sum(len(v) == 1 for v in graph.values())
    assert dead_ends > 0 and dead_ends == sc.provenance["layout"]["dead_ends"]


@pytest.mark.parametrize("index", INDICES)
def test_maze_v2_route_is_flyable_in_the_time(index):
    """The largest platform's body (held level at the start yaw) has a path at most 1.8 x
    the straight line (grid proof); the recorded route through cell centres keeps it clear
    (exact), turns at most 12 times, and flown stopping at every corner at 4 m/s with
    3 m/s^2 takes at most 45 s, half the 90 s budget."""
    sc = maze_v2(index)
    straight = float(np.linalg.norm(sc.goal - sc.start))
    found = body_path(sc, BIG_BODY.body(), yaws_deg=(0.0,))
    assert found is not None, sc.name
    body_m = float(np.linalg.norm(np.diff(found[0], axis=0), axis=1).sum())
    assert body_m <= MAZE_ROUTE_FACTOR * straight
    lay = sc.provenance["layout"]
    _, _, centre = _maze_cells(sc)
    route = np.array([centre(i, j) for i, j in lay["route_cells"]])
    np.testing.assert_allclose(route[[0, -1]], [sc.start, sc.goal])
    assert polyline_clearance(sc.mesh, route) > BIG_BODY.body().bounding_radius_m
    route_m = float(np.linalg.norm(np.diff(route, axis=0), axis=1).sum())
    assert route_m == pytest.approx(lay["route_length_m"])
    assert body_m <= route_m + 0.5 <= MAZE_ROUTE_FACTOR * straight + 0.5
    steps = np.diff(np.array(lay["route_cells"]), axis=0)
    turns = int(np.any(steps[1:] != steps[:-1], axis=1).sum())
    assert turns == lay["route_turns"] <= MAZE_TURNS
    assert _stop_and_go_s(route) == pytest.approx(lay["route_stop_and_go_s"])
    assert _stop_and_go_s(route) <= MAZE_STOP_AND_GO_S


def test_maze_v2_gets_harder_with_the_index():
    """A goal-greedy explorer wastes no step in configuration 1 and more in each next one
    (the dead ends facing the goal it has to back out of)."""
    waste = [maze_v2(i).provenance["layout"]["greedy_detour_cells"] for i in INDICES]
    bands = [maze_v2(i).provenance["parameters"]["detour_band_cells"] for i in INDICES]
    assert waste[0] == 0 and waste[-1] >= 34
    assert all(a < b for a, b in zip(waste, waste[1:])), waste
    assert all(lo <= w <= hi for w, (lo, hi) in zip(waste, bands))


@pytest.mark.slow
def test_perlin_version_1():
    for i in INDICES:
        sc = build_scenario("perlin", i, version=1)
        par, lay = sc.provenance["parameters"], sc.provenance["layout"]
        assert par["noise_frequency_per_voxel"] == 0.05 and par["fill_rate"] == 0.03
        assert lay["filled_voxels"] == round(0.03 * np.prod(lay["voxels"]))
        assert np.prod(lay["voxels"]) * par["voxel_m"] ** 3 == pytest.approx(40 * 50 * 4)
        assert sc.mesh.volume == pytest.approx(lay["filled_voxels"] * par["voxel_m"] ** 3)
        assert sc.obstacle_count == lay["blobs"] > 1


def _perlin_cells(sc) -> np.ndarray:
    """The filled 0.1 m cells of a Perlin version-2 scene, read back from its mesh: each
    cell centre inside one of the boxes (every box is its own 12-triangle piece)."""
    lay, voxel = sc.provenance["layout"], sc.provenance["parameters"]["voxel_m"]
    corners = sc.mesh.vertices.reshape(-1, 8, 3)
    lo = np.rint(corners.min(axis=1) / voxel).astype(int)
    hi = np.rint(corners.max(axis=1) / voxel).astype(int)
    cells = np.zeros(lay["voxels"], dtype=np.int16)
    for a, b in zip(lo, hi):
        cells[a[0]:b[0], a[1]:b[1], a[2]:b[2]] += 1
    assert cells.max() == 1  # the boxes do not overlap
    return cells.astype(bool)


def test_perlin_version_2_is_mockamaps_field_at_the_papers_numbers():
    """Version 2 (issue 20): the paper's frequency 0.05 and fill 0.03 read as mockamap reads
    them in EGO-Planner's simulator launch: 0.1 m cells, noise at 2 x 0.05 per cell (1.0
    cycles/m), the top 3 % of the cells filled; thousands of small blobs, several of them
    across the start->goal line, none within 3 m of the start and goal columns."""
    from scipy.ndimage import label
    for i in (1, 10):
        sc = built("perlin", i)
        par, lay = sc.provenance["parameters"], sc.provenance["layout"]
        assert sc.provenance["generator_version"] == 2
        assert (par["complexity"], par["fill_rate"], par["voxel_m"], par["fractal"]) == \
            (0.05, 0.03, 0.1, 1)
        assert par["noise_frequency_per_m"] == pytest.approx(1.0)
        assert lay["voxels"] == [400, 500, 40]
        assert lay["filled_voxels"] == round(0.03 * 400 * 500 * 40)
        cells = _perlin_cells(sc)
        assert cells.sum() == lay["filled_voxels"] and lay["boxes"] == len(sc.mesh.faces) // 12
        assert sc.mesh.volume == pytest.approx(lay["filled_voxels"] * 0.1 ** 3)
        _, blobs = label(cells)
        assert sc.obstacle_count == lay["blobs"] == blobs and 1000 < blobs < 4000
        # blobs across the line at the start altitude (0.1 m cells at x 19.9-20.1 m)
        on_line, n_line = label(cells[199:201, 30:470, 19:21])
        assert n_line >= 3
        # 3 m clear around the takeoff column and the goal
        c = (np.arange(400) + 0.5) * 0.1
        y = (np.arange(500) + 0.5) * 0.1
        for gy in (3.0, 47.0):
            near = np.hypot(c[:, None] - 20.0, y[None, :] - gy) < 3.0
            assert not cells[near].any()
        # the field's scale is mockamap's: blobs of ~0.1 m^3 on average (~120 cells, a
        # 0.5 m cube), where version 1's 0.2 cycles/m made 37-58 blobs of ~5 m^3
        assert 50 < cells.sum() / blobs < 300


def test_voxel_boxes_cover_the_filled_cells_exactly():
    rng = np.random.default_rng(3)
    for shape, p in (((7, 9, 5), 0.5), ((20, 11, 6), 0.9), ((4, 4, 4), 0.0), ((3, 5, 2), 1.0)):
        filled = rng.random(shape) < p
        lo, hi = voxel_boxes(filled)
        cover = np.zeros(shape, dtype=int)
        for a, b in zip(lo, hi):
            assert np.all(b > a)
            cover[a[0]:b[0], a[1]:b[1], a[2]:b[2]] += 1
        np.testing.assert_array_equal(cover, filled.astype(int))
    # a solid block is one box; two columns of different heights stay two
    lo, hi = voxel_boxes(np.ones((3, 4, 5), dtype=bool))
    assert lo.tolist() == [[0, 0, 0]] and hi.tolist() == [[3, 4, 5]]
    two = np.zeros((2, 1, 3), dtype=bool)
    two[0, 0, :] = True
    two[1, 0, :2] = True
    assert len(voxel_boxes(two)[0]) == 2


def test_mockamap_noise_octaves():
    """Octave it is Perlin noise at 2^it x complexity with amplitude attenuation / it."""
    perm = np.random.default_rng(1).permutation(256)
    x = np.linspace(0.0, 7.0, 50)
    one = mockamap_noise(x, 0.3, 0.7, perm, 0.5, 1, 0.5)
    np.testing.assert_allclose(one, 0.5 * perlin3(x, 0.3, 0.7, perm))
    two = mockamap_noise(x, 0.3, 0.7, perm, 0.5, 2, 0.5)
    np.testing.assert_allclose(two - one, 0.25 * perlin3(2 * x, 0.6, 1.4, perm))


def test_perlin_noise_is_smooth_and_bounded():
    perm = np.random.default_rng(0).permutation(256)
    x = np.linspace(0, 10, 2001)
    v = perlin3(x, 0.3 * x, 0.1 * x + 0.5, perm)
    assert np.all(np.abs(v) <= 1.5) and v.std() > 0.05
    assert np.abs(np.diff(v)).max() < 0.05  # continuous
    np.testing.assert_allclose(perlin3(np.arange(5.0), 0.0, 0.0, perm), 0.0, atol=1e-12)


# ---- errors ----------------------------------------------------------------------------


def test_bad_family_suggests():
    with pytest.raises(ValueError, match=r"unknown scenario family 'forrest'.*'forest'"):
        build_scenario("forrest", 1)
    with pytest.raises(ValueError, match="families: forest, urban"):
        build_scenario("desert", 1)
    assert resolve_family("Narrow-Gap") == "narrow_gap"
    assert resolve_family("Random Perlin-Noise") == "perlin"
    assert build_scenario("Random-Angle Cylinder", 2).family == "random_angle_cylinder"


@pytest.mark.parametrize("index", [0, 11, -1, 2.0, "3", True, None])
def test_bad_index(index):
    with pytest.raises(ValueError, match="index must be"):
        build_scenario("maze", index)
    with pytest.raises(ScenarioError, match="index must be"):
        FAMILIES["maze"](index, 0)


@pytest.mark.parametrize("seed", [-1, 1.5, "0", None])
def test_bad_seed(seed):
    with pytest.raises(ValueError, match="seed must be a non-negative integer"):
        build_scenario("forest", 1, seed)


def test_scenario_validates_its_fields():
    sc = built("maze", 1)
    fields = {f: getattr(sc, f) for f in Scenario.__dataclass_fields__}
    for change, message in [
        ({"category": "extreme"}, "category"),
        ({"takeoff": (1.0, 1.0, 0.5)}, "takeoff must be on the floor"),
        ({"goal": (1.0, 99.0, 1.0)}, "goal.*outside the bounds"),
        ({"start": (1.0, 2.0)}, "start: needs 3"),
        ({"bounds_min": (0.0, 0.0, -1.0)}, "floor"),
        ({"goal_radius_m": 0.0}, "goal_radius_m"),
        ({"mesh": "mesh.ply"}, "trimesh"),
    ]:
        with pytest.raises(ScenarioError, match=message):
            Scenario(**{**fields, **change})
    with pytest.raises(AttributeError):
        sc.index = 2
    assert not sc.start.flags.writeable


# ---- the solvability check itself ------------------------------------------------------


def test_segment_distance_is_exact():
    rng = np.random.default_rng(1)
    tri = rng.uniform(-1, 1, (15, 3, 3))
    t = np.linspace(0, 1, 101)[:, None]
    u, v = np.meshgrid(np.linspace(0, 1, 41), np.linspace(0, 1, 41))
    keep = (u + v) <= 1
    u, v = u[keep][:, None], v[keep][:, None]
    for _ in range(8):
        p, q = rng.uniform(-2, 2, (2, 3))
        d = segment_triangles_distance(p, q, tri)
        seg = p + t * (q - p)
        for k, (a, b, c) in enumerate(tri):  # brute force on dense samples
            pts = a + u * (b - a) + v * (c - a)
            brute = np.sqrt(((seg[:, None] - pts[None]) ** 2).sum(-1)).min()
            assert d[k] <= brute + 1e-12
            assert brute - d[k] < 0.08


def _slot(width: float, merged: bool = False) -> trimesh.Trimesh:
    """A wall across y = 5 (x in [0, 10], z in [0, 3]) with a slot of ``width`` at x = 5.
    ``merged``: the left part is two touching boxes with welded vertices (not convex)."""
    left = [trimesh.creation.box(bounds=[[0, 4.9, 0], [5 - width / 2, 5.1, 3]])]
    if merged:
        left = [trimesh.creation.box(bounds=[[0, 4.9, 0], [2, 5.1, 3]]),
                trimesh.creation.box(bounds=[[2, 4.9, 0], [5 - width / 2, 5.1, 3]])]
    right = trimesh.creation.box(bounds=[[5 + width / 2, 4.9, 0], [10, 5.1, 3]])
    if merged:
        left = trimesh.util.concatenate(left)
        left.merge_vertices()
        return trimesh.Trimesh(np.vstack([left.vertices, right.vertices]),
                               np.vstack([left.faces, right.faces + len(left.vertices)]),
                               process=False)
    return trimesh.util.concatenate(left + [right])


@pytest.mark.parametrize("merged", [False, True])
def test_grid_is_conservative_at_a_slot(merged):
    lo, hi = (0, 0, 0), (10, 10, 3)
    start, goal = (3.0, 1.0, 1.5), (7.0, 9.0, 1.5)
    r = 0.4
    pitch = (0.02, 0.25, 0.25)
    assert find_path(_slot(2 * r - 0.01, merged), start, goal, lo, hi, r, pitch) is None
    wide = _slot(2 * r + 0.06, merged)
    path = find_path(wide, start, goal, lo, hi, r, pitch)
    assert path is not None
    assert polyline_clearance(wide, path) >= r
    assert np.any(np.abs(path[:, 0] - 5.0) < 0.03)  # through the slot
    # the triangle fallback for a non-convex part blocks hardly more than convex pieces do
    free = occupancy_grid(wide, lo, hi, r, pitch).free.sum()
    assert free >= 0.98 * occupancy_grid(_slot(2 * r + 0.06), lo, hi, r, pitch).free.sum()


def test_segment_mesh_distance_cutoff():
    box = trimesh.creation.box(bounds=[[0, 0, 0], [1, 1, 1]])
    assert segment_mesh_distance(box, (2, 0.5, 0.5), (3, 0.5, 0.5)) == pytest.approx(1.0)
    assert segment_mesh_distance(box, (2, 0.5, 0.5), (3, 0.5, 0.5), cutoff=0.5) == math.inf
    assert segment_mesh_distance(box, (-1, 0.5, 0.5), (2, 0.5, 0.5)) == 0.0


# --- generator versions ------------------------------------------------------------------
V1_DIGESTS = Path(__file__).parent / "data" / "generator_v1_digests.json"


@pytest.mark.slow
def test_every_family_rebuilds_its_version_1_configurations_byte_for_byte():
    """Results written with a family's first generator stay reproducible after the family
    gets a newer one: version 1 of every configuration (seed 0) builds the mesh it built
    when those results were written (digests recorded then)."""
    recorded = json.loads(V1_DIGESTS.read_text())["digests"]
    assert len(recorded) == 70
    for key, digest in sorted(recorded.items()):
        family, index = key.rsplit("-", 1)
        sc = build_scenario(family, int(index), version=1)
        assert sc.provenance["generator_version"] == 1
        assert sc.mesh_digest() == digest, key


@pytest.mark.slow
def test_a_family_builds_its_newest_version_by_default_and_refuses_unknown_ones():
    for name, fam in REGISTRY.items():
        assert fam.version == max(fam.versions) and fam.schema is fam.versions[fam.version][0]
        assert set(fam.changes) == set(fam.versions)
        sc = build_scenario(name, 1)
        assert sc.provenance["generator_version"] == fam.version
        for bad in (0, fam.version + 1, "1", True, 1.0):
            with pytest.raises(ScenarioError, match=rf"{name}: no generator version .*"
                                                    rf"\(versions: 1"):
                build_scenario(name, 1, version=bad)


def test_the_generator_version_travels_in_the_spec_the_row_and_the_campaign(tmp_path):
    """A trial spec names its family's generator version (left out at 1, so the ids of
    rows written before versions existed stay); a stored spec without one is version 1;
    a campaign entry may ask for an older version and a bad one is refused by name."""
    from ft_sitl.missions.campaign_file import CampaignError, load_campaign
    from ft_sitl.missions.spec import TrialSpec, TrialSpecError

    spec = TrialSpec("straight", "0.98kg-EGO Planner DIY", "maze")
    assert spec.scenario_version == REGISTRY["maze"].version
    back = TrialSpec.from_dict({k: v for k, v in spec.to_dict().items()
                                if k != "scenario_version"})
    assert back.scenario_version == 1
    assert ("scenario_version" in spec.to_dict()) == (spec.scenario_version != 1)
    with pytest.raises(TrialSpecError, match="scenario_version: maze: no generator version 9"):
        TrialSpec("straight", "0.98kg-EGO Planner DIY", "maze", scenario_version=9)
    with pytest.raises(TrialSpecError, match="a scenario file has no generator version"):
        TrialSpec("straight", "0.98kg-EGO Planner DIY", "user", scenario_file="x.yaml",
                  scenario_version=1)
    p = tmp_path / "c.toml"
    p.write_text('name = "v"\nalgorithms = ["straight"]\nplatforms = ["0.98kg-EGO Planner DIY"]\n'
                 'scenarios = [{ family = "maze", indices = [2], version = 1 }]\ntrials = 1\n')
    (only,) = load_campaign(p).trial_specs()
    assert only.scenario_version == 1 and "scenario_version" not in only.to_dict()
    p.write_text(p.read_text().replace("version = 1", "version = 7"))
    with pytest.raises(CampaignError, match=r"scenarios\[0\]: version: maze: no generator "
                                            r"version 7"):
        load_campaign(p)


def test_a_perlin_field_too_fine_for_memory_is_refused_by_name():
    with pytest.raises(ScenarioError, match=r"perlin #1: 400 x 500 x 4 m in 0.05 m cells is "
                                            r"6,400,000,000 cells.*raise voxel_m"):
        build_scenario("perlin", 1, params={"size_m": (400.0, 500.0), "voxel_m": 0.05})
