"""Scenario difficulty: the shortest path among obstacles grown by a body, the narrowest
passage on it, turns, obstacle density, the flight-time model and the cache -- on a
hand-built configuration whose answers are known, and on real family configurations."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import trimesh

from ft_sitl.missions.spec import PROTOCOL_VERSION, PROTOCOLS, flight_budget
from ft_sitl.navigation.base import Limits
from ft_sitl.physics.catalog import catalog, largest_platform
from ft_sitl.rotations import matrix_from_quat
from ft_sitl.scenarios.collision import BodyProbe, CollisionWorld
from ft_sitl.scenarios.difficulty import (
    Difficulty,
    DifficultyError,
    FlightBudget,
    cached_difficulty,
    difficulty_key,
    flight_time_s,
    markdown_table,
    measure_difficulty,
    occupied_fraction,
    simplify,
    summarise,
    turn_angles_deg,
)
from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.io import load_scenario
from ft_sitl.scenarios.solvability import LevelBody, convex_pieces, find_path
from tests.scenarios.conftest import (
    CEILING,
    GAP_X,
    LENGTH,
    START,
    WALL_Y,
    WIDTH,
    expected_polyline,
    length,
)

BUDGET = FlightBudget(4.0, 3.0, 90.0)
BIG = largest_platform()

# the hand-built configuration: one thick wall with a 1.2 m gap 7.6 m off the line
# (tests/scenarios/test_shortest_path.py)


def _reach(body, axis: int) -> float:
    """How far the level body reaches along +axis at the start yaw (north), from its
    geometry: rotor hub offset plus rotor radius across, half the box height down, the
    rotor plane plus half a disk up."""
    desc = body.describe()
    if axis < 2:
        hubs = np.abs(np.array(desc["rotor_hubs_m"]))
        return float(hubs[:, 1 - axis].max() + desc["rotor_disk_radius_m"])  # yaw 90 deg
    return desc["rotor_height_m"] + desc["rotor_disk_thickness_m"] / 2


def test_the_protocol_budget():
    b = flight_budget()
    limits = Limits()
    assert (b.speed_m_s, b.time_s) == (limits.max_speed_m_s, limits.timeout_s) == (4.0, 90.0)
    assert b.acc_m_s2 == PROTOCOLS[PROTOCOL_VERSION].max_acc_m_s2 == 3.0


@pytest.mark.parametrize("bad", [0, -1.0, math.inf, math.nan, True, "4"])
def test_budget_rejects_bad_values(bad):
    with pytest.raises(DifficultyError, match="speed_m_s must be a positive number"):
        FlightBudget(bad, 3.0, 90.0)


@pytest.mark.slow
def test_hand_built_configuration(gap_spec):
    sc = load_scenario(gap_spec)
    d = measure_difficulty(sc, BIG, BUDGET)
    body = BIG.body()
    rx, ry = _reach(body, 0), _reach(body, 1)
    assert rx == pytest.approx(0.3789, abs=1e-3) and ry == pytest.approx(rx)
    expected = expected_polyline(rx, ry)
    shortest = length(expected)  # 2 x 13.28 + 2.76 = 29.33 m
    assert d.straight_m == 24.0
    assert d.path_m == pytest.approx(shortest, abs=0.005)
    assert d.path_ratio == pytest.approx(shortest / 24.0, abs=2e-4)
    assert d.body_yaw_deg == pytest.approx(90.0)
    # the narrowest passage is the gap: 1.2 m, less the body's width across it to spare
    assert d.passage_width_m == pytest.approx(GAP_X[1] - GAP_X[0], abs=1e-3)
    assert d.passage_spare_m == pytest.approx(GAP_X[1] - GAP_X[0] - 2 * rx, abs=1e-3)
    assert abs(d.passage_direction[0]) == pytest.approx(1.0, abs=1e-6)
    assert GAP_X[0] < d.passage_point[0] < GAP_X[1]
    assert WALL_Y[0] - ry <= d.passage_point[1] <= WALL_Y[1] + ry
    # two turns, each atan(7.98 / 10.62) = 36.9 degrees
    angle = math.degrees(math.atan2(GAP_X[0] + rx - START[0], WALL_Y[0] - ry - START[1]))
    assert d.turns == 2
    assert d.turn_angles_deg == pytest.approx((angle, angle), abs=0.1)
    assert d.obstacle_count == d.mesh_pieces == 2
    assert d.obstacles_per_100m2 == pytest.approx(100 * 2 / (WIDTH * LENGTH), abs=1e-4)
    filled = (GAP_X[0] + WIDTH - GAP_X[1]) * (WALL_Y[1] - WALL_Y[0]) * CEILING
    assert d.occupied_fraction == pytest.approx(filled / (WIDTH * LENGTH * CEILING), abs=1e-5)
    assert d.time_s == pytest.approx(flight_time_s(expected, BUDGET), abs=0.01)
    assert d.flyable and d.time_s < 90.0


def test_the_path_is_clear_for_the_real_body(gap_spec):
    """fcl, posing the body's box and rotor disks, agrees that the path is clear."""
    sc = load_scenario(gap_spec)
    d = measure_difficulty(sc, BIG, BUDGET)
    world = CollisionWorld(sc.mesh, sc.bounds_min, sc.bounds_max)
    probe = BodyProbe(BIG.body())
    yaw = math.radians(d.body_yaw_deg)
    rot = matrix_from_quat([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    path = np.array(d.path)
    for a, b in zip(path[:-1], path[1:]):
        for t in np.linspace(0.0, 1.0, max(2, int(np.linalg.norm(b - a) / 0.02) + 1)):
            assert world.body_distance(probe, a + t * (b - a), rot) > 0.0


def test_simplify_and_turns():
    pts = np.array([[0, 0, 0], [5, 0.2, 0], [10, 0, 0], [10, 5, 0.3], [10, 10, 0],
                    [20, 10, 0]], dtype=float)
    simple = simplify(pts, 0.5)
    np.testing.assert_array_equal(simple, pts[[0, 2, 4, 5]])  # 0.2 m and 0.3 m bumps go
    np.testing.assert_allclose(turn_angles_deg(simple), [90.0, 90.0], atol=1e-9)
    assert len(simplify(pts, 0.1)) == len(pts)
    np.testing.assert_allclose(turn_angles_deg([[0, 0, 0], [1, 0, 0], [1, 0, 1]]), [90.0])
    np.testing.assert_allclose(turn_angles_deg([[0, 0, 0], [1, 0, 0], [0, 0, 0]]), [180.0])


def test_flight_time_model():
    # straight 100 m from a hover: 4/3 s to reach 4 m/s over 8/3 m, then cruise
    assert flight_time_s([[0, 0, 0], [100, 0, 0]], BUDGET) == pytest.approx(25 + 2 / 3)
    # too short to reach the top speed: sqrt(2 L / a)
    assert flight_time_s([[0, 0, 0], [2, 0, 0]], BUDGET) == pytest.approx(math.sqrt(4 / 3))
    # a right angle is flown from a stop: start, brake, start again (4/3 s and 8/3 m each)
    right = flight_time_s([[0, 0, 0], [50, 0, 0], [50, 50, 0]], BUDGET)
    assert right == pytest.approx(3 * (4 / 3) + (100 - 3 * 8 / 3) / 4)
    # 60 degrees: through at 2 m/s; a collinear vertex costs nothing
    sixty = flight_time_s([[0, 0, 0], [50, 0, 0], [75, 25 * math.sqrt(3), 0]], BUDGET)
    brake = (4 - 2) / 3 - (16 - 4) / 6 / 4  # time lost braking 4 -> 2 m/s vs cruising
    assert sixty == pytest.approx(25 + 2 / 3 + 2 * brake)
    assert flight_time_s([[0, 0, 0], [40, 0, 0], [100, 0, 0]], BUDGET) == pytest.approx(
        25 + 2 / 3)
    assert flight_time_s([[1, 1, 1]], BUDGET) == 0.0


def test_occupied_fraction_counts_each_voxel_once():
    a = trimesh.creation.box(bounds=[[0, 0, 0], [2, 2, 2]])
    b = trimesh.creation.box(bounds=[[1, 1, 1], [3, 3, 5]])  # overlaps a, pokes out on top
    pieces = convex_pieces(trimesh.util.concatenate([a, b]))
    volume = 8 + 2 * 2 * 3 - 1  # b cut at the ceiling z = 4, less the shared unit cube
    assert occupied_fraction(pieces, (0, 0, 0), (4, 4, 4)) == pytest.approx(volume / 64)
    assert occupied_fraction([], (0, 0, 0), (4, 4, 4)) == 0.0


def test_the_cache(tmp_path, gap_spec):
    sc = load_scenario(gap_spec)
    first = cached_difficulty(sc, BIG, BUDGET, tmp_path)
    files = list(tmp_path.glob("*.json"))
    assert [f.stem for f in files] == [difficulty_key(sc, BIG, BUDGET)]
    # read back, not measured again: the file's content is what comes back
    doc = json.loads(files[0].read_text())
    doc["compute_s"] = 1234.0
    files[0].write_text(json.dumps(doc))
    again = cached_difficulty(sc, BIG, BUDGET, tmp_path)
    assert again.compute_s == 1234.0
    assert again == Difficulty.from_dict({**first.as_dict(), "compute_s": 1234.0})
    # a broken file is measured again and rewritten
    files[0].write_text("{not json")
    assert cached_difficulty(sc, BIG, BUDGET, tmp_path).path_m == first.path_m
    assert json.loads(files[0].read_text())["path_m"] == first.path_m
    # what the result depends on is in the key
    small = min(catalog().values(), key=lambda p: p.body().bounding_radius_m)
    assert difficulty_key(sc, small, BUDGET) != difficulty_key(sc, BIG, BUDGET)
    assert difficulty_key(sc, BIG, FlightBudget(4.0, 3.0, 60.0)) != files[0].stem
    assert difficulty_key(build_scenario("maze", 1), BIG, BUDGET) != files[0].stem
    assert cached_difficulty(sc, BIG, BUDGET, None).path_m == first.path_m


@pytest.mark.parametrize("family,index,version", [("maze", 2, None),
                                                  pytest.param("perlin", 3, None,
                                                               marks=pytest.mark.slow),
                                                  ("sudden_drop", 4, None),
                                                  ("random_angle_cylinder", 5, None)])
def test_family_configurations(family, index, version):
    """On real configurations: the path is clear for the body (fcl), never shorter than
    the straight line, shorter than the grid's own path, and the time is at least the
    length at top speed. (Perlin's newest version: ~40,000 boxes, a few seconds with the
    path-tightening kernel's piece index.)"""
    sc = build_scenario(family, index, version=version)
    d = measure_difficulty(sc, BIG, BUDGET)
    path = np.array(d.path)
    np.testing.assert_allclose(path[[0, -1]], [sc.start, sc.goal], atol=1e-4)
    assert d.path_ratio >= 1.0 and d.path_m == pytest.approx(length(path), abs=1e-3)
    assert d.time_s >= d.path_m / BUDGET.speed_m_s
    assert 0.0 < d.passage_spare_m < d.passage_width_m
    world = CollisionWorld(sc.mesh, sc.bounds_min, sc.bounds_max)
    probe = BodyProbe(BIG.body())
    yaw = math.radians(d.body_yaw_deg)
    rot = matrix_from_quat([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    for a, b in zip(path[:-1], path[1:]):
        for t in np.linspace(0.0, 1.0, max(2, int(np.linalg.norm(b - a) / 0.05) + 1)):
            assert world.body_distance(probe, a + t * (b - a), rot) > 0.0
    grid = find_path(sc.mesh, sc.start, sc.goal, sc.bounds_min, sc.bounds_max,
                     LevelBody(BIG.body(), yaw), sc.provenance.get("solvability_pitch_m",
                                                                   0.25))
    assert d.path_m <= length(grid)


def test_summary_and_table(gap_spec):
    sc = load_scenario(gap_spec)
    d = measure_difficulty(sc, BIG, BUDGET)
    blocked = Difficulty.from_dict({**d.as_dict(), "path_m": None, "path_ratio": None,
                                    "turns": None, "passage_width_m": None,
                                    "passage_spare_m": None, "time_s": None,
                                    "flyable": False})
    s = summarise([d, blocked])
    assert (s["configurations"], s["with_path"], s["flyable"]) == (2, 1, 1)
    assert s["path_m"] == [d.path_m, d.path_m] and s["obstacle_count"] == [2, 2]
    lines = markdown_table([d, blocked]).splitlines()
    assert len(lines) == 4 and lines[2].startswith(f"| {d.scenario} | {d.path_m:.1f} |")
    assert lines[3].endswith("| - | **no** |")
