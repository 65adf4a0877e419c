"""FlightBench's difficulty metrics (TO, VO, AOL) on hand-built worlds whose answers are
known: an empty room, a wall straight ahead, a wall across the way, an L-shaped path;
the pieces (rings, shared volume, the corridor's TO), determinism, the cache and bad
input."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh

from ft_sitl.scenarios.camera import CameraConfig, DepthCamera
from ft_sitl.scenarios.flightbench_metrics import (
    PARAMS,
    VIEW_WEIGHTS,
    FlightBenchError,
    FlightBenchMetrics,
    angle_over_length,
    cached_flightbench,
    corridor,
    corridor_obstruction,
    guide_path,
    measure_flightbench,
    resolve_params,
    shared_volume,
    view_occlusion,
    view_rings,
)
from ft_sitl.scenarios.scenario import Scenario

DEFAULTS = resolve_params(None)
R_S = DEFAULTS["sensing_range_m"]
#: fewer corridors where the number does not matter (each costs ~0.3 s here)
FEW = {"corridor_repeats": 2}


def room(mesh: trimesh.Trimesh, size=(12.0, 40.0, 10.0), z: float = 5.0) -> Scenario:
    """A tall room: start and goal 30 m apart along +y, ``z`` above the floor, at least
    5 m from every side (more than the largest ball, r_s + r_q)."""
    w, length, h = size
    return Scenario(family="room", index=1, seed=0, category="user", mesh=mesh,
                    bounds_min=(0.0, 0.0, 0.0), bounds_max=(w, length, h),
                    takeoff=(w / 2, 5.0, 0.0), start=(w / 2, 5.0, z), start_yaw=math.pi / 2,
                    goal=(w / 2, length - 5.0, z))


def empty() -> trimesh.Trimesh:
    return trimesh.Trimesh(vertices=np.zeros((0, 3)), faces=np.zeros((0, 3), dtype=np.int64))


def wall_across(gap_x: tuple[float, float] = (9.0, 11.0)) -> trimesh.Trimesh:
    """A 0.4 m wall across y = 20 for the room's whole height, but for a gap."""
    left = trimesh.creation.box(bounds=[[0.0, 19.8, 0.0], [gap_x[0], 20.2, 12.0]])
    right = trimesh.creation.box(bounds=[[gap_x[1], 19.8, 0.0], [12.0, 20.2, 12.0]])
    return trimesh.util.concatenate([left, right])


# --------------------------------------------------------------------------------------
# the empty world and the wall: the whole measurement
# --------------------------------------------------------------------------------------


def test_an_empty_room_gives_to_one_half_vo_zero_aol_zero():
    m = measure_flightbench(room(empty()))
    # every ball on the way is capped at r_s (the sides, floor and ceiling are >= 5 m from
    # it; a ball drawn more than 0.85 m off the line may come closer to one)
    assert m.to == R_S / (2 * R_S) == 0.5
    assert min(m.to_corridors) == 0.5 and max(m.to_corridors) < 0.51
    assert m.corridor_min_radius_m == R_S
    assert m.vo == 0.0 and m.vo_max == 0.0
    assert m.aol == 0.0 and m.turns == 0
    assert m.guide_length_m == pytest.approx(30.0)
    assert m.vo_points == int(30.0 / DEFAULTS["view_step_m"] + 1e-9)
    assert m.corridor_restarts == 0


def test_a_wall_across_the_way_obstructs_occludes_and_turns_the_path():
    free = measure_flightbench(room(empty()), FEW)
    m = measure_flightbench(room(wall_across()), FEW)
    assert m.to > free.to
    assert m.corridor_min_radius_m < R_S
    assert m.vo > 0.0
    assert m.aol > 0.0 and m.turns >= 2          # round the wall's end and back
    assert m.guide_length_m > 30.0
    # the guide path keeps FlightBench's 0.17 m from the wall: it passes the gap's jamb
    g = np.array(m.guide)
    assert np.all((g[:, 0] > 9.0 + 0.17 - 1e-6) | (np.abs(g[:, 1] - 20.0) > 0.2 + 0.17 - 1e-6))


def test_a_narrower_gap_is_more_obstructed():
    wide = measure_flightbench(room(wall_across((8.0, 11.0))), FEW)
    narrow = measure_flightbench(room(wall_across((9.0, 10.2))), FEW)
    assert narrow.to > wide.to
    # a ball in the 1.2 m gap has at most 0.6 - 0.15 m of radius
    assert narrow.corridor_min_radius_m <= 0.6 - DEFAULTS["drone_radius_m"] + 1e-9


def test_the_metrics_are_deterministic_and_follow_the_seed():
    sc = room(wall_across())
    a, b = measure_flightbench(sc, FEW), measure_flightbench(sc, FEW)
    assert (a.to, a.vo, a.aol, a.to_corridors) == (b.to, b.vo, b.aol, b.to_corridors)
    other = measure_flightbench(sc, {**FEW, "seed": 7})
    assert other.to_corridors != a.to_corridors
    assert (other.vo, other.aol) == (a.vo, a.aol)  # no draws in VO and AOL


# --------------------------------------------------------------------------------------
# view occlusion
# --------------------------------------------------------------------------------------


def test_view_rings_follow_flightbench_edges():
    eps = 1e-9
    phi = [0.0, math.pi / 12, math.pi / 12 + eps, math.pi / 8, math.pi / 8 + eps,
           math.pi / 6, math.pi / 6 + eps, math.pi / 5, math.pi / 5 + eps]
    assert view_rings(phi).tolist() == [3, 3, 2, 2, 1, 1, 0, 0, -1]


def test_a_wall_straight_ahead_gives_the_analytic_view_occlusion():
    # a wall y = 3 facing viewpoints at y = 0.4 and 0.8 that look along +y: the nearest
    # point of the ring between angles a and b from the axis is at D / cos(a)
    wall = trimesh.Trimesh(vertices=[[-50, 3, -50], [50, 3, -50], [50, 3, 50], [-50, 3, 50]],
                           faces=[[0, 1, 2], [0, 2, 3]])
    cam = DepthCamera(CameraConfig(width=1, height=1, max_range_m=R_S), wall)
    vo, per_point = view_occlusion(cam, [[0.0, 0.0, 0.0], [0.0, 0.8, 0.0]], DEFAULTS)
    inner = (0.0, math.pi / 12, math.pi / 8, math.pi / 6)[::-1]  # ring 0 .. 3's inner edge

    def expected(d):
        return sum(w * R_S * math.cos(a) / d for w, a in zip(VIEW_WEIGHTS, inner)
                   if d / math.cos(a) <= R_S)

    want = [expected(3.0 - 0.4), expected(3.0 - 0.8)]
    assert per_point == pytest.approx(want, rel=2e-3)
    assert vo == pytest.approx(np.mean(want), rel=2e-3)


def test_a_wall_beyond_the_sensing_range_is_not_seen():
    wall = trimesh.Trimesh(vertices=[[-50, 9, -50], [50, 9, -50], [50, 9, 50], [-50, 9, 50]],
                           faces=[[0, 1, 2], [0, 2, 3]])
    cam = DepthCamera(CameraConfig(width=1, height=1, max_range_m=R_S), wall)
    vo, per_point = view_occlusion(cam, [[0.0, 0.0, 0.0], [0.0, 4.0, 0.0]], DEFAULTS)
    # at y = 4.0 the wall is 5 m ahead: out of range; at 3.6 the axis sees it at 5.4 m
    assert vo == 0.0 and not per_point.any()


# --------------------------------------------------------------------------------------
# traversability obstruction: the pieces
# --------------------------------------------------------------------------------------


def test_corridor_obstruction_takes_the_smaller_half_of_the_radii():
    # the two smallest of four: 4 / (2 * 2) * (1 / 1 + 1 / 2)
    assert corridor_obstruction([4.0, 1.0, 3.0, 2.0], 4.0) == pytest.approx(1.5)
    assert corridor_obstruction([2.0], 4.0) == pytest.approx(1.0)  # N is at least 1


def test_shared_volume_of_two_balls():
    ball = 4.0 / 3.0 * math.pi
    assert shared_volume(1.0, 1.0, 2.0) == 0.0
    assert shared_volume(1.0, 2.0, 0.5) == pytest.approx(ball)  # the small one inside
    # two unit balls one radius apart share 5 pi / 12
    assert shared_volume(1.0, 1.0, 1.0) == pytest.approx(5.0 * math.pi / 12.0)
    # continuous at both ends
    assert shared_volume(1.0, 2.0, 1.0 + 1e-9) == pytest.approx(ball, rel=1e-6)
    assert shared_volume(1.0, 2.0, 3.0 - 1e-6) == pytest.approx(0.0, abs=1e-9)


def test_a_corridor_in_a_free_channel_is_bounded_by_its_half_width():
    # a ball's clearance is the distance to two walls 3 m apart, less nothing else
    def clearance(points):
        y = np.asarray(points)[:, 1]
        return np.minimum(y + 1.5, 1.5 - y) - DEFAULTS["drone_radius_m"]

    path = [[0.0, 0.0, 0.0], [30.0, 0.0, 0.0]]
    centres, radii, restarts = corridor(clearance, path, DEFAULTS, np.random.default_rng(0))
    assert restarts == 0
    best = 1.5 - DEFAULTS["drone_radius_m"]
    assert radii.max() <= best + 1e-12
    assert np.linalg.norm(centres[-1] - [30.0, 0.0, 0.0]) < radii[-1]  # holds the goal
    # consecutive balls overlap
    gaps = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    assert np.all(gaps <= radii[:-1] + radii[1:])
    assert corridor_obstruction(radii, R_S) >= R_S / (2.0 * best)


def test_a_start_inside_the_drone_radius_is_refused():
    with pytest.raises(FlightBenchError, match="within the drone radius"):
        corridor(lambda p: np.full(len(p), -0.1), [[0, 0, 0], [5, 0, 0]], DEFAULTS,
                 np.random.default_rng(0))


# --------------------------------------------------------------------------------------
# angle over length
# --------------------------------------------------------------------------------------


def test_angle_over_length_of_a_right_angle_and_a_straight_line():
    assert angle_over_length([[0, 0, 0], [10, 0, 0], [10, 10, 0]]) == pytest.approx(
        (math.e - 1.0) / 20.0)
    # collinear vertices and repeated points add nothing
    assert angle_over_length([[0, 0, 0], [3, 0, 0], [3, 0, 0], [7, 0, 0]]) == 0.0
    # a turn back on itself: exp(2) - 1
    assert angle_over_length([[0, 0, 0], [5, 0, 0], [1, 0, 0]]) == pytest.approx(
        (math.exp(2.0) - 1.0) / 9.0)


# --------------------------------------------------------------------------------------
# input, records and the cache
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize(("points", "match"), [
    ([[0, 0, 0]], "N >= 2"),
    ([[0, 0], [1, 1]], r"\(N, 3\)"),
    ([[0, 0, 0], [1, math.nan, 0]], "finite"),
    ([[1, 1, 1], [1, 1, 1]], "length 0"),
    ("abc", "array"),
])
def test_a_bad_guide_path_is_refused(points, match):
    with pytest.raises(FlightBenchError, match=match):
        guide_path(points)


@pytest.mark.parametrize(("params", "match"), [
    ({"sensing_range": 4.0}, "no parameter 'sensing_range'"),
    ({"sensing_range_m": -1.0}, r"sensing_range_m: must be a number 0.5..50 \(m\)"),
    ({"corridor_repeats": 0}, "corridor_repeats: must be an integer 1..1000"),
    ({"drone_radius_m": "big"}, "drone_radius_m"),
])
def test_bad_parameters_are_refused_with_the_allowed_range(params, match):
    with pytest.raises(FlightBenchError, match=match):
        resolve_params(params)


def test_every_parameter_is_declared_once_with_a_unit_and_a_range():
    for p in PARAMS:
        assert p.range is not None and p.doc and p.unit


def test_the_record_round_trips_and_the_cache_reads_back(tmp_path):
    sc = room(wall_across())
    first = cached_flightbench(sc, FEW, tmp_path)
    files = list(tmp_path.glob("*.json"))
    assert len(files) == 1
    again = cached_flightbench(sc, FEW, tmp_path)
    assert again == first
    assert FlightBenchMetrics.from_dict(json.loads(json.dumps(first.as_dict()))) == first
    files[0].write_text("{broken")
    assert cached_flightbench(sc, FEW, tmp_path).to == first.to
    assert json.loads(files[0].read_text())["to"] == first.to  # rewritten
    # other parameters are another entry
    cached_flightbench(sc, {**FEW, "seed": 1}, tmp_path)
    assert len(list(tmp_path.glob("*.json"))) == 2
