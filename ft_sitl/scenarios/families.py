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
"""

from __future__ import annotations

import difflib
import heapq
import math
import zlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np
import trimesh
from scipy.ndimage import label

from ft_sitl import __version__
from ft_sitl.scenarios.scenario import INDEX_RANGE, Scenario, ScenarioError
from ft_sitl.scenarios.solvability import segment_segment_distance
from ft_sitl.schema import Param, Schema, SchemaError

START_MARGIN_M = 3.0
"""Takeoff and goal lie this far inside the area's short sides."""
CLEAR_RADIUS_M = 3.0
"""Random obstacles keep this horizontal distance from the takeoff/start column and goal."""
CYLINDER_SECTIONS = 16
#: in the open classic families (Forest, Urban) the obstacle "on the line" may stand up to
#: this far beside it (m): a vehicle flying the line straight hits it unless its collision
#: radius is smaller than the gap (see the module docstring)
LINE_CORRIDOR_M = 0.6
#: Urban: probability that the centre line runs along an open boulevard (walls only)
BOULEVARD_PROBABILITY = 0.35
OPEN_FAMILIES = ("forest", "urban")
"""Sides of the prisms that stand for cylinders (circumscribed: they contain the circle)."""


def start_altitude(ceiling: float) -> float:
    """The start (and goal) altitude of every family but Sudden-Drop: min(2 m, ceiling/2)."""
    return min(2.0, ceiling / 2.0)


# --------------------------------------------------------------------------------------
# mesh building
# --------------------------------------------------------------------------------------

_BOX_FACES = np.array([
    [0, 4, 6], [0, 6, 2],  # -x
    [1, 3, 7], [1, 7, 5],  # +x
    [0, 1, 5], [0, 5, 4],  # -y
    [2, 6, 7], [2, 7, 3],  # +y
    [0, 2, 3], [0, 3, 1],  # -z
    [4, 5, 7], [4, 7, 6],  # +z
], dtype=np.int64)
_BOX_CORNERS = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)], dtype=bool)


class _MeshBuilder:
    """Closed convex pieces, concatenated without merging vertices (each piece stays its
    own connected component, which the solvability check relies on)."""

    def __init__(self):
        self._verts: list[np.ndarray] = []
        self._faces: list[np.ndarray] = []
        self._kinds: list[str] = []
        self._n = 0

    @property
    def pieces(self) -> int:
        return len(self._faces)

    def _add(self, verts, faces, kind):
        self._verts.append(np.asarray(verts, dtype=float))
        self._faces.append(np.asarray(faces, dtype=np.int64) + self._n)
        self._kinds.append(kind)
        self._n += len(verts)

    def box(self, lo, hi, kind: str = "obstacle"):
        self.boxes(np.asarray(lo, dtype=float)[None], np.asarray(hi, dtype=float)[None], kind)

    def boxes(self, lo, hi, kind: str = "obstacle"):
        """Axis-aligned boxes lo[i] .. hi[i] (arrays (n, 3)), each its own piece."""
        lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
        if np.any(hi <= lo):
            raise ValueError("empty box among the boxes to add")
        n = len(lo)
        verts = np.where(_BOX_CORNERS[None], hi[:, None, :], lo[:, None, :]).reshape(-1, 3)
        faces = _BOX_FACES[None] + 8 * np.arange(n, dtype=np.int64)[:, None, None]
        self._verts.append(verts)
        self._faces.extend(np.split(faces.reshape(-1, 3) + self._n, n) if n else [])
        self._kinds.extend([kind] * n)
        self._n += len(verts)

    def cylinder(self, p0, p1, radius: float, sections: int = CYLINDER_SECTIONS,
                 kind: str = "obstacle"):
        """A prism of ``sections`` sides around the axis p0 -> p1 containing the cylinder."""
        p0, p1 = np.asarray(p0, dtype=float), np.asarray(p1, dtype=float)
        d = p1 - p0
        d = d / np.linalg.norm(d)
        helper = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
        u = np.cross(d, helper)
        u /= np.linalg.norm(u)
        w = np.cross(d, u)
        theta = 2.0 * np.pi * np.arange(sections) / sections
        rc = radius / math.cos(math.pi / sections)
        ring = rc * (np.cos(theta)[:, None] * u + np.sin(theta)[:, None] * w)
        verts = np.vstack([p0 + ring, p1 + ring])
        n = sections
        k = np.arange(1, n - 1)
        bottom = np.column_stack([np.zeros(n - 2, dtype=np.int64), k + 1, k])
        top = np.column_stack([np.full(n - 2, n), n + k, n + k + 1])
        a = np.arange(n)
        b = (a + 1) % n
        sides = np.vstack([np.column_stack([a, b, n + b]), np.column_stack([a, n + b, n + a])])
        self._add(verts, np.vstack([bottom, top, sides]), kind)

    def piece_names(self) -> tuple[np.ndarray, tuple[str, ...]]:
        """(first face of each piece, its name: the kind and its ordinal, "tree 3")."""
        counts: dict[str, int] = {}
        names = []
        for k in self._kinds:
            counts[k] = counts.get(k, 0) + 1
            names.append(f"{k} {counts[k]}")
        sizes = np.array([len(f) for f in self._faces], dtype=np.int64)
        first = np.concatenate([[0], np.cumsum(sizes)[:-1]]) if len(sizes) else sizes
        return first.astype(np.int64), tuple(names)

    def mesh(self) -> trimesh.Trimesh:
        if not self._faces:
            return trimesh.Trimesh(np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64),
                                   process=False)
        return trimesh.Trimesh(np.vstack(self._verts), np.vstack(self._faces), process=False)


# --------------------------------------------------------------------------------------
# shared helpers
# --------------------------------------------------------------------------------------


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


def _plain(v):
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.ndarray):
        return _plain(v.tolist())
    if isinstance(v, np.generic):
        return v.item()
    return v


def _make(fam: Family, index: int, seed: int, builder: _MeshBuilder, params: dict, *,
          derived: dict, layout: dict, obstacle_count: int, altitude: float,
          start_xy=None, goal_xy=None, pitch=None, corridor: float = 0.0) -> Scenario:
    """The scenario: the area and ceiling from ``params`` (``size_m``, ``ceiling_m``), its
    provenance from the family's declaration (every parameter, ``derived`` values
    included, in declaration order)."""
    width, length = params["size_m"][:2]
    ceiling = params["ceiling_m"]
    sx, sy = start_xy if start_xy is not None else (width / 2.0, START_MARGIN_M)
    gx, gy = goal_xy if goal_xy is not None else (width / 2.0, length - START_MARGIN_M)
    provenance = {
        "generator": f"{__name__}.{fam.name}",
        "paper_name": fam.paper_name,
        "seed": int(seed),
        "index": int(index),
        "ft_sitl_version": __version__,
        "parameters": _plain(fam.schema.record(params, derived)),
        "obstacle_count": int(obstacle_count),
        "mesh_pieces": builder.pieces,
        "layout": _plain(layout),
    }
    first_face, names = builder.piece_names()
    if pitch is not None:
        provenance["solvability_pitch_m"] = [float(p) for p in pitch]
    sc = Scenario(
        family=fam.name, index=int(index), seed=int(seed), category=fam.category,
        mesh=builder.mesh(),
        piece_first_face=first_face, piece_names=names,
        bounds_min=(0.0, 0.0, 0.0), bounds_max=(width, length, ceiling),
        takeoff=(sx, sy, 0.0), start=(sx, sy, altitude),
        start_yaw=math.atan2(gy - sy, gx - sx),
        goal=(gx, gy, altitude), provenance=provenance,
    )
    if not sc.line_blocked(corridor):  # every generator guarantees this; a bug if not
        raise RuntimeError(f"{sc.name}: no obstacle within {corridor} m of the straight "
                           "start->goal line")
    return sc


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


# --------------------------------------------------------------------------------------
# the families' declarations
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Family:
    """One scenario family: its registry key, the paper's name, its category, the
    generator's parameters (defaults, units, ranges, docs) and ``build(index, seed=0,
    params=None, version=None) -> Scenario``; ``aliases`` are further names
    :func:`resolve_family` accepts.

    ``versions`` holds every generator the family has had (version -> its parameter
    schema and generator function), so that configurations of results written with an
    older generator stay buildable (``version=``); ``schema`` is the newest one's and
    ``version`` its number, what builds by default. A change to a generator that alters
    any configuration's mesh is a new version (docs/scenarios.md, "Generator versions")."""

    name: str
    paper_name: str
    category: str
    schema: Schema
    build: Callable[..., Scenario]
    aliases: tuple[str, ...] = ()
    versions: Mapping[int, tuple[Schema, Callable]] = field(default_factory=dict,
                                                            compare=False, repr=False)
    #: version -> what changed in it (docs)
    changes: Mapping[int, str] = field(default_factory=dict, compare=False, repr=False)

    @property
    def version(self) -> int:
        """The newest generator version (what builds unless asked for another)."""
        return max(self.versions)

    def check_version(self, version) -> int:
        """``version`` as a generator version of this family (None: the newest);
        ScenarioError naming the versions it has."""
        if version is None:
            return self.version
        if isinstance(version, bool) or not isinstance(version, (int, np.integer)) or \
                int(version) not in self.versions:
            raise ScenarioError(f"{self.name}: no generator version {version!r} (versions: "
                                f"{', '.join(map(str, sorted(self.versions)))})")
        return int(version)

    def resolve(self, params: Mapping | None, version: int | None = None) -> dict:
        """The generator's parameters: the defaults updated with ``params`` (checked; a
        ScenarioError names the family, the key, the value and the allowed range)."""
        schema = self.versions[self.check_version(version)][0] if self.versions else \
            self.schema
        try:
            return schema.resolve(params, f"scenario family {self.name!r}")
        except SchemaError as exc:
            raise ScenarioError(str(exc)) from None


REGISTRY: dict[str, Family] = {}
"""Family name -> its :class:`Family`, in the paper's order (the order of declaration)."""


def _builder(name: str):
    """``build(index, seed=0, params=None, version=None)`` of family ``name``: checks index,
    seed and version, resolves the parameters with that version's schema and seeds the
    generator (every version draws from the same stream: see the module docstring)."""
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


def _family(name: str, paper_name: str, category: str, schema: Schema,
            aliases: tuple[str, ...] = ()):
    """Declare the family whose generator (version 1) the decorated function is. The
    function takes ``(family, params, rng, index, seed)``; the decorator returns the
    family's ``build`` (:func:`_builder`)."""
    def declare(generator):
        build = _builder(name)
        build.__name__ = build.__qualname__ = generator.__name__
        build.__doc__ = generator.__doc__
        REGISTRY[name] = Family(name, paper_name, category, schema, build, aliases,
                                versions={1: (schema, generator)},
                                changes={1: "the first generator"})
        return build
    return declare


def _first(name: str, key: str) -> Param:
    """Parameter ``key`` as family ``name``'s version 1 declares it: a later version that
    keeps a parameter unchanged reuses its declaration (one declaration per parameter)."""
    return REGISTRY[name].versions[1][0][key]


def _revise(name: str, version: int, change: str, schema: Schema | None = None):
    """Declare generator ``version`` of family ``name`` (the decorated function, same
    signature as for :func:`_family`; ``schema``: its parameters when they differ from
    the previous version's), ``change`` saying what it changes and why. The older
    versions stay buildable by number."""
    def declare(generator):
        fam = REGISTRY[name]
        if version != fam.version + 1:
            raise RuntimeError(f"{name}: version {version} after {fam.version}")
        schema_v = schema if schema is not None else fam.schema
        REGISTRY[name] = replace(fam, schema=schema_v,
                                 versions={**fam.versions, version: (schema_v, generator)},
                                 changes={**fam.changes, version: change})
        return generator
    return declare


SIZE = Param("size_m", (40.0, 60.0), "m", (5.0, 500.0),
             doc="the area: width (x, east) and length (y, north, along the route)")
CEILING = Param("ceiling_m", 3.0, "m", (1.0, 100.0), doc="the flight volume's ceiling")
CLEAR_RADIUS = Param("clear_radius_m", CLEAR_RADIUS_M, "m", (0.0, 20.0),
                     doc="no obstacle within this horizontal distance of the takeoff/start "
                         "column and the goal")
START_ALTITUDE = Param("start_altitude_m", None, "m", derived=True,
                       doc="start and goal altitude: min(2 m, ceiling_m / 2)")
INTERVAL = "interval"


# --------------------------------------------------------------------------------------
# classic
# --------------------------------------------------------------------------------------


@_family("forest", "Forest", "classic", Schema((
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
    b = _MeshBuilder()
    for x, y, r, h in trees:
        b.cylinder((x, y, 0.0), (x, y, h), r, kind="tree")
    return _make(
        fam, index, seed, b, p, altitude=alt, obstacle_count=count, corridor=LINE_CORRIDOR_M,
        derived={"tree_count": count, "start_altitude_m": alt},
        layout={"trees_xyrh": trees, "moved_beside_line": moved},
    )


def _tree_ok(x, y, r, trees, keep_out, gap, clear) -> bool:
    for kx, ky in keep_out:
        if math.hypot(x - kx, y - ky) < clear + r:
            return False
    return all(math.hypot(x - tx, y - ty) >= r + tr + gap for tx, ty, tr, _ in trees)


@_family("urban", "Urban", "classic", Schema((
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
    Param("boulevard_probability", BOULEVARD_PROBABILITY, "-", (0.0, 1.0),
          doc="the centre line runs along an open boulevard (walls only)"),
    Param("line_corridor_m", LINE_CORRIDOR_M, "m", (0.0, 5.0),
          doc="an obstacle stands within this distance of the start->goal line"),
    START_ALTITUDE,
)).with_defaults(size_m=(60.0, 60.0), ceiling_m=10.0))
def urban(fam: Family, p: dict, rng: np.random.Generator, index: int, seed: int) -> Scenario:
    """Urban: 60 x 60 m, ceiling 10 m: buildings on a street grid, and walls.

    Blocks fill x in [4, 56], y in [8, 52]: 3 or 5 columns (mirror-symmetric about the
    centre line, so the middle column straddles it) by 3-5 rows, separated by streets
    (4.5-8 m), with a street ring at the edges. A block is a park (empty) with probability
    0.15 -- never in the middle column -- else split into 1-2 x 1-2 lots (1.2 m alleys)
    each holding one box building set back 0.3-0.8 m: 75 % are 12-40 m tall (above the
    ceiling), the rest 3-7 m (the vehicle can cross over them). 4-9 free-standing walls
    (0.3 m thick, 3-10 m long, 2-6 m tall) stand along streets, leaving them passable.
    """
    width, length = p["size_m"]
    alt = start_altitude(p["ceiling_m"])
    zone_x, zone_y = p["block_zone_x_m"], p["block_zone_y_m"]
    corridor = p["line_corridor_m"]
    ncols = int(rng.choice([3, 5]))
    nrows = int(rng.integers(3, 6))
    half = (zone_x[1] - zone_x[0]) / 2.0
    k = (ncols - 1) // 2
    if ncols == 3:
        centre_w = rng.uniform(6.0, 12.0)
        side_streets = rng.uniform(5.0, 8.0, k)
    else:
        centre_w = rng.uniform(5.0, 8.0)
        side_streets = rng.uniform(4.5, 6.5, k)
    weights = rng.uniform(0.7, 1.3, k)
    side_blocks = (half - centre_w / 2 - side_streets.sum()) * weights / weights.sum()
    cx = width / 2.0
    cols = [(cx - centre_w / 2, cx + centre_w / 2)]
    edge = centre_w / 2
    for s, bw in zip(side_streets, side_blocks):
        cols.append((cx + edge + s, cx + edge + s + bw))
        cols.insert(0, (cx - edge - s - bw, cx - edge - s))
        edge += s + bw
    row_streets = rng.uniform(5.0, 7.0, nrows - 1)
    row_w = rng.uniform(0.7, 1.3, nrows)
    row_w = (zone_y[1] - zone_y[0] - row_streets.sum()) * row_w / row_w.sum()
    rows, y = [], zone_y[0]
    for j in range(nrows):
        rows.append((y, y + row_w[j]))
        y += row_w[j] + (row_streets[j] if j < nrows - 1 else 0.0)
    mid = ncols // 2
    alley = p["alley_m"]
    # the middle column as an open boulevard: no buildings, a wall beside the line instead
    boulevard = bool(rng.random() < p["boulevard_probability"])
    b = _MeshBuilder()
    buildings, walls = [], []
    for i, (x0, x1) in enumerate(cols):
        if boulevard and i == mid:
            continue
        for y0, y1 in rows:
            park = rng.random() < p["park_probability"]
            if park and i != mid:
                continue
            nx = 1 if (i == mid or x1 - x0 < 8.0) else int(rng.integers(1, 3))
            ny = 1 if y1 - y0 < 8.0 else int(rng.integers(1, 3))
            xs = _split(rng, x0, x1, nx, alley)
            ys = _split(rng, y0, y1, ny, alley)
            for lx0, lx1 in xs:
                for ly0, ly1 in ys:
                    s = min(rng.uniform(0.3, 0.8), 0.2 * min(lx1 - lx0, ly1 - ly0))
                    tall = rng.random() < p["tall_probability"]
                    h = rng.uniform(*p["tall_height_m" if tall else "low_height_m"])
                    lo, hi = (lx0 + s, ly0 + s, 0.0), (lx1 - s, ly1 - s, h)
                    b.box(lo, hi, "building")
                    buildings.append([*lo, *hi])
    streets_ns = [(cols[i][1], cols[i + 1][0]) for i in range(ncols - 1)]
    streets_ew = [(rows[j][1], rows[j + 1][0]) for j in range(nrows - 1)]
    for _ in range(int(rng.integers(4, 10))):
        thick = 0.3
        wlen = rng.uniform(*p["wall_length_m"])
        h = rng.uniform(*p["wall_height_m"])
        if rng.random() < 0.5:  # along a north-south street
            a, c = streets_ns[int(rng.integers(len(streets_ns)))]
            xw = rng.uniform(a + 0.5, c - 0.5 - thick)
            yw = rng.uniform(zone_y[0], zone_y[1] - wlen)
            lo, hi = (xw, yw, 0.0), (xw + thick, yw + wlen, h)
        else:  # along an east-west street
            a, c = streets_ew[int(rng.integers(len(streets_ew)))]
            yw = rng.uniform(a + 0.5, c - 0.5 - thick)
            xw = rng.uniform(zone_x[0], zone_x[1] - wlen)
            lo, hi = (xw, yw, 0.0), (xw + wlen, yw + thick, h)
        b.box(lo, hi, "wall")
        walls.append([*lo, *hi])
    if boulevard:  # a wall along the line, its near face 0..line_corridor_m beside it
        thick, wlen, h = 0.3, rng.uniform(*p["wall_length_m"]), rng.uniform(3.0, 6.0)
        offset = rng.uniform(0.0, corridor)
        yw = rng.uniform(zone_y[0], zone_y[1] - wlen)
        x_near = cx + offset if rng.random() < 0.5 else cx - offset - thick
        lo, hi = (x_near, yw, 0.0), (x_near + thick, yw + wlen, h)
        b.box(lo, hi, "wall")
        walls.append([*lo, *hi])
    return _make(
        fam, index, seed, b, p, altitude=alt, obstacle_count=len(buildings) + len(walls),
        corridor=corridor, derived={"start_altitude_m": alt},
        layout={"columns_x_m": cols, "rows_y_m": rows, "buildings_lo_hi": buildings,
                "walls_lo_hi": walls, "boulevard": boulevard},
    )


#: Urban (version 2): obstacles in the avenue keep their footprints this far apart (m)
URBAN_ITEM_GAP_M = 2.5
#: Urban (version 2): obstacles across the line stand at least this far apart along it (m)
URBAN_BARRIER_SPACING_M = 7.0
#: Urban (version 2): an obstacle across the line leaves at least this much of the avenue
#: open on each side (m; min_passage_m on one of them)
URBAN_SIDE_GAP_M = 2.5
#: Urban (version 2): the avenue's obstacles stand this far inside the blocks' y range at
#: the start's and the goal's end (m)
URBAN_AVENUE_MARGIN_M = (5.0, 1.0)
#: Urban (version 2): a block (or a row of blocks) is at least this wide / long (m)
URBAN_MIN_BLOCK_M = 4.0


def urban_barrier_count(index: int) -> int:
    """Urban (version 2): walls across the start->goal line at flight altitude in
    configuration ``index``: 0, 0, 0, 1, 1, 2, 2, 3, 3, 4 for index 1..10."""
    return max(0, (index - 2) // 2)


@_revise("urban", 2, "the start->goal line runs along an avenue of a street grid, trucks and "
         "walls beside and across it (0-4 across, more and taller with the index), not "
         "through the column of buildings version 1 put on it, which every algorithm hit at "
         "the same building (issue 20)",
         schema=Schema((
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
def urban_v2(fam: Family, p: dict, rng: np.random.Generator, index: int,
             seed: int) -> Scenario:
    """Urban (version 2): 60 x 60 m, ceiling 10 m: streets and blocks; the start->goal line
    runs along an avenue, with trucks and walls beside and across it.

    Why: the paper's Urban is "structured but cluttered geometry with vertical obstacles
    resembling buildings and walls", an open field where "all algorithms perform well"
    and the straight-flight baseline succeeds in about 10-20 % of the trials. Version 1
    ran the line through a column of buildings in most configurations: every algorithm,
    the baseline included, hit the same first building. Here no building stands on the
    line; what stands on it is street clutter a planner passes at flight altitude.

    The street grid. The avenue (its building lines 6-8 m from the line, drawn per side)
    runs the whole length. Blocks fill x in [4, 56], y in [8, 52], inside a ring street:
    on each side of the avenue two block columns split by a north-south side street, and
    3-4 rows split by 2-3 east-west cross streets (streets 5-7 m wide). A block is split
    into 1-2 x 1-2 lots (1.2 m alleys; a side of 8 m or more may split), each holding one
    box building set back 0.3-0.8 m: 70 % are 12-40 m tall (above the ceiling), the rest
    3-8 m (the vehicle may cross over them). A block not facing the avenue is a park
    (empty) with probability 0.15, so buildings line the avenue.

    The avenue's obstacles stand in y in [13, 51] (10 m of clear avenue after the start,
    6 m before the goal), their footprints >= 2.5 m apart, two beside the line never
    abreast (that would be a gate, Narrow-Gap's test):

    * beside the line, parallel to it on a random side: 1-3 trucks (2.5 m wide, 4-7 m
      long, 3-4 m tall; 60 %) or median walls (0.5 m thick, 3-6 m long, 3-5 m tall). The
      first stands with its near face a uniform 0-0.6 m (``line_corridor_m``) from the
      line -- the open-family rule of the module docstring: the baseline, which flies the
      line, hits it unless its body is narrower than the gap -- the others 1-2.5 m off.
    * across the line at flight altitude: ``barrier_count`` = 0, 0, 0, 1, 1, 2, 2, 3, 3, 4
      (index 1..10) free-standing trucks (2.5 m deep, 4.5-6.5 m long, 3-4 m tall) or
      walls (0.5 m thick, 3-6 m long), half each, >= 7 m apart along the avenue. The line
      crosses each >= 0.6 m from its ends (no platform flies past it), and each leaves
      >= 2.5 m of the avenue open on both sides, >= 4 m on one. A wall's height is uniform
      in [3, 3 + 5 (index - 1) / 9] m: up to 8 m, under the 10 m ceiling. Difficulty --
      how many obstacles cross the line, and how tall -- rises with the index.
    * across the avenue, out of the way at flight altitude: a low wall over its whole
      width (0.4 m thick, 0.5-1 m tall), and with probability 0.5 an overhead passage
      between its buildings (2.5-4 m deep, 1.5-2.5 m thick, underside 4.5-6.5 m) over a
      row of blocks.

    So in configurations 1-3 only the truck or wall beside the line stands in the
    baseline's way (a platform narrower than the gap slips past), and from 4 on an
    obstacle across the line stops it: ~14 % baseline success over the catalog and the
    ten configurations (seeds 0-7, exact body checks along the line), as in the paper.
    Each obstacle across leaves passages on both sides at flight altitude, so no
    configuration is blocked for every algorithm at one obstacle (tests: a level path
    below 3 m exists for the largest body); side streets give further detours. 3-6
    free-standing walls (0.3 m thick, 3-8 m long, 2-6 m tall) stand along the side and
    cross streets, outside the avenue.
    """
    width, length = p["size_m"]
    alt = start_altitude(p["ceiling_m"])
    (zx0, zx1), (zy0, zy1) = p["block_zone_x_m"], p["block_zone_y_m"]
    corridor = p["line_corridor_m"]
    cx = width / 2.0
    half = rng.uniform(*p["avenue_half_width_m"], 2)  # west, east
    ave = (cx - half[0], cx + half[1])
    if not zx0 + URBAN_MIN_BLOCK_M <= ave[0] < ave[1] <= zx1 - URBAN_MIN_BLOCK_M:
        raise ScenarioError(f"urban #{index}: the avenue {ave[0]:.2f}..{ave[1]:.2f} m leaves "
                            f"no blocks in block_zone_x_m [{zx0:g}, {zx1:g}]")
    # block columns: on each side of the avenue two, split by a side street (one if narrow)
    cols: list[tuple[float, float]] = []
    facing: list[bool] = []  # the column lines the avenue
    streets_ns: list[tuple[float, float]] = []
    for a, c, west_side in ((zx0, ave[0], True), (ave[1], zx1, False)):
        street = rng.uniform(*p["street_width_m"])
        blocks = c - a - street
        if blocks >= 2 * URBAN_MIN_BLOCK_M:
            cut = a + blocks * rng.uniform(0.4, 0.6)
            parts = [(a, cut), (cut + street, c)]
            streets_ns.append((cut, cut + street))
        else:
            parts = [(a, c)]
        cols += parts
        facing += [k == (len(parts) - 1 if west_side else 0) for k in range(len(parts))]
    # rows of blocks between the cross streets
    lo_n, hi_n = p["cross_streets"]
    n_cross = int(rng.integers(lo_n, hi_n + 1))
    cross_w = rng.uniform(*p["street_width_m"], n_cross)
    spare = zy1 - zy0 - cross_w.sum()
    if spare < (n_cross + 1) * URBAN_MIN_BLOCK_M:
        raise ScenarioError(f"urban #{index}: {n_cross} cross streets leave no rows of blocks "
                            f"in block_zone_y_m [{zy0:g}, {zy1:g}]")
    weights = rng.uniform(0.7, 1.3, n_cross + 1)
    row_len = spare * weights / weights.sum()
    rows, y = [], zy0
    for j in range(n_cross + 1):
        rows.append((y, y + row_len[j]))
        y += row_len[j] + (cross_w[j] if j < n_cross else 0.0)
    streets_ew = [(rows[j][1], rows[j + 1][0]) for j in range(n_cross)]

    b = _MeshBuilder()
    buildings = []
    alley = p["alley_m"]
    for (x0, x1), on_avenue in zip(cols, facing):
        for y0, y1 in rows:
            if not on_avenue and rng.random() < p["park_probability"]:
                continue
            nx = 1 if x1 - x0 < 8.0 else int(rng.integers(1, 3))
            ny = 1 if y1 - y0 < 8.0 else int(rng.integers(1, 3))
            for lx0, lx1 in _split(rng, x0, x1, nx, alley):
                for ly0, ly1 in _split(rng, y0, y1, ny, alley):
                    s = min(rng.uniform(0.3, 0.8), 0.2 * min(lx1 - lx0, ly1 - ly0))
                    tall = rng.random() < p["tall_probability"]
                    h = rng.uniform(*p["tall_height_m" if tall else "low_height_m"])
                    lo, hi = (lx0 + s, ly0 + s, 0.0), (lx1 - s, ly1 - s, h)
                    b.box(lo, hi, "building")
                    buildings.append([*lo, *hi])

    # the avenue's obstacles: kind (the piece's name), role, box
    items: list[dict] = []
    y_lo, y_hi = zy0 + URBAN_AVENUE_MARGIN_M[0], zy1 - URBAN_AVENUE_MARGIN_M[1]

    def fits(lo, hi, role: str) -> bool:
        """Footprints URBAN_ITEM_GAP_M apart; two obstacles beside the line not abreast
        (a gate across the line would be a narrow gap, another family's test)."""
        for it in items:
            dx = max(it["lo"][0] - hi[0], lo[0] - it["hi"][0], 0.0)
            dy = max(it["lo"][1] - hi[1], lo[1] - it["hi"][1], 0.0)
            if math.hypot(dx, dy) < URBAN_ITEM_GAP_M or (
                    role == it["role"] == "beside" and dy < URBAN_ITEM_GAP_M):
                return False
        return True

    def place(draw, role: str, tries: int = 500) -> bool:
        """Add the first of ``tries`` draws (kind, lo, hi) whose footprint fits."""
        for _ in range(tries):
            kind, lo, hi = draw()
            if fits(lo, hi, role):
                items.append({"kind": kind, "role": role, "lo": list(lo), "hi": list(hi)})
                return True
        return False

    def beside(offset):
        """A truck or a median wall parallel to the line, its near face ``offset`` from it."""
        def draw():
            truck = rng.random() < 0.6
            east = rng.random() < 0.5
            off = rng.uniform(*offset)
            w, ln, h = ((2.5, rng.uniform(4.0, 7.0), rng.uniform(3.0, 4.0)) if truck
                        else (0.5, rng.uniform(3.0, 6.0), rng.uniform(3.0, 5.0)))
            y0 = rng.uniform(y_lo, y_hi - ln)
            xn = cx + off if east else cx - off - w
            return ("truck" if truck else "wall"), (xn, y0, 0.0), (xn + w, y0 + ln, h)
        return draw

    def across(yc):
        """A truck or a wall across the line at ``yc``: the line crosses it >= 0.6 m from
        its ends, both passages beside it >= URBAN_SIDE_GAP_M, one >= min_passage_m."""
        for _ in range(1000):
            truck = bool(rng.random() < 0.5)
            ln, depth, h = ((rng.uniform(4.5, 6.5), 2.5, rng.uniform(3.0, 4.0)) if truck else
                            (rng.uniform(3.0, 6.0), 0.5, rng.uniform(h_lo, h_top)))
            c_lo = max(-(ln / 2 - 0.6), ln / 2 + URBAN_SIDE_GAP_M - half[0])
            c_hi = min(ln / 2 - 0.6, half[1] - ln / 2 - URBAN_SIDE_GAP_M)
            if c_lo > c_hi:
                continue
            c = cx + rng.uniform(c_lo, c_hi)
            x0, x1 = c - ln / 2, c + ln / 2
            if max(x0 - ave[0], ave[1] - x1) >= p["min_passage_m"]:
                return ("truck" if truck else "wall"), (x0, yc - depth / 2, 0.0), \
                    (x1, yc + depth / 2, h)
        raise ScenarioError(f"urban #{index}: the avenue is too narrow for an obstacle across "
                            f"the line leaving min_passage_m = {p['min_passage_m']:g} m "
                            "beside it")

    def low_wall():
        y0 = rng.uniform(y_lo, y_hi - 0.4)
        h = rng.uniform(*p["low_wall_height_m"])
        return "low wall", (ave[0] - 1.0, y0, 0.0), (ave[1] + 1.0, y0 + 0.4, h)

    # the obstacle beside the line (the open-family rule) and those across it, drawn together
    n_bar = urban_barrier_count(index)
    h_lo, h_hi = p["barrier_height_m"]
    h_top = h_lo + (h_hi - h_lo) * (index - 1) / 9.0
    first = beside((0.0, corridor))
    for _ in range(5000):
        items.clear()
        kind, lo, hi = first()
        items.append({"kind": kind, "role": "beside", "lo": list(lo), "hi": list(hi)})
        ys = np.sort(rng.uniform(y_lo + 1.5, y_hi - 1.5, n_bar))
        if np.any(np.diff(ys) < URBAN_BARRIER_SPACING_M):  # along the avenue, spaced
            continue
        drawn = [across(yc) for yc in ys]
        if all(fits(lo, hi, "across") for _, lo, hi in drawn):
            items.extend({"kind": k, "role": "across", "lo": list(lo), "hi": list(hi)}
                         for k, lo, hi in drawn)
            break
    else:
        raise ScenarioError(f"urban #{index}: no room for {n_bar} obstacles across the line "
                            f"{URBAN_BARRIER_SPACING_M:g} m apart and one beside it in y "
                            f"[{y_lo:g}, {y_hi:g}]")
    if not place(low_wall, "under"):
        raise ScenarioError(f"urban #{index}: no room for the low wall across the avenue in "
                            f"y [{y_lo:g}, {y_hi:g}]")
    spans = [(max(r0, y_lo), min(r1, y_hi)) for r0, r1 in rows]
    spans = [(r0, r1) for r0, r1 in spans if r1 - r0 >= 6.0]  # the deepest bridge fits

    def bridge():  # over a row of blocks, its ends 1 m into the buildings
        depth, thick = rng.uniform(2.5, 4.0), rng.uniform(1.5, 2.5)
        under = rng.uniform(*p["bridge_underside_m"])
        r0, r1 = spans[int(rng.integers(len(spans)))]
        y0 = rng.uniform(r0 + 1.0, r1 - 1.0 - depth)
        return "bridge", (ave[0] - 1.0, y0, under), (ave[1] + 1.0, y0 + depth, under + thick)

    if rng.random() < p["bridge_probability"] and spans:
        place(bridge, "over")
    for _ in range(int(rng.integers(1, 3))):
        place(beside((1.0, 2.5)), "beside")
    for it in items:
        b.box(it["lo"], it["hi"], it["kind"])

    # free-standing walls along the side and cross streets, outside the avenue
    walls = []
    for _ in range(int(rng.integers(3, 7))):
        wlen, h = rng.uniform(*p["wall_length_m"]), rng.uniform(*p["wall_height_m"])
        if streets_ns and (not streets_ew or rng.random() < 0.5):
            a, c = streets_ns[int(rng.integers(len(streets_ns)))]
            xw, yw = rng.uniform(a + 0.5, c - 0.8), rng.uniform(zy0, zy1 - wlen)
            lo, hi = (xw, yw, 0.0), (xw + 0.3, yw + wlen, h)
        elif streets_ew:
            a, c = streets_ew[int(rng.integers(len(streets_ew)))]
            x0, x1 = (zx0, ave[0] - 1.0) if rng.random() < 0.5 else (ave[1] + 1.0, zx1)
            wlen = min(wlen, x1 - x0)
            xw, yw = rng.uniform(x0, x1 - wlen), rng.uniform(a + 0.5, c - 0.8)
            lo, hi = (xw, yw, 0.0), (xw + wlen, yw + 0.3, h)
        else:
            break
        b.box(lo, hi, "wall")
        walls.append([*lo, *hi])
    return _make(
        fam, index, seed, b, p, altitude=alt,
        obstacle_count=len(buildings) + len(items) + len(walls), corridor=corridor,
        derived={"barrier_count": n_bar, "start_altitude_m": alt},
        layout={"avenue_x_m": ave, "columns_x_m": cols, "rows_y_m": rows,
                "side_streets_x_m": streets_ns, "cross_streets_y_m": streets_ew,
                "buildings_lo_hi": buildings, "avenue_obstacles": items,
                "walls_lo_hi": walls},
    )


def _split(rng, a, b, n, alley):
    if n == 1:
        return [(a, b)]
    cut = a + (b - a) * rng.uniform(0.35, 0.65)
    return [(a, cut - alley / 2), (cut + alley / 2, b)]


@_family("random_angle_cylinder", "Random-Angle Cylinder", "classic", Schema((
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
    b = _MeshBuilder()
    for c in cyls:
        b.cylinder(c["p0"], c["p1"], c["r"], kind="cylinder")
    return _make(
        fam, index, seed, b, p, altitude=alt, obstacle_count=count,
        derived={"cylinder_count": count, "start_altitude_m": alt},
        layout={"cylinders": cyls, "moved_onto_line": moved},
    )


# --------------------------------------------------------------------------------------
# theoretical
# --------------------------------------------------------------------------------------

NARROW_GAP_PITCH_M = (0.025, 0.25, 0.25)
"""Solvability grid for Narrow-Gap: 2.5 cm across the gaps (x), whose free window for a
0.384 m radius is only 0.85 - 0.768 = 0.082 m wide."""


@_family("narrow_gap", "Narrow-Gap", "theoretical", Schema((
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
    b = _MeshBuilder()
    walls = []
    for j in range(index):
        y = 10.0 + spacing * (j + 0.5) + rng.uniform(-0.125, 0.125) * spacing
        w = rng.uniform(*p["gap_width_m"])
        c = width / 2.0 + side * rng.uniform(*p["gap_offset_m"])
        side = -side
        b.box((0.0, y - thick / 2, 0.0), (c - w / 2, y + thick / 2, height), "wall")
        b.box((c + w / 2, y - thick / 2, 0.0), (width, y + thick / 2, height), "wall")
        walls.append({"y_m": y, "gap_centre_x_m": c, "gap_width_m": w})
    return _make(
        fam, index, seed, b, p, altitude=alt, obstacle_count=index, pitch=NARROW_GAP_PITCH_M,
        derived={"gap_count": index, "start_altitude_m": alt},
        layout={"walls": walls},
    )


@_revise("narrow_gap", 2, "gaps on the start->goal line or 1-2 m beside it, in the "
         "camera's view from the line (version 1's, 4-18 m off, were out of view when the "
         "vehicle had to decide: every algorithm hit the first wall); walls in y 8-42 m",
         schema=Schema((
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
    b = _MeshBuilder()
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
    return _make(
        fam, index, seed, b, p, altitude=alt, obstacle_count=index, pitch=NARROW_GAP_PITCH_M,
        corridor=LINE_CORRIDOR_M,
        derived={"gap_count": index, "start_altitude_m": alt},
        layout={"walls": walls},
    )


@_family("sudden_drop", "Sudden-Drop", "theoretical", Schema((
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
    b = _MeshBuilder()
    blocks = []
    y = zone[0]
    for j in range(index):
        y += gaps[j]
        b.box((0.0, y, underside), (width, y + depths[j], top), "overhang")
        blocks.append([y, y + depths[j]])
        y += depths[j]
    return _make(
        fam, index, seed, b, p, altitude=alt, obstacle_count=index,
        derived={"volume_height_m": top, "block_count": index},
        layout={"blocks_y_m": blocks},
    )


@_family("maze", "Maze", "theoretical", Schema((
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
def maze(fam: Family, p: dict, rng: np.random.Generator, index: int, seed: int) -> Scenario:
    """Maze: 25 x 40 m, ceiling 2 m; a perfect maze (one path between any two cells).

    11 x 17 cells (2.27 x 2.35 m; corridors >= 2.07 m between 0.2 m walls, 2.5 m tall),
    carved by an iterative recursive backtracker from the start cell (the middle of the
    first row); the goal is the middle of the last row. A layout whose middle column is a
    straight corridor (start->goal line clear) is redrawn. Dead ends are counted.
    """
    width, length = p["size_m"]
    alt = start_altitude(p["ceiling_m"])
    (nx, ny), thick, height = p["cells"], p["wall_thickness_m"], p["wall_height_m"]
    cw, ch = width / nx, length / ny
    mid = nx // 2
    for _ in range(100):
        east, north = _carve(rng, nx, ny, (mid, 0))
        if not north[mid, :-1].all():  # a wall crosses the middle column
            break
    else:  # pragma: no cover - probability ~0
        raise RuntimeError(f"maze #{index}: every layout left the line clear")
    b = _MeshBuilder()
    t2 = thick / 2
    runs = 0
    # walls on vertical grid lines x = i * cw (i = 0..nx): closed unless a passage east
    for i in range(nx + 1):
        closed = np.ones(ny, dtype=bool) if i in (0, nx) else ~east[i - 1, :]
        for j0, j1 in _runs(closed):
            b.box((i * cw - t2, j0 * ch - t2, 0.0), (i * cw + t2, j1 * ch + t2, height),
                  "wall")
            runs += 1
    for j in range(ny + 1):
        closed = np.ones(nx, dtype=bool) if j in (0, ny) else ~north[:, j - 1]
        for i0, i1 in _runs(closed):
            b.box((i0 * cw - t2, j * ch - t2, 0.0), (i1 * cw + t2, j * ch + t2, height),
                  "wall")
            runs += 1
    degree = np.zeros((nx, ny), dtype=int)
    degree[:-1, :] += east[:-1, :]
    degree[1:, :] += east[:-1, :]
    degree[:, :-1] += north[:, :-1]
    degree[:, 1:] += north[:, :-1]
    dead_ends = int((degree == 1).sum())
    return _make(
        fam, index, seed, b, p, altitude=alt, obstacle_count=runs,
        start_xy=((mid + 0.5) * cw, 0.5 * ch), goal_xy=((mid + 0.5) * cw, (ny - 0.5) * ch),
        derived={"cell_m": [cw, ch], "corridor_width_m": min(cw, ch) - thick,
                 "start_altitude_m": alt},
        layout={"dead_ends": dead_ends,
                "east_passages": east[:-1, :].astype(int).tolist(),
                "north_passages": north[:, :-1].astype(int).tolist()},
    )


#: draws of a layout before giving up on the bounds (the default parameters need ~1-60)
MAZE_ATTEMPTS = 20_000


@_revise("maze", 2, "recursive division into 7 x 10 cells (3.4 m corridors) with 6 loops, "
         "the start cell open towards the goal, the shortest route bounded (<= 1.8 x the "
         "line, <= 12 turns, <= 45 s at 4 m/s and 3 m/s^2 stopping at every turn) and a "
         "greedy explorer's waste rising with the index: version 1's perfect 11 x 17 mazes "
         "(routes 98-259 m, start cell mostly closed ahead) were unflyable in 90 s "
         "(issue 20)", schema=Schema((
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
def maze_v2(fam: Family, p: dict, rng: np.random.Generator, index: int,
            seed: int) -> Scenario:
    """Maze, version 2: 25 x 40 m, ceiling 2 m; dead ends and loops, a route that a 4 m/s
    vehicle flies well within 90 s, and more exploration the higher the index.

    Why: version 1's perfect 11 x 17 mazes had shortest routes of 98-259 m with 23-72
    turns and 3-14 legs heading south (away from the goal), and the start cell was closed
    towards the goal in 8 of 10 configurations: hopeless for a goal-directed local planner
    in 90 s (0 % for every algorithm). The paper's planners succeed in ~15 % of its maze trials,
    NavRL in < 10 %, the baseline never (Sec. IV-B).

    How: 7 x 10 cells (3.57 x 4 m; corridors >= 3.37 m between 0.2 m walls, 2.5 m tall,
    above the 2 m ceiling) are drawn by recursive division, the maze of the original
    planners' map generator (mockamap): each chamber is cut across its longer side (in
    cells; a tie is a coin toss) by a wall with one door, down to corridors one cell wide
    (a perfect maze). Then 6 interior walls chosen at random are removed (loops: more than
    one way round, as in a real building), and the start cell (the middle of the first
    row) is opened to the north, towards the goal (the middle of the last row). A layout
    is kept only if

    * a wall crosses the straight start->goal line;
    * its shortest route (through cell centres; the fewest turns among the shortest) is
      at most 1.8 x the straight line (64.8 m), turns at most 12 times, and flying it at
      4 m/s with 3 m/s^2, stopping at every turn, takes at most 45 s: half the 90 s
      budget, so a vehicle that knew the way would have time to spare;
    * its difficulty is this configuration's: a goal-greedy explorer (depth first; at
      each cell it enters the open neighbour nearest to the goal, backs out of dead ends,
      and is unlucky at ties) wastes no step in configuration 1 and 34-36 in configuration
      10, the bands rising linearly in between (2-4, 6-8, ...). What it wastes are dead
      ends that face the goal, where a local planner has to turn back and replan.

    Otherwise the layout is redrawn from the same stream (``draws`` in the layout). The
    route, its length, turns, legs heading away from the goal and stop-and-go time, the
    explorer's waste, the dead ends and the loops are recorded in the provenance.
    """
    width, length = p["size_m"]
    alt = start_altitude(p["ceiling_m"])
    (nx, ny), thick, height = p["cells"], p["wall_thickness_m"], p["wall_height_m"]
    cw, ch = width / nx, length / ny
    mid = nx // 2
    start, goal = (mid, 0), (mid, ny - 1)
    straight = (ny - 1) * ch
    band = _detour_band(p["detour_cells"], index)
    draws = 0
    while True:
        draws += 1
        if draws > MAZE_ATTEMPTS:
            raise ScenarioError(f"maze #{index}: no layout within the route bounds and the "
                                f"detour band {band} in {MAZE_ATTEMPTS} draws; loosen "
                                "route_factor_max, route_turns_max, route_time_max_s or "
                                "detour_cells")
        east, north = _divide(rng, nx, ny)
        _open_walls(rng, east, north, p["extra_passages"])
        north[mid, 0] = True  # the start cell opens towards the goal
        if north[mid, :-1].all():  # the middle column is a straight corridor
            continue
        route = _maze_route(east, north, start, goal, cw, ch)
        legs = _legs(route, cw, ch)
        route_m = sum(leg for leg, _ in legs)
        route_s = sum(_stop_and_go_s(leg, p["route_speed_m_s"], p["route_acc_m_s2"])
                      for leg, _ in legs)
        if route_m > p["route_factor_max"] * straight + 1e-9 or \
                len(legs) - 1 > p["route_turns_max"] or route_s > p["route_time_max_s"]:
            continue
        detour = _greedy_detour(east, north, start, goal, cw, ch)
        if band[0] <= detour <= band[1]:
            break
    b = _MeshBuilder()
    runs = _maze_walls(b, east, north, cw, ch, thick, height)
    degree = _maze_degree(east, north)
    passages = int(east.sum() + north.sum())
    return _make(
        fam, index, seed, b, p, altitude=alt, obstacle_count=runs,
        start_xy=((mid + 0.5) * cw, 0.5 * ch), goal_xy=((mid + 0.5) * cw, (ny - 0.5) * ch),
        derived={"cell_m": [cw, ch], "corridor_width_m": min(cw, ch) - thick,
                 "detour_band_cells": list(band), "start_altitude_m": alt},
        layout={"dead_ends": int((degree == 1).sum()),
                "loops": passages - (nx * ny - 1),
                "route_cells": [list(c) for c in route],
                "route_length_m": route_m,
                "straight_m": straight,
                "route_turns": len(legs) - 1,
                "route_legs_away": sum(1 for _, d in legs if d == (0, -1)),
                "route_stop_and_go_s": route_s,
                "greedy_detour_cells": detour,
                "draws": draws,
                "east_passages": east[:-1, :].astype(int).tolist(),
                "north_passages": north[:, :-1].astype(int).tolist()},
    )


def _detour_band(lo_hi, index: int) -> tuple[int, int]:
    """Configuration ``index``'s band of a greedy explorer's wasted steps: the target
    rises linearly from lo (index 1) to hi (index 10), rounded to an even number (a
    dead-end cell costs two steps, in and out), and the band is [target - 2, target]."""
    lo, hi = lo_hi
    first, last = INDEX_RANGE
    target = int(2 * round((lo + (hi - lo) * (index - first) / (last - first)) / 2))
    if index == first:
        return target, target
    return max(int(lo), target - 2), target


def _divide(rng, nx, ny):
    """Perfect maze by recursive division (east / north as in :func:`_carve`): a chamber
    two or more cells wide and long is cut across its longer side (in cells; a tie is a
    coin toss) at a random line, with one door at a random cell of the cut."""
    east = np.zeros((nx, ny), dtype=bool)
    north = np.zeros((nx, ny), dtype=bool)
    east[:-1, :] = True
    north[:, :-1] = True
    chambers = [(0, 0, nx, ny)]
    while chambers:
        x0, y0, x1, y1 = chambers.pop()
        w, h = x1 - x0, y1 - y0
        if w < 2 or h < 2:
            continue
        if h > w or (h == w and rng.random() < 0.5):  # a wall along x above row y
            y = int(rng.integers(y0, y1 - 1))
            door = int(rng.integers(x0, x1))
            north[x0:x1, y] = False
            north[door, y] = True
            chambers += [(x0, y0, x1, y + 1), (x0, y + 1, x1, y1)]
        else:  # a wall along y east of column x
            x = int(rng.integers(x0, x1 - 1))
            door = int(rng.integers(y0, y1))
            east[x, y0:y1] = False
            east[x, door] = True
            chambers += [(x0, y0, x + 1, y1), (x + 1, y0, x1, y1)]
    return east, north


def _open_walls(rng, east, north, count: int) -> None:
    """Remove ``count`` interior walls chosen at random (each closes a loop)."""
    nx, ny = east.shape
    walls = [(east, i, j) for i in range(nx - 1) for j in range(ny) if not east[i, j]] + \
            [(north, i, j) for i in range(nx) for j in range(ny - 1) if not north[i, j]]
    if count > len(walls):
        raise ScenarioError(f"maze: extra_passages {count} but only {len(walls)} interior "
                            "walls to remove")
    for k in rng.choice(len(walls), count, replace=False):
        grid, i, j = walls[int(k)]
        grid[i, j] = True


def _maze_neighbours(east, north, cell):
    """The cells that ``cell`` opens into (east, west, north, south)."""
    i, j = cell
    nx, ny = east.shape
    if i + 1 < nx and east[i, j]:
        yield (i + 1, j)
    if i > 0 and east[i - 1, j]:
        yield (i - 1, j)
    if j + 1 < ny and north[i, j]:
        yield (i, j + 1)
    if j > 0 and north[i, j - 1]:
        yield (i, j - 1)


def _maze_route(east, north, start, goal, cw: float, ch: float) -> list[tuple[int, int]]:
    """The shortest route in metres between cell centres (fewest turns among equals;
    Dijkstra over cell and heading)."""
    best = {}
    queue = [(0.0, 0, start, (0, 0), (start,))]
    while queue:
        metres, turns, cell, heading, path = heapq.heappop(queue)
        if cell == goal:
            return list(path)
        if best.get((cell, heading), (math.inf, 0)) <= (metres, turns):
            continue
        best[(cell, heading)] = (metres, turns)
        for nb in _maze_neighbours(east, north, cell):
            step = (nb[0] - cell[0], nb[1] - cell[1])
            turn = int(heading != (0, 0) and step != heading)
            heapq.heappush(queue, (metres + (cw if step[0] else ch), turns + turn, nb, step,
                                   path + (nb,)))
    raise RuntimeError("maze: the goal cell is not connected to the start cell")


def _legs(route, cw: float, ch: float) -> list[tuple[float, tuple[int, int]]]:
    """The route's straight legs: (length in metres, direction (di, dj))."""
    legs: list[list] = []
    for a, b in zip(route[:-1], route[1:]):
        step = (b[0] - a[0], b[1] - a[1])
        if legs and legs[-1][1] == step:
            legs[-1][0] += cw if step[0] else ch
        else:
            legs.append([cw if step[0] else ch, step])
    return [(float(m), d) for m, d in legs]


def _stop_and_go_s(leg_m: float, speed: float, acc: float) -> float:
    """Time to fly ``leg_m`` from rest to rest at most at ``speed`` with ``acc``."""
    if leg_m >= speed * speed / acc:
        return leg_m / speed + speed / acc
    return 2.0 * math.sqrt(leg_m / acc)


def _greedy_detour(east, north, start, goal, cw: float, ch: float) -> int:
    """Steps a depth-first explorer wastes before it reaches the goal (its walk minus its
    final path): at each cell it enters the unvisited open neighbour nearest to the goal
    and backs out of a cell with none left. An unlucky one: of two neighbours equally near
    (either side of the straight line) it may take either, and the worse of the two tie
    orders (west first, east first) counts."""
    def dist(c):
        return math.hypot((c[0] - goal[0]) * cw, (c[1] - goal[1]) * ch)

    def walk(side: int) -> int:
        seen, stack, steps = {start}, [start], 0
        while stack[-1] != goal:
            options = [n for n in _maze_neighbours(east, north, stack[-1]) if n not in seen]
            if options:
                nxt = min(options, key=lambda c: (dist(c), side * c[0], c[1]))
                seen.add(nxt)
                stack.append(nxt)
            else:
                stack.pop()
            steps += 1
        return steps - (len(stack) - 1)

    return max(walk(1), walk(-1))


def _maze_degree(east, north) -> np.ndarray:
    """How many passages each cell has (1: a dead end)."""
    degree = np.zeros(east.shape, dtype=int)
    degree[:-1, :] += east[:-1, :]
    degree[1:, :] += east[:-1, :]
    degree[:, :-1] += north[:, :-1]
    degree[:, 1:] += north[:, :-1]
    return degree


def _maze_walls(b: _MeshBuilder, east, north, cw: float, ch: float, thick: float,
                height: float) -> int:
    """Box walls on the cell grid's lines wherever there is no passage (collinear wall
    segments merged into one box; the outer walls closed); returns the number of boxes."""
    nx, ny = east.shape
    t2 = thick / 2
    runs = 0
    for i in range(nx + 1):  # vertical lines x = i * cw
        closed = np.ones(ny, dtype=bool) if i in (0, nx) else ~east[i - 1, :]
        for j0, j1 in _runs(closed):
            b.box((i * cw - t2, j0 * ch - t2, 0.0), (i * cw + t2, j1 * ch + t2, height),
                  "wall")
            runs += 1
    for j in range(ny + 1):  # horizontal lines y = j * ch
        closed = np.ones(nx, dtype=bool) if j in (0, ny) else ~north[:, j - 1]
        for i0, i1 in _runs(closed):
            b.box((i0 * cw - t2, j * ch - t2, 0.0), (i1 * cw + t2, j * ch + t2, height),
                  "wall")
            runs += 1
    return runs


def _carve(rng, nx, ny, start):
    """Perfect maze: east[i, j] / north[i, j] say cell (i, j) opens east / north."""
    east = np.zeros((nx, ny), dtype=bool)
    north = np.zeros((nx, ny), dtype=bool)
    seen = np.zeros((nx, ny), dtype=bool)
    seen[start] = True
    stack = [start]
    while stack:
        i, j = stack[-1]
        options = [(di, dj) for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))
                   if 0 <= i + di < nx and 0 <= j + dj < ny and not seen[i + di, j + dj]]
        if not options:
            stack.pop()
            continue
        di, dj = options[int(rng.integers(len(options)))]
        if di:
            east[min(i, i + di), j] = True
        else:
            north[i, min(j, j + dj)] = True
        seen[i + di, j + dj] = True
        stack.append((i + di, j + dj))
    return east, north


def _runs(mask):
    """(start, end) of each run of True in a 1-D mask, end exclusive."""
    out, start = [], None
    for k, v in enumerate(list(mask) + [False]):
        if v and start is None:
            start = k
        elif not v and start is not None:
            out.append((start, k))
            start = None
    return out


# Perlin ------------------------------------------------------------------------------

_GRAD = np.array([[1, 1, 0], [-1, 1, 0], [1, -1, 0], [-1, -1, 0], [1, 0, 1], [-1, 0, 1],
                  [1, 0, -1], [-1, 0, -1], [0, 1, 1], [0, -1, 1], [0, 1, -1], [0, -1, -1],
                  [1, 1, 0], [0, -1, 1], [-1, 1, 0], [0, -1, -1]], dtype=float)
#: the gradients' components, gathered one at a time (a gather of (n, 3) rows was 2 s of
#: a 0.1 m field's 3 s)
_GRAD_X, _GRAD_Y, _GRAD_Z = (np.ascontiguousarray(_GRAD[:, c]) for c in range(3))


def perlin3(x, y, z, perm: np.ndarray) -> np.ndarray:
    """Improved Perlin gradient noise (Perlin 2002) at points (arrays), about in [-1, 1].

    ``perm`` is a permutation of 0..255 (draw it from a seeded Generator).
    """
    p = np.concatenate([perm, perm]).astype(np.int64)
    x, y, z = (np.asarray(v, dtype=float) for v in (x, y, z))
    fx, fy, fz = np.floor(x), np.floor(y), np.floor(z)
    xi, yi, zi = (f.astype(np.int64) & 255 for f in (fx, fy, fz))
    x, y, z = x - fx, y - fy, z - fz

    def fade(t):
        return t * t * t * (t * (t * 6 - 15) + 10)

    u, v, w = fade(x), fade(y), fade(z)
    a = p[xi] + yi
    aa, ab = p[a] + zi, p[a + 1] + zi
    b = p[xi + 1] + yi
    ba, bb = p[b] + zi, p[b + 1] + zi

    def grad(h, dx, dy, dz):
        k = h & 15
        return _GRAD_X[k] * dx + _GRAD_Y[k] * dy + _GRAD_Z[k] * dz

    def lerp(t, a0, a1):
        return a0 + t * (a1 - a0)

    x1, y1, z1 = x - 1, y - 1, z - 1
    return lerp(w,
                lerp(v, lerp(u, grad(p[aa], x, y, z), grad(p[ba], x1, y, z)),
                     lerp(u, grad(p[ab], x, y1, z), grad(p[bb], x1, y1, z))),
                lerp(v, lerp(u, grad(p[aa + 1], x, y, z1), grad(p[ba + 1], x1, y, z1)),
                     lerp(u, grad(p[ab + 1], x, y1, z1), grad(p[bb + 1], x1, y1, z1))))


def fbm3(x, y, z, perm, frequency: float, octaves: int = 4, lacunarity: float = 2.0,
         gain: float = 0.5) -> np.ndarray:
    """Fractal sum of :func:`perlin3` octaves; ``frequency`` in cycles per metre."""
    total = np.zeros(np.broadcast(x, y, z).shape)
    f, amp = frequency, 1.0
    for _ in range(octaves):
        total += amp * perlin3(x * f, y * f, z * f, perm)
        f *= lacunarity
        amp *= gain
    return total


@_family("perlin", "Random Perlin-Noise", "theoretical", Schema((
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
def perlin(fam: Family, p: dict, rng: np.random.Generator, index: int, seed: int) -> Scenario:
    """Random Perlin-Noise (version 1): 40 x 50 m, ceiling 4 m, noise frequency 0.05 per
    0.25 m voxel, fill rate 0.03.

    The flight volume is cut into 0.25 m voxels (160 x 200 x 16). Perlin noise is sampled
    at their centres with the paper's frequency 0.05 taken per voxel -- voxel generators
    multiply integer voxel indices by it -- i.e. 0.2 cycles/m (features ~5 m across), plus
    a second octave (lacunarity 2, gain 0.5) for irregular edges; the permutation and the
    offset are random. The filling and the line rule are :func:`_perlin_fill`'s. Filled
    voxels are merged into one box per run in each voxel column.
    """
    voxel = p["voxel_m"]
    frequency = p["noise_frequency_per_voxel"] / voxel  # cycles per metre

    def noise(x, y, z, perm):
        return fbm3(x, y, z, perm, frequency, p["octaves"], p["lacunarity"], p["gain"])

    filled, shape, offset, shift, alt = _perlin_fill(p, rng, index, noise)
    i0, j0, k0, k1 = _column_runs(filled)
    b = _MeshBuilder()
    b.boxes(np.column_stack([i0, j0, k0]) * voxel, np.column_stack([i0 + 1, j0 + 1, k1]) * voxel,
            "noise column")

    _, blobs = label(filled)
    return _make(
        fam, index, seed, b, p, altitude=alt, obstacle_count=blobs,
        derived={"noise_frequency_per_m": frequency, "start_altitude_m": alt},
        layout={"voxels": list(shape), "filled_voxels": int(filled.sum()),
                "noise_offset_m": offset, "x_shift_voxels": shift, "blobs": blobs},
    )


#: the most cells a Perlin field may have (the paper's area at 0.1 m: 8 M; each cell costs
#: ~100 bytes while the field is built)
PERLIN_MAX_CELLS = 40_000_000


def _perlin_fill(p: dict, rng: np.random.Generator, index: int, noise):
    """The filled voxels of a Perlin field (both versions): ``noise(x, y, z, perm)`` (x, y,
    z in metres, broadcast) sampled at the voxel centres plus a random offset (the
    permutation, then the offset, are the first draws of ``rng``); exactly ``fill_rate``
    of the voxels -- those with the highest values, outside ``clear_radius_m`` of the
    takeoff column and the goal -- are filled. If that leaves the start->goal line clear,
    the noise is shifted along x (whole voxels) until a filled 2 x 2 voxel block surrounds
    the line. Returns (filled (nx, ny, nz) bool, shape, offset, x shift in voxels, start
    altitude)."""
    width, length = p["size_m"]
    ceiling = p["ceiling_m"]
    alt = start_altitude(ceiling)
    voxel, fill_rate = p["voxel_m"], p["fill_rate"]
    shape = (int(width / voxel), int(length / voxel), int(ceiling / voxel))
    cells = shape[0] * shape[1] * shape[2]
    if cells > PERLIN_MAX_CELLS:
        raise ScenarioError(
            f"perlin #{index}: {width:g} x {length:g} x {ceiling:g} m in {voxel:g} m cells "
            f"is {cells:,} cells, more than {PERLIN_MAX_CELLS:,} (the field needs ~100 "
            f"bytes per cell): raise voxel_m or shrink size_m / ceiling_m")
    perm = rng.permutation(256)
    offset = rng.uniform(0.0, 1000.0, 3)
    n_fill = round(fill_rate * cells)
    cx = (np.arange(shape[0]) + 0.5) * voxel
    cy = (np.arange(shape[1]) + 0.5) * voxel
    cz = (np.arange(shape[2]) + 0.5) * voxel
    line_x = width / 2.0
    sy, gy = START_MARGIN_M, length - START_MARGIN_M
    clear = p["clear_radius_m"]
    near = ((np.hypot(cx[:, None] - line_x, cy[None, :] - sy) < clear)
            | (np.hypot(cx[:, None] - line_x, cy[None, :] - gy) < clear))
    # voxels around the line: columns either side of x = 20, layers either side of z = alt
    ix = [int(line_x / voxel) - 1, int(line_x / voxel)]
    iz = [int(alt / voxel) - 1, int(alt / voxel)]
    route = (cy > sy) & (cy < gy)

    def fill(shift):
        val = noise((cx[:, None, None] + offset[0] + shift * voxel),
                    (cy[None, :, None] + offset[1]), (cz[None, None, :] + offset[2]), perm)
        val = np.where(near[:, :, None], -np.inf, val)
        return val, _largest(val.ravel(), n_fill).reshape(shape)

    def blocks_line(filled):
        sub = filled[np.ix_(ix, np.flatnonzero(route), iz)]
        return bool(sub.all(axis=(0, 2)).any())

    val, filled = fill(0)
    shift = 0
    if not blocks_line(filled):
        # move the strongest filled voxels (blob cores) onto the line, one by one
        cand = np.argsort(-np.where(filled, val, -np.inf).ravel(), kind="stable")[:200]
        for flat in cand:
            i, j, _ = np.unravel_index(flat, shape)
            if not route[j]:
                continue
            s = int(i) - ix[1]
            val2, filled2 = fill(s)
            if blocks_line(filled2):
                shift, filled = s, filled2
                break
        else:
            raise RuntimeError(f"perlin #{index}: could not put an obstacle on the line")
    return filled, shape, offset, shift, alt


def _largest(values: np.ndarray, n: int) -> np.ndarray:
    """Mask of the ``n`` largest of ``values`` (1-D), ties at the threshold going to the
    lowest indices: the first ``n`` of a stable sort by decreasing value, found by a
    partition (a sort of a 0.1 m field's 8 M cells took 1 s)."""
    mask = np.zeros(values.size, dtype=bool)
    if n <= 0:
        return mask
    if n >= values.size:
        mask[:] = True
        return mask
    threshold = np.partition(values, values.size - n)[values.size - n]
    mask = values > threshold
    mask[np.flatnonzero(values == threshold)[:n - int(mask.sum())]] = True
    return mask


def _column_runs(filled: np.ndarray):
    """The runs of filled voxels in each voxel column (along z): index arrays i, j, k0, k1
    (k1 exclusive), in C order (column by column, bottom up)."""
    pad = np.zeros(filled.shape[:2] + (1,), dtype=np.int8)
    step = np.diff(np.concatenate([pad, filled.astype(np.int8), pad], axis=2), axis=2)
    i0, j0, k0 = np.nonzero(step == 1)
    k1 = np.nonzero(step == -1)[2]
    return i0, j0, k0, k1


def _join_consecutive(keys: tuple[np.ndarray, ...], pos: np.ndarray):
    """Group items whose ``keys`` are all equal and whose ``pos`` values are consecutive
    integers: (order, first, last) -- ``order`` sorts the items by keys then pos, and
    group g is ``order[first[g]:last[g] + 1]``."""
    order = np.lexsort((pos,) + tuple(reversed(keys)))
    p = pos[order]
    joins = np.ones(len(p), dtype=bool)
    joins[:1] = False
    for k in keys:
        ks = k[order]
        joins[1:] &= ks[1:] == ks[:-1]
    joins[1:] &= p[1:] == p[:-1] + 1
    first = np.flatnonzero(~joins)
    last = np.append(first[1:] - 1, len(p) - 1)
    return order, first, last


def voxel_boxes(filled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Filled voxels (a 3-D bool array) as disjoint axis-aligned boxes of voxel indices,
    (lo, hi) arrays (n, 3), hi exclusive, that together cover exactly the filled voxels:
    the runs of each voxel column, joined along x where neighbouring columns have a run
    over the same z range, then along y where neighbouring slabs match. Deterministic;
    about 0.64 x the column runs of a Perlin version-2 field (docs/scenarios.md)."""
    i, j, k0, k1 = _column_runs(filled)
    if not len(i):
        return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 3), dtype=np.int64)
    order, first, last = _join_consecutive((j, k0, k1), i)
    i0, i1 = i[order][first], i[order][last] + 1
    j, k0, k1 = j[order][first], k0[order][first], k1[order][first]
    order, first, last = _join_consecutive((i0, i1, k0, k1), j)
    lo = np.column_stack([i0[order][first], j[order][first], k0[order][first]])
    hi = np.column_stack([i1[order][first], j[order][last] + 1, k1[order][first]])
    return lo, hi


def mockamap_noise(x, y, z, perm, complexity_per_m: float, fractal: int,
                   attenuation: float) -> np.ndarray:
    """The noise of mockamap's Perlin map (HKUST-Aerial-Robotics/mockamap, src/maps.cpp):
    the sum over octaves it = 1..``fractal`` of (attenuation / it) x Perlin noise at
    2^it x complexity -- with ``complexity_per_m`` its complexity per cell over the cell
    edge -- at the point (x, y, z in metres)."""
    total = np.zeros(np.broadcast(x, y, z).shape)
    for it in range(1, fractal + 1):
        f = 2 ** it * complexity_per_m
        total += (attenuation / it) * perlin3(x * f, y * f, z * f, perm)
    return total


@_revise("perlin", 2, "mockamap's convention, the generator the planners' authors fly "
         "(EGO-Planner's simulator launch: 0.1 m cells, complexity 0.05, one octave): the "
         "paper's frequency 0.05 is mockamap's complexity, sampled at 2 x 0.05 per 0.1 m "
         "cell = 1.0 cycles/m, top 3 % filled: ~2,000 blobs, 9-15 across the line. "
         "Version 1 read 0.05 per 0.25 m voxel (0.2 cycles/m: 37-58 blobs, 1-2 on the "
         "line), a choice of ours that decided Perlin's results (issue 20; "
         "docs/results/perlin-v2-study)", schema=Schema((
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
def perlin_v2(fam: Family, p: dict, rng: np.random.Generator, index: int,
              seed: int) -> Scenario:
    """Random Perlin-Noise (version 2): 40 x 50 m, ceiling 4 m, mockamap's reading of
    frequency 0.05 and fill rate 0.03.

    The flight volume is cut into 0.1 m cells (400 x 500 x 40, mockamap's resolution in
    EGO-Planner's own simulator launch). mockamap samples Perlin noise at 2 x complexity
    per cell index for its one octave; with the paper's 0.05 as complexity that is 1.0
    cycles/m. The permutation and offset are random; filling and the line rule are
    :func:`_perlin_fill`'s (3 % of the cells, those of highest noise, outside 3 m of the
    takeoff column and the goal; an obstacle across the line). Filled cells are merged into
    disjoint boxes (:func:`voxel_boxes`).
    """
    voxel = p["voxel_m"]
    per_m = p["complexity"] / voxel

    def noise(x, y, z, perm):
        return mockamap_noise(x, y, z, perm, per_m, p["fractal"], p["attenuation"])

    filled, shape, offset, shift, alt = _perlin_fill(p, rng, index, noise)
    lo, hi = voxel_boxes(filled)
    b = _MeshBuilder()
    b.boxes(lo * voxel, hi * voxel, "noise blob")
    _, blobs = label(filled)
    return _make(
        fam, index, seed, b, p, altitude=alt, obstacle_count=blobs,
        derived={"noise_frequency_per_m": 2.0 * per_m, "start_altitude_m": alt},
        layout={"voxels": list(shape), "filled_voxels": int(filled.sum()),
                "noise_offset_m": offset, "x_shift_voxels": shift, "blobs": blobs,
                "boxes": len(lo)},
    )


# --------------------------------------------------------------------------------------
# registry
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
    """Configuration ``index`` (1..10) of ``family`` for ``seed`` (see the module docs);
    ``params`` change the generator's parameters (:func:`describe_family`); ``version``
    builds with an older generator of the family (None: the newest)."""
    key = resolve_family(family)
    _check(key, index, seed)
    return REGISTRY[key].build(int(index), int(seed), params, version)
