"""What the family generators share: the common layout's constants and parameters, the
:class:`Family` declaration they receive, the mesh builder and the scenario's assembly
(:func:`make_scenario`). The common layout itself is described in the package docstring
(:mod:`ft_sitl.scenarios.families`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np
import trimesh

from ft_sitl import __version__
from ft_sitl.scenarios.scenario import Scenario, ScenarioError, jsonable
from ft_sitl.schema import Param, Schema, SchemaError

START_MARGIN_M = 3.0
"""Takeoff and goal lie this far inside the area's short sides."""
CLEAR_RADIUS_M = 3.0
"""Random obstacles keep this horizontal distance from the takeoff/start column and goal."""
CYLINDER_SECTIONS = 16
"""Sides of the prisms that stand for cylinders (circumscribed: they contain the circle)."""
#: in the open classic families (Forest, Urban) the obstacle "on the line" may stand up to
#: this far beside it (m): a vehicle flying the line straight hits it unless its collision
#: radius is smaller than the gap (see the package docstring)
LINE_CORRIDOR_M = 0.6
OPEN_FAMILIES = ("forest", "urban")
"""The open classic families: an obstacle within LINE_CORRIDOR_M of the line suffices."""

#: the package whose module ``<family name>`` a scenario's provenance names as its generator
GENERATOR_PACKAGE = __name__.rpartition(".")[0]


def start_altitude(ceiling: float) -> float:
    """The start (and goal) altitude of every family but Sudden-Drop: min(2 m, ceiling/2)."""
    return min(2.0, ceiling / 2.0)


# --------------------------------------------------------------------------------------
# parameters every family declares
# --------------------------------------------------------------------------------------

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
# the declaration a generator receives
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Family:
    """One scenario family: its registry key, the paper's name, its category, the
    generator's parameters (defaults, units, ranges, docs) and ``build(index, seed=0,
    params=None, version=None) -> Scenario``; ``aliases`` are further names
    :func:`~ft_sitl.scenarios.families.resolve_family` accepts.

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


class MeshBuilder:
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
# the scenario
# --------------------------------------------------------------------------------------


def make_scenario(fam: Family, index: int, seed: int, builder: MeshBuilder, params: dict, *,
                  derived: dict, layout: dict, obstacle_count: int, altitude: float,
                  start_xy=None, goal_xy=None, pitch=None,
                  corridor: float = 0.0) -> Scenario:
    """The scenario: the area and ceiling from ``params`` (``size_m``, ``ceiling_m``), its
    provenance from the family's declaration (every parameter, ``derived`` values
    included, in declaration order)."""
    width, length = params["size_m"][:2]
    ceiling = params["ceiling_m"]
    sx, sy = start_xy if start_xy is not None else (width / 2.0, START_MARGIN_M)
    gx, gy = goal_xy if goal_xy is not None else (width / 2.0, length - START_MARGIN_M)
    provenance = {
        "generator": f"{GENERATOR_PACKAGE}.{fam.name}",
        "paper_name": fam.paper_name,
        "seed": int(seed),
        "index": int(index),
        "ft_sitl_version": __version__,
        "parameters": jsonable(fam.schema.record(params, derived)),
        "obstacle_count": int(obstacle_count),
        "mesh_pieces": builder.pieces,
        "layout": jsonable(layout),
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
