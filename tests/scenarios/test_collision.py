"""Collision world (ft_sitl.scenarios.collision) against geometry with analytic answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from ft_sitl.scenarios.collision import (
    KINDS,
    CollisionMonitor,
    CollisionWorld,
    Contact,
)

TOL = 1e-6
BIG_LO = (-50.0, -50.0, -50.0)
BIG_HI = (50.0, 50.0, 50.0)


def box(extents, center=(0.0, 0.0, 0.0)) -> trimesh.Trimesh:
    m = trimesh.creation.box(extents=extents)
    m.apply_translation(center)
    return m


def world(mesh=None, lo=BIG_LO, hi=BIG_HI, **kw) -> CollisionWorld:
    return CollisionWorld(trimesh.Trimesh() if mesh is None else mesh, lo, hi, **kw)


def wall(x0: float = 0.0, thickness: float = 0.2) -> trimesh.Trimesh:
    """A wall x0 <= x <= x0 + thickness, 20 m wide (y) and 10 m high (z 0..10)."""
    return box([thickness, 20.0, 10.0], [x0 + thickness / 2, 0.0, 5.0])


def rot_x(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[1.0, 0.0, 0.0], [0.0, math.cos(a), -math.sin(a)],
                     [0.0, math.sin(a), math.cos(a)]])


# --------------------------------------------------------------------------------------
# static queries against a box (2 x 2 x 2 at the origin)
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def unit_box_world() -> CollisionWorld:
    return world(box([2.0, 2.0, 2.0]))


@pytest.mark.parametrize("p, dist", [
    ((3.0, 0.0, 0.0), 2.0),                       # face
    ((0.2, -4.0, 0.5), 3.0),                      # face
    ((2.0, 2.0, 0.0), math.sqrt(2.0)),            # edge
    ((2.0, -3.0, 4.0), math.sqrt(1 + 4 + 9)),     # corner
])
def test_far_miss_clearance_is_analytic(unit_box_world, p, dist):
    r = 0.5
    assert unit_box_world.clearance(p, r) == pytest.approx(dist - r, abs=1e-12)
    assert unit_box_world.obstacle_distance(p) == pytest.approx(dist, abs=1e-12)
    assert unit_box_world.check(p, r) is None


def test_touching_is_a_contact_with_zero_depth(unit_box_world):
    r = 0.5
    c = unit_box_world.check((1.5, 0.3, -0.2), r)
    assert unit_box_world.clearance((1.5, 0.3, -0.2), r) == pytest.approx(0.0, abs=TOL)
    assert isinstance(c, Contact) and c.kind == "obstacle"
    assert c.penetration_m == pytest.approx(0.0, abs=TOL)
    np.testing.assert_allclose(c.point, [1.0, 0.3, -0.2], atol=1e-12)
    np.testing.assert_allclose(c.normal, [1.0, 0.0, 0.0], atol=1e-12)
    assert 0 <= c.triangle < 12
    # a hair away is free, and the clearance says by how much
    assert unit_box_world.check((1.5 + 1e-4, 0.3, -0.2), r) is None
    assert unit_box_world.clearance((1.5 + 1e-4, 0.3, -0.2), r) == pytest.approx(1e-4, abs=1e-12)


def test_touching_an_edge_and_a_corner(unit_box_world):
    r = 0.5
    s = r / math.sqrt(2.0)
    c = unit_box_world.check((1 + s, 1 + s, 0.3), r)
    assert c is not None and c.penetration_m == pytest.approx(0.0, abs=TOL)
    np.testing.assert_allclose(c.normal, [s / r, s / r, 0.0], atol=1e-9)
    k = r / math.sqrt(3.0)
    c = unit_box_world.check((-1 - k, 1 + k, -1 - k), r)
    assert c is not None and c.penetration_m == pytest.approx(0.0, abs=TOL)
    np.testing.assert_allclose(c.point, [-1.0, 1.0, -1.0], atol=1e-12)
    assert unit_box_world.check((-1 - 1.01 * k, 1 + 1.01 * k, -1 - 1.01 * k), r) is None


def test_penetration_depth_into_a_face(unit_box_world):
    r = 0.5
    c = unit_box_world.check((-0.2, -1.4, 0.1), r)  # 0.1 m into the face y = -1
    assert c is not None
    assert c.penetration_m == pytest.approx(0.1, abs=1e-12)
    np.testing.assert_allclose(c.point, [-0.2, -1.0, 0.1], atol=1e-12)
    np.testing.assert_allclose(c.normal, [0.0, -1.0, 0.0], atol=1e-12)
    assert unit_box_world.clearance((-0.2, -1.4, 0.1), r) == pytest.approx(-0.1, abs=1e-12)


def test_centre_inside_a_closed_obstacle(unit_box_world):
    r = 0.3
    assert unit_box_world.closed
    # just inside the face x = 1: depth r + 0.1, normal still out of the box (+x)
    c = unit_box_world.check((0.9, 0.2, 0.0), r)
    assert c is not None and c.penetration_m == pytest.approx(r + 0.1, abs=1e-12)
    np.testing.assert_allclose(c.normal, [1.0, 0.0, 0.0], atol=1e-12)
    # deep inside, farther than r from every face: still a contact
    assert unit_box_world.clearance((0.0, 0.0, 0.0), r) == pytest.approx(-(1.0 + r), abs=1e-12)
    assert unit_box_world.check((0.0, 0.0, 0.0), r).penetration_m == pytest.approx(1.0 + r)
    # on a face diagonal (nearest feature an edge between two coplanar triangles)
    assert unit_box_world.obstacle_distance((0.5, 0.5, 0.2)) == pytest.approx(-0.5, abs=1e-12)


def test_open_mesh_is_a_surface():
    quad = trimesh.Trimesh([[0, -1, -1], [0, 1, -1], [0, 1, 1], [0, -1, 1]],
                           [[0, 1, 2], [0, 2, 3]])
    w = world(quad)
    assert not w.closed
    assert w.clearance((-0.8, 0.0, 0.0), 0.5) == pytest.approx(0.3)
    assert w.clearance((0.8, 0.0, 0.0), 0.5) == pytest.approx(0.3)  # no "inside" either side
    c = w.check((0.4, 0.0, 0.0), 0.5)
    assert c.penetration_m == pytest.approx(0.1) and c.normal[0] == pytest.approx(1.0)


def test_signed_distance_matches_trimesh_on_a_tilted_cylinder():
    cyl = trimesh.creation.cylinder(radius=0.5, height=3.0, sections=24)
    cyl.apply_transform(trimesh.transformations.rotation_matrix(math.radians(30), [1, 0, 0]))
    w = world(cyl)
    rng = np.random.default_rng(7)
    pts = rng.uniform(-1.5, 1.5, (150, 3))
    ours = np.array([w.obstacle_distance(p) for p in pts])
    ref = -trimesh.proximity.signed_distance(cyl, pts)  # trimesh: positive inside
    np.testing.assert_allclose(ours, ref, atol=1e-9)


# --------------------------------------------------------------------------------------
# tilted cylinder: R = 0.5, height 4, 64 sections (a vertex every 5.625 deg), rotated
# 30 deg about x and centred at C. Directions that point at a vertex line are exact.
# --------------------------------------------------------------------------------------

R_CYL, H_CYL = 0.5, 4.0
C_CYL = np.array([1.0, 2.0, 3.0])
ROT = rot_x(30.0)
AXIS, N90, N0 = ROT @ [0.0, 0.0, 1.0], ROT @ [0.0, 1.0, 0.0], ROT @ [1.0, 0.0, 0.0]


@pytest.fixture(scope="module")
def tilted_world() -> CollisionWorld:
    cyl = trimesh.creation.cylinder(radius=R_CYL, height=H_CYL, sections=64)
    T = np.eye(4)
    T[:3, :3] = ROT
    T[:3, 3] = C_CYL
    cyl.apply_transform(T)
    return world(cyl)


def test_tilted_cylinder_hit_and_miss(tilted_world):
    r = 0.3
    assert AXIS == pytest.approx([0.0, -0.5, math.sqrt(3) / 2])
    for along in (-1.5, 0.0, 1.2):
        base = C_CYL + along * AXIS
        # hit: 0.1 m deep on the vertex line at 90 deg
        c = tilted_world.check(base + (R_CYL + r - 0.1) * N90, r)
        assert c is not None and c.penetration_m == pytest.approx(0.1, abs=1e-9)
        np.testing.assert_allclose(c.point, base + R_CYL * N90, atol=1e-9)
        np.testing.assert_allclose(c.normal, N90, atol=1e-9)
        # miss: 5 cm off the vertex line at 0 deg
        p = base + (R_CYL + r + 0.05) * N0
        assert tilted_world.check(p, r) is None
        assert tilted_world.clearance(p, r) == pytest.approx(0.05, abs=1e-9)
    # beyond the tilted top cap, on the axis
    p = C_CYL + (H_CYL / 2 + r + 0.1) * AXIS
    assert tilted_world.clearance(p, r) == pytest.approx(0.1, abs=1e-9)
    c = tilted_world.check(C_CYL + (H_CYL / 2 + r - 0.02) * AXIS, r)
    np.testing.assert_allclose(c.normal, AXIS, atol=1e-9)
    assert c.penetration_m == pytest.approx(0.02, abs=1e-9)
    # a vertical climb 0.9 m off the centre (it would clear a vertical cylinder of this
    # radius) meets the tilted side where its distance to the axis, |0.9 cos30 - 0.5 z|,
    # falls to R + r
    start = C_CYL + np.array([0.0, -0.9, -1.5])
    assert tilted_world.check(start, r) is None
    c = tilted_world.sweep(start, start + [0, 0, 5.5], r)
    z_hit = 2.0 * (0.9 * math.cos(math.radians(30)) - (R_CYL + r))
    assert c is not None and c.center[2] == pytest.approx(C_CYL[2] + z_hit, abs=1e-5)
    np.testing.assert_allclose(c.normal, -N90, atol=1e-5)
    # 0.81 m off across the axis (x): outside R + r all the way up
    start = C_CYL + np.array([0.81, 0.0, -3.0])
    assert tilted_world.sweep(start, start + [0, 0, 6.0], r) is None


def test_tilted_cylinder_sweeps(tilted_world):
    r = 0.3
    base = C_CYL + 0.4 * AXIS
    # head-on along the 90-deg vertex line: first touch at R + r from the axis
    c = tilted_world.sweep(base + 3.0 * N90, base, r)
    assert c is not None and c.kind == "obstacle"
    np.testing.assert_allclose(c.center, base + (R_CYL + r) * N90, atol=2 * TOL)
    assert c.t == pytest.approx((3.0 - R_CYL - r) / 3.0, abs=1e-6)
    assert c.penetration_m <= TOL
    # passing 1 cm outside the circumscribed cylinder: a miss (x is across the axis)
    off = base + (R_CYL + r + 0.01) * N90
    assert tilted_world.sweep(off - 3.0 * N0, off + 3.0 * N0, r) is None
    # passing 1 cm inside it: a hit
    off = base + (R_CYL + r - 0.01) * N90
    assert tilted_world.sweep(off - 3.0 * N0, off + 3.0 * N0, r) is not None


# --------------------------------------------------------------------------------------
# thin walls at speed: no tunnelling
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("r", [0.3, 0.05])
def test_single_huge_step_through_a_thin_wall_hits_the_near_face(r):
    w = world(wall(0.0, 0.2))
    # 1 m step, both ends free: the sphere is clear of the wall before and after
    p0, p1 = np.array([-r - 0.4, 0.5, 2.0]), np.array([0.6 + r, 0.5, 2.0])
    assert w.check(p0, r) is None and w.check(p1, r) is None
    c = w.sweep(p0, p1, r)
    assert c is not None and c.kind == "obstacle"
    assert c.center[0] == pytest.approx(-r, abs=2 * TOL)
    assert c.point[0] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(c.normal, [-1.0, 0.0, 0.0], atol=1e-6)
    assert c.t == pytest.approx(0.4 / (1.0 + 2 * r), abs=1e-5)
    # the other way round hits the other face
    c = w.sweep(p1, p0, r)
    assert c.center[0] == pytest.approx(0.2 + r, abs=2 * TOL)
    np.testing.assert_allclose(c.normal, [1.0, 0.0, 0.0], atol=1e-6)


def test_thin_wall_at_4_m_s_and_1_khz_every_path():
    r, v, dt = 0.3, 4.0, 1e-3
    w = world(wall(5.0, 0.2), lo=(-10, -20, 0), hi=(20, 20, 12))
    xs = np.arange(0.0, 8.0, v * dt)
    pts = np.column_stack([xs, np.full_like(xs, 0.7), np.full_like(xs, 2.0)])
    # per-step sweeps
    first = next(i for i in range(len(pts) - 1) if w.sweep(pts[i], pts[i + 1], r) is not None)
    c = w.sweep(pts[first], pts[first + 1], r)
    assert c.center[0] == pytest.approx(5.0 - r, abs=2 * TOL)
    # the monitor, step by step and in one call
    mon = CollisionMonitor(w)
    hit = None
    for i in range(len(pts) - 1):
        hit = mon.update(pts[i], pts[i + 1], r)
        if hit is not None:
            break
    assert i == first and hit.center[0] == pytest.approx(5.0 - r, abs=2 * TOL)
    assert hit.kind == "obstacle" and mon.queries < (i + 1) / 10
    mon2 = CollisionMonitor(w)
    j, hit2 = mon2.update_path(pts, r)
    assert j == first and hit2.center[0] == pytest.approx(hit.center[0], abs=1e-9)
    assert abs(mon2.queries - mon.queries) <= 2
    # a 1 m step of the monitor (0.25 s at 4 m/s in one step) still hits the near face
    mon3 = CollisionMonitor(w)
    assert mon3.update((4.5 - r, 0.7, 2.0), (4.6 - r, 0.7, 2.0), r) is None
    hit3 = mon3.update((4.6 - r, 0.7, 2.0), (5.6 + r, 0.7, 2.0), r)
    assert hit3 is not None and hit3.center[0] == pytest.approx(5.0 - r, abs=2 * TOL)


# --------------------------------------------------------------------------------------
# grazing contacts
# --------------------------------------------------------------------------------------


def test_grazing_pass_along_a_face(unit_box_world):
    r = 0.5
    # tangent all along the face y = 1: a contact from the first instant of overlap
    c = unit_box_world.sweep((-3.0, 1.5, 0.0), (3.0, 1.5, 0.0), r)
    assert c is not None and c.penetration_m <= TOL
    assert -1.0 - 2e-3 < c.center[0] < -1.0  # touches at the edge x = -1 (within tol)
    # 1 mm off: a miss; 10 um off: a miss too, via the capsule fallback, in few queries
    assert unit_box_world.sweep((-3.0, 1.501, 0.0), (3.0, 1.501, 0.0), r) is None
    q0 = unit_box_world.queries
    assert unit_box_world.sweep((-3.0, 1.5 + 1e-5, 0.0), (3.0, 1.5 + 1e-5, 0.0), r) is None
    assert unit_box_world.queries - q0 < 40
    # 10 um off, then a box ahead: found beyond the graze
    two = trimesh.util.concatenate([box([2.0, 2.0, 2.0]), box([1.0, 1.0, 1.0], [4.0, 1.5, 0])])
    w = world(two)
    c = w.sweep((-3.0, 1.5 + 1e-5, 0.0), (6.0, 1.5 + 1e-5, 0.0), r)
    assert c is not None and c.center[0] == pytest.approx(3.5 - r, abs=1e-5)


def test_grazing_an_edge_at_zero_and_small_gaps(unit_box_world):
    r = 0.5
    s = r / math.sqrt(2.0)
    # straight line x + y = const touching the vertical edge (1, 1, z) at one point
    d = np.array([1.0, -1.0, 0.0]) / math.sqrt(2.0)
    touch = np.array([1.0 + s, 1.0 + s, 0.2])
    c = unit_box_world.sweep(touch - 2.0 * d, touch + 2.0 * d, r)
    assert c is not None and c.penetration_m <= TOL
    np.testing.assert_allclose(c.center, touch, atol=3e-3)  # a tangent touch: tol in depth
    gap = 1e-3
    off = touch + gap * np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)
    assert unit_box_world.sweep(off - 2.0 * d, off + 2.0 * d, r) is None
    assert unit_box_world.clearance(off, r) == pytest.approx(gap, abs=1e-12)


# --------------------------------------------------------------------------------------
# floor, ceiling and area bounds
# --------------------------------------------------------------------------------------


def test_bounds_are_reported_by_kind():
    w = world(None, lo=(-10.0, -5.0, 0.0), hi=(10.0, 5.0, 4.0))
    r = 0.25
    assert w.clearance((0, 0, 2), r) == pytest.approx(1.75)
    assert w.clearance((9.5, 0, 2), r) == pytest.approx(0.25)
    cases = [((0, 0, 0.1), "floor", [0, 0, 1], [0, 0, 0], 0.15),
             ((0, 0, 3.8), "ceiling", [0, 0, -1], [0, 0, 4], 0.05),
             ((9.9, 1, 2), "bounds", [-1, 0, 0], [10, 1, 2], 0.15),
             ((1, -5.1, 2), "bounds", [0, 1, 0], [1, -5, 2], 0.35)]
    for p, kind, n, q, depth in cases:
        c = w.check(p, r)
        assert c.kind == kind and c.triangle == -1
        np.testing.assert_allclose(c.normal, n)
        np.testing.assert_allclose(c.point, q)
        assert c.penetration_m == pytest.approx(depth)
    # sweeps: climb into the ceiling, fall to the floor, leave the area sideways
    c = w.sweep((0, 0, 2), (0, 0, 6), r)
    assert c.kind == "ceiling" and c.center[2] == pytest.approx(3.75, abs=2 * TOL)
    assert c.t == pytest.approx(1.75 / 4.0, abs=1e-6)
    c = w.sweep((1, 1, 3), (1, 1, -1), r)
    assert c.kind == "floor" and c.center[2] == pytest.approx(0.25, abs=2 * TOL)
    c = w.sweep((0, 0, 2), (0, 8, 2), r)
    assert c.kind == "bounds" and c.center[1] == pytest.approx(4.75, abs=2 * TOL)
    # the kinds filter: ignore the floor (e.g. while landed)
    assert w.check((0, 0, 0.1), r, kinds=("ceiling", "bounds", "obstacle")) is None
    assert w.clearance((0, 0, 2), r, kinds=()) == math.inf


def test_earliest_of_obstacle_and_ceiling_wins():
    r = 0.3
    ceiling_box = box([1.0, 1.0, 1.0], [0.0, 0.0, 5.0])  # 4.5 .. 5.5, above a 5 m ceiling
    w = world(ceiling_box, lo=(-10, -10, 0), hi=(10, 10, 5.0))
    c = w.sweep((0, 0, 2), (0, 0, 6), r)  # box bottom at 4.5 comes before the 5 m ceiling
    assert c.kind == "obstacle" and c.center[2] == pytest.approx(4.2, abs=2 * TOL)
    c = w.sweep((3, 0, 2), (3, 0, 6), r)
    assert c.kind == "ceiling" and c.center[2] == pytest.approx(4.7, abs=2 * TOL)


# --------------------------------------------------------------------------------------
# the monitor: cost follows proximity
# --------------------------------------------------------------------------------------


def test_monitor_queries_few_when_far_and_still_catches_a_wall():
    r = 0.3
    obstacles = trimesh.util.concatenate([box([1, 1, 6], [10, 8, 3]), wall(30.0, 0.2)])
    w = world(obstacles, lo=(-10, -20, 0), hi=(40, 20, 10))
    v, dt = 4.0, 1e-3
    xs = np.arange(0.0, 35.0, v * dt)
    pts = np.column_stack([xs, np.zeros_like(xs), np.full_like(xs, 3.0)])
    mon = CollisionMonitor(w)
    hit, i = None, 0
    for i in range(len(pts) - 1):
        hit = mon.update(pts[i], pts[i + 1], r)
        if hit is not None:
            break
    assert hit is not None and hit.kind == "obstacle"
    assert hit.center[0] == pytest.approx(30.0 - r, abs=2 * TOL)
    assert mon.steps == i + 1 > 7000
    assert mon.queries < mon.steps / 50  # ~ log-like approach to the wall, a few when far
    # far from everything (8 m from the box, 30 m from the wall): barely any queries
    mon2 = CollisionMonitor(w)
    assert mon2.update_path(pts[:2500], r) is None  # first 10 m
    assert mon2.queries < 30 and mon2.steps == 2499
    # continuing in a second call resumes without a restart
    q = mon2.queries
    j, c = mon2.update_path(pts[2499:], r)
    assert c.center[0] == pytest.approx(30.0 - r, abs=2 * TOL) and 2499 + j == i
    assert mon2.queries - q < 200


def test_monitor_without_obstacles_checks_bounds_only():
    w = world(None, lo=(-10, -10, 0), hi=(10, 10, 3))
    mon = CollisionMonitor(w, kinds=("ceiling", "bounds"))
    zs = np.linspace(1.0, 3.0, 2001)
    pts = np.column_stack([np.zeros_like(zs), np.zeros_like(zs), zs])
    j, c = mon.update_path(pts, 0.2)
    assert c.kind == "ceiling" and c.center[2] == pytest.approx(2.8, abs=2 * TOL)
    assert mon.queries == 0 and pts[j][2] <= 2.8 + TOL <= pts[j + 1][2] + TOL
    # the floor is ignored: start on it
    mon = CollisionMonitor(w, kinds=("ceiling", "bounds"))
    assert mon.update((0, 0, 0.0), (0, 0, 0.01), 0.2) is None


def test_monitor_restarts_on_a_jump_and_reports_a_start_inside():
    w = world(box([2.0, 2.0, 2.0]))
    mon = CollisionMonitor(w)
    assert mon.update((5, 0, 0), (5.01, 0, 0), 0.3) is None
    assert mon.clearance_bound > 3.0
    c = mon.update((0.0, 0, 0), (0.01, 0, 0), 0.3)  # teleported inside the box
    assert c is not None and c.t == 0.0 and c.penetration_m == pytest.approx(1.3)
    c = mon.update((0.01, 0, 0), (0.02, 0, 0), 0.3)  # still inside: still a contact
    assert c is not None


# --------------------------------------------------------------------------------------
# construction
# --------------------------------------------------------------------------------------


def test_construction_errors():
    good = box([1, 1, 1])
    with pytest.raises(ValueError, match="inverted"):
        CollisionWorld(good, (0, 0, 5), (10, 10, 4))
    with pytest.raises(ValueError, match="inverted"):
        CollisionWorld(good, (0, 0, 0), (0, 10, 4))
    with pytest.raises(ValueError, match="bounds_min"):
        CollisionWorld(good, (0, 0), (10, 10, 4))
    with pytest.raises(ValueError, match="degenerate"):
        CollisionWorld(trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 1, 2]],
                                       process=False), BIG_LO, BIG_HI)
    bad = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]], [[0, 1, 2]], process=False)
    with pytest.raises(ValueError, match="finite"):
        CollisionWorld(bad, BIG_LO, BIG_HI)
    with pytest.raises(TypeError):
        CollisionWorld(None, BIG_LO, BIG_HI)
    w = CollisionWorld(trimesh.Trimesh(), BIG_LO, BIG_HI)  # no obstacles is allowed
    assert w.n_triangles == 0 and w.obstacle_distance((0, 0, 0)) == math.inf
    assert w.check((0, 0, 0), 0.5) is None and w.sweep((0, 0, 0), (1, 1, 1), 0.5) is None
    with pytest.raises(ValueError, match="radius"):
        w.check((0, 0, 0), 0.0)
    with pytest.raises(ValueError, match="kinds"):
        w.check((0, 0, 0), 0.5, kinds=("wall",))
    with pytest.raises(ValueError, match="finite"):
        w.clearance((0, np.nan, 0), 0.5)
    with pytest.raises(ValueError, match="margin"):
        CollisionMonitor(w, margin_m=0.0)
    assert set(KINDS) == {"obstacle", "floor", "ceiling", "bounds"}


# --------------------------------------------------------------------------------------
# randomised: sweeps and the monitor against dense sampling in a cluttered scene
# --------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def clutter_world() -> CollisionWorld:
    rng = np.random.default_rng(11)
    parts = []
    for _ in range(12):
        c = trimesh.creation.cylinder(radius=rng.uniform(0.1, 0.6), height=rng.uniform(1, 4),
                                      sections=20)
        T = trimesh.transformations.random_rotation_matrix(rng.random(3))
        T[:3, 3] = rng.uniform(-4, 4, 3)
        c.apply_transform(T)
        parts.append(c)
        parts.append(box(rng.uniform(0.05, 1.0, 3), rng.uniform(-4, 4, 3)))
    return world(trimesh.util.concatenate(parts), lo=(-6, -6, -6), hi=(6, 6, 6))


def test_sweep_never_tunnels_random_segments(clutter_world):
    rng = np.random.default_rng(3)
    w, r = clutter_world, 0.2
    ts = np.linspace(0.0, 1.0, 301)
    n_hits = 0
    for _ in range(40):
        p0 = rng.uniform(-5, 5, 3)
        if w.clearance(p0, r) <= 0.0:
            continue
        p1 = p0 + rng.normal(size=3) * rng.uniform(0.5, 4.0)
        c = w.sweep(p0, p1, r)
        dense = np.array([w.clearance(p0 + t * (p1 - p0), r) for t in ts])
        if c is None:
            assert dense.min() > 0.0
            continue
        n_hits += 1
        # first contact: touching there, free everywhere before it
        assert w.clearance(c.center, r) <= 2 * TOL
        assert c.penetration_m <= 2 * TOL
        assert np.all(dense[ts < c.t - 1e-6] > -2 * TOL)
        if dense.min() < -1e-3:
            assert c.t <= ts[np.argmax(dense < -1e-3)]
    assert n_hits >= 10


def test_monitor_matches_per_step_sweeps_on_a_random_walk(clutter_world):
    rng = np.random.default_rng(5)
    w, r = clutter_world, 0.3
    kinds = []
    for _ in range(8):
        p = np.array([-5.5, rng.uniform(-3, 3), rng.uniform(-3, 3)])
        v = np.array([4.0, 0.0, 0.0])
        pts = [p]
        for _ in range(4000):  # 4 s at 1 kHz, smooth random heading
            v = v + rng.normal(scale=0.05, size=3)
            v *= 4.0 / np.linalg.norm(v)
            pts.append(pts[-1] + v * 1e-3)
        pts = np.array(pts)
        ref = next(((i, c) for i in range(len(pts) - 1)
                    if (c := w.sweep(pts[i], pts[i + 1], r)) is not None), None)
        mon = CollisionMonitor(w)
        got = mon.update_path(pts, r)
        if ref is None:
            assert got is None
            continue
        kinds.append(ref[1].kind)
        assert got is not None and got[0] == ref[0] and got[1].kind == ref[1].kind
        assert isinstance(got[1].t, float) and got[1].t == pytest.approx(ref[1].t, abs=1e-3)
        np.testing.assert_allclose(got[1].center, ref[1].center, atol=1e-5)
        assert mon.queries < got[0] / 10
    assert {"obstacle", "floor", "bounds"} <= set(kinds)
