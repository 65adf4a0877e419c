"""EGO-Planner's optimisation core: ESDF-free B-spline optimisation with "rebound".

Behaviours and defaults are EGO-Planner's (Zhou et al., RA-L 2021; ZJU-FAST-Lab/ego-planner,
see /work/shared/docs/planner-facts.md); the code is our own. The trajectory is a uniform
cubic B-spline (:class:`~ft_sitl.navigation.trajectories.bspline.BSpline`) with control
points
``Q[0..N-1]``; the first and last three are fixed (they pin the start and end state) and the
interior ones are optimised.

Collision handling without a distance field: every control point in a colliding stretch gets
"anchor pairs" ``{p, v}`` (a point on the obstacle surface and a unit direction out of it)
and is pushed along ``v`` until it is ``clearance`` (0.5 m) beyond ``p``:

1. Colliding stretches (:func:`colliding_segments`): the control polygon ``Q[2] .. Q[i_end]``
   (``i_end = (N-3) - (N-6) // 3``, EGO's "first 2/3") is sampled every half voxel against
   the inflated map; each occupied run (runs closer than 3 samples merged) becomes
   ``(in_id, out_id)``: the control point before it and the one after it.
2. A 26-connected A* (:mod:`~ft_sitl.navigation.planners.astar`) from ``Q[in_id]`` to ``Q[out_id]``.
3. Anchors (:func:`anchors_for_segment`): for each ``Q[j]`` strictly inside the stretch, the
   plane through ``Q[j]`` with normal ``Q[j+1] - Q[j-1]`` cuts the A* path at ``c``;
   ``v = (c - Q[j]) / |c - Q[j]|``; ``p`` is found by marching from ``c`` back toward
   ``Q[j]`` one voxel at a time: the first occupied sample, moved back one voxel toward
   ``c`` (i.e. the obstacle surface seen from the free A* side); if the march reaches
   ``Q[j]`` without meeting an occupied voxel, ``p`` is the last sample (within a voxel of
   ``Q[j]``). Points of the stretch without a cut (and the stretch's end points) copy the
   pair of their neighbour. A stretch with no interior point uses the plane through the
   midpoint of its two control points and gives the pair to both.

Costs (all with analytic gradients w.r.t. the full ``(N, 3)`` control-point array):

- smoothness ``sum_i ||Q[i+3] - 3 Q[i+2] + 3 Q[i+1] - Q[i]||^2`` (jerk form, unscaled);
- collision, per pair, with ``d = (Q[j] - p) . v`` and ``e = c0 - d`` (``c0`` = clearance
  0.5 m): 0 for ``e <= 0``, ``e^3`` for ``0 < e <= c0``, ``3 c0 e^2 - 3 c0^2 e + c0^3``
  beyond (``1.5 e^2 - 0.75 e + 0.125`` at ``c0 = 0.5``; value, slope and curvature agree
  at ``e = c0``, so the cost is C2);
- feasibility per axis on velocity control points ``V = (Q[i+1] - Q[i]) / dt``:
  ``(|V| - vmax)^2 / dt^2`` where exceeded (EGO's ``1/dt^2`` puts it on the scale of the
  acceleration term) and on acceleration control points ``A`` likewise ``(|A| - amax)^2``;
- fitness (refinement only) on the curve's knot positions ``x_k = (Q[k] + 4 Q[k+1] +
  Q[k+2]) / 6`` against reference points ``r_k`` (k = 1 .. N-4) with the unit tangent
  ``t = normalise(r_{k+1} - r_{k-1})``: ``((x-r).t)^2 / 25 + |(x-r) x t|^2 / 1``.

The total is ``w_s smooth + w_c collision + w_f feasibility`` (rebound) or
``w_s smooth + w_fit fitness + w_f feasibility`` (refinement), weights 1.0 / 0.5 / 0.1 / 1.0.

The solve (:meth:`EgoOptimizer.rebound`): L-BFGS (memory 16, <= 200 iterations) over the
interior points, stopped like EGO's lbfgs when ``||g|| < 0.01 max(1, ||x||)`` (0.001 when
refining). The L-BFGS is the project's own numba one (:mod:`.lbfgs`, shared with
Fast-Planner and PGO: two-loop recursion, Lewis-Overton weak-Wolfe line search with EGO's
constants c1 = 1e-4, c2 = 0.9, <= 40 trials) rather than scipy's L-BFGS-B: on this project's
machines scipy's costs 40 us of Python per iteration and, with OpenBLAS threads on a loaded
machine, up to ~8 ms per iteration (tiny BLAS calls), against a budget of < 20 ms for a
whole local plan; the tests check it reaches scipy's minimum on a convex problem. After
each iteration, once past iteration 3 and smooth enough
(smoothness per free point < 0.1), the control points ``Q[2] .. Q[i_end]`` are checked: an
occupied point that is not already behind one of its planes (``d < resolution``) is a new
collision; its stretch (nearest free points on either side) gets A* and anchors and the
solve restarts from the current points (a "rebound", <= 20). When the solver stops, the curve
is sampled every half voxel over the first 2/3 of its duration: collision-free is success; a
collision within the first knot span is a failure; otherwise new anchors are added for the
colliding stretches, the collision weight is doubled and the solve repeats (at most 3
rounds in all, EGO's ``MAX_RESART_NUMS_SET``).

:meth:`EgoOptimizer.refine` re-times an infeasible result (time stretched by
``max(v/vmax, sqrt(a/amax))``, knot positions re-fitted with the original end derivatives)
and optimises smoothness + fitness + feasibility; :meth:`EgoOptimizer.optimize` is EGO's
``reboundReplan`` steps 2-3 (rebound, then refine if infeasible).

Differences from the original, all small and deliberate:

- The rebound check runs after each accepted L-BFGS iteration, not inside every cost
  evaluation (line-search trials included); a rebound restarts the solve only when the new
  collision got new anchor pairs (EGO also restarts when its A* failed, which only repeats
  the same solve until the 20 rebounds are used up).
- A stretch whose A* fails is skipped (EGO abandons the whole initialisation and goes on
  with no pairs at all); the final check still catches the collision.
- The colliding-stretch scan samples each polygon piece at most half a voxel apart
  (EGO: half the *average* control-point spacing, taken from the start-end chord), and a
  stretch that never leaves the obstacle ends at the last control point (EGO drops it).
- The final check samples the curve every half voxel of control-polygon length (EGO: one
  voxel of start-end chord), so it does not step over the corners of inflated obstacles.
- A line search that cannot decrease the cost (round-off near a minimum) ends the solve
  like convergence; EGO reports a solver error and gives up the plan.
"""

from __future__ import annotations

import enum
import math
import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ft_sitl.navigation.optimisers.lbfgs import (
    EVALUATE,
    EVALUATIONS,
    F_TRIAL,
    ITERATED,
    ITERATIONS,
    LbfgsRules,
    StopRule,
    advance,
    put_rows,
    take_rows,
)
from ft_sitl.navigation.optimisers.penalties import as_points, smoothness, smoothness_cost
from ft_sitl.navigation.planners.astar import AStarMemo, OccupancyView, search
from ft_sitl.navigation.trajectories.bspline import BSpline, Feasibility

__all__ = [
    "Anchors", "EgoOptimizer", "EgoParams", "EgoResult", "EgoStatus", "anchors_for_segment",
    "check_end_index", "colliding_segments", "collision_cost", "feasibility_cost",
    "first_collision_time", "fitness_cost", "smoothness_cost",
]

ORDER = 3  # cubic B-spline; the first/last ORDER control points are fixed
_ENOUGH_INTERVAL = 2  # free samples that separate two occupied runs (EGO)


@dataclass(frozen=True)
class EgoParams:
    """EGO-Planner's optimiser parameters (``advanced_param.xml`` values unless noted)."""

    max_vel: float = 4.0  # m/s; the benchmark's cap (EGO default 2.0)
    max_acc: float = 3.0  # m/s^2; EGO default, the navigator passes the platform's
    w_smooth: float = 1.0  # lambda_smooth
    w_collision: float = 0.5  # lambda_collision
    w_feasibility: float = 0.1  # lambda_feasibility
    w_fitness: float = 1.0  # lambda_fitness
    clearance: float = 0.5  # m, optimization/dist0
    fitness_along: float = 25.0  # a^2: deviation along the tangent weighted 1/25
    fitness_across: float = 1.0  # b^2
    feasibility_tolerance: float = 0.05  # manager/feasibility_tolerance
    lbfgs_memory: int = 16
    max_iterations: int = 200
    g_epsilon_rebound: float = 0.01  # stop when ||g|| < eps * max(1, ||x||) (EGO's lbfgs)
    g_epsilon_refine: float = 0.001
    rebound_smoothness: float = 0.1  # smoothness per free point below which rebound is checked
    max_rebounds: int = 20
    max_rounds: int = 3  # solves with collision weight w, 2w, 4w
    astar_max_expansions: int = 100_000  # deterministic stand-in for EGO's 0.2 s A* cap

    def __post_init__(self):
        for name in ("max_vel", "max_acc", "clearance", "fitness_along", "fitness_across",
                     "g_epsilon_rebound", "g_epsilon_refine", "rebound_smoothness"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"EgoParams.{name} must be a positive number, got {v!r}")
        for name in ("w_smooth", "w_collision", "w_feasibility", "w_fitness",
                     "feasibility_tolerance"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v >= 0):
                raise ValueError(f"EgoParams.{name} must be a non-negative number, got {v!r}")
        for name in ("lbfgs_memory", "max_iterations", "max_rounds", "astar_max_expansions"):
            v = getattr(self, name)
            if not (isinstance(v, int) and v >= 1):
                raise ValueError(f"EgoParams.{name} must be a positive integer, got {v!r}")
        if not (isinstance(self.max_rebounds, int) and self.max_rebounds >= 0):
            raise ValueError(f"EgoParams.max_rebounds must be >= 0, got {self.max_rebounds!r}")


# ---------------------------------------------------------------------------------------
# cost terms: numba kernels (one implementation, used by the solver and the Python wrappers;
# the smoothness is the shared one, optimisers.penalties).
# Each ``_*_acc`` returns its unweighted cost and adds ``w`` times its gradient to ``grad``.
# ---------------------------------------------------------------------------------------
@njit(cache=True)
def _collision_acc(q, idx, ap, av, c0, w, grad):
    f = 0.0
    for k in range(idx.shape[0]):
        i = idx[k]
        dist = 0.0
        for d in range(3):
            dist += (q[i, d] - ap[k, d]) * av[k, d]
        e = c0 - dist
        if e <= 0.0:
            continue
        if e <= c0:
            f += e * e * e
            slope = 3.0 * e * e
        else:
            f += 3.0 * c0 * e * e - 3.0 * c0 * c0 * e + c0 * c0 * c0
            slope = 6.0 * c0 * e - 3.0 * c0 * c0
        for d in range(3):
            grad[i, d] -= w * slope * av[k, d]
    return f


@njit(cache=True)
def _feasibility_acc(q, dt, vmax, amax, w, grad):
    f = 0.0
    n = q.shape[0]
    inv_dt = 1.0 / dt
    inv_dt2 = inv_dt * inv_dt
    for i in range(n - 1):
        for d in range(3):
            v = (q[i + 1, d] - q[i, d]) * inv_dt
            ex = abs(v) - vmax
            if ex > 0.0:
                f += ex * ex * inv_dt2
                gv = w * 2.0 * ex * (1.0 if v > 0.0 else -1.0) * inv_dt2 * inv_dt
                grad[i + 1, d] += gv
                grad[i, d] -= gv
    for i in range(n - 2):
        for d in range(3):
            a = (q[i + 2, d] - 2.0 * q[i + 1, d] + q[i, d]) * inv_dt2
            ex = abs(a) - amax
            if ex > 0.0:
                f += ex * ex
                ga = w * 2.0 * ex * (1.0 if a > 0.0 else -1.0) * inv_dt2
                grad[i + 2, d] += ga
                grad[i + 1, d] -= 2.0 * ga
                grad[i, d] += ga
    return f


@njit(cache=True)
def _fitness_acc(q, ref, tan, along, across, w, grad):
    f = 0.0
    x = np.empty(3)
    for k in range(1, q.shape[0] - 3):
        xt = 0.0
        xx = 0.0
        for d in range(3):
            x[d] = (q[k, d] + 4.0 * q[k + 1, d] + q[k + 2, d]) / 6.0 - ref[k, d]
            xt += x[d] * tan[k - 1, d]
            xx += x[d] * x[d]
        f += xt * xt / along + (xx - xt * xt) / across
        for d in range(3):
            dfdx = w * (2.0 * xt * tan[k - 1, d] / along
                        + 2.0 * (x[d] - xt * tan[k - 1, d]) / across)
            grad[k, d] += dfdx / 6.0
            grad[k + 1, d] += 4.0 * dfdx / 6.0
            grad[k + 2, d] += dfdx / 6.0
    return f


@njit(cache=True)
def _total_cost(q, grad, mode, w, c0, dt, vmax, amax, idx, ap, av, ref, tan, along, across):
    """mode 0: rebound (smooth, collision, feasibility); mode 1: refine (smooth, fitness,
    feasibility). ``w`` = [smooth, collision, feasibility, fitness]."""
    grad[:, :] = 0.0
    f = w[0] * smoothness(q, w[0], grad)
    if mode == 0:
        f += w[1] * _collision_acc(q, idx, ap, av, c0, w[1], grad)
    f += w[2] * _feasibility_acc(q, dt, vmax, amax, w[2], grad)
    if mode == 1:
        f += w[3] * _fitness_acc(q, ref, tan, along, across, w[3], grad)
    return f


def collision_cost(q, idx, p, v, clearance: float) -> tuple[float, np.ndarray]:
    """Anchor-pair cost: for pair ``k`` on control point ``idx[k]``, ``d = (Q - p) . v``,
    ``e = clearance - d``; see the module docstring. Returns (cost, gradient (N, 3))."""
    q = as_points(q)
    grad = np.zeros_like(q)
    idx = np.ascontiguousarray(idx, dtype=np.int64)
    p = np.ascontiguousarray(p, dtype=float).reshape(-1, 3)
    v = np.ascontiguousarray(v, dtype=float).reshape(-1, 3)
    return float(_collision_acc(q, idx, p, v, float(clearance), 1.0, grad)), grad


def feasibility_cost(q, dt: float, vmax: float, amax: float) -> tuple[float, np.ndarray]:
    """Per-axis penalty on velocity and acceleration control points beyond the limits."""
    q = as_points(q)
    grad = np.zeros_like(q)
    return float(_feasibility_acc(q, float(dt), float(vmax), float(amax), 1.0, grad)), grad


def fitness_tangents(ref) -> np.ndarray:
    """Unit tangents ``normalise(r[k+1] - r[k-1])`` at the reference knots 1 .. K-2."""
    ref = np.asarray(ref, dtype=float)
    t = ref[2:] - ref[:-2]
    norm = np.linalg.norm(t, axis=1, keepdims=True)
    return np.ascontiguousarray(np.divide(t, norm, out=np.zeros_like(t), where=norm > 1e-12))


def fitness_cost(q, ref, along: float = 25.0, across: float = 1.0) -> tuple[float, np.ndarray]:
    """Anisotropic deviation of the knot positions from ``ref`` (``N - 2`` reference points,
    the knots of the reference curve): ``(x.t)^2 / along + |x cross t|^2 / across`` summed
    over the interior knots 1 .. N-4."""
    q = as_points(q)
    ref = np.ascontiguousarray(ref, dtype=float)
    n = q.shape[0]
    if ref.shape != (n - 2, 3):
        raise ValueError(f"fitness_cost: ref must have shape ({n - 2}, 3), got {ref.shape}")
    grad = np.zeros_like(q)
    f = _fitness_acc(q, ref, fitness_tangents(ref), float(along), float(across), 1.0, grad)
    return float(f), grad


# ---------------------------------------------------------------------------------------
# the solve: the shared L-BFGS (optimisers.lbfgs) with EGO's rules, paused for the rebound
# check
# ---------------------------------------------------------------------------------------
_PAUSED = -3  # _solve's code: an iteration passed the rebound check's smoothness test


@njit(cache=True)
def _solve(st, q, lo, hi, check_smooth, mode, w, c0, dt, vmax, amax, idx, ap, av, ref, tan,
           along, across):
    """Drive the L-BFGS state ``st`` over rows ``lo:hi`` of ``q`` (in place) with the
    rebound or refinement cost. Returns a stop code of :mod:`.lbfgs`, or ``_PAUSED`` after
    an iteration past the third whose smoothness per free point is below ``check_smooth``
    (with ``check_smooth > 0``; call again to resume). ``q`` holds the current point."""
    grad = np.zeros_like(q)
    scratch = np.zeros_like(q)
    while True:
        code = advance(st)
        if code == EVALUATE:
            put_rows(st.xn, q, lo, hi)
            st.reals[F_TRIAL] = _total_cost(q, grad, mode, w, c0, dt, vmax, amax, idx, ap,
                                            av, ref, tan, along, across)
            take_rows(grad, st.gn, lo, hi)
        elif code == ITERATED:  # q holds the point just accepted (the last evaluated)
            if check_smooth > 0.0 and st.ints[ITERATIONS] > 3:
                scratch[:, :] = 0.0
                if smoothness(q, 0.0, scratch) / (hi - lo) < check_smooth:
                    return _PAUSED
        else:
            put_rows(st.x, q, lo, hi)
            return code


class _Lbfgs:
    """One L-BFGS solve over the interior rows of ``q`` (modified in place) with EGO's
    rules: ``memory`` pairs, at most ``max_iter`` iterations, stopped when ``||g|| <=
    g_epsilon max(1, ||x||)``, line search steps within 1e-20 .. 1e20."""

    def __init__(self, q: np.ndarray, memory: int, max_iter: int, g_epsilon: float,
                 cost_args: tuple, check_smooth: float = 0.0):
        self.q = q
        self.lo, self.hi = ORDER, q.shape[0] - ORDER
        rules = LbfgsRules(memory=int(memory), stop=StopRule.GRADIENT,
                           tolerance=float(g_epsilon), max_iterations=int(max_iter),
                           step_min=1e-20, step_max=1e20)
        self.state = rules.start(q[self.lo:self.hi])
        self.check_smooth = float(check_smooth)
        self.cost_args = cost_args

    def run(self) -> int:
        """Solve on; returns a stop code of :mod:`.lbfgs` or ``_PAUSED``."""
        return int(_solve(self.state, self.q, self.lo, self.hi, self.check_smooth,
                          *self.cost_args))

    @property
    def iterations(self) -> int:
        return int(self.state.ints[ITERATIONS])

    @property
    def evaluations(self) -> int:
        return int(self.state.ints[EVALUATIONS])


# ---------------------------------------------------------------------------------------
# anchors
# ---------------------------------------------------------------------------------------
class Anchors:
    """The ``{p, v}`` pairs of each control point (a point may hold several)."""

    def __init__(self, n_points: int):
        self.n_points = int(n_points)
        self._per_point: list[list[tuple[np.ndarray, np.ndarray]]] = [
            [] for _ in range(self.n_points)]

    def add(self, j: int, p: np.ndarray, v: np.ndarray) -> None:
        self._per_point[j].append((np.asarray(p, dtype=float).copy(),
                                   np.asarray(v, dtype=float).copy()))

    def of(self, j: int) -> list[tuple[np.ndarray, np.ndarray]]:
        return list(self._per_point[j])

    def __len__(self) -> int:
        return sum(len(a) for a in self._per_point)

    def arrays(self, lo: int = 0, hi: int | None = None):
        """``(idx (K,), p (K, 3), v (K, 3))`` of the pairs on points ``lo <= j < hi``."""
        hi = self.n_points if hi is None else hi
        idx, ps, vs = [], [], []
        for j in range(lo, hi):
            for p, v in self._per_point[j]:
                idx.append(j)
                ps.append(p)
                vs.append(v)
        if not idx:
            return np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3))
        return np.array(idx, dtype=np.int64), np.array(ps), np.array(vs)

    def behind_a_plane(self, j: int, point: np.ndarray, margin: float) -> bool:
        """True if ``point`` is less than ``margin`` beyond one of ``j``'s planes
        (``(point - p) . v < margin``): an occupied point that is already being pushed."""
        return any(float((point - p) @ v) < margin for p, v in self._per_point[j])


def check_end_index(n_points: int) -> int:
    """Last control point of the checked stretch: EGO's "first 2/3" of the free points,
    ``i_end = (N - 3) - (N - 6) // 3``."""
    end_idx = n_points - ORDER
    return end_idx - (end_idx - ORDER) // 3


def _polygon_samples(q: np.ndarray, first: int, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Samples of the polygon ``q[first-1] -> q[first] -> ... -> q[-1]`` at most ``step``
    apart; sample ``s`` lies on piece ``owner[s]``, the piece from ``q[owner-1]`` (excluded,
    except for the very first sample) to ``q[owner]`` (included)."""
    pts, owner = [q[first - 1:first]], [np.array([first], dtype=np.int64)]
    for i in range(first, q.shape[0]):
        a, b = q[i - 1], q[i]
        m = max(int(math.ceil(float(np.linalg.norm(b - a)) / step)), 1)
        f = np.arange(1, m + 1)[:, None] / m
        pts.append(a + f * (b - a))
        owner.append(np.full(m, i, dtype=np.int64))
    return np.concatenate(pts), np.concatenate(owner)


def colliding_segments(q: np.ndarray, grid: OccupancyView) -> list[tuple[int, int]]:
    """Colliding stretches ``(in_id, out_id)`` of the control polygon (see the module
    docstring, step 1). A stretch must start on a piece ending at or before
    :func:`check_end_index`; its exit is looked for up to the last control point (the
    last point itself if the polygon never leaves the obstacle)."""
    n = q.shape[0]
    i_end = check_end_index(n)
    pts, owner = _polygon_samples(q, ORDER, grid.resolution / 2.0)
    occ = grid.is_occupied(pts)
    segments: list[tuple[int, int]] = []
    s = 0
    n_s = occ.shape[0]
    while s < n_s:
        if not occ[s]:
            s += 1
            continue
        if owner[s] > i_end:
            break
        in_id = int(owner[s]) - 1
        # extend the run over gaps of <= _ENOUGH_INTERVAL free samples
        e = s
        out_sample = None
        while e < n_s:
            if occ[e]:
                e += 1
                continue
            gap_end = e
            while gap_end < n_s and not occ[gap_end] and gap_end - e <= _ENOUGH_INTERVAL:
                gap_end += 1
            if gap_end < n_s and occ[gap_end]:
                e = gap_end  # short gap: same run
                continue
            out_sample = e
            break
        out_id = n - 1 if out_sample is None else int(owner[out_sample])
        if segments and in_id < segments[-1][1]:
            segments[-1] = (segments[-1][0], max(out_id, segments[-1][1]))
        else:
            segments.append((in_id, out_id))
        if out_sample is None:
            break
        s = out_sample
    return segments


def _plane_cut(path: np.ndarray, point: np.ndarray, normal: np.ndarray) -> np.ndarray | None:
    """Where the plane through ``point`` with ``normal`` cuts the polyline ``path``; the
    crossing nearest the middle of the path when there are several."""
    if path.shape[0] < 2:
        return None
    s = (path - point) @ normal
    prod = s[:-1] * s[1:]
    cand = np.flatnonzero((prod <= 0.0) & ((s[:-1] != 0.0) | (s[1:] != 0.0)))
    if cand.size == 0:
        return None
    k = int(cand[np.argmin(np.abs(cand + 0.5 - (path.shape[0] - 1) / 2.0))])
    a, b = path[k], path[k + 1]
    return a + (b - a) * (s[k] / (s[k] - s[k + 1]))


def _surface_points(origins: np.ndarray, cuts: np.ndarray,
                    grid: OccupancyView) -> np.ndarray:
    """For each ray from ``cuts[k]`` back toward ``origins[k]``: the first occupied sample
    (every voxel) moved back one voxel toward the cut, or the last sample (within one voxel
    of the origin) if none is occupied."""
    res = grid.resolution
    out = np.empty_like(origins)
    pts, owner, dists = [], [], []
    lengths = np.linalg.norm(cuts - origins, axis=1)
    for k in range(origins.shape[0]):
        a = lengths[k] - res * np.arange(int(math.floor(lengths[k] / res)) + 1)
        a = a[a >= 0.0]
        w = (a / lengths[k])[:, None]
        pts.append(w * cuts[k] + (1.0 - w) * origins[k])
        owner.append(np.full(a.shape[0], k))
        dists.append(a)
    occ = grid.is_occupied(np.concatenate(pts))
    owner_all = np.concatenate(owner)
    dist_all = np.concatenate(dists)
    for k in range(origins.shape[0]):
        sel = np.flatnonzero(owner_all == k)
        hit = sel[occ[sel]]
        if hit.size:
            a = dist_all[hit[0]] + res
        else:
            a = dist_all[sel[-1]]
        out[k] = origins[k] + (a / lengths[k]) * (cuts[k] - origins[k])
    return out


def anchors_for_segment(q: np.ndarray, segment: tuple[int, int], path: np.ndarray,
                        grid: OccupancyView, anchors: Anchors) -> int:
    """Add ``{p, v}`` pairs for the stretch ``segment`` around A* ``path`` (module docstring,
    step 3). Returns the number of control points that got a pair from a plane cut."""
    in_id, out_id = segment
    js, cuts, origins = [], [], []
    if out_id - in_id == 1:
        mid = 0.5 * (q[in_id] + q[out_id])
        c = _plane_cut(path, mid, q[out_id] - q[in_id])
        if c is not None and np.linalg.norm(c - mid) > 1e-5:
            p = _surface_points(mid[None, :], c[None, :], grid)[0]
            v = (c - mid) / np.linalg.norm(c - mid)
            for j in (in_id, out_id):
                anchors.add(j, p, v)
            return 1
        return 0
    for j in range(in_id + 1, out_id):
        c = _plane_cut(path, q[j], q[j + 1] - q[j - 1])
        if c is not None and np.linalg.norm(c - q[j]) > 1e-5:
            js.append(j)
            cuts.append(c)
            origins.append(q[j])
    if not js:
        return 0
    origins_a = np.array(origins)
    cuts_a = np.array(cuts)
    ps = _surface_points(origins_a, cuts_a, grid)
    vs = (cuts_a - origins_a) / np.linalg.norm(cuts_a - origins_a, axis=1, keepdims=True)
    fresh: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for j, p, v in zip(js, ps, vs):
        anchors.add(j, p, v)
        fresh[j] = (p, v)
    # points of the stretch without a cut copy a neighbour's new pair: after the last cut
    # from the left, before it from the right (EGO's order)
    last = js[-1]
    carry = fresh[last]
    for j in range(last + 1, out_id + 1):
        anchors.add(j, *carry)
    carry = fresh[last]
    for j in range(last - 1, in_id - 1, -1):
        if j in fresh:
            carry = fresh[j]
        else:
            anchors.add(j, *carry)
    return len(js)


def first_collision_time(spline: BSpline, grid: OccupancyView,
                         fraction: float = 2.0 / 3.0) -> float | None:
    """Time of the first occupied sample of the curve over ``[0, fraction * duration)``,
    sampled at most half a voxel apart (the control-polygon length bounds the curve
    length); None if free. EGO's final check, which samples about one voxel apart along the
    start-end chord and so can step over the corner of an inflated obstacle."""
    q = spline.control_points
    length = float(np.sum(np.linalg.norm(np.diff(q, axis=0), axis=1)))
    horizon = fraction * spline.duration
    n = max(int(math.ceil(2.0 * length / grid.resolution)), 1)
    t = np.arange(n) * (horizon / n)
    occ = grid.is_occupied(spline.position(t))
    hit = np.flatnonzero(occ)
    return float(t[hit[0]]) if hit.size else None


# ---------------------------------------------------------------------------------------
# the optimiser
# ---------------------------------------------------------------------------------------
class EgoStatus(enum.Enum):
    SUCCESS = "success"
    COLLISION_AT_START = "collision_at_start"  # the curve collides within the first span
    TERMINAL_IN_OBSTACLE = "terminal_in_obstacle"  # no free control point after a collision
    TOO_MANY_REBOUNDS = "too_many_rebounds"
    STILL_COLLIDING = "still_colliding"  # collides after max_rounds solves
    REFINE_COLLIDES = "refine_collides"  # the re-timed trajectory collides


@dataclass(frozen=True, eq=False)
class EgoResult:
    """Outcome of an optimisation: the trajectory (also on failure), its feasibility, and
    counters (rebounds, solve rounds, L-BFGS iterations and cost evaluations, A* calls,
    anchor pairs), wall time and, for refinements, ``info["ratio"]``."""

    status: EgoStatus
    spline: BSpline  # the last trajectory, also on failure
    feasibility: Feasibility
    rebounds: int = 0
    rounds: int = 0
    iterations: int = 0
    evaluations: int = 0
    astar_calls: int = 0
    refined: bool = False
    time_s: float = 0.0
    anchors: int = 0
    info: dict = field(default_factory=dict)

    @property
    def success(self) -> bool:
        return self.status is EgoStatus.SUCCESS


class EgoOptimizer:
    """EGO's B-spline optimiser over an
    :class:`~ft_sitl.navigation.planners.astar.OccupancyView`."""

    def __init__(self, grid: OccupancyView, params: EgoParams | None = None):
        if not isinstance(grid, OccupancyView):
            raise TypeError("grid must be an OccupancyView (wrap occupied(points) and the "
                            "resolution)")
        self.grid = grid
        self.params = params if params is not None else EgoParams()
        # searches repeated on an unchanged map (the rounds and rebounds of one
        # optimisation, failed plans retried from the same place) are answered once
        self.astar_memo = AStarMemo()

    # ---- helpers -----------------------------------------------------------------------
    def _astar(self, a: np.ndarray, b: np.ndarray):
        return search(a, b, self.grid, max_expansions=self.params.astar_max_expansions,
                      memo=self.astar_memo)

    def _add_segments(self, q: np.ndarray, segments, anchors: Anchors, stats: dict) -> int:
        """A* + anchors for each stretch; stretches whose A* fails are skipped. Returns the
        number of stretches that got new pairs."""
        added = 0
        for seg in segments:
            stats["astar_calls"] += 1
            res = self._astar(q[seg[0]], q[seg[1]])
            if not res.found:
                continue
            before = len(anchors)
            anchors_for_segment(q, seg, res.path, self.grid, anchors)
            added += len(anchors) > before
        return added

    def _new_collisions(self, q: np.ndarray, anchors: Anchors):
        """Stretches around control points that are occupied and not behind any of their
        planes (EGO's ``check_collision_and_rebound``); None if a stretch has no free point
        after it (the end is in an obstacle)."""
        n = q.shape[0]
        i_end = check_end_index(n)
        occ = self.grid.is_occupied(q)
        res = self.grid.resolution
        segments = []
        i = ORDER - 1
        while i <= i_end:
            if occ[i] and not anchors.behind_a_plane(i, q[i], res):
                free_before = np.flatnonzero(~occ[:i])
                in_id = int(free_before[-1]) if free_before.size else 0
                free_after = np.flatnonzero(~occ[i + 1:])
                if free_after.size == 0:
                    return None
                out_id = i + 1 + int(free_after[0])
                segments.append((in_id, out_id))
                i = out_id + 1
            else:
                i += 1
        return segments

    def _cost_args(self, mode: int, dt: float, w_col: float, anchors: Anchors | None = None,
                   ref: np.ndarray | None = None) -> tuple:
        p = self.params
        n = anchors.n_points if anchors is not None else ref.shape[0] + 2
        if anchors is not None:
            idx, ap, av = anchors.arrays(ORDER, n - ORDER)
        else:
            idx, ap, av = np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3))
        if ref is None:
            ref_a, tan = np.zeros((0, 3)), np.zeros((0, 3))
        else:
            ref_a, tan = np.ascontiguousarray(ref, dtype=float), fitness_tangents(ref)
        w = np.array([p.w_smooth, w_col, p.w_feasibility, p.w_fitness], dtype=float)
        return (mode, w, p.clearance, float(dt), p.max_vel, p.max_acc, idx, ap, av, ref_a, tan,
                p.fitness_along, p.fitness_across)

    # ---- public ------------------------------------------------------------------------
    def rebound(self, spline: BSpline) -> EgoResult:
        """EGO's ``BsplineOptimizeTrajRebound`` (with ``initControlPoints`` first)."""
        t0 = time.perf_counter()
        self._check_spline(spline)
        p = self.params
        q = np.array(spline.control_points)
        dt = spline.dt
        n = q.shape[0]
        anchors = Anchors(n)
        stats = {"astar_calls": 0}
        self._add_segments(q, colliding_segments(q, self.grid), anchors, stats)
        w_col = p.w_collision
        rebounds = rounds = iterations = evaluations = 0
        status = None
        while status is None:
            solver = _Lbfgs(q, p.lbfgs_memory, p.max_iterations, p.g_epsilon_rebound,
                            self._cost_args(0, dt, w_col, anchors=anchors),
                            check_smooth=p.rebound_smoothness)
            interrupted = False
            while True:
                code = solver.run()
                if code != _PAUSED:
                    break
                segs = self._new_collisions(q, anchors)
                if segs is None:
                    status = EgoStatus.TERMINAL_IN_OBSTACLE
                    break
                if segs and self._add_segments(q.copy(), segs, anchors, stats) > 0:
                    interrupted = True
                    break
            iterations += solver.iterations
            evaluations += solver.evaluations
            if status is not None:
                break
            if interrupted:
                rebounds += 1
                if rebounds > p.max_rebounds:
                    status = EgoStatus.TOO_MANY_REBOUNDS
                continue
            rounds += 1
            out = spline.with_control_points(q)
            t_hit = first_collision_time(out, self.grid)
            if t_hit is None:
                status = EgoStatus.SUCCESS
                break
            if t_hit <= dt:
                status = EgoStatus.COLLISION_AT_START
                break
            if rounds >= p.max_rounds:
                status = EgoStatus.STILL_COLLIDING
                break
            self._add_segments(q.copy(), colliding_segments(q, self.grid), anchors, stats)
            w_col *= 2.0
        out = spline.with_control_points(q)
        return EgoResult(status=status, spline=out,
                         feasibility=out.feasibility(p.max_vel, p.max_acc,
                                                     p.feasibility_tolerance),
                         rebounds=rebounds, rounds=rounds, iterations=iterations,
                         evaluations=evaluations, astar_calls=stats["astar_calls"],
                         time_s=time.perf_counter() - t0, anchors=len(anchors))

    def refine(self, spline: BSpline, v0, v1, a0, a1,
               ratio: float | None = None) -> EgoResult:
        """EGO's ``refineTrajAlgo``: stretch time by ``ratio`` (default the spline's
        feasibility ratio, at least 1), re-fit the knot positions with the end derivatives
        ``v0, v1, a0, a1`` and optimise smoothness + fitness + feasibility. Success means
        the first 2/3 of the result is collision-free."""
        t0 = time.perf_counter()
        self._check_spline(spline)
        p = self.params
        if ratio is None:
            ratio = spline.feasibility(p.max_vel, p.max_acc).ratio
        ratio = max(float(ratio), 1.0)
        fitted = BSpline.fit(spline.knot_points(), spline.dt * ratio, v0, v1, a0, a1)
        ref = fitted.knot_points()
        q = np.array(fitted.control_points)
        dt = fitted.dt

        solver = _Lbfgs(q, p.lbfgs_memory, p.max_iterations, p.g_epsilon_refine,
                        self._cost_args(1, dt, 0.0, ref=ref))
        solver.run()
        it, ev = solver.iterations, solver.evaluations
        out = fitted.with_control_points(q)
        free = first_collision_time(out, self.grid) is None
        return EgoResult(status=EgoStatus.SUCCESS if free else EgoStatus.REFINE_COLLIDES,
                         spline=out,
                         feasibility=out.feasibility(p.max_vel, p.max_acc,
                                                     p.feasibility_tolerance),
                         rounds=1, iterations=it, evaluations=ev, refined=True,
                         time_s=time.perf_counter() - t0, info={"ratio": ratio})

    def optimize(self, spline: BSpline, v0, v1, a0, a1) -> EgoResult:
        """EGO's ``reboundReplan`` steps 2-3: :meth:`rebound`; if the result is infeasible
        (beyond ``feasibility_tolerance``), :meth:`refine` it with the end derivatives
        ``v0, v1, a0, a1`` (those the initial fit used)."""
        t0 = time.perf_counter()
        first = self.rebound(spline)
        if not first.success or first.feasibility.ok:
            return first
        second = self.refine(first.spline, v0, v1, a0, a1, first.feasibility.ratio)
        info = dict(second.info)
        info["rebound_time_s"] = first.time_s
        return EgoResult(status=second.status, spline=second.spline,
                         feasibility=second.feasibility, rebounds=first.rebounds,
                         rounds=first.rounds, iterations=first.iterations + second.iterations,
                         evaluations=first.evaluations + second.evaluations,
                         astar_calls=first.astar_calls, refined=True,
                         time_s=time.perf_counter() - t0, anchors=first.anchors, info=info)

    @staticmethod
    def _check_spline(spline: BSpline) -> None:
        if spline.degree != ORDER:
            raise ValueError(f"EGO optimises cubic B-splines, got degree {spline.degree}")
        if spline.num_control_points < 2 * ORDER + 1:
            raise ValueError(f"need at least {2 * ORDER + 1} control points (3 fixed at each "
                             f"end), got {spline.num_control_points}")
