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

Time re-allocation (:meth:`~ft_sitl.navigation.trajectories.bspline.BSpline.reallocate_time`,
the original's ``reallocateTime``): the optimised curve becomes a B-spline evaluated by de Boor
(``Evaluation.DE_BOOR``, as the original's ``NonUniformBspline``, even while its knots are
still uniform), whose knots the re-allocation then moves; every velocity
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
from ft_sitl.navigation.trajectories.bspline import BSpline, Evaluation

__all__ = [
    "FastOptimizer", "FastParams", "FastResult", "cost_terms",
    "distance_cost", "endpoint_cost", "feasibility_cost", "minimise",
    "plan_yaw", "smoothness_cost", "total_cost",
]

ORDER = 3


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

    spline: BSpline
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

    def optimize(self, spline: BSpline, esdf: EsdfGrid,
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


def plan_yaw(pos: BSpline, start_state, dt_yaw: float = 0.3, forward_t: float = 2.0,
             w_smooth: float = 10.0, w_waypoint: float = 100.0) -> BSpline:
    """Fast-Planner's ``planYaw`` (module docstring): a 1-D uniform B-spline (de Boor) over
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
    return BSpline(y[:, None], dt, evaluation=Evaluation.DE_BOOR)
