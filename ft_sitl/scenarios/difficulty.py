"""How hard a scenario configuration is, measured on its geometry (issue 20).

Every measure is taken for one vehicle body, the largest catalog platform's
(:func:`ft_sitl.physics.catalog.largest_platform`; protocol 5 flies bodies), held level at
one yaw -- the start yaw, or the first of :func:`~ft_sitl.scenarios.solvability.body_path`'s
other yaws that has a path -- and nothing is tuned to a family: the same definitions apply
to any scenario, a user's mesh included.

Measures
--------
``path_m``, ``path_ratio``
    The length of the shortest collision-free path of the body's centre from the start to
    the goal, and its ratio to the straight start-goal distance. The path comes from the
    solvability grid (26-connected A*) pulled tight among the obstacles grown by the body
    (:func:`~ft_sitl.scenarios.solvability.tauten`); every segment of it is proven clear,
    so it is never shorter than the true shortest path, and it is longer by a little where
    the grid chose the way round an obstacle (docs/scenarios.md, "Difficulty", gives the
    measured tolerance).
``passage_width_m``, ``passage_spare_m``
    The narrowest passage on that path: at each point the chord of the body's free space
    across the nearest obstacle face, the shortest along the path
    (:func:`~ft_sitl.scenarios.solvability.narrowest_passage`). ``spare`` is that chord:
    the room the body has across the passage (a 0.85 m slot less the body's 0.76 m across
    it: 0.09 m). ``width`` adds the body's own width along the chord: the passage's width
    (the slot's 0.85 m), exact between parallel faces. The floor, the ceiling and the sides
    of the area count as faces: under a 1.5 m overhang the passage is 1.5 m tall.
``turns``
    The path simplified (Ramer-Douglas-Peucker, :data:`SIMPLIFY_M` = 0.5 m: bends closer
    together than that, such as the two corners of a slot in a thick wall, merge into one),
    and the vertices of the simplified path where the direction of travel (in 3-D)
    changes by more than :data:`TURN_DEG` = 30 degrees counted.
``obstacle_count``, ``obstacles_per_100m2``, ``mesh_pieces``, ``occupied_fraction``
    The generator's obstacle count (``Scenario.obstacle_count``: trees, buildings and
    walls, walls with a gap, blocks, maze wall runs, Perlin blobs; a user mesh's connected
    parts), the same per 100 m^2 of the area, the closed convex pieces of the mesh, and
    the fraction of the flight volume (area x floor to ceiling) that obstacles fill --
    counted on voxel centres :data:`OCCUPANCY_VOXEL_M` = 0.1 m apart, inside closed convex
    pieces (every generator's obstacles are such pieces; a user mesh's other parts are
    surfaces and fill nothing).
``time_s``, ``flyable``
    The time the path takes at best under the protocol's limits (:class:`FlightBudget`:
    4 m/s, 3 m/s^2, 90 s): :func:`flight_time_s` on the simplified path, and whether it
    is within the budget. ``flyable`` is False when no path was found.

The time model (:func:`flight_time_s`)
--------------------------------------
The vehicle starts from a hover at the start and flies the simplified path, its speed
along the path never above ``speed_m_s``, changed at no more than ``acc_m_s2``. At a
vertex where the direction turns by theta it may go no faster than ``speed_m_s * max(cos
theta, 0)`` -- the part of its velocity that already points along the next segment; a
turn of 90 degrees or more is flown from a stop. It need not stop at the goal. The fastest
speed profile under these rules (a forward and a backward pass over the vertices, then
accelerate - cruise - brake on each segment) gives the time. A full stop costs
``speed / acc`` = 1.33 s more than flying through; a 45-degree turn 0.11 s. The model is
a bound for a vehicle that follows the path exactly; a real flight (a planner's detours,
PX4's jerk limits, the vehicle's own response) takes longer.

Computing and caching
---------------------
:func:`measure_difficulty` takes 0.1-5 s per configuration (a Narrow-Gap or Perlin one:
fine grid, many pieces). :func:`cached_difficulty` keeps each result as a JSON file named
after a SHA-256 of what it depends on: the scenario's content (mesh digest, bounds, start,
goal, start yaw, grid pitch), the platform's body, the budget, and the source of this
module and of the solvability module (an edit of either recomputes everything).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ft_sitl.physics.platform import Platform
from ft_sitl.scenarios import solvability
from ft_sitl.scenarios.solvability import (
    LevelBody,
    body_path,
    convex_pieces,
    grow_pieces,
    narrowest_passage,
    scenario_pitch,
)

#: direction changes above this count as turns (degrees)
TURN_DEG = 30.0
#: the path is simplified with this tolerance (m) before turns are counted and timed
SIMPLIFY_M = 0.5
#: voxel edge for the occupied fraction of the flight volume (m)
OCCUPANCY_VOXEL_M = 0.1
#: spacing of the points along the path where the passage is measured (m)
PASSAGE_STEP_M = 0.05


class DifficultyError(ValueError):
    """A difficulty measure was asked for with invalid input; the message says which."""


@dataclass(frozen=True)
class FlightBudget:
    """The limits a route is timed under: the protocol's top speed (m/s), the acceleration
    planners plan with (m/s^2) and the time limit of the navigation (s). The protocol's own
    values come from :func:`ft_sitl.missions.spec.flight_budget`."""

    speed_m_s: float
    acc_m_s2: float
    time_s: float

    def __post_init__(self):
        for name in ("speed_m_s", "acc_m_s2", "time_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v <= 0:
                raise DifficultyError(f"flight budget: {name} must be a positive number, "
                                      f"got {v!r}")
            object.__setattr__(self, name, float(v))


# --------------------------------------------------------------------------------------
# path measures
# --------------------------------------------------------------------------------------


def simplify(points, tol_m: float = SIMPLIFY_M) -> np.ndarray:
    """Ramer-Douglas-Peucker: the fewest of ``points`` (N, 3), ends kept, such that every
    dropped point lies within ``tol_m`` of the segment that replaces it."""
    pts = np.asarray(points, dtype=float)
    if len(pts) <= 2:
        return pts.copy()
    keep = np.zeros(len(pts), dtype=bool)
    keep[[0, -1]] = True
    stack = [(0, len(pts) - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        a, b = pts[i], pts[j]
        ab = b - a
        den = float(ab @ ab)
        mid = pts[i + 1:j]
        if den == 0.0:
            dist = np.linalg.norm(mid - a, axis=1)
        else:
            t = np.clip((mid - a) @ ab / den, 0.0, 1.0)
            dist = np.linalg.norm(mid - (a + t[:, None] * ab), axis=1)
        k = int(np.argmax(dist))
        if dist[k] > tol_m:
            keep[i + 1 + k] = True
            stack += [(i, i + 1 + k), (i + 1 + k, j)]
    return pts[keep]


def _directions(points) -> tuple[np.ndarray, np.ndarray]:
    pts = np.asarray(points, dtype=float)
    seg = np.diff(pts, axis=0)
    length = np.linalg.norm(seg, axis=1)
    keep = length > 0.0
    return seg[keep] / length[keep, None], length[keep]


def turn_angles_deg(points) -> np.ndarray:
    """The change of direction (degrees, 0-180) at each interior vertex of a polyline."""
    d, _ = _directions(points)
    cos = np.clip(np.einsum("ij,ij->i", d[:-1], d[1:]), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def flight_time_s(points, budget: FlightBudget) -> float:
    """The time to fly the polyline ``points`` from a hover under ``budget`` (the model of
    the module docstring: speed capped at each vertex by the cosine of its turn, changed at
    no more than the acceleration limit)."""
    d, length = _directions(points)
    if not len(length):
        return 0.0
    v_max, acc = budget.speed_m_s, budget.acc_m_s2
    cap = np.full(len(length) + 1, v_max)
    cap[0] = 0.0
    cap[1:-1] = v_max * np.maximum(np.einsum("ij,ij->i", d[:-1], d[1:]), 0.0)
    v = cap.copy()
    for i in range(len(length)):  # forward: what accelerating allows
        v[i + 1] = min(v[i + 1], math.sqrt(v[i] ** 2 + 2.0 * acc * length[i]))
    for i in reversed(range(len(length))):  # backward: what braking allows
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2.0 * acc * length[i]))
    total = 0.0
    for v0, v1, s in zip(v[:-1], v[1:], length):
        peak = min(v_max, math.sqrt(acc * s + 0.5 * (v0 * v0 + v1 * v1)))
        cruise = max(0.0, s - (2.0 * peak * peak - v0 * v0 - v1 * v1) / (2.0 * acc))
        total += (2.0 * peak - v0 - v1) / acc + cruise / peak
    return total


def occupied_fraction(pieces, bounds_min, bounds_max,
                      voxel_m: float = OCCUPANCY_VOXEL_M) -> float:
    """The fraction of the box ``bounds_min .. bounds_max`` inside the convex ``pieces``
    (:func:`~ft_sitl.scenarios.solvability.convex_pieces`), counted on the centres of
    voxels of about ``voxel_m`` (the box is cut into a whole number of them per axis)."""
    lo, hi = np.asarray(bounds_min, dtype=float), np.asarray(bounds_max, dtype=float)
    n = np.maximum(1, np.ceil((hi - lo) / voxel_m - 1e-9).astype(int))
    step = (hi - lo) / n
    centres = [lo[a] + (np.arange(n[a]) + 0.5) * step[a] for a in range(3)]
    filled = np.zeros(n, dtype=bool)
    for piece in pieces:
        i0 = np.maximum(np.ceil((piece.lo - lo) / step - 0.5).astype(int), 0)
        i1 = np.minimum(np.floor((piece.hi - lo) / step - 0.5).astype(int) + 1, n)
        if np.any(i1 <= i0):
            continue
        cx = centres[0][i0[0]:i1[0]][:, None, None]
        cy = centres[1][i0[1]:i1[1]][None, :, None]
        cz = centres[2][i0[2]:i1[2]][None, None, :]
        inside = np.ones(i1 - i0, dtype=bool)
        for nrm, b in zip(piece.normals, piece.offsets):
            inside &= nrm[0] * cx + nrm[1] * cy + nrm[2] * cz <= b
        filled[i0[0]:i1[0], i0[1]:i1[1], i0[2]:i1[2]] |= inside
    return float(filled.mean())


# --------------------------------------------------------------------------------------
# one configuration
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Difficulty:
    """The measures of one scenario configuration (see the module docstring). The path
    measures are None when no path was found (then ``flyable`` is False)."""

    scenario: str
    family: str
    index: int
    seed: int
    platform: str
    body_yaw_deg: float | None
    straight_m: float
    path_m: float | None
    path_ratio: float | None
    turns: int | None
    turn_angles_deg: tuple[float, ...]
    passage_width_m: float | None
    passage_spare_m: float | None
    passage_point: tuple[float, ...] | None
    passage_direction: tuple[float, ...] | None
    obstacle_count: int
    obstacles_per_100m2: float
    mesh_pieces: int
    occupied_fraction: float
    time_s: float | None
    budget: FlightBudget
    flyable: bool
    path: tuple[tuple[float, ...], ...]
    compute_s: float

    def as_dict(self) -> dict:
        """Plain JSON types (tuples become lists)."""
        return json.loads(json.dumps(asdict(self)))

    @classmethod
    def from_dict(cls, d: dict) -> Difficulty:
        def tup(v):
            return None if v is None else tuple(tup(x) if isinstance(x, list) else x for x in v)

        fields = dict(d)
        fields["budget"] = FlightBudget(**d["budget"])
        for key in ("turn_angles_deg", "passage_point", "passage_direction", "path"):
            fields[key] = tup(d[key])
        return cls(**fields)


def _r(x: float, digits: int = 4) -> float:
    return round(float(x), digits)


def measure_difficulty(scenario, platform: Platform, budget: FlightBudget) -> Difficulty:
    """The measures of ``scenario`` for ``platform``'s body under ``budget``."""
    t0 = time.perf_counter()
    if not isinstance(platform, Platform):
        raise DifficultyError(f"platform must be a Platform, got {type(platform).__name__}")
    if not isinstance(budget, FlightBudget):
        raise DifficultyError(f"budget must be a FlightBudget, got {type(budget).__name__}")
    body = platform.body()
    pieces = convex_pieces(scenario.mesh)
    area = float(np.prod(scenario.size[:2]))
    straight = float(np.linalg.norm(scenario.goal - scenario.start))
    common = dict(
        scenario=scenario.name, family=scenario.family, index=scenario.index,
        seed=scenario.seed, platform=platform.name, straight_m=_r(straight),
        obstacle_count=int(scenario.obstacle_count),
        obstacles_per_100m2=_r(100.0 * scenario.obstacle_count / area),
        mesh_pieces=len(pieces),
        occupied_fraction=_r(occupied_fraction(pieces, scenario.bounds_min,
                                               scenario.bounds_max), 5),
        budget=budget,
    )
    found = body_path(scenario, body, shortest=True)
    if found is None:
        return Difficulty(**common, body_yaw_deg=None, path_m=None, path_ratio=None,
                          turns=None, turn_angles_deg=(), passage_width_m=None,
                          passage_spare_m=None, passage_point=None, passage_direction=None,
                          time_s=None, flyable=False, path=(),
                          compute_s=_r(time.perf_counter() - t0, 3))
    path, yaw = found
    grown = grow_pieces(scenario.mesh, scenario.bounds_min, scenario.bounds_max,
                        LevelBody(body, yaw), pieces=pieces)
    passage = narrowest_passage(grown, path, PASSAGE_STEP_M)
    length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
    simple = simplify(path)
    angles = turn_angles_deg(simple)
    flight = flight_time_s(simple, budget)
    return Difficulty(
        **common,
        body_yaw_deg=_r(math.degrees(yaw), 3),
        path_m=_r(length),
        path_ratio=_r(length / straight) if straight > 0 else None,
        turns=int((angles > TURN_DEG).sum()),
        turn_angles_deg=tuple(_r(a, 2) for a in angles),
        passage_width_m=_r(passage.width_m),
        passage_spare_m=_r(passage.spare_m),
        passage_point=tuple(_r(v) for v in passage.point),
        passage_direction=tuple(_r(v) for v in passage.direction),
        time_s=_r(flight, 3),
        flyable=bool(flight <= budget.time_s),
        path=tuple(tuple(float(v) for v in p) for p in path),
        compute_s=_r(time.perf_counter() - t0, 3),
    )


# --------------------------------------------------------------------------------------
# the cache
# --------------------------------------------------------------------------------------


def _source_digest() -> str:
    h = hashlib.sha256()
    for module in (__file__, solvability.__file__):
        h.update(Path(module).read_bytes())
    return h.hexdigest()


def difficulty_key(scenario, platform: Platform, budget: FlightBudget) -> str:
    """SHA-256 of everything a :class:`Difficulty` depends on (module docstring)."""
    content = {
        "source": _source_digest(),
        "mesh": scenario.mesh_digest(),
        "bounds": [scenario.bounds_min.tolist(), scenario.bounds_max.tolist()],
        "start": scenario.start.tolist(),
        "goal": scenario.goal.tolist(),
        "start_yaw": scenario.start_yaw,
        "pitch": scenario_pitch(scenario).tolist(),
        "name": [scenario.name, scenario.family, scenario.index, scenario.seed,
                 scenario.obstacle_count],
        "platform": [platform.name, platform.body().describe()],
        "budget": asdict(budget),
    }
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/ft-sitl/difficulty`` (``~/.cache`` without XDG_CACHE_HOME)."""
    root = os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")
    return Path(root) / "ft-sitl" / "difficulty"


def cached_difficulty(scenario, platform: Platform, budget: FlightBudget,
                      cache_dir: Path | None) -> Difficulty:
    """:func:`measure_difficulty`, kept in ``cache_dir`` (None: not cached). A cache file
    that cannot be read is measured again and rewritten."""
    if cache_dir is None:
        return measure_difficulty(scenario, platform, budget)
    cache_dir = Path(cache_dir)
    path = cache_dir / f"{difficulty_key(scenario, platform, budget)}.json"
    try:
        return Difficulty.from_dict(json.loads(path.read_text()))
    except (OSError, ValueError, TypeError, KeyError):
        pass
    result = measure_difficulty(scenario, platform, budget)
    cache_dir.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=cache_dir, suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(result.as_dict(), fh)
    os.replace(tmp, path)  # atomic: parallel writers leave one whole file
    return result


# --------------------------------------------------------------------------------------
# tables
# --------------------------------------------------------------------------------------


def summarise(results) -> dict:
    """Ranges over several configurations (a family's): how many are flyable, and the
    smallest and largest of each measure among those with a path."""
    results = list(results)
    found = [d for d in results if d.path_m is not None]

    def span(key):
        vals = [getattr(d, key) for d in found]
        return [min(vals), max(vals)] if vals else None

    return {
        "configurations": len(results),
        "with_path": len(found),
        "flyable": sum(d.flyable for d in results),
        **{key: span(key) for key in (
            "path_m", "path_ratio", "turns", "passage_width_m", "passage_spare_m",
            "time_s")},
        "obstacle_count": [min(d.obstacle_count for d in results),
                           max(d.obstacle_count for d in results)] if results else None,
        "occupied_fraction": [min(d.occupied_fraction for d in results),
                              max(d.occupied_fraction for d in results)] if results else None,
    }


MARKDOWN_HEADER = ("| config | path (m) | path / line | turns | narrowest (m) | spare (m) | "
                   "obstacles | per 100 m^2 | filled | time (s) | in budget |\n"
                   "|---|---|---|---|---|---|---|---|---|---|---|")


def num(v, fmt: str) -> str:
    """``v`` formatted, or "-" for a measure that does not exist (no path)."""
    return "-" if v is None else format(v, fmt)


def markdown_row(d: Difficulty) -> str:
    """One configuration as a row of :data:`MARKDOWN_HEADER`'s table."""
    return (f"| {d.scenario} | {num(d.path_m, '.1f')} | {num(d.path_ratio, '.2f')} | "
            f"{num(d.turns, 'd')} | {num(d.passage_width_m, '.2f')} | "
            f"{num(d.passage_spare_m, '.2f')} | {d.obstacle_count} | "
            f"{d.obstacles_per_100m2:.2f} | {100 * d.occupied_fraction:.1f} % | "
            f"{num(d.time_s, '.1f')} | {'yes' if d.flyable else '**no**'} |")


def markdown_table(results) -> str:
    """A Markdown table of configurations, one row each (docs/scenarios.md)."""
    return "\n".join([MARKDOWN_HEADER, *(markdown_row(d) for d in results)])


def markdown_summary(by_family: dict) -> str:
    """A Markdown table of each family's ranges (:func:`summarise`) over its
    configurations: ``by_family`` maps a family name to its :class:`Difficulty` list."""
    def span(pair, fmt, scale=None):
        if pair is None:
            return "-"
        lo, hi = (format(v if scale is None else scale * v, fmt) for v in pair)
        return lo if lo == hi else f"{lo} - {hi}"

    lines = ["| family | in budget | path / line | turns | narrowest (m) | spare (m) | "
             "obstacles | filled (%) | time (s) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for family, results in by_family.items():
        s = summarise(results)
        lines.append(
            f"| {family} | {s['flyable']} / {s['configurations']} | "
            f"{span(s['path_ratio'], '.2f')} | {span(s['turns'], 'd')} | "
            f"{span(s['passage_width_m'], '.2f')} | {span(s['passage_spare_m'], '.2f')} | "
            f"{span(s['obstacle_count'], 'd')} | {span(s['occupied_fraction'], '.1f', 100)} | "
            f"{span(s['time_s'], '.1f')} |")
    return "\n".join(lines)
