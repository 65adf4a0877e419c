"""Sudden-Drop (theoretical): overhanging blocks the vehicle must pass under. Declared in
:mod:`ft_sitl.scenarios.families`."""

from __future__ import annotations

import numpy as np

from ft_sitl.scenarios.families.common import Family, MeshBuilder, make_scenario
from ft_sitl.scenarios.scenario import Scenario


def sudden_drop(fam: Family, p: dict, rng: np.random.Generator, index: int,
                seed: int) -> Scenario:
    """Sudden-Drop: 50 x 50 x 14 m, ceiling 4 m, start at 2.5 m; ``index`` blocks.

    Blocks span the full width and hang from 1.5 m (the lowest obstacle point) to 14 m;
    each is U(1.5, 3) m deep, placed in order along y in [8, 44] with random gaps (>= 0.5
    m). The start altitude 2.5 m passes through them: the vehicle must drop below 1.5 m.
    """
    width, length, top = p["size_m"]
    underside = p["lowest_obstacle_m"]
    alt = p["start_altitude_m"]
    zone = p["block_zone_y_m"]
    depths = rng.uniform(*p["block_depth_m"], index)
    spare = zone[1] - zone[0] - depths.sum() - 0.5 * (index + 1)
    gaps = 0.5 + spare * rng.dirichlet(np.ones(index + 1))
    b = MeshBuilder()
    blocks = []
    y = zone[0]
    for j in range(index):
        y += gaps[j]
        b.box((0.0, y, underside), (width, y + depths[j], top), "overhang")
        blocks.append([y, y + depths[j]])
        y += depths[j]
    return make_scenario(
        fam, index, seed, b, p, altitude=alt, obstacle_count=index,
        derived={"volume_height_m": top, "block_count": index},
        layout={"blocks_y_m": blocks},
    )
