"""The seven FLYINGTRUST scenario families (paper Sec. III-B), 10 configurations each.

``build_scenario(family, index, seed=0)`` returns configuration ``index`` (1..10) of a
family. Every random draw comes from one ``numpy.random.Generator`` seeded with
``SeedSequence(seed, spawn_key=(crc32(family), index))``: the index and the seed together
choose the layout, and the same three arguments always give the same mesh, byte for byte.

Common layout (all families)
----------------------------
The area spans ``x in [0, width]`` (east) by ``y in [0, length]`` (north); the vehicle
travels north, from near the short side ``y = 0`` to near ``y = length``.

* takeoff: on the floor at ``(width / 2, 3 m, 0)`` (Maze: the centre of its first cell);
* start: above takeoff at the start altitude, ``min(2.0 m, ceiling / 2)`` -- 1.5 m for
  Forest and Random-Angle Cylinder, 1.0 m for Maze, 2.0 m otherwise -- except Sudden-Drop,
  which starts at the paper's 2.5 m; start yaw faces the goal (pi/2, north);
* goal: ``(width / 2, length - 3 m, start altitude)`` (Maze: the centre of its last
  cell), reached within 2 m;
* bounds: the area times ``[0, ceiling]``; obstacles may rise above the ceiling.
* Obstacles sit on the straight start->goal segment (checked at build time): in five
  families at least one crosses it; in the two open classic families, Forest and Urban,
  at least one stands within ``LINE_CORRIDOR_M`` (0.6 m) of it -- on it, or beside it
  with a gap smaller than most platforms' collision radius (0.15-0.38 m). Flying the line
  straight then hits something in most configurations, and a small platform slips past in
  a few: the paper's straight-flight baseline succeeds in 10-20 % of its Forest and Urban
  trials and never elsewhere (Sec. IV-B, A4), which strict blocking could not reproduce.
  Urban (version 2) runs the line along an avenue: configurations 1-3 have only a truck or
  wall 0-0.6 m beside it; from 4 on, trucks and walls stand across it (version 1: along
  an open boulevard with probability 0.35, else through a column of buildings).
  Narrow-Gap (version 2) holds to the corridor too: a gap may be centred on the line,
  its walls 0.43-0.45 m either side, and a configuration whose gaps all are is flown
  straight (the paper compares its Narrow-Gap planners with a baseline that succeeds
  there sometimes, Sec. IV-B, A1); version 1 crosses the line with every wall.
* A collision-free path exists for the largest catalog platform's collision radius
  (0.384 m), and for its body held level at the start yaw (protocol 5; in Narrow-Gap it
  fits a gap nose first, not yawed 45 degrees): see :mod:`ft_sitl.scenarios.solvability`
  and the tests.
* Random families keep obstacles at least 3 m (horizontally) from the takeoff/start column
  and the goal.

Families
--------
=====================  ===========  =========  =======  ==================================
family (registry key)  category     area (m)   ceiling  obstacles (what ``index`` changes)
=====================  ===========  =========  =======  ==================================
forest                 classic      40 x 60    3 m      49 trunks (density 1/49 per m^2):
                                                        vertical cylinders, radius
                                                        0.15-0.30 m, 6-12 m tall; >= 1.5 m
                                                        between trunks (random layout)
urban                  classic      60 x 60    10 m     (version 2) buildings (boxes, 70 %
                                                        12-40 m tall, the rest 3-8 m) on
                                                        blocks of a street grid; the line
                                                        runs along a 12-16 m avenue with
                                                        1-3 trucks or walls beside it (one
                                                        0-0.6 m off), 0 0 0 1 1 2 2 3 3 4
                                                        trucks or walls across it (walls
                                                        3 m to up to 3-8 m tall with the
                                                        index), a low wall under the
                                                        flight altitude, 50 % a bridge
                                                        over it; 3-6 side-street walls
random_angle_cylinder  classic      40 x 60    3 m      67 cylinders (density 1/36),
                                                        radius 0.25-0.5 m, 8 m long, tilt
                                                        0-180 deg from vertical, random
                                                        azimuth; axes >= r1 + r2 + 1 m apart
narrow_gap             theoretical  50 x 50    4 m      ``index`` walls (5 m tall, 0.3 m
                                                        thick) across the route, each with
                                                        one full-height gap 0.85-0.90 m
                                                        wide, on the centre line (p = 0.4)
                                                        or 1-2 m beside it, in the camera's
                                                        view from the line: gaps = index
                                                        (version 1: 4-18 m off the line on
                                                        alternating sides)
sudden_drop            theoretical  50 x 50    4 m      ``index`` overhanging blocks, full
                                    (x 14 m)            width, 1.5-3 m deep, from 1.5 m
                                                        (the lowest obstacle point) up to
                                                        14 m; start at 2.5 m
maze                   theoretical  25 x 40    2 m      (version 2) recursive division
                                                        into 7 x 10 cells: corridors
                                                        >= 3.37 m, walls 0.2 m thick,
                                                        2.5 m tall; 6 extra passages
                                                        (loops), dead ends; the start
                                                        cell open towards the goal;
                                                        shortest route <= 1.8 x the line,
                                                        <= 12 turns, <= 45 s stopping at
                                                        every turn; a greedy explorer
                                                        wastes 0 steps (index 1) to 34-36
                                                        (index 10). Version 1: a perfect
                                                        11 x 17 maze (backtracker)
perlin                 theoretical  40 x 50    4 m      (version 2) 0.1 m cells filled
                                                        where Perlin noise is in its top
                                                        3 % (fill rate 0.03), sampled as
                                                        mockamap samples it: 2 x 0.05 per
                                                        cell = 1.0 cycles/m, one octave;
                                                        ~2,000 blobs, 9-15 across the
                                                        line, merged into disjoint boxes.
                                                        Version 1: 0.25 m voxels at 0.05
                                                        per voxel (0.2/m, 2 octaves)
=====================  ===========  =========  =======  ==================================

Obstacle counts (``Scenario.obstacle_count``): trees, buildings + street clutter, cylinders, walls
(one gap each), blocks, maze wall boxes (collinear wall segments merged), Perlin blobs
(6-connected groups of filled voxels).

Layout of the package
---------------------
This module holds the registry: each family's declaration (its parameters, every version
of its generator and what each version changed) and the public API, :func:`build_scenario`,
:func:`describe_family`, :func:`resolve_family`. The generators are in one module per family
(``forest``, ``urban``, ``random_angle_cylinder``, ``narrow_gap``, ``sudden_drop``, ``maze``,
``perlin``; every version of a family in its module); ``common`` holds what they share (the
mesh builder, the common layout's constants and parameters, the scenario's assembly) and
``noise`` the Perlin noise.
"""

from __future__ import annotations

import difflib
import zlib
from collections.abc import Callable, Mapping
from dataclasses import replace

import numpy as np

from ft_sitl.scenarios.families import (
    forest,
    maze,
    narrow_gap,
    perlin,
    random_angle_cylinder,
    sudden_drop,
    urban,
)
from ft_sitl.scenarios.families.common import (
    CEILING,
    CLEAR_RADIUS,
    INTERVAL,
    LINE_CORRIDOR_M,
    OPEN_FAMILIES,
    SIZE,
    START_ALTITUDE,
    Family,
    start_altitude,
)
from ft_sitl.scenarios.families.noise import fbm3, mockamap_noise, perlin3, voxel_boxes
from ft_sitl.scenarios.scenario import INDEX_RANGE, Scenario, ScenarioError
from ft_sitl.schema import Param, Schema

__all__ = [
    "CATEGORY",
    "FAMILIES",
    "LINE_CORRIDOR_M",
    "OPEN_FAMILIES",
    "PAPER_NAMES",
    "REGISTRY",
    "Family",
    "build_scenario",
    "describe_family",
    "fbm3",
    "mockamap_noise",
    "perlin3",
    "resolve_family",
    "start_altitude",
    "voxel_boxes",
]


def _rng(family: str, index: int, seed: int) -> np.random.Generator:
    key = zlib.crc32(family.encode("utf-8"))
    return np.random.default_rng(np.random.SeedSequence(entropy=seed, spawn_key=(key, index)))


def _check(family: str, index, seed) -> None:
    lo, hi = INDEX_RANGE
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
        raise ScenarioError(f"{family}: index must be an integer from {lo} to {hi}, "
                            f"got {index!r}")
    if not lo <= index <= hi:
        raise ScenarioError(f"{family}: index must be from {lo} to {hi} (the paper's ten "
                            f"configurations), got {index}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ScenarioError(f"{family}: seed must be a non-negative integer, got {seed!r}")


# --------------------------------------------------------------------------------------
# the registry
# --------------------------------------------------------------------------------------

REGISTRY: dict[str, Family] = {}
"""Family name -> its :class:`Family`, in the paper's order (the order of declaration)."""


def _builder(name: str):
    """``build(index, seed=0, params=None, version=None)`` of family ``name``: checks index,
    seed and version, resolves the parameters with that version's schema and seeds the
    generator (every version draws from the same stream: see the package docstring)."""
    def build(index: int, seed: int = 0, params: Mapping | None = None,
              version: int | None = None) -> Scenario:
        fam = REGISTRY[name]
        _check(name, index, seed)
        v = fam.check_version(version)
        schema, generator = fam.versions[v]
        view = replace(fam, schema=schema)
        sc = generator(view, fam.resolve(params, v), _rng(name, index, seed), index, seed)
        sc.provenance["generator_version"] = v
        return sc
    return build


def _family(name: str, paper_name: str, category: str, generator: Callable[..., Scenario],
            schema: Schema, aliases: tuple[str, ...] = ()) -> None:
    """Declare family ``name`` with ``generator`` as its version 1. The generator takes
    ``(family, params, rng, index, seed)``; the family's ``build`` (:func:`_builder`)
    carries its name and docstring."""
    build = _builder(name)
    build.__name__ = build.__qualname__ = generator.__name__
    build.__module__ = generator.__module__
    build.__doc__ = generator.__doc__
    REGISTRY[name] = Family(name, paper_name, category, schema, build, aliases,
                            versions={1: (schema, generator)},
                            changes={1: "the first generator"})


def _first(name: str, key: str) -> Param:
    """Parameter ``key`` as family ``name``'s version 1 declares it: a later version that
    keeps a parameter unchanged reuses its declaration (one declaration per parameter)."""
    return REGISTRY[name].versions[1][0][key]


def _revise(name: str, version: int, generator: Callable[..., Scenario], change: str,
            schema: Schema | None = None) -> None:
    """Declare ``generator`` (same signature as for :func:`_family`) as version ``version``
    of family ``name`` (``schema``: its parameters when they differ from the previous
    version's), ``change`` saying what it changes and why. The older versions stay
    buildable by number."""
    fam = REGISTRY[name]
    if version != fam.version + 1:
        raise RuntimeError(f"{name}: version {version} after {fam.version}")
    schema_v = schema if schema is not None else fam.schema
    REGISTRY[name] = replace(fam, schema=schema_v,
                             versions={**fam.versions, version: (schema_v, generator)},
                             changes={**fam.changes, version: change})


# --------------------------------------------------------------------------------------
# classic
# --------------------------------------------------------------------------------------

_family("forest", "Forest", "classic", forest.forest, Schema((
    SIZE,
    CEILING,
    Param("density_per_m2", 1.0 / 49.0, "1/m^2", (0.0001, 0.2), doc="trunks per square metre"),
    Param("tree_count", None, derived=True, doc="round(width x length x density_per_m2)"),
    Param("trunk_radius_m", (0.15, 0.30), "m", (0.02, 2.0), kind=INTERVAL,
          doc="trunk radius, uniform in [lo, hi]"),
    Param("trunk_height_m", (6.0, 12.0), "m", (0.5, 100.0), kind=INTERVAL,
          doc="trunk height, uniform in [lo, hi]"),
    Param("min_trunk_gap_m", 1.5, "m", (0.0, 20.0), doc="minimum gap between trunk surfaces"),
    CLEAR_RADIUS,
    START_ALTITUDE,
)).with_defaults(size_m=(40.0, 60.0), ceiling_m=3.0))


_family("urban", "Urban", "classic", urban.urban, Schema((
    SIZE,
    CEILING,
    Param("block_zone_x_m", (4.0, 56.0), "m", (0.0, 500.0), kind=INTERVAL,
          doc="the blocks fill x in [lo, hi]"),
    Param("block_zone_y_m", (8.0, 52.0), "m", (0.0, 500.0), kind=INTERVAL,
          doc="the blocks fill y in [lo, hi]"),
    Param("park_probability", 0.15, "-", (0.0, 1.0),
          doc="a block outside the middle column is an empty park"),
    Param("tall_probability", 0.75, "-", (0.0, 1.0), doc="a building is tall"),
    Param("tall_height_m", (12.0, 40.0), "m", (0.5, 500.0), kind=INTERVAL,
          doc="a tall building's height, uniform in [lo, hi]"),
    Param("low_height_m", (3.0, 7.0), "m", (0.5, 500.0), kind=INTERVAL,
          doc="a low building's height, uniform in [lo, hi]"),
    Param("alley_m", 1.2, "m", (0.0, 20.0), doc="alley between the lots of a block"),
    Param("wall_height_m", (2.0, 6.0), "m", (0.1, 100.0), kind=INTERVAL,
          doc="a free-standing wall's height, uniform in [lo, hi]"),
    Param("wall_length_m", (3.0, 10.0), "m", (0.5, 100.0), kind=INTERVAL,
          doc="a free-standing wall's length, uniform in [lo, hi]"),
    Param("boulevard_probability", urban.BOULEVARD_PROBABILITY, "-", (0.0, 1.0),
          doc="the centre line runs along an open boulevard (walls only)"),
    Param("line_corridor_m", LINE_CORRIDOR_M, "m", (0.0, 5.0),
          doc="an obstacle stands within this distance of the start->goal line"),
    START_ALTITUDE,
)).with_defaults(size_m=(60.0, 60.0), ceiling_m=10.0))


_revise("urban", 2, urban.urban_v2, change=(
    "the start->goal line runs along an avenue of a street grid, trucks and walls beside and "
    "across it (0-4 across, more and taller with the index), not through the column of "
    "buildings version 1 put on it, which every algorithm hit at the same building "
    "(issue 20)"), schema=Schema((
    SIZE,
    CEILING,
    _first("urban", "block_zone_x_m"),
    Param("block_zone_y_m", (8.0, 52.0), "m", (0.0, 500.0), kind=INTERVAL,
          doc="the blocks fill y in [lo, hi]; the avenue's obstacles stand in "
              "[lo + 5, hi - 1]"),
    Param("avenue_half_width_m", (6.0, 8.0), "m", (1.0, 100.0), kind=INTERVAL,
          doc="the avenue carrying the start->goal line: each side's building "
              "line stands this far from the line, uniform in [lo, hi] per side"),
    Param("street_width_m", (5.0, 7.0), "m", (1.0, 100.0), kind=INTERVAL,
          doc="a side street's (north-south) or cross street's (east-west) width, "
              "uniform in [lo, hi]"),
    Param("cross_streets", (2, 3), "-", (0, 20), kind=INTERVAL,
          doc="east-west cross streets, an integer uniform in [lo, hi]"),
    Param("park_probability", 0.15, "-", (0.0, 1.0),
          doc="a block not facing the avenue is an empty park"),
    Param("tall_probability", 0.7, "-", (0.0, 1.0), doc="a building is tall"),
    _first("urban", "tall_height_m"),
    Param("low_height_m", (3.0, 8.0), "m", (0.5, 500.0), kind=INTERVAL,
          doc="a low building's height, uniform in [lo, hi]"),
    _first("urban", "alley_m"),
    Param("barrier_count", None, derived=True,
          doc="trucks or walls across the line at flight altitude: max(0, "
              "(index - 2) // 2), 0, 0, 0, 1, 1, 2, 2, 3, 3, 4 for index 1..10"),
    Param("barrier_height_m", (3.0, 8.0), "m", (0.5, 100.0), kind=INTERVAL,
          doc="a wall across the line: its height, uniform in [lo, lo + (hi - lo) "
              "(index - 1) / 9] (rises with the index)"),
    Param("min_passage_m", 4.0, "m", (0.5, 50.0),
          doc="a truck or wall across the line leaves at least this much of the "
              "avenue open on one side (and 2.5 m on the other)"),
    Param("low_wall_height_m", (0.5, 1.0), "m", (0.1, 100.0), kind=INTERVAL,
          doc="the low wall across the whole avenue (under the flight altitude): "
              "its height, uniform in [lo, hi]"),
    Param("bridge_probability", 0.5, "-", (0.0, 1.0),
          doc="an overhead passage spans the avenue"),
    Param("bridge_underside_m", (4.5, 6.5), "m", (0.5, 100.0), kind=INTERVAL,
          doc="the overhead passage's underside height, uniform in [lo, hi]"),
    Param("wall_height_m", (2.0, 6.0), "m", (0.1, 100.0), kind=INTERVAL,
          doc="a wall along a side or cross street: its height, uniform in "
              "[lo, hi]"),
    Param("wall_length_m", (3.0, 8.0), "m", (0.5, 100.0), kind=INTERVAL,
          doc="a wall along a side or cross street: its length, uniform in "
              "[lo, hi]"),
    Param("line_corridor_m", LINE_CORRIDOR_M, "m", (0.0, 5.0),
          doc="the first obstacle beside the line stands within this distance of "
              "it"),
    START_ALTITUDE,
)).with_defaults(size_m=(60.0, 60.0), ceiling_m=10.0))


_family("random_angle_cylinder", "Random-Angle Cylinder", "classic",
        random_angle_cylinder.random_angle_cylinder, Schema((
    SIZE,
    CEILING,
    Param("density_per_m2", 1.0 / 36.0, "1/m^2", (0.0001, 0.2),
          doc="cylinders per square metre"),
    Param("cylinder_count", None, derived=True, doc="round(width x length x density_per_m2)"),
    Param("radius_m", (0.25, 0.5), "m", (0.02, 2.0), kind=INTERVAL,
          doc="cylinder radius, uniform in [lo, hi]"),
    Param("length_m", 8.0, "m", (0.5, 50.0), doc="cylinder length"),
    Param("tilt_deg", (0.0, 180.0), "deg", (0.0, 180.0), kind=INTERVAL,
          doc="axis tilt from vertical, uniform in [lo, hi]"),
    Param("min_axis_gap_m", 1.0, "m", (0.0, 20.0),
          doc="axes at least r1 + r2 + this apart"),
    CLEAR_RADIUS,
    START_ALTITUDE,
)).with_defaults(size_m=(40.0, 60.0), ceiling_m=3.0), aliases=("cylinder", "random_cylinder"))


# --------------------------------------------------------------------------------------
# theoretical
# --------------------------------------------------------------------------------------

_family("narrow_gap", "Narrow-Gap", "theoretical", narrow_gap.narrow_gap, Schema((
    SIZE,
    CEILING,
    Param("gap_count", None, derived=True, doc="walls, one gap each: the configuration index"),
    Param("gap_width_m", (0.85, 0.90), "m", (0.1, 10.0), kind=INTERVAL,
          doc="gap width, uniform in [lo, hi]"),
    Param("gap_offset_m", (4.0, 18.0), "m", (0.0, 100.0), kind=INTERVAL,
          doc="gap centre's distance from the centre line, uniform in [lo, hi]"),
    Param("wall_thickness_m", 0.3, "m", (0.05, 5.0), doc="wall thickness"),
    Param("wall_height_m", 5.0, "m", (0.5, 100.0), doc="wall height"),
    START_ALTITUDE,
)).with_defaults(size_m=(50.0, 50.0), ceiling_m=4.0))


_revise("narrow_gap", 2, narrow_gap.narrow_gap_v2, change=(
    "gaps on the start->goal line or 1-2 m beside it, in the camera's view from the line "
    "(version 1's, 4-18 m off, were out of view when the vehicle had to decide: every "
    "algorithm hit the first wall); walls in y 8-42 m"), schema=Schema((
    SIZE,
    CEILING,
    Param("gap_count", None, derived=True,
          doc="walls, one gap each: the configuration index"),
    _first("narrow_gap", "gap_width_m"),
    Param("on_line_probability", 0.4, "-", (0.0, 1.0),
          doc="a gap is centred on the start->goal line (else beside it)"),
    Param("gap_offset_m", (1.0, 2.0), "m", (0.0, 100.0), kind=INTERVAL,
          doc="a gap beside the line: its centre's distance from the line, uniform "
              "in [lo, hi], east or west (a fair coin)"),
    Param("wall_zone_y_m", (8.0, 42.0), "m", (0.0, 500.0), kind=INTERVAL,
          doc="the walls stand in y in [lo, hi], one in each of gap_count equal "
              "slots"),
    _first("narrow_gap", "wall_thickness_m"),
    _first("narrow_gap", "wall_height_m"),
    START_ALTITUDE,
)).with_defaults(size_m=(50.0, 50.0), ceiling_m=4.0))


_family("sudden_drop", "Sudden-Drop", "theoretical", sudden_drop.sudden_drop, Schema((
    Param("size_m", (50.0, 50.0, 14.0), "m", (1.0, 500.0),
          doc="the area's width and length, and the volume's height (the blocks' top)"),
    CEILING,
    Param("volume_height_m", None, derived=True, doc="size_m[2]"),
    Param("lowest_obstacle_m", 1.5, "m", (0.1, 100.0), doc="the blocks' underside"),
    Param("start_altitude_m", 2.5, "m", (0.1, 100.0), doc="start and goal altitude"),
    Param("block_count", None, derived=True, doc="the configuration index"),
    Param("block_depth_m", (1.5, 3.0), "m", (0.1, 100.0), kind=INTERVAL,
          doc="a block's depth along y, uniform in [lo, hi]"),
    Param("block_zone_y_m", (8.0, 44.0), "m", (0.0, 500.0), kind=INTERVAL,
          doc="the blocks lie in y in [lo, hi]"),
)).with_defaults(ceiling_m=4.0))


_family("maze", "Maze", "theoretical", maze.maze, Schema((
    SIZE,
    CEILING,
    Param("cells", (11, 17), "-", (2, 200), doc="cells across (x) and along (y)"),
    Param("cell_m", None, derived=True, doc="size_m / cells"),
    Param("corridor_width_m", None, derived=True, doc="min(cell_m) - wall_thickness_m"),
    Param("wall_thickness_m", 0.2, "m", (0.01, 5.0), doc="wall thickness"),
    Param("wall_height_m", 2.5, "m", (0.1, 100.0), doc="wall height"),
    Param("algorithm", "recursive backtracker", choices=("recursive backtracker",),
          doc="how the passages are carved"),
    START_ALTITUDE,
)).with_defaults(size_m=(25.0, 40.0), ceiling_m=2.0))


_revise("maze", 2, maze.maze_v2, change=(
    "recursive division into 7 x 10 cells (3.4 m corridors) with 6 loops, the start cell open "
    "towards the goal, the shortest route bounded (<= 1.8 x the line, <= 12 turns, <= 45 s "
    "at 4 m/s and 3 m/s^2 stopping at every turn) and a greedy explorer's waste rising with "
    "the index: version 1's perfect 11 x 17 mazes (routes 98-259 m, start cell mostly closed "
    "ahead) were unflyable in 90 s (issue 20)"), schema=Schema((
    SIZE,
    CEILING,
    Param("cells", (7, 10), "-", (2, 200), doc="cells across (x) and along (y)"),
    Param("cell_m", None, derived=True, doc="size_m / cells"),
    Param("corridor_width_m", None, derived=True, doc="min(cell_m) - wall_thickness_m"),
    _first("maze", "wall_thickness_m"),
    _first("maze", "wall_height_m"),
    Param("algorithm", "recursive division", choices=("recursive division",),
          doc="how the walls are drawn"),
    Param("extra_passages", 6, "-", (0, 10_000),
          doc="walls removed at random after the division, each closing a loop"),
    Param("route_factor_max", 1.8, "-", (1.0, 100.0),
          doc="the shortest route (through cell centres) is at most this times the "
              "straight start->goal distance"),
    Param("route_turns_max", 12, "-", (0, 10_000),
          doc="the shortest route turns at most this often"),
    Param("route_time_max_s", 45.0, "s", (1.0, 10_000.0),
          doc="the shortest route flown at route_speed_m_s and route_acc_m_s2, stopping at "
              "every turn, takes at most this"),
    Param("route_speed_m_s", 4.0, "m/s", (0.1, 100.0),
          doc="speed of the route time bound (the benchmark's speed cap)"),
    Param("route_acc_m_s2", 3.0, "m/s^2", (0.1, 100.0),
          doc="acceleration of the route time bound (the protocol's limit)"),
    Param("detour_cells", (0, 36), "cells", (0, 10_000), kind=INTERVAL,
          doc="a goal-greedy explorer's wasted steps: exactly lo in configuration 1, rising "
              "linearly to hi in configuration 10 (a band of 2 below each target)"),
    Param("detour_band_cells", None, derived=True,
          doc="this configuration's band of wasted steps"),
    START_ALTITUDE,
)).with_defaults(size_m=(25.0, 40.0), ceiling_m=2.0))


_family("perlin", "Random Perlin-Noise", "theoretical", perlin.perlin, Schema((
    SIZE,
    CEILING,
    Param("voxel_m", 0.25, "m", (0.05, 5.0), doc="voxel edge"),
    Param("noise_frequency_per_voxel", 0.05, "1/voxel", (0.001, 1.0),
          doc="the paper's noise frequency, taken per voxel index"),
    Param("noise_frequency_per_m", None, derived=True,
          doc="noise_frequency_per_voxel / voxel_m (cycles per metre)"),
    Param("octaves", 2, "-", (1, 8), doc="noise octaves"),
    Param("lacunarity", 2.0, "-", (1.0, 4.0), doc="frequency factor between octaves"),
    Param("gain", 0.5, "-", (0.0, 1.0), doc="amplitude factor between octaves"),
    Param("fill_rate", 0.03, "-", (0.001, 0.5),
          doc="fraction of the voxels filled (those of highest noise)"),
    CLEAR_RADIUS,
    START_ALTITUDE,
)).with_defaults(size_m=(40.0, 50.0), ceiling_m=4.0), aliases=("perlin_noise", "random_perlin"))


_revise("perlin", 2, perlin.perlin_v2, change=(
    "mockamap's convention, the generator the planners' authors fly (EGO-Planner's simulator "
    "launch: 0.1 m cells, complexity 0.05, one octave): the paper's frequency 0.05 is "
    "mockamap's complexity, sampled at 2 x 0.05 per 0.1 m cell = 1.0 cycles/m, top 3 % filled: "
    "~2,000 blobs, 9-15 across the line. Version 1 read 0.05 per 0.25 m voxel (0.2 cycles/m: "
    "37-58 blobs, 1-2 on the line), a choice of ours that decided Perlin's results (issue 20; "
    "docs/results/perlin-v2-study)"), schema=Schema((
    SIZE,
    CEILING,
    Param("voxel_m", 0.1, "m", (0.05, 5.0),
          doc="cell edge (mockamap's 1 / scale; 0.1 m in EGO-Planner's simulator launch)"),
    Param("complexity", 0.05, "1/cell", (0.001, 1.0),
          doc="the paper's noise frequency as mockamap's complexity: its first octave "
              "samples the noise at 2 x complexity per cell index"),
    Param("noise_frequency_per_m", None, derived=True,
          doc="2 x complexity / voxel_m: the first octave's cycles per metre"),
    Param("fractal", 1, "-", (1, 6),
          doc="mockamap's octaves: octave it (1..fractal) at 2^it x complexity per cell, "
              "amplitude attenuation / it"),
    Param("attenuation", 0.5, "-", (0.0, 1.0), doc="mockamap's octave amplitude factor"),
    _first("perlin", "fill_rate"),
    CLEAR_RADIUS,
    START_ALTITUDE,
)).with_defaults(size_m=(40.0, 50.0), ceiling_m=4.0))


# --------------------------------------------------------------------------------------
# views of the registry, and the public API
# --------------------------------------------------------------------------------------

FAMILIES: dict[str, Callable[..., Scenario]] = {k: f.build for k, f in REGISTRY.items()}
"""Family name -> ``build(index, seed=0, params=None) -> Scenario``, in the paper's order
(a view of :data:`REGISTRY`)."""

CATEGORY = {k: f.category for k, f in REGISTRY.items()}
"""Family name -> category (a view of :data:`REGISTRY`)."""

PAPER_NAMES = {k: f.paper_name for k, f in REGISTRY.items()}
"""Family name -> the paper's name (a view of :data:`REGISTRY`)."""


def _normalise(name: str) -> str:
    return "_".join(name.strip().lower().replace("-", " ").replace("_", " ").split())


_ALIASES = {_normalise(f.paper_name): k for k, f in REGISTRY.items()}
_ALIASES.update({a: k for k, f in REGISTRY.items() for a in f.aliases})


def resolve_family(name) -> str:
    """The registry key for a family name; accepts the paper's names ("Narrow-Gap")."""
    if not isinstance(name, str):
        raise ScenarioError(f"scenario family must be a string, got {name!r}")
    key = _normalise(name)
    key = _ALIASES.get(key, key)
    if key in FAMILIES:
        return key
    choices = list(FAMILIES) + list(_ALIASES)
    close = []
    for c in difflib.get_close_matches(key, choices, n=3, cutoff=0.5):
        c = _ALIASES.get(c, c)
        if c not in close:
            close.append(c)
    hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
    raise ScenarioError(f"unknown scenario family {name!r}{hint} "
                        f"(families: {', '.join(FAMILIES)})")


def describe_family(name: str) -> Family:
    """The declaration of family ``name`` (the paper's names are accepted; ScenarioError if
    there is none by that name): ``.paper_name``, ``.category``, and ``.schema.rows()``
    giving name, default, unit, range and doc of each generator parameter."""
    return REGISTRY[resolve_family(name)]


def build_scenario(family: str, index: int, seed: int = 0,
                   params: Mapping | None = None, version: int | None = None) -> Scenario:
    """Configuration ``index`` (1..10) of ``family`` for ``seed`` (see the package docstring);
    ``params`` change the generator's parameters (:func:`describe_family`); ``version``
    builds with an older generator of the family (None: the newest)."""
    key = resolve_family(family)
    _check(key, index, seed)
    return REGISTRY[key].build(int(index), int(seed), params, version)
