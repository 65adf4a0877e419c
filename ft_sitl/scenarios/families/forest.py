"""Forest (classic): vertical trunks at a random layout, one of them on or beside the
start->goal line. Declared in :mod:`ft_sitl.scenarios.families`."""

from __future__ import annotations

import math

import numpy as np

from ft_sitl.scenarios.families.common import (
    LINE_CORRIDOR_M,
    START_MARGIN_M,
    Family,
    MeshBuilder,
    make_scenario,
    start_altitude,
)
from ft_sitl.scenarios.scenario import Scenario


def forest(fam: Family, p: dict, rng: np.random.Generator, index: int, seed: int) -> Scenario:
    """Forest: 40 x 60 m, ceiling 3 m, 49 trunks (density 1/49 per m^2).

    Trunks are vertical cylinders from the ground, radius U(0.15, 0.30) m, height
    U(6, 12) m (canopies would sit above the 3 m ceiling and are omitted). Positions are
    uniform with rejection: trunk surfaces >= 1.5 m apart and >= 3 m from the takeoff
    column and the goal. If no trunk comes within 0.6 m (LINE_CORRIDOR_M) of the
    start->goal line, the trunk nearest to it is moved beside it, its surface a uniform
    0-0.6 m from the line (keeping the density exact): a vehicle flying the line straight
    hits it unless its collision radius is smaller than the gap.
    """
    width, length = p["size_m"]
    alt = start_altitude(p["ceiling_m"])
    count = round(width * length * p["density_per_m2"])
    gap, clear = p["min_trunk_gap_m"], p["clear_radius_m"]
    line_x = width / 2.0
    keep_out = [(line_x, START_MARGIN_M), (line_x, length - START_MARGIN_M)]
    trees: list[list[float]] = []  # x, y, r, h
    attempts = 0
    while len(trees) < count:
        attempts += 1
        if attempts > 100_000:
            raise RuntimeError(f"forest #{index}: could not place {count} trees")
        x = rng.uniform(0.5, width - 0.5)
        y = rng.uniform(0.5, length - 0.5)
        r = rng.uniform(*p["trunk_radius_m"])
        h = rng.uniform(*p["trunk_height_m"])
        if not _tree_ok(x, y, r, trees, keep_out, gap, clear):
            continue
        trees.append([x, y, r, h])
    moved = None
    # a trunk whose surface comes within LINE_CORRIDOR_M of the line blocks the largest
    # platform; if none does, the nearest trunk is moved beside the line, its surface a
    # uniform 0..LINE_CORRIDOR_M from it
    near_line = [i for i, (x, y, r, _) in enumerate(trees)
                 if abs(x - line_x) - r < LINE_CORRIDOR_M
                 and keep_out[0][1] < y < keep_out[1][1]]
    if not near_line:
        offset = rng.uniform(0.0, LINE_CORRIDOR_M)
        side = 1.0 if rng.random() < 0.5 else -1.0
        for i in sorted(range(count), key=lambda i: (abs(trees[i][0] - line_x), i)):
            x, y, r, h = trees[i]
            others = trees[:i] + trees[i + 1:]
            nx = line_x + side * (r + offset)
            if _tree_ok(nx, y, r, others, keep_out, gap, clear):
                trees[i][0] = nx
                moved = i
                break
        else:
            raise RuntimeError(f"forest #{index}: no trunk can be moved beside the line")
    b = MeshBuilder()
    for x, y, r, h in trees:
        b.cylinder((x, y, 0.0), (x, y, h), r, kind="tree")
    return make_scenario(
        fam, index, seed, b, p, altitude=alt, obstacle_count=count, corridor=LINE_CORRIDOR_M,
        derived={"tree_count": count, "start_altitude_m": alt},
        layout={"trees_xyrh": trees, "moved_beside_line": moved},
    )


def _tree_ok(x, y, r, trees, keep_out, gap, clear) -> bool:
    for kx, ky in keep_out:
        if math.hypot(x - kx, y - ky) < clear + r:
            return False
    return all(math.hypot(x - tx, y - ty) >= r + tr + gap for tx, ty, tr, _ in trees)
