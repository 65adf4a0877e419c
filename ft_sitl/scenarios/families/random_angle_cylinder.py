"""Random-Angle Cylinder (classic): cylinders tilted at random, one across the start->goal
line. Declared in :mod:`ft_sitl.scenarios.families`."""

from __future__ import annotations

import math

import numpy as np

from ft_sitl.scenarios.families.common import (
    START_MARGIN_M,
    Family,
    MeshBuilder,
    make_scenario,
    start_altitude,
)
from ft_sitl.scenarios.scenario import Scenario
from ft_sitl.scenarios.solvability import segment_segment_distance


def _far_from(p, q, points, min_dist) -> bool:
    """Is the segment p->q at least min_dist from each of the segments in points?"""
    if not len(points):
        return True
    a = np.array([s[0] for s in points])
    b = np.array([s[1] for s in points])
    m = len(a)
    d = segment_segment_distance(np.broadcast_to(p, (m, 3)), np.broadcast_to(q, (m, 3)),
                                  a, b)
    return bool(np.all(d >= min_dist))


def random_angle_cylinder(fam: Family, p: dict, rng: np.random.Generator, index: int,
                          seed: int) -> Scenario:
    """Random-Angle Cylinder: 40 x 60 m, ceiling 3 m, 67 cylinders (density 1/36).

    Each cylinder: radius U(0.25, 0.5) m, length 8 m, centre uniform over the area at a
    height U(0, 3) m, axis tilted U(0, 180) deg from vertical towards a uniform azimuth.
    Rejection keeps axes >= r1 + r2 + 1 m apart (wider than the largest platform) and
    >= 3 m + r from the takeoff column and the goal column. If none crosses the
    start->goal line, the one nearest to it is moved (translated) onto it.
    """
    width, length = p["size_m"]
    ceiling = p["ceiling_m"]
    alt = start_altitude(ceiling)
    count = round(width * length * p["density_per_m2"])
    cyl_len, gap, clear = p["length_m"], p["min_axis_gap_m"], p["clear_radius_m"]
    tilt_range = tuple(math.radians(a) for a in p["tilt_deg"])
    line_x = width / 2.0
    columns = [np.array([[line_x, y, 0.0], [line_x, y, ceiling]])
               for y in (START_MARGIN_M, length - START_MARGIN_M)]
    start = np.array([line_x, START_MARGIN_M, alt])
    goal = np.array([line_x, length - START_MARGIN_M, alt])
    cyls: list[dict] = []

    def ok(p0, p1, r, skip=None):
        for col in columns:
            if not _far_from(p0, p1, [col], clear + r):
                return False
        for i, c in enumerate(cyls):
            if i != skip and not _far_from(p0, p1, [(c["p0"], c["p1"])], r + c["r"] + gap):
                return False
        return True

    attempts = 0
    while len(cyls) < count:
        attempts += 1
        if attempts > 200_000:
            raise RuntimeError(f"random_angle_cylinder #{index}: could not place {count}")
        centre = np.array([rng.uniform(0.0, width), rng.uniform(0.0, length),
                           rng.uniform(0.0, ceiling)])
        r = rng.uniform(*p["radius_m"])
        tilt = rng.uniform(*tilt_range)
        azimuth = rng.uniform(0.0, 2.0 * math.pi)
        axis = np.array([math.sin(tilt) * math.cos(azimuth),
                         math.sin(tilt) * math.sin(azimuth), math.cos(tilt)])
        p0, p1 = centre - axis * cyl_len / 2, centre + axis * cyl_len / 2
        if ok(p0, p1, r):
            cyls.append({"p0": p0, "p1": p1, "r": r, "tilt_deg": math.degrees(tilt),
                         "azimuth_deg": math.degrees(azimuth)})
    moved = None
    line = [(start, goal)]
    if all(_far_from(c["p0"], c["p1"], line, c["r"]) for c in cyls):
        def off_line(i):
            c = cyls[i]
            return float(segment_segment_distance(c["p0"][None], c["p1"][None],
                                                   start[None], goal[None])[0]), i
        for i in sorted(range(count), key=off_line):
            c = cyls[i]
            centre = (c["p0"] + c["p1"]) / 2
            y = min(max(centre[1], START_MARGIN_M + 8.0), length - START_MARGIN_M - 8.0)
            shift = np.array([line_x, y, alt]) - centre
            if ok(c["p0"] + shift, c["p1"] + shift, c["r"], skip=i):
                c["p0"], c["p1"] = c["p0"] + shift, c["p1"] + shift
                moved = i
                break
        else:
            raise RuntimeError(f"random_angle_cylinder #{index}: none can move onto the line")
    b = MeshBuilder()
    for c in cyls:
        b.cylinder(c["p0"], c["p1"], c["r"], kind="cylinder")
    return make_scenario(
        fam, index, seed, b, p, altitude=alt, obstacle_count=count,
        derived={"cylinder_count": count, "start_altitude_m": alt},
        layout={"cylinders": cyls, "moved_onto_line": moved},
    )
