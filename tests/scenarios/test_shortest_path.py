"""Shortest paths among obstacles grown by a ball or a level body (26-connected A* over
the solvability grid, pulled tight), the segment test they keep to, and the narrowest
passage along a path, on hand-built geometry with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh

from ft_sitl.physics.catalog import catalog, largest_platform
from ft_sitl.scenarios.solvability import (
    LevelBody,
    find_path,
    grow_pieces,
    narrowest_passage,
    polyline_clearance,
    segment_free,
    tauten,
)
from tests.scenarios.conftest import (
    CEILING,
    GOAL,
    LENGTH,
    START,
    WIDTH,
    expected_polyline,
    length,
    wall,
)

BIG = largest_platform()


@pytest.mark.parametrize("radius", [0.2, 0.35])
def test_shortest_path_for_a_ball(radius):
    """The same wall for a ball: the tight path bends round the jamb's corners grown by the
    radius (square corners: the grown pieces' bounding boxes), and clears the mesh."""
    mesh = wall()
    lo, hi = (0.0, 0.0, 0.0), (WIDTH, LENGTH, CEILING)
    path = find_path(mesh, START, GOAL, lo, hi, radius, shortest=True)
    expected = expected_polyline(radius, radius)
    assert length(path) == pytest.approx(length(expected), abs=0.005)
    assert polyline_clearance(mesh, path) >= radius
    bfs = find_path(mesh, START, GOAL, lo, hi, radius)
    assert length(bfs) > length(path) + 1.0  # the grid's staircase is much longer
    # too wide for the gap: no path, as for the breadth-first search
    assert find_path(mesh, START, GOAL, lo, hi, 0.61, shortest=True) is None
    assert find_path(mesh, START, GOAL, lo, hi, 0.61) is None


def test_tauten_keeps_the_ends_and_every_segment_free():
    mesh = wall()
    grown = grow_pieces(mesh, (0, 0, 0), (WIDTH, LENGTH, CEILING), 0.3)
    detour = np.array([START, (10.0, 10.0, 2.0), (18.2, 12.0, 3.0), (18.2, 18.0, 1.0),
                       (12.0, 20.0, 2.0), GOAL])
    assert all(segment_free(grown, a, b) for a, b in zip(detour[:-1], detour[1:]))
    tight = tauten(grown, detour)
    np.testing.assert_array_equal(tight[[0, -1]], detour[[0, -1]])
    assert all(segment_free(grown, a, b) for a, b in zip(tight[:-1], tight[1:]))
    assert length(tight) == pytest.approx(length(expected_polyline(0.3, 0.3)), abs=0.005)
    # straight through the wall is not free
    assert not segment_free(grown, START, GOAL)
    # leaving the volume shrunk by the radius is not free either
    assert not segment_free(grown, (10.0, 3.0, 2.0), (10.0, 3.0, 3.8))


def test_the_piece_index_gives_the_answers_of_testing_every_piece():
    """tauten's segment test looks only at the pieces of the 1 m columns a segment crosses
    (PieceIndex): on a Forest configuration's grown trunks it answers as the test of every
    piece for random segments of every length and direction, the boxes' own diagonals and
    segments ending exactly on their faces and corners."""
    from ft_sitl.scenarios.families import build_scenario
    from ft_sitl.scenarios.solvability import (
        PieceIndex,
        _kernel_args,
        _segment_free,
        _segment_free_indexed,
    )
    sc = build_scenario("forest", 3, 0)
    grown = grow_pieces(sc.mesh, sc.bounds_min, sc.bounds_max, 0.3)
    index = PieceIndex.build(grown.lo, grown.hi)
    assert index.dims.prod() > 100 and len(index.items) >= len(grown.lo)
    args = _kernel_args(grown)
    lo, hi = grown.free_lo, grown.free_hi
    rng = np.random.default_rng(0)
    segments = []
    for k in range(6000):
        a = rng.uniform(lo, hi)
        d = rng.normal(size=3)
        if k % 3 == 0:
            d[2] = 0.0  # level
        if k % 7 == 0:
            d = np.eye(3)[k % 2]  # along x or y
        d /= np.linalg.norm(d)
        segments.append((a, a + (0.0, 0.05, 0.5, 3.0, 60.0)[k % 5] * d))
    for k in range(len(grown.lo)):
        corner = np.array([grown.lo[k, 0], grown.hi[k, 1], grown.lo[k, 2]])
        segments += [(grown.lo[k], grown.hi[k]), (grown.lo[k] - 0.5, corner),
                     (corner + (0.0, 2.0, 0.0), corner)]
    answers = []
    for a, b in segments:
        a, b = np.clip(a, lo, hi), np.clip(b, lo, hi)
        plain = _segment_free(a, b, *args)
        assert _segment_free_indexed(a, b, *args, index.kernel_args()) == plain
        answers.append(plain)
    assert 0.05 < 1.0 - np.mean(answers) < 0.95  # both answers are tested, many times
    empty = PieceIndex.build(np.zeros((0, 3)), np.zeros((0, 3)))
    assert len(empty.items) == 0


def test_narrowest_passage_under_an_overhang():
    """A block from 1.5 m up across the whole area: the passage is its underside's 1.5 m
    above the floor, vertical; the body has its own height less to spare."""
    block = trimesh.creation.box(bounds=[[0.0, 10.0, 1.5], [WIDTH, 12.0, 6.0]])
    lo, hi = (0.0, 0.0, 0.0), (WIDTH, LENGTH, CEILING)
    shape = LevelBody(BIG.body(), math.pi / 2)
    path = find_path(block, START, GOAL, lo, hi, shape, shortest=True)
    assert path[:, 2].min() < 1.5
    grown = grow_pieces(block, lo, hi, shape)
    p = narrowest_passage(grown, path)
    height = shape.support([0, 0, 1]) + shape.support([0, 0, -1])
    assert p.width_m == pytest.approx(1.5, abs=1e-6)
    assert p.spare_m == pytest.approx(1.5 - height, abs=1e-6)
    assert abs(p.direction[2]) == pytest.approx(1.0)


def test_the_largest_platform_is_the_one_with_the_largest_body():
    big = largest_platform()
    assert all(p.body().bounding_radius_m <= big.body().bounding_radius_m
               for p in catalog().values())
    assert 0.46 < big.body().bounding_radius_m < 0.48


def test_narrowest_passage_is_measured_across_the_face_a_path_touches():
    """A path that hugs a jamb 0.3 m below the (shrunk) ceiling: the passage is the 2 m gap
    (less the ball), not the way from the touching point up to the ceiling along the
    face."""
    left = trimesh.creation.box(bounds=[[0.0, 14.0, 0.0], [17.0, 16.0, 5.0]])
    right = trimesh.creation.box(bounds=[[19.0, 14.0, 0.0], [WIDTH, 16.0, 5.0]])
    mesh = trimesh.util.concatenate([left, right])
    lo, hi, r = (0.0, 0.0, 0.0), (WIDTH, LENGTH, CEILING), 0.3
    start, goal = (10.0, 3.0, 3.4), (10.0, 27.0, 3.4)
    path = find_path(mesh, start, goal, lo, hi, r, shortest=True)
    assert np.abs(path[1:-1, 0] - (17.0 + r)).max() < 1e-3  # it touches the jamb
    p = narrowest_passage(grow_pieces(mesh, lo, hi, r), path)
    assert p.spare_m == pytest.approx(2.0 - 2 * r, abs=1e-6)
    assert p.width_m == pytest.approx(2.0, abs=1e-6)
    np.testing.assert_allclose(np.abs(p.direction), [1.0, 0.0, 0.0], atol=1e-9)
