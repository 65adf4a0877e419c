"""FlightBench's scenario-difficulty metrics: traversability obstruction (TO), view
occlusion (VO) and angle over length (AOL) (issue 44, point 5).

Where the definitions come from
-------------------------------
Yu, Yu, Gao, Wu and Wang, *FlightBench: Benchmarking Learning-based Methods for
Ego-vision-based Quadrotors Navigation*, arXiv 2406.05687 (2024), Section 3.1 ("task
difficulty metrics"), Eqs. (1)-(3): TO from spherical flight corridors sampled along a
topological guide path (Eq. 1 scores the candidate spheres with four weights), VO from the
obstacles in a cone of view ahead along that path (Eq. 2), AOL from the path's turns per
unit of length (Eq. 3). The paper's text was not available when this was written; every
formula and number below is read from the authors' reference implementation,
``flightbench/script/cal_difficulty.py`` of github.com/thu-uav/FlightBench (commit
af88801), with which the values of the paper's test cases were computed (the repository
README's table: forest-low TO 0.76, VO 0.30, AOL 7.6e-4 ... racing-mid 1.58, 1.13, 0.94).
The line numbers are that file's. The code here is our own.

The guide path
    A polyline from the start to the goal. FlightBench takes the shortest topologically
    distinct path of sb_min_time's roadmap, shortened (README, "Evaluate task difficulty";
    the script reads ``roadmap_shortened_unique_path*.csv``, lines 17-34), planned with
    0.17 m of clearance (``min_clearance`` of every test case in sst.yaml of
    github.com/thu-uav/benchmark_sb_min_time, commit e24c656). Here it is the shortest
    path of a ball of ``guide_clearance_m`` 0.17 m from the project's solvability search
    (:func:`~ft_sitl.scenarios.solvability.scenario_path`: the 26-connected A* path pulled
    tight among the obstacles grown by the ball, which keeps it 0.17 m from the floor,
    the ceiling and the area's sides too), segments of zero length dropped. L is its
    length. It is a path of FlightBench's vehicle, not of a catalog platform: the
    metrics describe the scenario alone.

Traversability obstruction, TO (lines 55-214)
    A corridor of balls ``B_0 .. B_n`` is laid along the guide path. A ball centred at c
    has radius ``r(c) = min(d(c) - r_q, r_s)``: d the distance to the nearest obstacle
    (here also the floor, the ceiling or a side of the area: see below), r_q =
    ``drone_radius_m`` 0.15 m (line 53), r_s = ``sensing_range_m`` 4 m (line 202).
    ``B_0`` sits at the start. From the current ball (p, r) the next is found
    so:

    * the guide point g: a progress counter along the path (kept from ball to ball)
      advances by ``progress_step_m`` 0.3 m (lines 134-151) until the path's point at
      that arc length lies outside the current ball;
    * candidates: g itself and ``corridor_samples`` K = 40 points ``g + e`` (line 157),
      e Gaussian with standard deviations ``(s/4, s/2, s/2)`` along and across the
      direction u from p to g, s = |g - p| (lines 74-83);
    * a candidate c of radius r_c is admissible when r_c > 0 and its ball overlaps the
      current one without either containing the other: ``|r - r_c| <= |c - p| <= r +
      r_c`` (lines 88-99);
    * score (Eq. 1): ``0.7 V(r_c) + 0.1 V_lens - 0.35 a - 0.1 b``, V the ball's volume,
      V_lens the volume the two balls share, a = (c - g) . u and b the rest of c - g's
      length across u (lines 100-107); g itself scores ``0.7 V + 0.1 V_lens - 0.4``
      (line 70). The best admissible candidate is the next ball; when none is, K more are
      drawn (lines 158-159).

    The corridor ends with the first ball that holds the goal (line 162). Of its n + 1
    radii the N = floor((n + 1) / 2) smallest give ``TO = r_s / (2 N) * sum 1 / r_i``
    (lines 205-210), and TO is the least of ``corridor_repeats`` M = 8 corridors drawn
    afresh (lines 203-212). An obstacle-free corridor (every radius r_s) gives TO = 0.5;
    narrower corridors give more.

View occlusion, VO (lines 216-267)
    At every ``view_step_m`` 0.4 m (r_s / 10, line 223) along the guide path, looking
    along the segment there (line 239): the obstacle surface within r_s of the point and
    within the cone of half-angle pi/5 about that direction (line 220), split by the angle
    phi from the direction into four rings -- (pi/6, pi/5], (pi/8, pi/6], (pi/12, pi/8]
    and [0, pi/12] -- weighted 0.05, 0.1, 0.3 and 0.55 (lines 221-263). With d_k the
    distance to the nearest surface point in ring k (no term when there is none),
    ``o = sum w_k r_s / d_k``; VO is the mean of o over the points (line 266). An empty
    view gives 0.

Angle over length, AOL (lines 269-288)
    ``AOL = sum_i (exp(2 theta_i / pi) - 1) / L`` over the guide path's interior vertices,
    theta_i the angle (0..pi) between the segments meeting there. FlightBench weighs the
    junction between the legs to successive gates of a multi-waypoint course by
    ``exp(6 theta / pi) - 1`` (line 284); a FLYINGTRUST configuration has one goal, so
    that term never occurs. A straight path gives 0.

What we chose where the source leaves it open, or could not be followed
    * What bounds a ball. FlightBench reads a point cloud of its Unity scene,
      voxel-filtered at 0.15 m (line 13), and does not say whether the ground is in it.
      Here d is the exact distance (python-fcl through
      :meth:`~ft_sitl.scenarios.collision.CollisionWorld.clearance`) to the scenario's
      mesh, its floor, its ceiling and the sides of its area, all of which end a flight:
      with the mesh alone (which holds the obstacles only) the balls escape through the
      floor, where nothing limits them (forest-01's corridor wandered to z = -4 m). Inside
      a closed obstacle d is negative, so no candidate there is admissible.
    * VO sees the mesh only, as the navigators' depth camera does: the floor, ceiling and
      sides are no obstacles in view.
    * VO's nearest surface point per ring is found by casting rays
      (:meth:`~ft_sitl.scenarios.camera.DepthCamera.cast_fans`, Embree) on a grid of
      ``view_ray_spacing_deg`` 0.5 degrees over the cone: a ring is star-shaped about the
      viewpoint, so its nearest surface point is seen along its own ray, and the least
      first-hit distance over the rays of a ring converges to it (rays 3.5 cm apart at
      4 m). FlightBench's point cloud sees through surfaces, which changes nothing here:
      the nearest point of a ring is always visible.
    * The guide point stops at the goal (FlightBench's counter runs on past the end of the
      path along its last segment, lines 151 and 238); VO's points run from ``view_step_m``
      to L (FlightBench's last point may lie up to one step past the goal).
    * Draws come from a seeded generator (``seed``), so the metrics are deterministic;
      FlightBench draws from numpy's global state.
    * A corridor can get stuck: a small ball in a tight corner with the guide point
      farther from it than any ball near the guide point reaches (FlightBench then draws
      forever, lines 158-159). After :data:`MAX_DRAWS` batches of K the corridor is drawn
      again from the start, at most :data:`MAX_RESTARTS` times (then an error);
      ``corridor_restarts`` counts these. TO is then the least over M corridors that
      reached the goal.
    * N is at least 1 (FlightBench divides by zero when the start ball already holds the
      goal).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ft_sitl.scenarios import camera, collision, solvability
from ft_sitl.scenarios.camera import CameraConfig, DepthCamera
from ft_sitl.scenarios.collision import CollisionWorld
from ft_sitl.scenarios.solvability import scenario_path, scenario_pitch
from ft_sitl.schema import Param, Schema, SchemaError

__all__ = [
    "PARAMS",
    "FlightBenchError",
    "FlightBenchMetrics",
    "angle_over_length",
    "cached_flightbench",
    "corridor",
    "guide_path",
    "scenario_guide_path",
    "measure_flightbench",
    "traversability_obstruction",
    "view_occlusion",
    "markdown_table",
    "markdown_summary",
]

PARAMS = Schema((
    Param("sensing_range_m", 4.0, "m", (0.5, 50.0),
          doc="r_s: the balls' largest radius, TO's scale, VO's range and scale "
              "(cal_difficulty.py lines 58, 202, 219)"),
    Param("drone_radius_m", 0.15, "m", (0.001, 2.0),
          doc="r_q: a ball's radius is the obstacle distance less this (line 53)"),
    Param("corridor_samples", 40, "-", (1, 10_000),
          doc="K: candidates drawn round each guide point (line 157)"),
    Param("corridor_repeats", 8, "-", (1, 1_000),
          doc="M: corridors drawn; TO is the least of theirs (line 203)"),
    Param("progress_step_m", 0.3, "m", (0.01, 10.0),
          doc="how far the guide point advances along the path per try (lines 135-138)"),
    Param("view_step_m", 0.4, "m", (0.01, 10.0),
          doc="spacing of VO's viewpoints along the path: r_s / 10 (line 223)"),
    Param("view_ray_spacing_deg", 0.5, "deg", (0.05, 5.0),
          doc="angular spacing of the rays that find VO's nearest surface points (ours)"),
    Param("guide_clearance_m", 0.17, "m", (0.0, 2.0),
          doc="clearance of the guide path, a ball's shortest path (sb_min_time's "
              "min_clearance in FlightBench's sst.yaml)"),
    Param("seed", 0, "-", (0, 2**63 - 1),
          doc="seed of the corridor draws (ours: FlightBench draws unseeded)"),
))
"""The metrics' parameters (defaults: FlightBench's values, and our ray spacing and
seed)."""

#: Eq. (1)'s weights (cal_difficulty.py lines 70, 106-107): a candidate ball's volume,
#: the volume it shares with the current ball, its offset from the guide point along and
#: across the path's direction, and the guide point's own handicap
K_VOLUME, K_SHARED, K_ALONG, K_ACROSS, K_GUIDE = 0.7, 0.1, 0.35, 0.1, 0.4
#: VO's cone (half-angle pi/5) and its rings' outer edges, outermost first, with their
#: weights (lines 220-263)
VIEW_EDGES_RAD = (math.pi / 5, math.pi / 6, math.pi / 8, math.pi / 12)
VIEW_WEIGHTS = (0.05, 0.1, 0.3, 0.55)
#: AOL's growth of a turn's weight with its angle: exp(AOL_RATE * theta / pi) - 1 (line 278)
AOL_RATE = 2.0
#: batches of K candidates drawn round one guide point before the corridor is drawn again
#: from its start ...
MAX_DRAWS = 50
#: ... at most this many times
MAX_RESTARTS = 50
#: a segment shorter than this (m) is dropped from the guide path
MIN_SEGMENT_M = 1e-9


class FlightBenchError(ValueError):
    """A metric was asked for with invalid input, or could not be computed; the message
    says which."""


# --------------------------------------------------------------------------------------
# the guide path
# --------------------------------------------------------------------------------------


def guide_path(points) -> np.ndarray:
    """``points`` as a guide path: an (N, 3) float array of at least two distinct points,
    consecutive duplicates dropped."""
    try:
        pts = np.array(points, dtype=float)
    except (TypeError, ValueError):
        raise FlightBenchError(f"guide path: needs an (N, 3) array of numbers, got "
                               f"{type(points).__name__}") from None
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) < 2:
        raise FlightBenchError(f"guide path: needs an (N, 3) array with N >= 2, got shape "
                               f"{pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise FlightBenchError("guide path: every coordinate must be finite")
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    keep = np.concatenate([[True], seg > MIN_SEGMENT_M])
    pts = pts[keep]
    if len(pts) < 2:
        raise FlightBenchError("guide path: start and goal coincide (length 0)")
    return pts


class _Polyline:
    """Arc-length look-ups on a guide path."""

    def __init__(self, pts: np.ndarray):
        self.pts = pts
        seg = np.diff(pts, axis=0)
        self.seg_len = np.linalg.norm(seg, axis=1)
        self.dirs = seg / self.seg_len[:, None]
        self.cum = np.concatenate([[0.0], np.cumsum(self.seg_len)])
        self.length = float(self.cum[-1])

    def segment(self, s) -> np.ndarray:
        """Index of the segment holding arc length s (a vertex belongs to the segment that
        leaves it; the goal to the last)."""
        i = np.searchsorted(self.cum, s, side="right") - 1
        return np.clip(i, 0, len(self.seg_len) - 1)

    def point(self, s) -> np.ndarray:
        """The point at arc length s, clamped to the path's ends."""
        s = np.clip(s, 0.0, self.length)
        i = self.segment(s)
        return self.pts[i] + (s - self.cum[i])[..., None] * self.dirs[i]


def _frames(u: np.ndarray) -> np.ndarray:
    """Rotations (V, 3, 3) whose first column is the unit vector u (V, 3): orthonormal
    frames (u, v, w)."""
    u = np.atleast_2d(u)
    helper = np.zeros_like(u)
    helper[np.arange(len(u)), np.argmin(np.abs(u), axis=1)] = 1.0
    v = np.cross(u, helper)
    v /= np.linalg.norm(v, axis=1)[:, None]
    w = np.cross(u, v)
    return np.stack([u, v, w], axis=2)


# --------------------------------------------------------------------------------------
# traversability obstruction
# --------------------------------------------------------------------------------------


def _ball_volume(r):
    return 4.0 / 3.0 * math.pi * r ** 3


def shared_volume(r1: float, r2: float, d: float) -> float:
    """The volume two balls of radii r1, r2 whose centres are d apart have in common."""
    lo, hi = min(r1, r2), max(r1, r2)
    if d >= lo + hi:
        return 0.0
    if d <= hi - lo:
        return _ball_volume(lo)
    return (math.pi * (lo + hi - d) ** 2
            * (d * d + 2.0 * d * (lo + hi) - 3.0 * (hi - lo) ** 2) / (12.0 * d))


class _Stuck(Exception):
    """No admissible ball round a guide point within MAX_DRAWS batches."""


def corridor(clearance, path, params: Mapping, rng: np.random.Generator
             ) -> tuple[np.ndarray, np.ndarray, int]:
    """One corridor of balls along the guide path (module docstring, TO): their centres
    (n + 1, 3) and radii (n + 1,), and how many times it was drawn again from the start
    after getting stuck. ``clearance(points (K, 3)) -> (K,)`` gives each point's distance
    to the nearest obstacle less the drone radius (negative inside one); ``params`` are
    :data:`PARAMS`' values."""
    line = _Polyline(guide_path(path))
    r0 = min(float(np.asarray(clearance(line.pts[:1]), dtype=float)[0]),
             params["sensing_range_m"])
    if not r0 > 0.0:
        raise FlightBenchError(
            f"corridor: the start {line.pts[0].round(3).tolist()} is within the drone "
            f"radius {params['drone_radius_m']} m of an obstacle (ball radius {r0:.3f} m)")
    for restarts in range(MAX_RESTARTS + 1):
        try:
            centres, radii = _draw_corridor(clearance, line, r0, params, rng)
            return centres, radii, restarts
        except _Stuck as exc:
            stuck = exc
    raise FlightBenchError(f"corridor: drawn {MAX_RESTARTS + 1} times, stuck every time "
                           f"(last: {stuck})")


def _draw_corridor(clearance, line: _Polyline, r0: float, params: Mapping,
                   rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    r_s = params["sensing_range_m"]
    k, step = params["corridor_samples"], params["progress_step_m"]
    goal = line.pts[-1]
    p, r = line.pts[0], r0
    centres, rads = [p], [r]
    progress = 0.0
    while np.linalg.norm(goal - p) >= r:
        g = line.point(progress)
        while np.linalg.norm(g - p) < r:  # ends: the goal lies outside the ball
            progress += step
            g = line.point(progress)
        gap = g - p
        s = float(np.linalg.norm(gap))
        frame = _frames(gap / s)[0]
        sigma = np.array([s / 4.0, s / 2.0, s / 2.0])
        for _ in range(MAX_DRAWS):
            cand = np.vstack([g, g + (rng.standard_normal((k, 3)) * sigma) @ frame.T])
            rc = np.minimum(np.asarray(clearance(cand), dtype=float), r_s)
            off = cand - g
            along = off @ frame[:, 0]
            across = np.linalg.norm(off - along[:, None] * frame[:, 0], axis=1)
            dist = np.linalg.norm(cand - p, axis=1)
            ok = (rc > 0.0) & (dist >= np.abs(r - rc)) & (dist <= r + rc) & (dist > 0.0)
            if not ok.any():
                continue
            score = np.full(len(cand), -np.inf)
            for i in np.flatnonzero(ok):
                score[i] = (K_VOLUME * _ball_volume(rc[i])
                            + K_SHARED * shared_volume(r, rc[i], dist[i])
                            - K_ALONG * along[i] - K_ACROSS * across[i])
            score[0] -= K_GUIDE
            best = int(np.argmax(score))  # the first of equal scores
            p, r = cand[best], float(rc[best])
            break
        else:
            raise _Stuck(f"no ball overlapping the one at {p.round(3).tolist()} (radius "
                         f"{r:.3f} m) round {g.round(3).tolist()} in {MAX_DRAWS} draws of {k}")
        centres.append(p)
        rads.append(r)
    return np.array(centres), np.array(rads)


def corridor_obstruction(radii, sensing_range_m: float) -> float:
    """``r_s / (2 N) * sum 1 / r_i`` over the N = floor(n / 2) smallest of a corridor's n
    radii (at least one)."""
    r = np.sort(np.asarray(radii, dtype=float))
    n = max(1, len(r) // 2)
    return float(sensing_range_m / (2.0 * n) * np.sum(1.0 / r[:n]))


def traversability_obstruction(clearance, path, params: Mapping
                               ) -> tuple[float, list[tuple[np.ndarray, np.ndarray]]]:
    """TO: the least :func:`corridor_obstruction` of ``corridor_repeats`` corridors drawn
    from one generator seeded with ``seed``; also returns the corridors."""
    rng = np.random.default_rng(params["seed"])
    corridors = [corridor(clearance, path, params, rng)
                 for _ in range(params["corridor_repeats"])]
    values = [corridor_obstruction(r, params["sensing_range_m"]) for _, r, _ in corridors]
    return min(values), corridors


# --------------------------------------------------------------------------------------
# view occlusion
# --------------------------------------------------------------------------------------


def cone_rays(half_angle_rad: float, spacing_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit rays (N, 3) about +x covering the cone of ``half_angle_rad``: the axis, then
    rings at the middles of equal steps of about ``spacing_rad`` in the angle from the
    axis, each with rays about ``spacing_rad`` apart round it; and each ray's angle from
    the axis (N,)."""
    n_rings = max(1, math.ceil(half_angle_rad / spacing_rad - 1e-9))
    dphi = half_angle_rad / n_rings
    dirs, phis = [np.array([[1.0, 0.0, 0.0]])], [np.zeros(1)]
    for i in range(n_rings):
        phi = (i + 0.5) * dphi
        m = max(3, math.ceil(2.0 * math.pi * math.sin(phi) / dphi))
        az = 2.0 * math.pi * (np.arange(m) + 0.5) / m
        dirs.append(np.column_stack([np.full(m, math.cos(phi)), math.sin(phi) * np.cos(az),
                                     math.sin(phi) * np.sin(az)]))
        phis.append(np.full(m, phi))
    return np.vstack(dirs), np.concatenate(phis)


def view_rings(phi) -> np.ndarray:
    """Ring index (0: outermost .. 3: about the axis) of each angle ``phi`` from the view
    direction, -1 outside the cone (FlightBench's rings: (pi/6, pi/5], (pi/8, pi/6],
    (pi/12, pi/8], [0, pi/12])."""
    phi = np.asarray(phi, dtype=float)
    ring = np.full(phi.shape, -1, dtype=int)
    for k, edge in enumerate(VIEW_EDGES_RAD):
        ring[phi <= edge] = k
    return ring


def view_occlusion(caster, path, params: Mapping, chunk: int = 32
                   ) -> tuple[float, np.ndarray]:
    """VO, and the value at each viewpoint. ``caster`` is a
    :class:`~ft_sitl.scenarios.camera.DepthCamera` on the scenario's mesh, or None for a
    world without obstacles."""
    line = _Polyline(guide_path(path))
    r_s, step = params["sensing_range_m"], params["view_step_m"]
    s = step * np.arange(1, int(math.floor(line.length / step + 1e-9)) + 1)
    if not len(s):  # a path shorter than one step: its end
        s = np.array([line.length])
    if caster is None:
        return 0.0, np.zeros(len(s))
    origins = line.point(s)
    rots = _frames(line.dirs[line.segment(s)])
    rays, phi = cone_rays(VIEW_EDGES_RAD[0], math.radians(params["view_ray_spacing_deg"]))
    ring = view_rings(phi)
    values = np.empty(len(s))
    for a in range(0, len(s), chunk):
        lengths = caster.cast_fans(origins[a:a + chunk], rots[a:a + chunk], rays,
                                   max_range_m=r_s)
        lengths = np.where(lengths <= r_s, lengths, np.inf)
        total = np.zeros(len(lengths))
        for k, w in enumerate(VIEW_WEIGHTS):
            nearest = lengths[:, ring == k].min(axis=1)
            total += np.where(np.isfinite(nearest), w * r_s / nearest, 0.0)
        values[a:a + chunk] = total
    return float(values.mean()), values


# --------------------------------------------------------------------------------------
# angle over length
# --------------------------------------------------------------------------------------


def turn_angles_rad(path) -> np.ndarray:
    """The angle (0..pi) between the segments meeting at each interior vertex."""
    d = _Polyline(guide_path(path)).dirs
    return np.arccos(np.clip(np.einsum("ij,ij->i", d[:-1], d[1:]), -1.0, 1.0))


def angle_over_length(path) -> float:
    """AOL: ``sum (exp(2 theta / pi) - 1) / L`` over the interior vertices (1/m)."""
    line = _Polyline(guide_path(path))
    theta = turn_angles_rad(line.pts)
    return float(np.sum(np.expm1(AOL_RATE * theta / math.pi)) / line.length)


# --------------------------------------------------------------------------------------
# one configuration
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FlightBenchMetrics:
    """TO, VO and AOL of one configuration, with what they came from: the guide path's
    length, each corridor's TO, the balls and the smallest radius of the corridor that
    gave TO, how many times a corridor was drawn again after getting stuck, VO's
    viewpoints and worst one, the turns (vertices with a turn above 1 degree), the
    parameters, the guide path's vertices and the time taken."""

    scenario: str
    to: float
    vo: float
    aol: float
    guide_length_m: float
    to_corridors: tuple[float, ...]
    corridor_balls: int
    corridor_min_radius_m: float
    corridor_restarts: int
    vo_points: int
    vo_max: float
    turns: int
    params: dict
    guide: tuple[tuple[float, ...], ...]
    compute_s: float

    def as_dict(self) -> dict:
        """Plain JSON types."""
        return json.loads(json.dumps(asdict(self)))

    @classmethod
    def from_dict(cls, d: dict) -> FlightBenchMetrics:
        fields = dict(d)
        fields["to_corridors"] = tuple(d["to_corridors"])
        fields["guide"] = tuple(tuple(p) for p in d["guide"])
        return cls(**fields)


def _r(x: float, digits: int = 5) -> float:
    return round(float(x), digits)


def resolve_params(params: Mapping | None) -> dict:
    """The defaults updated with ``params`` (checked: an unknown key or a value out of
    range raises :class:`FlightBenchError` naming it and the allowed range)."""
    try:
        return PARAMS.resolve(params, "flightbench metrics")
    except SchemaError as exc:
        raise FlightBenchError(str(exc)) from None


def scenario_guide_path(scenario, params: Mapping | None = None) -> np.ndarray:
    """The guide path of ``scenario``: the shortest path of a ball of ``guide_clearance_m``
    (module docstring). Raises :class:`FlightBenchError` when the solvability grid finds
    none."""
    values = resolve_params(params)
    path = scenario_path(scenario, values["guide_clearance_m"], shortest=True)
    if path is None:
        raise FlightBenchError(f"{scenario.name}: no path for a ball of "
                               f"{values['guide_clearance_m']} m from start to goal")
    return guide_path(path)


def measure_flightbench(scenario, params: Mapping | None = None, path=None
                        ) -> FlightBenchMetrics:
    """TO, VO and AOL of ``scenario`` with ``params`` (:data:`PARAMS`; None: FlightBench's
    values) along ``path`` (N, 3), by default :func:`scenario_guide_path`."""
    t0 = time.perf_counter()
    values = resolve_params(params)
    pts = scenario_guide_path(scenario, values) if path is None else guide_path(path)
    mesh = scenario.mesh
    has_obstacles = len(mesh.faces) > 0
    world = CollisionWorld(mesh, scenario.bounds_min, scenario.bounds_max)

    r_q = values["drone_radius_m"]

    def clearance(points):  # from the obstacles, the floor, the ceiling and the sides
        return [world.clearance(q, r_q) for q in points]

    to, corridors = traversability_obstruction(clearance, pts, values)
    per_corridor = [corridor_obstruction(r, values["sensing_range_m"])
                    for _, r, _ in corridors]
    best = int(np.argmin(per_corridor))
    caster = (DepthCamera(CameraConfig(width=1, height=1,
                                       max_range_m=values["sensing_range_m"]), mesh)
              if has_obstacles else None)
    vo, per_point = view_occlusion(caster, pts, values)
    theta = turn_angles_rad(pts)
    return FlightBenchMetrics(
        scenario=scenario.name,
        to=_r(to), vo=_r(vo), aol=_r(angle_over_length(pts), 7),
        guide_length_m=_r(_Polyline(pts).length, 4),
        to_corridors=tuple(_r(v) for v in per_corridor),
        corridor_balls=len(corridors[best][1]),
        corridor_min_radius_m=_r(corridors[best][1].min(), 4),
        corridor_restarts=sum(n for *_, n in corridors),
        vo_points=len(per_point), vo_max=_r(per_point.max()),
        turns=int((theta > math.radians(1.0)).sum()),
        params=values,
        guide=tuple(tuple(float(v) for v in q) for q in pts),
        compute_s=_r(time.perf_counter() - t0, 3),
    )


# --------------------------------------------------------------------------------------
# the cache
# --------------------------------------------------------------------------------------


def flightbench_key(scenario, params: Mapping) -> str:
    """SHA-256 of everything :func:`measure_flightbench` (with its own guide path) depends
    on: this module's source and that of the modules it calls (solvability, collision,
    camera), the scenario's content (mesh, bounds, start, goal, grid pitch) and the
    parameters."""
    h = hashlib.sha256()
    for module in (__file__, camera.__file__, collision.__file__, solvability.__file__):
        h.update(Path(module).read_bytes())
    h.update(scenario.mesh_digest().encode())
    h.update(json.dumps([scenario.name, scenario.bounds_min.tolist(),
                         scenario.bounds_max.tolist(), scenario.start.tolist(),
                         scenario.goal.tolist(), scenario_pitch(scenario).tolist(),
                         dict(params)], sort_keys=True).encode())
    return h.hexdigest()


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/ft-sitl/flightbench`` (``~/.cache`` without XDG_CACHE_HOME)."""
    root = os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")
    return Path(root) / "ft-sitl" / "flightbench"


def cached_flightbench(scenario, params: Mapping | None,
                       cache_dir: Path | None) -> FlightBenchMetrics:
    """:func:`measure_flightbench`, kept in ``cache_dir`` (None: not cached). A cache file
    that cannot be read is measured again and rewritten."""
    values = resolve_params(params)
    if cache_dir is None:
        return measure_flightbench(scenario, values)
    cache_dir = Path(cache_dir)
    file = cache_dir / f"{flightbench_key(scenario, values)}.json"
    try:
        return FlightBenchMetrics.from_dict(json.loads(file.read_text()))
    except (OSError, ValueError, TypeError, KeyError):
        pass
    result = measure_flightbench(scenario, values)
    cache_dir.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=cache_dir, suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        json.dump(result.as_dict(), fh)
    os.replace(tmp, file)  # atomic: parallel writers leave one whole file
    return result


# --------------------------------------------------------------------------------------
# tables
# --------------------------------------------------------------------------------------


TABLE_HEADER = ("| config | TO | TO over the corridors | VO | AOL (1/m) | guide (m) | "
                "path / line | turns | spare (m) | filled | time (s) |\n"
                "|---|---|---|---|---|---|---|---|---|---|---|")


def markdown_row(d, m: FlightBenchMetrics) -> str:
    """One configuration: FlightBench's metrics ``m`` beside the project's measures ``d``
    (a :class:`~ft_sitl.scenarios.difficulty.Difficulty`)."""
    def num(v, fmt):
        return "-" if v is None else format(v, fmt)

    return (f"| {d.scenario} | {m.to:.2f} | {min(m.to_corridors):.2f} - "
            f"{max(m.to_corridors):.2f} | {m.vo:.2f} | {m.aol:.4f} | "
            f"{m.guide_length_m:.1f} | {num(d.path_ratio, '.2f')} | {num(d.turns, 'd')} | "
            f"{num(d.passage_spare_m, '.2f')} | {100 * d.occupied_fraction:.1f} % | "
            f"{num(d.time_s, '.1f')} |")


def markdown_table(pairs) -> str:
    """A Markdown table of configurations: ``pairs`` of (Difficulty, FlightBenchMetrics)."""
    return "\n".join([TABLE_HEADER, *(markdown_row(d, m) for d, m in pairs)])


def markdown_summary(by_family: dict) -> str:
    """Each family's median and range of TO, VO and AOL: ``by_family`` maps a family to
    its :class:`FlightBenchMetrics` list."""
    lines = ["| family | TO median (range) | VO median (range) | AOL median (range), 1/m |",
             "|---|---|---|---|"]
    for family, found in by_family.items():
        cells = []
        for key, fmt in (("to", ".2f"), ("vo", ".2f"), ("aol", ".4f")):
            v = np.array([getattr(m, key) for m in found])
            cells.append(f"{np.median(v):{fmt}} ({v.min():{fmt}} - {v.max():{fmt}})")
        lines.append(f"| {family} | " + " | ".join(cells) + " |")
    return "\n".join(lines)
