"""Fast-Planner's back end: ESDF-based B-spline optimisation, time re-allocation, yaw.

Behaviours and defaults are Fast-Planner's (Zhou et al., RA-L 2019;
HKUST-Aerial-Robotics/Fast-Planner: ``bspline_optimizer``, ``non_uniform_bspline``,
``planner_manager``; see /work/shared/docs/planner-facts.md); the code is our own.

Optimisation (:class:`FastOptimizer`). The trajectory is a uniform cubic B-spline with knot
span ``ts`` and control points ``Q[0..N-1]`` (the least-squares fit of the kinodynamic
search's samples). The first three control points are fixed (they pin the start state);
the last three are fixed too when the search reached the goal, and free when it stopped at
its horizon (then an endpoint term keeps the curve's end near where the search ended). The
cost, with analytic gradients w.r.t. the whole ``(N, 3)`` array:

- smoothness ``sum_i ||Q[i+3] - 3 Q[i+2] + 3 Q[i+1] - Q[i]||^2`` (jerk form, unscaled),
  weight ``w_smooth`` = 10 (``lambda1``);
- distance ``sum_i (d_i - d0)^2`` over the control points with ``d_i < d0``, where ``d_i`` is
  the map's ESDF at ``Q[i]`` (trilinear interpolation, :meth:`LocalMap.esdf`), ``d0`` = 0.4 m
  (``dist0``), over the free points ``Q[3] .. Q[N-4]`` (``Q[N-1]`` with a free end), weight
  ``w_distance`` = 5 (``lambda2``);
- feasibility per axis on the velocity control points ``V = (Q[i+1] - Q[i]) / ts`` and the
  acceleration control points ``A = (Q[i+2] - 2 Q[i+1] + Q[i]) / ts^2``:
  ``(V^2 - vmax^2)^2`` where ``|V| > vmax``, ``(A^2 - amax^2)^2`` where ``|A| > amax``, weight
  ``w_feasibility`` = 1e-5 (``lambda3``: nearly nothing; time re-allocation does the work);
- endpoint (free end only) ``||(Q[N-3] + 4 Q[N-2] + Q[N-1]) / 6 - p_end||^2`` with ``p_end``
  the initial curve's end, weight ``w_endpoint`` = 0.01 (``lambda4``).

The solver is the shared numba L-BFGS (:mod:`.lbfgs`; memory ``lbfgs_memory``, a
Lewis-Overton weak-Wolfe line search) with Fast-Planner's rules
(:meth:`FastParams.lbfgs_rules`), stopped after ``max_evaluations`` (300,
``max_iteration_num2``) cost evaluations or when a step changes the variables by less than
``xtol_rel`` (1e-5) of their norm, as Fast-Planner's NLopt L-BFGS (``set_maxeval``,
``set_xtol_rel``). Like the original it returns the best point evaluated
(``best_variable_``), not the last.

Differences from the original, on purpose:

- the distance gradient is the exact gradient of the interpolated ESDF; the original
  normalises the ESDF gradient to unit length (an ESDF's gradient has norm ~1 almost
  everywhere, so the directions agree), which makes the reported gradient inconsistent with
  the cost and confuses the line search;
- no wall-clock cap (the original also stops after 5 ms): deterministic; the evaluation cap
  binds first at our problem sizes (a solve takes a few ms in numba).

Time re-allocation (:meth:`KnotBSpline.reallocate_time`, the original's ``reallocateTime``):
the optimised curve becomes a non-uniform B-spline (:class:`KnotBSpline`); every velocity
control point ``p (Q[i+1] - Q[i]) / (u[i+4] - u[i+1])`` beyond ``vmax`` on an axis lengthens
the three knot intervals it spans, together by ``min(max|V| / vmax + 1e-4, 1.1)``; every
acceleration control point beyond ``amax`` its two intervals by ``min(sqrt(max|A| / amax) +
1e-4, 1.1)`` (the original's special case for ``i = 1, 2`` included: it lengthens the first
four intervals); later knots shift. One interval belongs to up to three control points, so
one pass can lengthen it by more than 1.1. The navigator runs up to three passes, as the
planner manager, and flies the result even if still infeasible (the original does).
Options, both on in the navigator: ``vel_norm`` bounds the velocity control points' norm
(the benchmark's speed cap is a speed, and per-axis limits allow 4 sqrt 2 m/s on a
diagonal, which the autopilot's cap turns into a growing tracking lag); ``keep_start``
leaves alone the first five knot intervals, which shape the curve's position, velocity and
acceleration at its start: the original stretches them too, so a re-timed plan starts
slower than the state it was planned from (3.8 -> 2.9 m/s in Perlin 2, a jump the
autopilot must absorb).

Yaw (:func:`plan_yaw`, the planner manager's ``planYaw``): a 1-D uniform cubic B-spline with
knot span ~0.3 s over the position trajectory's duration; waypoint ``k`` (at ``t_k = k dt``)
is the heading from ``p(t_k)`` to ``p(min(t_k + 2 s, T))``, unwrapped to the previous one;
the first three control points pin the start (yaw, rate, acceleration), the last three the
heading of the velocity 0.1 s before the end (rate and acceleration 0); the interior points
minimise ``10 smoothness + 100 sum_k ((y[k] + 4 y[k+1] + y[k+2]) / 6 - w_k)^2``. The cost is
quadratic, so instead of the original's NLopt solve we solve it exactly (linear least
squares).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.interpolate import BSpline

from ft_sitl.navigation.maps.esdf import EsdfGrid
from ft_sitl.navigation.optimisers.lbfgs import (
    CONVERGED,
    EVALUATE,
    EVALUATIONS,
    F_BEST,
    F_TRIAL,
    ITERATED,
    ITERATIONS,
    LINE_SEARCH,
    MAX_EVALUATIONS,
    ZERO_GRADIENT,
    LbfgsRules,
    StopRule,
    advance,
    put_rows,
    take_rows,
)
from ft_sitl.navigation.optimisers.penalties import (
    as_points,
    endpoint,
    esdf_distance,
    fast_planner_cost,
    feasibility,
    smoothness_cost,
)
from ft_sitl.navigation.trajectories.base import Trajectory
from ft_sitl.navigation.trajectories.bspline import UniformBSpline

__all__ = [
    "FastOptimizer", "FastParams", "FastResult", "KnotBSpline", "cost_terms",
    "distance_cost", "endpoint_cost", "feasibility_cost", "minimise",
    "plan_yaw", "smoothness_cost", "total_cost",
]

ORDER = 3
#: knot intervals 0 .. 4 of a cubic B-spline shape its state (position, velocity,
#: acceleration) at the start of its domain, u[3]
START_INTERVALS = 5


@dataclass(frozen=True)
class FastParams:
    """Fast-Planner's optimiser parameters (``kino_algorithm.xml``)."""

    max_vel: float = 4.0  # m/s, per axis; the benchmark's cap (Fast-Planner default 3)
    max_acc: float = 2.0  # m/s^2, per axis (Fast-Planner default)
    w_smooth: float = 10.0  # lambda1
    w_distance: float = 5.0  # lambda2
    w_feasibility: float = 1e-5  # lambda3
    w_endpoint: float = 0.01  # lambda4
    dist0: float = 0.4  # m, ESDF distance below which control points are pushed
    max_evaluations: int = 300  # max_iteration_num2
    xtol_rel: float = 1e-5
    lbfgs_memory: int = 10
    limit_ratio: float = 1.1  # bspline/limit_ratio, per re-allocation of one control point
    realloc_passes: int = 3

    def __post_init__(self):
        for name in ("max_vel", "max_acc", "dist0", "xtol_rel"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v <= 0:
                raise ValueError(f"FastParams.{name} must be a positive number, got {v!r}")
        for name in ("w_smooth", "w_distance", "w_feasibility", "w_endpoint"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0:
                raise ValueError(f"FastParams.{name} must be a number >= 0, got {v!r}")
        if not (isinstance(self.limit_ratio, (int, float)) and self.limit_ratio > 1.0):
            raise ValueError(f"FastParams.limit_ratio must be > 1, got {self.limit_ratio!r}")
        for name in ("max_evaluations", "lbfgs_memory", "realloc_passes"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"FastParams.{name} must be a positive integer, got {v!r}")

    def lbfgs_rules(self) -> LbfgsRules:
        """The solve's rules (Fast-Planner's NLopt L-BFGS): stop after ``max_evaluations``
        cost evaluations or when a step is shorter than ``xtol_rel`` times the point's
        norm; the best point evaluated is the result."""
        return LbfgsRules(memory=self.lbfgs_memory, stop=StopRule.STEP,
                          tolerance=self.xtol_rel, max_evaluations=self.max_evaluations,
                          keep_best=True)


# ---------------------------------------------------------------------------------------
# the solve: the shared L-BFGS (optimisers.lbfgs) on Fast-Planner's cost (PGO's too)
# ---------------------------------------------------------------------------------------
@njit(cache=True)
def minimise(st, q, lo, hi, w, ts, vmax, amax, d0, free_end, end_pt, field, origin, inv_res,
             unit_gradient):
    """Drive the L-BFGS state ``st`` (:mod:`.lbfgs`) over rows ``lo:hi`` of ``q`` (in place)
    on :func:`~ft_sitl.navigation.optimisers.penalties.fast_planner_cost`; ``q`` ends at
    ``st.best`` (the rules keep the best point evaluated, as Fast-Planner's
    ``best_variable_``). Returns the stop code."""
    grad = np.zeros_like(q)
    terms = np.zeros(4)
    code = advance(st)
    while code == EVALUATE or code == ITERATED:
        if code == EVALUATE:
            put_rows(st.xn, q, lo, hi)
            st.reals[F_TRIAL] = fast_planner_cost(q, grad, w, ts, vmax, amax, d0, free_end,
                                                  end_pt, field, origin, inv_res,
                                                  unit_gradient, terms)
            take_rows(grad, st.gn, lo, hi)
        code = advance(st)
    put_rows(st.best, q, lo, hi)
    return code


# ---------------------------------------------------------------------------------------
# Python wrappers (tests, diagnostics)
# ---------------------------------------------------------------------------------------
def distance_cost(q, esdf: EsdfGrid, dist0: float = 0.4, first: int = ORDER,
                  last: int | None = None) -> tuple[float, np.ndarray]:
    """``sum (d - dist0)^2`` over control points ``first .. last - 1`` (default: ``N - 3``)
    whose ESDF distance ``d`` is below ``dist0``, and its gradient (N, 3)."""
    q = as_points(q)
    n = q.shape[0]
    last = n - ORDER if last is None else int(last)
    g = np.zeros_like(q)
    f = esdf_distance(q, int(first), last, esdf.field, esdf.origin, 1.0 / esdf.resolution,
                      float(dist0), 1.0, g, False)
    return float(f), g


def feasibility_cost(q, ts: float, vmax: float, amax: float) -> tuple[float, np.ndarray]:
    """Per-axis ``(V^2 - vmax^2)^2`` and ``(A^2 - amax^2)^2`` beyond the limits."""
    q = as_points(q)
    g = np.zeros_like(q)
    return float(feasibility(q, float(ts), float(vmax), float(amax), 1.0, g)), g


def endpoint_cost(q, end_pt) -> tuple[float, np.ndarray]:
    """``||(Q[N-3] + 4 Q[N-2] + Q[N-1]) / 6 - end_pt||^2``."""
    q = as_points(q)
    g = np.zeros_like(q)
    e = np.asarray(end_pt, dtype=np.float64).reshape(3)
    return float(endpoint(q, e, 1.0, g)), g


def _weights(p: FastParams) -> np.ndarray:
    return np.array([p.w_smooth, p.w_distance, p.w_feasibility, p.w_endpoint])


def total_cost(q, ts: float, esdf: EsdfGrid, params: FastParams | None = None,
               free_end: bool = False, end_pt=None) -> tuple[float, np.ndarray]:
    """The weighted sum the optimiser minimises and its gradient (N, 3) (gradients of the
    fixed rows included)."""
    p = params or FastParams()
    q = as_points(q)
    g = np.zeros_like(q)
    e = _curve_end(q) if end_pt is None else np.asarray(end_pt, dtype=np.float64).reshape(3)
    f = fast_planner_cost(q, g, _weights(p), float(ts), p.max_vel, p.max_acc, p.dist0,
                          bool(free_end), e, esdf.field, esdf.origin, 1.0 / esdf.resolution,
                          False, np.zeros(4))
    return float(f), g


def cost_terms(q, ts: float, esdf: EsdfGrid, params: FastParams | None = None,
               free_end: bool = False, end_pt=None) -> dict:
    """The unweighted terms {smooth, distance, feasibility, endpoint} and the total."""
    p = params or FastParams()
    q = as_points(q)
    e = _curve_end(q) if end_pt is None else np.asarray(end_pt, dtype=np.float64).reshape(3)
    terms = np.zeros(4)
    f = fast_planner_cost(q, np.zeros_like(q), _weights(p), float(ts), p.max_vel, p.max_acc,
                          p.dist0, bool(free_end), e, esdf.field, esdf.origin,
                          1.0 / esdf.resolution, False, terms)
    return {"smooth": float(terms[0]), "distance": float(terms[1]),
            "feasibility": float(terms[2]), "endpoint": float(terms[3]), "total": float(f)}


def _curve_end(q: np.ndarray) -> np.ndarray:
    return (q[-3] + 4.0 * q[-2] + q[-1]) / 6.0


# ---------------------------------------------------------------------------------------
# the optimiser
# ---------------------------------------------------------------------------------------
_STOP = {MAX_EVALUATIONS: "evaluation_cap", CONVERGED: "xtol", ZERO_GRADIENT: "zero_gradient",
         LINE_SEARCH: "line_search"}


@dataclass(frozen=True, eq=False)
class FastResult:
    """An optimised uniform B-spline with the solver's counters."""

    spline: UniformBSpline
    evaluations: int
    iterations: int
    cost: float
    initial_cost: float
    stop: str
    free_end: bool
    time_s: float


class FastOptimizer:
    """Fast-Planner's ``BsplineOptimizer`` in its ``NORMAL_PHASE`` (+ ``ENDPOINT``)."""

    def __init__(self, params: FastParams | None = None):
        self.params = params if params is not None else FastParams()
        if not isinstance(self.params, FastParams):
            raise TypeError(f"params must be a FastParams, got {type(params).__name__}")

    def optimize(self, spline: UniformBSpline, esdf: EsdfGrid,
                 free_end: bool = False) -> FastResult:
        """Optimise the interior control points of ``spline`` (and its last three with
        ``free_end``) against ``esdf``; the knot span is kept."""
        t0 = time.perf_counter()
        if spline.degree != ORDER:
            raise ValueError(f"Fast-Planner optimises cubic B-splines, got {spline.degree}")
        n = spline.num_control_points
        if n < 2 * ORDER + 1:
            raise ValueError(f"need at least {2 * ORDER + 1} control points, got {n}")
        p = self.params
        q = np.array(spline.control_points, dtype=np.float64)
        end_pt = _curve_end(q)
        f_init, _ = total_cost(q, spline.dt, esdf, p, free_end, end_pt)
        hi = n if free_end else n - ORDER
        st = p.lbfgs_rules().start(q[ORDER:hi])
        code = minimise(st, q, ORDER, hi, _weights(p), spline.dt, p.max_vel, p.max_acc,
                        p.dist0, bool(free_end), end_pt, esdf.field, esdf.origin,
                        1.0 / esdf.resolution, False)
        return FastResult(spline=spline.with_control_points(q),
                          evaluations=int(st.ints[EVALUATIONS]),
                          iterations=int(st.ints[ITERATIONS]), cost=float(st.reals[F_BEST]),
                          initial_cost=f_init, stop=_STOP[int(code)], free_end=bool(free_end),
                          time_s=time.perf_counter() - t0)


# ---------------------------------------------------------------------------------------
# non-uniform B-splines and time re-allocation
# ---------------------------------------------------------------------------------------
@njit(cache=True)
def _deboor(t, c, k, x, out):
    """The spline (knots t, coefficients c (n, d), degree k) at x in [t[k], t[n]] (the
    last span closed at its right end, as scipy's BSpline) into out (d,)."""
    n = c.shape[0]
    i = k
    while i < n - 1 and t[i + 1] <= x:
        i += 1
    d = c.shape[1]
    work = np.empty((k + 1, d))
    for j in range(k + 1):
        for a in range(d):
            work[j, a] = c[i - k + j, a]
    for r in range(1, k + 1):
        for j in range(k, r - 1, -1):
            lo = t[i - k + j]
            hi = t[i + 1 + j - r]
            alpha = (x - lo) / (hi - lo)
            for a in range(d):
                work[j, a] = (1.0 - alpha) * work[j - 1, a] + alpha * work[j, a]
    for a in range(d):
        out[a] = work[k, a]


class KnotBSpline(Trajectory):
    """A cubic B-spline with an arbitrary (non-decreasing) knot vector ``u`` of ``N + 4``
    knots over control points ``(N, d)``; time ``t`` runs from 0 at ``u[3]`` to
    ``duration = u[N] - u[3]`` (Fast-Planner's ``evaluateDeBoorT``), evaluation clamps to
    that domain. Immutable.

    Still a second B-spline class beside
    :class:`~ft_sitl.navigation.trajectories.bspline.UniformBSpline` (issue 42, point 3,
    left open): this one evaluates by de Boor (scipy's BSpline, :func:`_deboor`) and takes
    velocity control points from knot differences (``3 diff(c) / (u[i+4] - u[i+1])``), the
    uniform one by the matrix form and ``diff(c) / dt``: the same curve in different
    floating-point operations, and Fast-Planner's rows were flown with this arithmetic even
    on uniform knots (a plan needing no re-timing, built by :meth:`from_uniform`). One class
    must therefore take its evaluation (matrix form or de Boor, and with it the
    derivative-control-point arithmetic) as a constructor argument, not infer it from its
    knots, and keep this one's ``(N, d)`` control points (the 1-D yaw curve) and cubic-only
    re-timing. Nothing stops that merge bit for bit; it was not done in the change that
    merged the L-BFGS loops (time), so the two classes stay, both implementing
    :class:`~ft_sitl.navigation.trajectories.base.Trajectory`."""

    __slots__ = ("_c", "_u", "_b", "_tck")

    def __init__(self, control_points, knots):
        c = np.array(control_points, dtype=np.float64)
        if c.ndim == 1:
            c = c[:, None]
        u = np.array(knots, dtype=np.float64).reshape(-1)
        if c.ndim != 2 or c.shape[0] < ORDER + 1:
            raise ValueError(f"control_points: need (N >= 4, d), got {c.shape}")
        if u.shape != (c.shape[0] + ORDER + 1,):
            raise ValueError(f"knots: need {c.shape[0] + ORDER + 1}, got {u.shape}")
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(u))):
            raise ValueError("control points and knots must be finite")
        if np.any(np.diff(u) <= 0.0):
            raise ValueError("knots must be strictly increasing")
        c.setflags(write=False)
        u.setflags(write=False)
        self._c, self._u = c, u
        b0 = BSpline(u, c, ORDER, extrapolate=False)
        self._b = (b0, b0.derivative(1), b0.derivative(2), b0.derivative(3))
        # knots, coefficients (n, d) and degree of the spline and its first two derivatives
        self._tck = tuple((np.ascontiguousarray(b.t), np.ascontiguousarray(b.c), int(b.k))
                          for b in self._b[:3])

    @classmethod
    def uniform(cls, control_points, dt: float) -> KnotBSpline:
        """The uniform B-spline with knot span ``dt`` (knots ``(i - 3) dt``)."""
        c = np.asarray(control_points, dtype=np.float64)
        return cls(c, (np.arange(c.shape[0] + ORDER + 1) - ORDER) * float(dt))

    @classmethod
    def from_uniform(cls, spline: UniformBSpline) -> KnotBSpline:
        return cls.uniform(spline.control_points, spline.dt)

    @property
    def control_points(self) -> np.ndarray:
        return self._c

    @property
    def knots(self) -> np.ndarray:
        return self._u

    @property
    def duration(self) -> float:
        n = self._c.shape[0]
        return float(self._u[n] - self._u[ORDER])

    def evaluate(self, t, order: int = 0) -> np.ndarray:
        """The ``order``-th derivative at ``t`` (clamped to [0, duration]); ``(d,)`` for a
        scalar, ``(M, d)`` for an array."""
        x = np.clip(np.asarray(t, dtype=np.float64), 0.0, self.duration) + self._u[ORDER]
        n = self._c.shape[0]
        x = np.minimum(x, self._u[n])
        return self._b[order](x)

    def pva(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`evaluate` of orders 0, 1, 2 at one time ``t`` in one compiled call each
        (the 100 Hz setpoint path)."""
        n = self._c.shape[0]
        x = min(min(max(float(t), 0.0), self.duration) + self._u[ORDER], self._u[n])
        out = np.empty((3, self._c.shape[1]))
        for order, (tk, ck, k) in enumerate(self._tck):
            _deboor(tk, ck, k, x, out[order])
        return out[0], out[1], out[2]

    def velocity_control_points(self) -> np.ndarray:
        c, u = self._c, self._u
        n = c.shape[0]
        return ORDER * np.diff(c, axis=0) / (u[ORDER + 1:n + ORDER] - u[1:n])[:, None]

    def acceleration_control_points(self) -> np.ndarray:
        c, u = self._c, self._u
        n = c.shape[0]
        v = self.velocity_control_points()
        span = (u[ORDER + 1:n + ORDER - 1] - u[2:n])[:, None]
        return (ORDER - 1) * np.diff(v, axis=0) / span

    def feasible(self, vmax: float, amax: float, vel_norm: bool = False) -> bool:
        """Fast-Planner's ``checkFeasibility``: every velocity / acceleration control point
        within ``vmax`` / ``amax`` (+ 1e-4) on every axis (``vel_norm``: the velocity
        control points' Euclidean norm within ``vmax``)."""
        v = self.velocity_control_points()
        vm = np.linalg.norm(v, axis=1) if vel_norm else np.abs(v)
        return bool(np.all(vm <= vmax + 1e-4)
                    and np.all(np.abs(self.acceleration_control_points()) <= amax + 1e-4))

    def reallocate_time(self, vmax: float, amax: float, limit_ratio: float = 1.1,
                        vel_norm: bool = False,
                        keep_start: bool = True) -> tuple[KnotBSpline, bool]:
        """One pass of Fast-Planner's ``reallocateTime`` (module docstring): returns the
        re-timed spline and whether this pass found everything feasible (nothing changed).
        ``vel_norm`` bounds the velocity control points' norm instead of each axis;
        ``keep_start`` leaves the knot intervals that shape the start state (the first
        ``START_INTERVALS``) as they are, so the re-timed curve starts in the same position,
        velocity and acceleration (the original stretches them too)."""
        c = self._c
        h = np.diff(self._u)  # knot intervals; interval k is [u[k], u[k+1]]
        n = c.shape[0]
        p = ORDER
        frozen = START_INTERVALS if keep_start else 0

        def grow(k: int, dt: float) -> None:
            if k >= frozen:
                h[k] += dt

        feasible = True
        for i in range(n - 1):  # velocity control point i spans intervals i+1 .. i+3
            span = h[i + 1] + h[i + 2] + h[i + 3]
            v = p * (c[i + 1] - c[i]) / span
            vm = float(np.linalg.norm(v)) if vel_norm else float(np.max(np.abs(v)))
            if vm > vmax + 1e-4:
                feasible = False
                ratio = min(vm / vmax + 1e-4, limit_ratio)
                for k in range(i + 1, i + p + 1):
                    grow(k, (ratio - 1.0) * span / p)
        for i in range(n - 2):  # acceleration control point i spans intervals i+2, i+3
            v0 = (c[i + 1] - c[i]) / (h[i + 1] + h[i + 2] + h[i + 3])
            v1 = (c[i + 2] - c[i + 1]) / (h[i + 2] + h[i + 3] + h[i + 4])
            span = h[i + 2] + h[i + 3]
            a = p * (p - 1) * (v1 - v0) / span
            am = float(np.max(np.abs(a)))
            if am > amax + 1e-4:
                feasible = False
                ratio = min(math.sqrt(am / amax) + 1e-4, limit_ratio)
                inc = (ratio - 1.0) * span / (p - 1)
                # the original's special case for i = 1, 2: the first four intervals
                for k in (range(1, 5) if i in (1, 2) else range(i + 2, i + p)):
                    grow(k, inc)
        u = np.concatenate([[self._u[0]], self._u[0] + np.cumsum(h)])
        return KnotBSpline(c, u), feasible

    def retimed(self, vmax: float, amax: float, limit_ratio: float = 1.1, passes: int = 3,
                vel_norm: bool = False, keep_start: bool = True) -> tuple[KnotBSpline, int]:
        """The planner manager's loop: re-allocate while infeasible, at most ``passes``
        times. Returns the spline and the number of passes made."""
        out = self
        if out.feasible(vmax, amax, vel_norm):
            return out, 0
        k = 0
        while k < passes:
            out, ok = out.reallocate_time(vmax, amax, limit_ratio, vel_norm, keep_start)
            k += 1
            if ok:
                break
        return out, k


# ---------------------------------------------------------------------------------------
# yaw
# ---------------------------------------------------------------------------------------
def _next_yaw(last: float, yaw: float) -> float:
    """``yaw`` moved by a multiple of 2 pi to within pi of ``last`` (unwrapping)."""
    return last + (yaw - last + math.pi) % (2.0 * math.pi) - math.pi


def _states_to_points(state, dt: float) -> np.ndarray:
    """Three control points of a uniform cubic B-spline whose value, first and second
    derivative at their middle knot are ``state``."""
    y, yd, ydd = (float(s) for s in state)
    return np.array([y - dt * yd + dt * dt / 3.0 * ydd,
                     y - dt * dt / 6.0 * ydd,
                     y + dt * yd + dt * dt / 3.0 * ydd])


def plan_yaw(pos: KnotBSpline, start_state, dt_yaw: float = 0.3, forward_t: float = 2.0,
             w_smooth: float = 10.0, w_waypoint: float = 100.0) -> KnotBSpline:
    """Fast-Planner's ``planYaw`` (module docstring): a 1-D uniform B-spline over
    ``pos.duration`` starting in ``start_state`` (yaw, rate, acceleration); the yaw is
    continuous (not wrapped)."""
    duration = pos.duration
    seg = max(int(math.ceil(duration / dt_yaw - 1e-9)), ORDER)
    dt = duration / seg
    last = float(start_state[0])
    tc = np.arange(seg) * dt
    pc = pos.position(tc)
    pf = pos.position(np.minimum(tc + forward_t, duration))
    way = np.empty(seg)
    for k in range(seg):
        d = pf[k] - pc[k]
        if math.hypot(d[0], d[1]) > 1e-3:
            last = _next_yaw(last, math.atan2(d[1], d[0]))
        way[k] = last
    ve = pos.velocity(max(duration - 0.1, 0.0))
    end_yaw = _next_yaw(last, math.atan2(ve[1], ve[0])) if math.hypot(ve[0], ve[1]) > 1e-3 \
        else last
    n = seg + ORDER
    y = np.zeros(n)
    y[:3] = _states_to_points(start_state, dt)
    y[seg:] = _states_to_points((end_yaw, 0.0, 0.0), dt)
    free = np.arange(ORDER, seg)
    if free.size:
        rows, rhs = [], []
        ws, ww = math.sqrt(w_smooth), math.sqrt(w_waypoint)
        for i in range(n - 3):
            r = np.zeros(n)
            r[i:i + 4] = ws * np.array([-1.0, 3.0, -3.0, 1.0])
            rows.append(r)
            rhs.append(0.0)
        for k in range(seg):
            r = np.zeros(n)
            r[k:k + 3] = ww * np.array([1.0, 4.0, 1.0]) / 6.0
            rows.append(r)
            rhs.append(ww * way[k])
        a = np.array(rows)
        b = np.array(rhs)
        fixed = np.setdiff1d(np.arange(n), free)
        b = b - a[:, fixed] @ y[fixed]
        sol, *_ = np.linalg.lstsq(a[:, free], b, rcond=None)
        y[free] = sol
    return KnotBSpline.uniform(y[:, None], dt)
