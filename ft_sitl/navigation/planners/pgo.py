"""PGO as a navigator: Fast-Planner's topological replanning ("path-guided optimisation").

Behaviours and defaults are those of Fast-Planner's topological replanner (Zhou et al.,
ICRA 2020; HKUST-Aerial-Robotics/Fast-Planner: ``topo_replan_fsm``, ``planner_manager``'s
``topoReplan``, ``bspline_optimizer``; see /work/shared/docs/planner-facts.md); the code is
our own. Structure as :mod:`ft_sitl.navigation.planners.ego` (same perception, latency model, safety
logic and give-up rule). Each call (``rate_hz`` 100), in simulated time:

1. **Perception.** A due depth frame is fused into the
   :class:`~ft_sitl.navigation.maps.mapping.LocalMap` (the camera of ``camera_config``); unknown
   space counts as free, the scenario ceiling is a virtual ceiling.
2. **Global reference.** A min-snap polynomial start -> goal through a point every 4 m
   (:func:`~ft_sitl.navigation.trajectories.minsnap.global_reference`), Fast-Planner's
   ``planGlobalTraj``.
   As in Fast-Planner's ``GlobalTrajData`` the planner follows the *composite* reference:
   the current local trajectory while it lasts, then the global polynomial, delayed by the
   time the local trajectories added (:class:`_Reference`).
3. **Replanning** (Fast-Planner's topo FSM):

   * the first plan at once; then a new plan ``replan_period_s`` (0.5 s) after the current
     trajectory started, unless it already ends at the goal and the vehicle is within
     ``no_replan_threshold_m`` (2 m) of its end;
   * a 20 Hz safety check of the current trajectory from now up to 6 m ahead against the
     map (unsafe: within a voxel of the inflated map, Fast-Planner's ESDF < 0.1 m): an
     unsafe point more than ``stop_distance_m`` (0.5 m, Euclidean from the current point)
     ahead triggers a replan at once, a closer one an emergency stop (hover where it is,
     then plan from rest with a new global reference from there);
   * a plan (:func:`plan_segment`): a ``local_segment_m`` (7 m) local segment of the
     composite reference from the state ``latency_s`` ahead (Fast-Planner's
     ``getTrajByRadius``: a point every ``ctrl_pt_dist_m`` 0.3 m of length), fitted to a
     uniform cubic B-spline; the ESDF is updated over the map window; if the segment's
     clearance stays >= 0.3 m it is only optimised (the normal cost below); otherwise the
     topological search (:mod:`~ft_sitl.navigation.planners.topo`) finds up to 6 distinct paths
     around the colliding stretch and each guides an optimisation (phase 1: smoothness +
     1.5 x distance to guide points, solved exactly; phase 2: Fast-Planner's cost 10 x
     jerk + 5 x sum (d - 0.4)^2 where the ESDF d < 0.4 + 1e-5 x feasibility, L-BFGS, <= 300
     evaluations); candidates are taken in order of jerk; each is re-timed to the limits
     (Fast-Planner's ``refineTraj``: inner knot spans scaled by max(v/vmax, sqrt(a/amax)),
     re-fitted, re-optimised) when that ratio is off 1 by more than 5 %, and the first
     safe one (the safety check's test, on the whole trajectory) is adopted.

   A failed plan (no path, or every candidate collides) is retried after 0.05 s, doubling
   up to 1 s; after ``GIVE_UP_AFTER`` (8) failures in a row from the same state with the
   same map the planner gives up ("no plan", a timeout).
4. **Latency.** As EGO's navigator: a plan is computed from the trajectory's state
   ``latency_s`` ahead and replaces it ``latency_s`` later in simulated time; the default
   :data:`DEFAULT_LATENCY_S` estimates the original's replan time in C++;
   ``measured_latency=True`` uses this process's compute time instead.
5. **Output.** Position + velocity + acceleration + yaw from the current trajectory; yaw
   toward the trajectory 2 s ahead (Fast-Planner's look-ahead), rate-limited to pi rad/s,
   low-pass 0.5 (as the EGO navigator).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ft_sitl.navigation.base import Observation, Task
from ft_sitl.navigation.maps.esdf import EsdfGrid
from ft_sitl.navigation.optimisers.fast import minimise
from ft_sitl.navigation.optimisers.lbfgs import EVALUATIONS, UNLIMITED, LbfgsRules, StopRule
from ft_sitl.navigation.optimisers.penalties import fast_planner_cost
from ft_sitl.navigation.planners.astar import OccupancyView
from ft_sitl.navigation.planners.skeleton import (
    NO_REPLAN_THRESHOLD,
    ReplanningPlanner,
    planner_schema,
)
from ft_sitl.navigation.planners.topo import (
    TopoParams,
    TopoSearch,
    collision_range,
    discretize_path,
    find_topo_paths,
    path_length,
)
from ft_sitl.navigation.trajectories.base import SplineTrajectory
from ft_sitl.navigation.trajectories.bspline import BSpline
from ft_sitl.navigation.trajectories.minsnap import global_reference
from ft_sitl.schema import Param

__all__ = ["DEFAULT_LATENCY_S", "PgoParams", "PgoPlan", "PgoPlanner", "first_collision_time",
           "guide_phase", "jerk_cost", "lengthen_time", "near_occupied", "normal_cost",
           "normal_phase", "plan_segment", "refine"]

#: estimated compute time of one topological replan in the original C++ on a desktop CPU:
#: roadmap sampling <= 5 ms (its time cap) + path search, shortcut and pruning (a few ms)
#: + up to 6 optimisations in parallel threads (each capped at 5 ms by NLopt's maxtime)
#: + the refinement (<= 5 ms), i.e. <= ~20 ms of capped work plus thread and message
#: overheads. The ESDF is maintained by the map's own 20 Hz timer, not per replan.
DEFAULT_LATENCY_S = 0.03
#: Fast-Planner's safety check: from the current point up to this far ahead ...
SAFETY_RADIUS_M = 6.0
#: ... sampled every this many seconds of the trajectory
SAFETY_STEP_S = 0.02
#: the fewest knot spans of a fitted segment (3 fixed control points at each end + >= 1)
MIN_SEGMENTS = 4
#: :func:`first_collision_time` evaluates at most this many samples at once (the samples
#: are half a voxel apart along the control polygon: 65536 cover a 3.3 km polygon at 0.1 m).
#: Only a diverged spline exceeds it; the check is ours (the original adopts the lowest-jerk
#: candidate unchecked), so the bound is a memory bound, not one of the original's caps.
COLLISION_CHECK_BLOCK = 1 << 16
ORDER = 3


def esdf_centre(local_map, point, half_extent_m: float) -> np.ndarray:
    """Where PGO centres its ESDF box of ``half_extent_m``: ``point`` (the segment's
    middle), or, when that box would miss the map's window (a segment far beyond it),
    ``point`` moved onto the window's edge."""
    p = np.asarray(point, dtype=float).reshape(3)
    if local_map.esdf_box_overlaps(p, half_extent_m):
        return p
    return np.clip(p, local_map.window_min_m, local_map.window_max_m)


@dataclass(frozen=True)
class PgoParams:
    """Fast-Planner's ``BsplineOptimizer`` weights (topo launch) and limits."""

    max_vel: float = 4.0  # m/s: the benchmark's cap
    max_acc: float = 2.0  # m/s^2: Fast-Planner's default
    w_smooth: float = 10.0  # lambda1
    w_distance: float = 5.0  # lambda2
    w_feasibility: float = 1e-5  # lambda3
    w_guide: float = 1.5  # lambda5
    dist0: float = 0.4  # m: distance below which the ESDF cost acts
    max_evaluations: int = 300  # max_iteration_num2 (NLopt maxeval)
    xtol_rel: float = 1e-5
    lbfgs_memory: int = 10
    ctrl_pt_dist: float = 0.3  # m: manager/control_points_distance (topo launch)
    feasibility_tolerance: float = 0.05  # re-time when max(v/vmax, sqrt(a/amax)) is off 1 by more
    min_ratio: float = 0.5  # a re-timing speeds a segment up by at most 2x per replan

    def __post_init__(self):
        for name in ("max_vel", "max_acc", "dist0", "xtol_rel", "ctrl_pt_dist", "min_ratio"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"PgoParams.{name} must be a positive number, got {v!r}")
        for name in ("w_smooth", "w_distance", "w_feasibility", "w_guide",
                     "feasibility_tolerance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"PgoParams.{name} must be a number >= 0, got {v!r}")
        for name in ("max_evaluations", "lbfgs_memory"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"PgoParams.{name} must be a positive integer, got {v!r}")

    def lbfgs_rules(self) -> LbfgsRules:
        """The normal phase's solve: the shared L-BFGS as PGO's own loop was written
        (numpy's BLAS dot products, stop when no variable moves by more than ``xtol_rel``
        relative, no line-search trial cap but the ``max_evaluations`` budget, a NaN
        trial passes the Armijo test), keeping the best point evaluated."""
        return LbfgsRules(memory=self.lbfgs_memory, stop=StopRule.VARIABLES,
                          tolerance=self.xtol_rel, max_evaluations=self.max_evaluations,
                          line_search_trials=UNLIMITED, blas_dot=True,
                          keep_best=True, nan_passes_armijo=True)


# ---------------------------------------------------------------------------------------
# Fast-Planner's normal cost
# ---------------------------------------------------------------------------------------
@njit(cache=True)
def _normal_cost(q, grad, dt, ws, wd, wf, d0, vmax, amax, fld, origin, res):
    """``ws`` jerk smoothness + ``wd`` ESDF distance + ``wf`` feasibility (Fast-Planner's
    ``calcSmoothnessCost``/``calcDistanceCost``/``calcFeasibilityCost``: the shared
    :func:`~ft_sitl.navigation.optimisers.penalties.fast_planner_cost` with the original's
    unit-length ESDF gradient); the distance term acts on the free rows ``3 .. N-4``.
    Fills ``grad`` (all rows)."""
    return fast_planner_cost(q, grad, np.array([ws, wd, wf, 0.0]), dt, vmax, amax, d0, False,
                             np.zeros(3), fld, origin, 1.0 / res, True, np.zeros(4))


# ---------------------------------------------------------------------------------------
# the optimisation steps
# ---------------------------------------------------------------------------------------
def _check(spline: BSpline) -> None:
    if spline.degree != ORDER or spline.num_control_points < 2 * ORDER + 1:
        raise ValueError(f"PGO optimises cubic B-splines with >= {2 * ORDER + 1} control "
                         f"points, got degree {spline.degree} with "
                         f"{spline.num_control_points}")


def normal_phase(spline: BSpline, grid: EsdfGrid,
                 params: PgoParams | None = None) -> tuple[BSpline, int]:
    """Fast-Planner's ``NORMAL_PHASE``: smoothness + ESDF distance + feasibility over the
    free control points (the first and last 3 fixed). Returns (spline, evaluations)."""
    _check(spline)
    p = params if params is not None else PgoParams()
    q = np.array(spline.control_points)
    hi = q.shape[0] - ORDER
    st = p.lbfgs_rules().start(q[ORDER:hi])
    minimise(st, q, ORDER, hi, np.array([p.w_smooth, p.w_distance, p.w_feasibility, 0.0]),
             spline.dt, p.max_vel, p.max_acc, p.dist0, False, np.zeros(3), grid.field,
             grid.origin, 1.0 / grid.resolution, True)
    return spline.with_control_points(q), int(st.ints[EVALUATIONS])


def normal_cost(spline: BSpline, grid: EsdfGrid,
                params: PgoParams | None = None) -> tuple[float, np.ndarray]:
    """The normal cost of a spline and its gradient (N, 3) (all rows; the optimiser uses
    the free ones)."""
    p = params if params is not None else PgoParams()
    q = np.array(spline.control_points)
    grad = np.zeros_like(q)
    f = _normal_cost(q, grad, spline.dt, p.w_smooth, p.w_distance, p.w_feasibility, p.dist0,
                     p.max_vel, p.max_acc, grid.field, grid.origin, grid.resolution)
    return float(f), grad


def guide_phase(control_points, guide, w_smooth: float = 10.0,
                w_guide: float = 1.5) -> np.ndarray:
    """Phase 1 (``GUIDE_PHASE``): the free control points ``3 .. N-4`` minimising
    ``w_smooth sum ||Q[i+3] - 3 Q[i+2] + 3 Q[i+1] - Q[i]||^2 + w_guide sum ||Q[i] -
    guide[i-3]||^2`` (a quadratic: solved exactly). Returns the new (N, 3) array."""
    q = np.array(control_points, dtype=float)
    n = q.shape[0]
    g = np.asarray(guide, dtype=float).reshape(-1, 3)
    if n < 2 * ORDER + 1 or g.shape[0] != n - 2 * ORDER:
        raise ValueError(f"guide_phase: {n} control points need {n - 2 * ORDER} guide "
                         f"points, got {g.shape[0]}")
    d = np.zeros((n - 3, n))
    for i in range(n - 3):
        d[i, i:i + 4] = (-1.0, 3.0, -3.0, 1.0)
    free = slice(ORDER, n - ORDER)
    df = d[:, free]
    fixed = q.copy()
    fixed[free] = 0.0
    a = w_smooth * df.T @ df + w_guide * np.eye(n - 2 * ORDER)
    b = w_guide * g - w_smooth * df.T @ (d @ fixed)
    q[free] = np.linalg.solve(a, b)
    return q


def jerk_cost(spline: BSpline) -> float:
    """Fast-Planner's ``getJerk``: knot span x sum of the squared jerk control points."""
    j = spline.derivative_control_points(3)
    return float(spline.dt * np.sum(j * j))


def near_occupied(occupied, resolution: float, points) -> np.ndarray:
    """Whether any of the 8 voxel centres around each point (the support of the ESDF's
    trilinear interpolation) is occupied according to ``occupied(points) -> bool``: "the
    ESDF is below one voxel" (Fast-Planner's safety threshold 0.1 m) read from occupancy,
    slightly more conservative, and without recomputing the ESDF."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    base = np.floor(p / resolution - 0.5)
    centres = (base[:, None, :] + _CORNERS[None, :, :] + 0.5) * resolution
    return np.asarray(occupied(centres.reshape(-1, 3)), dtype=bool).reshape(-1, 8).any(axis=1)


_CORNERS = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)], dtype=float)


def first_collision_time(spline: BSpline, grid: EsdfGrid) -> float | None:
    """Time of the first unsafe sample along the whole curve (:func:`near_occupied` on the
    snapshot, which includes the flight volume's bounds; samples at most half a voxel apart
    from the control-polygon length). None if safe: the same test as the navigator's
    safety check, so an adopted plan does not trigger it against the same map. More than
    ``COLLISION_CHECK_BLOCK`` samples are evaluated in blocks (same samples and result)."""
    q = spline.control_points
    length = float(np.sum(np.linalg.norm(np.diff(q, axis=0), axis=1)))
    n = max(int(math.ceil(2.0 * length / grid.resolution)), 1)
    if n + 1 <= COLLISION_CHECK_BLOCK:
        t = np.linspace(0.0, spline.duration, n + 1)
        hit = np.flatnonzero(near_occupied(grid.occupied, grid.resolution, spline.position(t)))
        return float(t[hit[0]]) if hit.size else None
    # a very long control polygon (a diverged fit or optimisation): the same samples, in
    # blocks, stopping at the first unsafe one, so memory stays bounded
    step = spline.duration / n
    for i0 in range(0, n + 1, COLLISION_CHECK_BLOCK):
        t = np.arange(i0, min(i0 + COLLISION_CHECK_BLOCK, n + 1), dtype=float) * step
        if i0 + t.shape[0] == n + 1:
            t[-1] = spline.duration  # as np.linspace's end point
        hit = np.flatnonzero(near_occupied(grid.occupied, grid.resolution, spline.position(t)))
        if hit.size:
            return float(t[hit[0]])
    return None


def lengthen_time(spline: BSpline, ratio: float) -> tuple[np.ndarray, float]:
    """Fast-Planner's ``lengthenTime`` (:meth:`BSpline.lengthen_time`: the knot spans between
    the first two and the last two are stretched so that the duration grows by ``(ratio -
    1)`` times theirs; the curve's shape is unchanged and its start and end keep their speed)
    + ``reparamBspline``: the result sampled at ``N - 3 + 1`` equal time steps. Returns
    (points, dt)."""
    curve = spline.lengthen_time(ratio)
    seg_num = spline.num_control_points - ORDER
    duration = curve.duration
    return curve.position(np.linspace(0.0, duration, seg_num + 1)), duration / seg_num


def refine(spline: BSpline, derivs, ratio: float, grid: EsdfGrid,
           params: PgoParams | None = None) -> BSpline:
    """Fast-Planner's ``refineTraj``: time lengthened by ``ratio`` (:func:`lengthen_time`,
    the same knot count), re-fitted with the segment's end derivatives ``(v0, v1, a0,
    a1)``, then the normal optimisation."""
    points, dt = lengthen_time(spline, ratio)
    fitted = BSpline.fit(points, dt, *derivs)
    return normal_phase(fitted, grid, params)[0]


@dataclass(eq=False)
class PgoPlan:
    """Outcome of :func:`plan_segment`.

    ``status``: "free" (the segment kept its clearance: optimised only), "topo" (the
    topological search guided the result), "ends_in_obstacle" (the segment ends in the
    unsafe region after a single colliding stretch: adopted as it is, as the original
    does), "no_path" (the search found nothing) or "all_collide" (every optimised
    candidate collides). ``spline`` is None on failure.
    """

    status: str
    spline: BSpline | None
    search: TopoSearch | None = None
    candidates: list[BSpline] = field(default_factory=list)
    chosen: int = -1  # index into candidates
    refined: bool = False
    evaluations: int = 0

    @property
    def success(self) -> bool:
        return self.spline is not None


def plan_segment(init: BSpline, resample: Callable[[int], tuple[np.ndarray, float]],
                 derivs, grid: EsdfGrid, rng: np.random.Generator,
                 params: PgoParams | None = None,
                 topo_params: TopoParams | None = None) -> PgoPlan:
    """One PGO replan of a local segment (module docstring, step 3).

    ``init``: the segment fitted to a B-spline; ``resample(seg_num)`` -> ``(points, dt)``:
    the same segment (same duration) sampled with ``seg_num`` knot spans; ``derivs``:
    ``(v0, v1, a0, a1)`` at its ends; ``grid``: the ESDF snapshot; ``rng``: the sampler's
    random generator.
    """
    p = params if params is not None else PgoParams()
    tp = topo_params if topo_params is not None else TopoParams()
    colli_start, colli_end, start_pts, end_pts = collision_range(init, grid, tp.clearance)
    evals = 0
    search = None
    candidates: list[BSpline] = []
    if not colli_start:
        status = "free"
        out, evals = normal_phase(init, grid, p)
        candidates.append(out)
    elif len(colli_start) == 1 and not colli_end:
        return PgoPlan("ends_in_obstacle", init)
    else:
        status = "topo"
        search = find_topo_paths(colli_start[0], colli_end[-1], start_pts, end_pts, grid,
                                 rng, tp)
        if not search.paths:
            return PgoPlan("no_path", None, search)
        for path in search.paths:
            seg_num = max(int(path_length(path) / p.ctrl_pt_dist), MIN_SEGMENTS)
            pts, dt = resample(seg_num)
            c0 = BSpline.fit(pts, dt, *derivs)
            guide = discretize_path(path, c0.num_control_points - 2)[2:-2]
            c1 = c0.with_control_points(guide_phase(c0.control_points, guide, p.w_smooth,
                                                    p.w_guide))
            c2, ev = normal_phase(c1, grid, p)
            evals += ev
            candidates.append(c2)
    order = np.argsort([jerk_cost(c) for c in candidates], kind="stable")
    for k in order:
        c = candidates[int(k)]
        feas = c.feasibility(p.max_vel, p.max_acc)
        options = []
        if abs(feas.ratio - 1.0) > p.feasibility_tolerance:
            # re-timed to the limits: slower if it exceeds them, faster if well below
            options.append((refine(c, derivs, max(feas.ratio, p.min_ratio), grid, p), True))
        if feas.ratio <= 1.0 + p.feasibility_tolerance:
            options.append((c, False))
        for out, refined in options:
            if first_collision_time(out, grid) is None:
                return PgoPlan(status, out, search, candidates, int(k), refined, evals)
    return PgoPlan("all_collide", None, search, candidates, -1, False, evals)


# ---------------------------------------------------------------------------------------
# the composite reference (Fast-Planner's GlobalTrajData)
# ---------------------------------------------------------------------------------------
class _Reference:
    """The global polynomial (started at navigation time ``t0``) with the current local
    B-spline over ``[local_t0, local_t1]``; after it, the polynomial delayed by the time
    the local trajectories added (``time_increase``)."""

    def __init__(self, poly, t0: float):
        self.poly = poly
        self.t0 = float(t0)
        self.local: BSpline | None = None
        self.local_t0 = -math.inf
        self.local_t1 = -math.inf
        self.time_increase = 0.0

    @property
    def end_time(self) -> float:
        return self.t0 + self.poly.duration + self.time_increase

    @property
    def local_reaches_end(self) -> bool:
        """Whether the local trajectory ends where the global one does (at the goal)."""
        if self.local is None:
            return False
        end = self.local.position(self.local.duration)
        return float(np.linalg.norm(end - self.poly.position(self.poly.duration))) < 0.1

    def evaluate(self, t, order: int = 0) -> np.ndarray:
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.empty((tt.shape[0], 3))
        on_local = np.zeros(tt.shape[0], dtype=bool)
        if self.local is not None:
            on_local = (tt >= self.local_t0) & (tt <= self.local_t1)
            if on_local.any():
                out[on_local] = self.local.evaluate(tt[on_local] - self.local_t0, order)
        glob = ~on_local
        if glob.any():
            out[glob] = self.poly.evaluate(tt[glob] - self.t0 - self.time_increase, order)
        return out[0] if np.ndim(t) == 0 else out

    def derivs(self, t0: float, t1: float):
        v = self.evaluate(np.array([t0, t1]), 1)
        a = self.evaluate(np.array([t0, t1]), 2)
        return v[0], v[1], a[0], a[1]

    def by_radius(self, t_start: float, radius: float, dist_pt: float):
        """Fast-Planner's ``getTrajByRadius``: forward in 0.2 s steps until ``radius`` from
        the first point (or the end); points every ``length / floor(length / dist_pt)``.
        Returns (points, dt, duration) or None when nothing is left."""
        remaining = self.end_time - t_start
        if remaining <= 1e-3:
            return None
        steps = np.minimum(np.arange(1, int(math.ceil(remaining / 0.2)) + 1) * 0.2, remaining)
        pts = self.evaluate(t_start + np.concatenate([[0.0], steps]))
        radii = np.linalg.norm(pts - pts[0], axis=1)
        far = np.flatnonzero(radii[1:] >= radius)
        k = int(far[0]) + 1 if far.size else len(steps)
        seg_time = float(steps[k - 1])
        seg_len = float(np.sum(np.linalg.norm(np.diff(pts[:k + 1], axis=0), axis=1)))
        seg_num = max(int(math.floor(seg_len / dist_pt)), MIN_SEGMENTS)
        points, dt = self.by_duration(t_start, seg_time, seg_num)
        return points, dt, seg_time

    def by_duration(self, t_start: float, duration: float, seg_num: int):
        """``seg_num + 1`` points at equal time steps over ``[t_start, t_start + duration]``
        (Fast-Planner's ``getTrajByDuration``). Returns (points, dt)."""
        return (self.evaluate(t_start + np.linspace(0.0, duration, seg_num + 1)),
                duration / seg_num)

    def set_local(self, spline: BSpline, t0: float, time_inc: float) -> None:
        self.local = spline
        self.local_t0 = float(t0)
        self.local_t1 = float(t0) + spline.duration
        self.time_increase += float(time_inc)


# ---------------------------------------------------------------------------------------
# the navigator
# ---------------------------------------------------------------------------------------
class PgoPlanner(ReplanningPlanner):
    """Fast-Planner's topological replanning (Zhou et al. 2020): path-guided optimisation."""

    name = "pgo"
    #: yaw points at the trajectory this far ahead (Fast-Planner's planYaw forward_t)
    yaw_lookahead_s = 2.0

    schema = planner_schema(
        Param("local_segment_m", 7.0, "m", (2.0, 20.0),
              doc="length of the local segment of the global path that is optimised"),
        Param("replan_period_s", 0.5, "s", (0.05, 5.0), doc="replan this often"),
        NO_REPLAN_THRESHOLD,
        Param("stop_distance_m", 0.5, "m", (0.0, 5.0),
              doc="an unsafe point on the trajectory closer than this is an emergency stop "
                  "(farther: a replan at once)"),
        Param("ctrl_pt_dist_m", 0.3, "m", (0.1, 2.0),
              doc="B-spline control-point spacing of the local trajectory"),
        max_acc_m_s2=2.0, latency_s=DEFAULT_LATENCY_S)

    def __init__(self, **params):
        super().__init__(**params)
        p = self.settings
        self.segment_len = float(p["local_segment_m"])
        self.replan_period = float(p["replan_period_s"])
        self.no_replan_threshold = float(p["no_replan_threshold_m"])
        self.stop_distance = float(p["stop_distance_m"])
        self.ctrl_pt_dist = float(p["ctrl_pt_dist_m"])

    # --- set-up ---------------------------------------------------------------------------
    def reset(self, task: Task) -> None:
        super().reset(task)
        self.params = PgoParams(max_vel=self.vmax, max_acc=self.max_acc,
                                ctrl_pt_dist=self.ctrl_pt_dist)
        self.topo_params = TopoParams()
        self.view = OccupancyView.from_map(self.map, bounds=self.bounds)
        self.rng = task.rng
        self.ref: _Reference | None = None
        self.stats = {"free": 0, "topo": 0, "ends_in_obstacle": 0, "no_path": 0,
                      "all_collide": 0, "stops": 0, "safety_replans": 0}
        self.last_plan: PgoPlan | None = None

    # --- planning ---------------------------------------------------------------------------
    def _plan(self, obs: Observation) -> None:
        t_start = time.perf_counter()
        t_eff = obs.time_s + self.latency
        goal = np.asarray(self.task.goal, dtype=float)
        if self.traj is not None and not self.from_rest and t_eff >= self.traj.end_time:
            # the trajectory ran out (plans kept failing): hold its end, restart from rest
            self.stop_at = self.traj.state(self.traj.end_time)[0]
            self.from_rest = True
        if self.ref is None or self.from_rest:
            p0 = np.array(obs.position if self.stop_at is None else self.stop_at, dtype=float)
            if float(np.linalg.norm(goal - p0)) < 0.1:
                self._adopt(None, obs, t_start)
                return
            self.ref = _Reference(global_reference(p0, goal, self.vmax), t_eff)
        ref = self.ref
        self.replans += 1
        seg = ref.by_radius(t_eff, self.segment_len, self.ctrl_pt_dist)
        if seg is None:  # the reference is used up: hold what there is
            self._adopt(None, obs, t_start)
            return
        points, dt, duration = seg
        derivs = ref.derivs(t_eff, t_eff + duration)
        init = BSpline.fit(points, dt, *derivs)
        # the ESDF over a box around the segment's middle that holds the segment and the
        # topological sampling box around any stretch of it (+-(L/2 + 1) along, 3.5 across);
        # a box off the map's window (a segment far from the vehicle) has no field at all:
        # it is moved onto the window's edge
        half = 0.5 * self.segment_len + 2.0
        grid = EsdfGrid.from_map(self.map,
                                 esdf_centre(self.map, points[len(points) // 2], half),
                                 half, bounds=self.bounds)
        plan = plan_segment(init, lambda n: ref.by_duration(t_eff, duration, n), derivs, grid,
                            self.rng, self.params, self.topo_params)
        self.last_plan = plan
        self.stats[plan.status] += 1
        if not plan.success:
            self._failed(obs, ref.evaluate(t_eff), plan.status, t_start)
            return
        self._succeeded()
        self._adopt(plan.spline, obs, t_start, duration)

    def _adopt(self, spline: BSpline | None, obs: Observation, t_start: float,
               seg_duration: float = 0.0) -> None:
        latency = self._compute_time(t_start)
        traj = None
        if spline is not None:
            t0 = obs.time_s + latency
            self.ref.set_local(spline, t0, spline.duration - seg_duration)
            traj = SplineTrajectory(spline, t0)
        self._adopt_at(traj, obs, latency)

    # --- the replanning loop's hooks ----------------------------------------------------------
    def _replan_due(self, obs: Observation) -> bool:
        """``replan_period_s`` after the trajectory started, unless it ends at the goal and
        the vehicle is within ``no_replan_threshold_m`` of its end."""
        t = obs.time_s
        if t >= self.traj.t0 + self.replan_period:
            near_end = (self.ref is not None and self.ref.local_reaches_end
                        and float(np.linalg.norm(self.traj.state(t)[0]
                                                 - self.traj.state(self.traj.end_time)[0]))
                        <= self.no_replan_threshold)
            return not near_end
        return False

    def _emergency(self, obs: Observation, ahead: float) -> None:
        """An unsafe point within ``stop_distance_m``: stop (then plan from rest, with a
        new global reference, at once)."""
        self.stats["safety_replans"] += 1
        if ahead <= self.stop_distance:
            self.stats["stops"] += 1
            self._stop(np.array(obs.position))
            self.retry_at = obs.time_s

    def _collision_ahead(self, t: float) -> float | None:
        """Fast-Planner's ``checkTrajCollision``: the current trajectory sampled every
        0.02 s from now, up to 6 m from the current point or its end; the distance from
        the current point to the last free sample before the first occupied one (None if
        free)."""
        tr = self.traj
        tau0 = min(max(t - tr.t0, 0.0), tr.spline.duration)
        taus = tau0 + SAFETY_STEP_S * np.arange(1, int((tr.spline.duration - tau0)
                                                        / SAFETY_STEP_S) + 1)
        taus = taus[taus < tr.spline.duration]
        if taus.size == 0:
            return None
        cur = tr.spline.position(tau0)
        pts = tr.spline.position(taus)
        radii = np.linalg.norm(pts - cur, axis=1)
        far = np.flatnonzero(radii >= SAFETY_RADIUS_M)
        last = int(far[0]) + 1 if far.size else len(taus)
        occ = np.flatnonzero(near_occupied(self.view.is_occupied, self.view.resolution,
                                           pts[:last]))
        if occ.size == 0:
            return None
        k = int(occ[0])
        return float(radii[k - 1]) if k > 0 else 0.0
