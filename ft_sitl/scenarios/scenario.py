"""The Scenario type: one navigation configuration of the FLYINGTRUST benchmark.

World frame ENU (x east, y north, z up), metres, radians. The floor is the plane
``z = bounds_min[2] = 0``; the flight ceiling is ``bounds_max[2]``. ``bounds_min[:2]`` and
``bounds_max[:2]`` are the scenario's area. The mesh holds the obstacles only (no floor,
no ceiling) and may reach above the ceiling (trunks, walls, Sudden-Drop's 14 m blocks).

A scenario is built deterministically from ``(family, index, seed)``: the same three
give byte-identical mesh vertices and faces (see :meth:`Scenario.mesh_digest`).
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np
import trimesh

from ft_sitl.scenarios.solvability import segment_mesh_distance

CATEGORIES = ("classic", "theoretical", "user")
INDEX_RANGE = (1, 10)
GOAL_RADIUS_M = 2.0


class ScenarioError(ValueError):
    """A scenario's fields, or a request for one, are invalid; the message says which."""


def _vec3(name: str, value) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ScenarioError(f"{name}: needs 3 numbers [x, y, z], got {value!r}") from None
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ScenarioError(f"{name}: needs 3 finite numbers [x, y, z], got {value!r}")
    arr.flags.writeable = False
    return arr


def _inside(name: str, p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> None:
    if np.any(p < lo) or np.any(p > hi):
        raise ScenarioError(
            f"{name}: {p.tolist()} lies outside the bounds {lo.tolist()} .. {hi.tolist()}"
        )


def jsonable(v):
    """``v`` with numpy arrays and scalars made plain Python, dict keys made strings."""
    if isinstance(v, dict):
        return {str(k): jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [jsonable(x) for x in v]
    if isinstance(v, np.ndarray):
        return jsonable(v.tolist())
    if isinstance(v, np.generic):
        return v.item()
    return v


@dataclass(frozen=True, eq=False)
class Scenario:
    """One configuration: obstacles, flight volume, takeoff, start pose and goal.

    ``takeoff`` is on the floor; ``start`` is the waypoint above it where the navigation
    run begins, with yaw ``start_yaw`` (ENU, counter-clockwise from east) facing the goal.
    The run succeeds within ``goal_radius_m`` of ``goal``. ``provenance`` records the
    generator, the parameters it used, the seed, the index and the ft_sitl version.
    """

    family: str
    index: int
    seed: int
    category: str
    mesh: trimesh.Trimesh
    bounds_min: np.ndarray
    bounds_max: np.ndarray
    takeoff: np.ndarray
    start: np.ndarray
    start_yaw: float
    goal: np.ndarray
    goal_radius_m: float = GOAL_RADIUS_M
    provenance: dict = field(default_factory=dict)
    #: first face index of each named obstacle piece (ascending) and the pieces' names,
    #: e.g. "tree 7"; empty when the mesh's parts are not named (a user mesh)
    piece_first_face: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    piece_names: tuple = ()
    #: moving obstacles (:class:`~ft_sitl.scenarios.movers.Movers`; None: a static world):
    #: added by :func:`~ft_sitl.scenarios.movers.with_movers`, not by the generators
    movers: object = None

    def __post_init__(self):
        where = f"scenario {self.family!r} #{self.index}"
        if not isinstance(self.family, str) or not self.family:
            raise ScenarioError(f"family: must be a non-empty string, got {self.family!r}")
        if self.category not in CATEGORIES:
            raise ScenarioError(
                f"{where}: category {self.category!r} is not one of {', '.join(CATEGORIES)}"
            )
        for name in ("index", "seed"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)):
                raise ScenarioError(f"{where}: {name} must be an integer, got {v!r}")
            object.__setattr__(self, name, int(v))
        lo_i, hi_i = INDEX_RANGE
        if not lo_i <= self.index <= hi_i:
            raise ScenarioError(f"{where}: index must be {lo_i}..{hi_i}, got {self.index}")
        if self.seed < 0:
            raise ScenarioError(f"{where}: seed must be >= 0, got {self.seed}")
        if not isinstance(self.mesh, trimesh.Trimesh):
            raise ScenarioError(f"{where}: mesh must be a trimesh.Trimesh, got "
                                f"{type(self.mesh).__name__}")
        for name in ("bounds_min", "bounds_max", "takeoff", "start", "goal"):
            object.__setattr__(self, name, _vec3(f"{where}: {name}", getattr(self, name)))
        lo, hi = self.bounds_min, self.bounds_max
        if np.any(hi <= lo):
            raise ScenarioError(f"{where}: bounds_max {hi.tolist()} must exceed bounds_min "
                                f"{lo.tolist()} on every axis")
        if lo[2] != 0.0:
            raise ScenarioError(f"{where}: the floor (bounds_min z) must be 0, got {lo[2]}")
        for name in ("takeoff", "start", "goal"):
            _inside(f"{where}: {name}", getattr(self, name), lo, hi)
        if self.takeoff[2] != lo[2]:
            raise ScenarioError(f"{where}: takeoff must be on the floor (z = {lo[2]}), "
                                f"got z = {self.takeoff[2]}")
        if not math.isfinite(self.start_yaw):
            raise ScenarioError(f"{where}: start_yaw must be a finite angle in radians")
        object.__setattr__(self, "start_yaw", float(self.start_yaw))
        if not (math.isfinite(self.goal_radius_m) and self.goal_radius_m > 0):
            raise ScenarioError(f"{where}: goal_radius_m must be positive, got "
                                f"{self.goal_radius_m!r}")
        object.__setattr__(self, "goal_radius_m", float(self.goal_radius_m))
        if not isinstance(self.provenance, dict):
            raise ScenarioError(f"{where}: provenance must be a dict")
        first = np.asarray(self.piece_first_face, dtype=np.int64).reshape(-1)
        names = tuple(str(n) for n in self.piece_names)
        if len(first) != len(names) or (len(first) and (
                first[0] != 0 or np.any(np.diff(first) <= 0)
                or first[-1] >= len(self.mesh.faces))):
            raise ScenarioError(f"{where}: piece_first_face must start at 0, rise strictly, "
                                f"stay below the face count and match piece_names")
        first.flags.writeable = False
        object.__setattr__(self, "piece_first_face", first)
        object.__setattr__(self, "piece_names", names)

    # ---- derived -----------------------------------------------------------------------

    @property
    def name(self) -> str:
        """``family-NN-sSEED``, e.g. ``forest-03-s0``; a user scenario's own name (movers
        do not change it: they are described by :meth:`summary`)."""
        if self.category == "user":
            return self.family
        return f"{self.family}-{self.index:02d}-s{self.seed}"

    @property
    def floor(self) -> float:
        return float(self.bounds_min[2])

    @property
    def ceiling(self) -> float:
        """The flight ceiling (m); obstacles may reach higher."""
        return float(self.bounds_max[2])

    @property
    def size(self) -> np.ndarray:
        """Extent of the flight volume (m): area width, length, ceiling height."""
        return self.bounds_max - self.bounds_min

    @property
    def obstacle_count(self) -> int:
        return int(self.provenance.get("obstacle_count", 0))

    def obstacle_name(self, face: int) -> str:
        """The name of the obstacle that mesh face ``face`` belongs to ("tree 7",
        "building 3", ...), or "obstacle" when the mesh's parts are not named."""
        if not len(self.piece_names) or not 0 <= face < len(self.mesh.faces):
            return "obstacle"
        k = int(np.searchsorted(self.piece_first_face, face, side="right")) - 1
        return self.piece_names[k]

    def line_distance(self, cutoff: float = np.inf) -> float:
        """Exact distance from the straight start->goal segment to the obstacles
        (``inf`` when farther than ``cutoff``)."""

        return segment_mesh_distance(self.mesh, self.start, self.goal, cutoff)

    def line_blocked(self, radius: float = 0.0) -> bool:
        """Does the straight start->goal segment come within ``radius`` of an obstacle?
        (``radius=0``: does it touch one.) A vehicle of that radius flying it would hit."""
        if not (math.isfinite(radius) and radius >= 0):
            raise ScenarioError(f"radius must be a non-negative number of metres, got {radius!r}")
        return self.line_distance(cutoff=radius) <= radius

    def mesh_digest(self) -> str:
        """SHA-256 of the mesh's vertex (float64) and face (int64) bytes."""
        h = hashlib.sha256()
        h.update(np.ascontiguousarray(self.mesh.vertices, dtype="<f8").tobytes())
        h.update(np.ascontiguousarray(self.mesh.faces, dtype="<i8").tobytes())
        return h.hexdigest()

    def summary(self) -> dict:
        """Everything but the mesh itself, as plain JSON types."""
        ext = self.mesh.bounds if len(self.mesh.faces) else np.zeros((2, 3))
        return jsonable({
            "name": self.name,
            "family": self.family,
            "index": self.index,
            "seed": self.seed,
            "category": self.category,
            "bounds_min": self.bounds_min,
            "bounds_max": self.bounds_max,
            "floor_m": self.floor,
            "ceiling_m": self.ceiling,
            "takeoff": self.takeoff,
            "start": self.start,
            "start_yaw_rad": self.start_yaw,
            "goal": self.goal,
            "goal_radius_m": self.goal_radius_m,
            "obstacle_count": self.obstacle_count,
            **({"movers": self.movers.describe(), "mover_settings": self.movers.settings}
               if self.movers is not None else {}),
            "mesh": {
                "vertices": len(self.mesh.vertices),
                "faces": len(self.mesh.faces),
                "bounds_min": ext[0],
                "bounds_max": ext[1],
                "sha256": self.mesh_digest(),
            },
            "provenance": self.provenance,
        })
