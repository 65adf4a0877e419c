"""Narrow-Gap (theoretical): walls across the route, one narrow gap each. Declared in
:mod:`ft_sitl.scenarios.families`."""

from __future__ import annotations

import numpy as np

from ft_sitl.scenarios.families.common import (
    LINE_CORRIDOR_M,
    Family,
    MeshBuilder,
    make_scenario,
    start_altitude,
)
from ft_sitl.scenarios.scenario import Scenario

NARROW_GAP_PITCH_M = (0.025, 0.25, 0.25)
"""Solvability grid for Narrow-Gap: 2.5 cm across the gaps (x), whose free window for a
0.384 m radius is only 0.85 - 0.768 = 0.082 m wide."""


def narrow_gap(fam: Family, p: dict, rng: np.random.Generator, index: int,
               seed: int) -> Scenario:
    """Narrow-Gap: 50 x 50 m, ceiling 4 m; ``index`` walls, one gap each (gaps = index).

    Walls span the full width (x in [0, 50]), 0.3 m thick and 5 m tall, at evenly spaced
    y in [10, 40] (+-1/8 of the spacing of jitter). Each has one full-height slot
    U(0.85, 0.90) m wide whose centre lies U(4, 18) m off the centre line, on alternating
    sides, so the vehicle must move laterally between gaps.
    """
    width, length = p["size_m"]
    alt = start_altitude(p["ceiling_m"])
    thick, height = p["wall_thickness_m"], p["wall_height_m"]
    spacing = 30.0 / index
    side = 1.0 if rng.random() < 0.5 else -1.0
    b = MeshBuilder()
    walls = []
    for j in range(index):
        y = 10.0 + spacing * (j + 0.5) + rng.uniform(-0.125, 0.125) * spacing
        w = rng.uniform(*p["gap_width_m"])
        c = width / 2.0 + side * rng.uniform(*p["gap_offset_m"])
        side = -side
        b.box((0.0, y - thick / 2, 0.0), (c - w / 2, y + thick / 2, height), "wall")
        b.box((c + w / 2, y - thick / 2, 0.0), (width, y + thick / 2, height), "wall")
        walls.append({"y_m": y, "gap_centre_x_m": c, "gap_width_m": w})
    return make_scenario(
        fam, index, seed, b, p, altitude=alt, obstacle_count=index, pitch=NARROW_GAP_PITCH_M,
        derived={"gap_count": index, "start_altitude_m": alt},
        layout={"walls": walls},
    )


def narrow_gap_v2(fam: Family, p: dict, rng: np.random.Generator, index: int,
                  seed: int) -> Scenario:
    """Narrow-Gap (version 2): 50 x 50 m, ceiling 4 m; ``index`` walls, one gap each.

    Walls span the full width (x in [0, 50]), 0.3 m thick and 5 m tall (above the
    ceiling: no way over or around), one near the middle of each of ``index`` equal slots
    of y in [8, 42] (+-1/8 of a slot of jitter): 34 m apart for one wall, 3.4 m for ten.
    Each has one full-height slot U(0.85, 0.90) m wide. With probability 0.4 the slot is
    centred on the start->goal line; otherwise its centre lies U(1, 2) m east or west of
    it (a fair coin per wall).

    Why there. A gap has to be in view when the vehicle must decide. The planners' map
    marks a depth pixel as an obstacle only within 4.5 m of the camera
    (``max_ray_length_m``) and the camera sees 39.6 degrees either side of its axis, so
    from the line a wall is mapped at most 2.87 m either side of it (from 3.5 m before
    it). A gap 1-2 m off has its far edge <= 2.45 m off: the whole gap is mapped from the
    line, from 3.8 m to 3.0 m before the wall, and passing it takes a lateral jink of
    1-2 m (a heading change of 14-27 degrees) in the last ~4 m, the camera yawed along
    (EGO, Fast-Planner and PGO point it along their path). With eight walls or more the
    previous wall may stand in that stretch: the next gap, up to 4 m across from the last
    one, is then seen through the last gap, from nearer, with a narrower view -- the
    densest configurations are the hardest. Version 1's gaps, 4-18 m off, were out of view
    until the vehicle stood at the wall, and every algorithm hit the first one; a gap 3 m
    off is mapped whole from nowhere on the line. A gap on the line is reachable flying
    straight, so a configuration whose gaps all lie on it is passed by the straight-flight
    baseline (probability 0.4^n for n gaps: the paper's baseline succeeds sometimes in
    Narrow-Gap); a gap off the line blocks the line for every platform (its near edge is
    >= 0.55 m off, the largest body's half width nose first 0.38 m).

    What separates platforms is the body and what the navigator makes of it. The largest
    body (0.76 m across nose first, 0.93 m yawed 45 degrees) fits a 0.85-0.90 m gap only
    within 14-25 degrees of nose (or side) first, so it must pass square to the wall, its
    yaw settled; the 0.98 kg EGO-Planner DIY's (0.38-0.47 m across) fits at any yaw. And a
    navigator inflates its map by the body's half span (protocol 4 on): with a half span
    above 0.3 m (four voxels or more) every gap is closed in its map, and it passes only
    gaps it flies through without replanning around them, on the line; below, a gap is a
    one- or two-voxel channel to thread at speed.
    """
    width, length = p["size_m"]
    alt = start_altitude(p["ceiling_m"])
    thick, height = p["wall_thickness_m"], p["wall_height_m"]
    y0, y1 = p["wall_zone_y_m"]
    spacing = (y1 - y0) / index
    line_x = width / 2.0
    b = MeshBuilder()
    walls = []
    for j in range(index):
        y = y0 + spacing * (j + 0.5) + rng.uniform(-0.125, 0.125) * spacing
        w = rng.uniform(*p["gap_width_m"])
        on_line = bool(rng.random() < p["on_line_probability"])
        offset = rng.uniform(*p["gap_offset_m"])
        side = 1.0 if rng.random() < 0.5 else -1.0
        c = line_x if on_line else line_x + side * offset
        b.box((0.0, y - thick / 2, 0.0), (c - w / 2, y + thick / 2, height), "wall")
        b.box((c + w / 2, y - thick / 2, 0.0), (width, y + thick / 2, height), "wall")
        walls.append({"y_m": y, "gap_centre_x_m": c, "gap_width_m": w, "on_line": on_line})
    return make_scenario(
        fam, index, seed, b, p, altitude=alt, obstacle_count=index, pitch=NARROW_GAP_PITCH_M,
        corridor=LINE_CORRIDOR_M,
        derived={"gap_count": index, "start_altitude_m": alt},
        layout={"walls": walls},
    )
