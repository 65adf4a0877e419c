"""What the scenario tests share: a hand-built configuration with known answers."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

# A 20 x 30 m area, ceiling 4 m; start (10, 3, 2), goal (10, 27, 2): 24 m apart. One wall
# 2 m thick across y in [14, 16], 5 m tall, from x = 0 to 20 but for a 1.2 m gap at
# x in [17.6, 18.8], 7.6 m east of the line: two boxes.
WIDTH, LENGTH, CEILING = 20.0, 30.0, 4.0
START, GOAL = (10.0, 3.0, 2.0), (10.0, 27.0, 2.0)
WALL_Y = (14.0, 16.0)
GAP_X = (17.6, 18.8)


def wall() -> trimesh.Trimesh:
    left = trimesh.creation.box(bounds=[[0.0, WALL_Y[0], 0.0], [GAP_X[0], WALL_Y[1], 5.0]])
    right = trimesh.creation.box(bounds=[[GAP_X[1], WALL_Y[0], 0.0], [WIDTH, WALL_Y[1], 5.0]])
    return trimesh.util.concatenate([left, right])


def expected_polyline(rx: float, ry: float) -> np.ndarray:
    """Start, the two corners of the gap's west jamb grown by the reach, goal."""
    x = GAP_X[0] + rx
    return np.array([START, (x, WALL_Y[0] - ry, 2.0), (x, WALL_Y[1] + ry, 2.0), GOAL])


def length(p) -> float:
    return float(np.linalg.norm(np.diff(np.asarray(p), axis=0), axis=1).sum())


@pytest.fixture(scope="module")
def gap_spec(tmp_path_factory):
    """The configuration as a user scenario file: a PLY mesh and its TOML spec."""
    d = tmp_path_factory.mktemp("gap")
    wall().export(d / "wall.ply")
    (d / "gap.toml").write_text(
        'name = "one_gap"\nmesh = "wall.ply"\n'
        f"start = {list(START)}\ngoal = {list(GOAL)}\n"
        f"bounds_min = [0.0, 0.0, 0.0]\nbounds_max = [{WIDTH}, {LENGTH}, {CEILING}]\n")
    return d / "gap.toml"
