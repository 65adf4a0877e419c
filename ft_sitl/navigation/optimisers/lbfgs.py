"""The one L-BFGS of the trajectory optimisers (EGO, Fast-Planner and PGO), in numba.

It is written once, as a reverse-communication solver: :func:`advance` moves a
:class:`LbfgsState` on until it needs the cost at a point (``EVALUATE``: the caller writes
the value at ``state.xn`` into ``state.reals[F_TRIAL]`` and its gradient into ``state.gn``),
has accepted an iteration (``ITERATED``: the caller may look at the point, then calls
again), or stops (a stop code). So each optimiser keeps its cost in its own module and
drives the solver with a loop of a few lines (:func:`~ft_sitl.navigation.optimisers.ego`'s
``_solve``, :func:`~ft_sitl.navigation.optimisers.fast.minimise`), and numba can cache
every kernel (a cost passed in as a function argument is typed by the function object,
and such kernels are recompiled in every process).

The variables are a flat vector; the optimisers' free control-point rows ``lo:hi`` of an
``(N, 3)`` array are that vector row by row (:func:`put_rows`, :func:`take_rows`: copies,
no arithmetic). One iteration: the two-loop recursion over the stored pairs (initial
Hessian scaled by the newest pair; a direction that is not a descent direction drops the
memory and becomes ``-g``); a first step of 1, or ``min(1, 1 / ||g||)`` with no memory;
the one line search, Lewis-Overton weak Wolfe bracketing (Armijo ``c1`` = 1e-4, curvature
``c2`` = 0.9: bisect a bracket once the upper end is known, double the step before);
the memory update (a pair is kept when ``y . s > 1e-16``); the stop rule.

Where the three planners' loops differ, :class:`LbfgsRules` says which (each optimiser's
rows are re-flown bit for bit, so each keeps its floating-point operations):

==================  ===================  ====================  ========================
rule                EGO                  Fast-Planner          PGO
==================  ===================  ====================  ========================
dot products        row loop (``ROWS``)  row loop              numpy's ``np.dot`` (BLAS)
stop rule           ``GRADIENT``         ``STEP``              ``VARIABLES``
budget              200 iterations       300 evaluations       300 evaluations
line-search trials  40                   40                    until the evaluation cap
step range          1e-20 .. 1e20        1e-16 .. 1e16         1e-16 .. 1e16
result              the last iterate     the best evaluated    the best evaluated
NaN trial           rejected (bisect)    rejected              passes Armijo
==================  ===================  ====================  ========================

``ROWS`` sums ``a[i] * b[i]`` in index order; BLAS ddot sums in blocks with several partial
sums, so the two differ in the last bits and a planner keeps the one it was flown with.
The stop rules, each with the guard its original had:

- ``GRADIENT`` (EGO's lbfgs): ``||g|| <= tol max(1, ||x||)``, checked at the start and
  after every iteration;
- ``STEP`` (NLopt's ``xtol_rel`` on the step norm, Fast-Planner): ``||s|| <= tol ||x||``
  after an iteration; before each iteration a gradient with ``g . g <= 1e-24`` stops
  (``ZERO_GRADIENT``);
- ``VARIABLES`` (per-variable ``xtol_rel``, PGO): stop when no variable moved by more than
  ``tol (|x_new| + |x_old|) / 2``; a direction whose slope is exactly 0 stops
  (``ZERO_GRADIENT``).

PGO's Armijo test ``f > f0 + c1 step g.d`` lets a NaN cost through (then its curvature
test accepts the point and its stop rule ends the solve); EGO's and Fast-Planner's
``not f <= f0 + c1 step g.d`` rejects it and bisects. A line search that runs out of
trials or leaves the step range fails (``LINE_SEARCH``, or ``MAX_EVALUATIONS`` when the
evaluation cap ended it) and leaves the point where it was.
"""

from __future__ import annotations

import enum
import math
from collections import namedtuple
from dataclasses import dataclass

import numpy as np
from numba import njit

__all__ = [
    "EVALUATE", "ITERATED", "LINE_SEARCH", "MAX_EVALUATIONS", "MAX_ITERATIONS", "CONVERGED",
    "UNLIMITED", "ZERO_GRADIENT", "LbfgsRules", "LbfgsState", "StopRule", "advance",
    "put_rows", "take_rows",
]

#: what :func:`advance` returns when it is not done
EVALUATE, ITERATED = -1, -2
#: why it stopped
MAX_ITERATIONS, MAX_EVALUATIONS, CONVERGED, ZERO_GRADIENT, LINE_SEARCH = 0, 1, 2, 3, 4
#: no cap (iterations, evaluations, line-search trials)
UNLIMITED = int(np.iinfo(np.int64).max)

_C1, _C2 = 1e-4, 0.9  # Armijo and weak-Wolfe curvature constants (EGO's ftol, wolfe)
_ZERO_GG = 1e-24  # STEP's zero-gradient guard on g . g
_MIN_YS = 1e-16  # a pair (s, y) enters the memory when y . s is above this

# state.ints: the solver's counters and phase, then the integer rules
PHASE, ITERATIONS, EVALUATIONS, COUNT, HEAD, TRIALS, CODE = 0, 1, 2, 3, 4, 5, 6
_MAX_ITER, _MAX_EVALS, _LS_TRIALS, _RULE, _BLAS, _KEEP_BEST, _NAN_PASSES = 7, 8, 9, 10, 11, 12, 13
# state.reals: the cost at x, the best cost, the caller's answer, the line search, the rules
F, F_BEST, F_TRIAL, _DG, _STEP, _S_LO, _S_HI, _TOL, _STEP_MIN, _STEP_MAX = range(10)
# StopRule's values inside the kernels
_GRADIENT, _STEP_NORM, _VARIABLES = 0, 1, 2
# phases
_START, _STARTED, _DIRECTION, _TRIAL, _DONE = 0, 1, 2, 3, 4


class StopRule(enum.IntEnum):
    """Which stop rule :func:`advance` applies (module docstring)."""

    GRADIENT = 0  # EGO
    STEP = 1  # Fast-Planner
    VARIABLES = 2  # PGO


#: a solve's arrays: ``ints`` / ``reals`` (counters, line search, rules: the index
#: constants), the point ``x``, its gradient ``g``, the direction ``d``, the point to
#: evaluate ``xn`` and its gradient ``gn`` (the caller's answer), the best point evaluated
#: ``best`` (with ``keep_best``), the memory ``S``, ``Y`` (pairs x rows), ``rho`` and the
#: two-loop scratch ``alpha``
LbfgsState = namedtuple("LbfgsState", "ints reals x g d xn gn best S Y rho alpha")


@dataclass(frozen=True)
class LbfgsRules:
    """What differs between the planners' solves (module docstring)."""

    memory: int  # stored pairs
    stop: StopRule
    tolerance: float  # of the stop rule
    max_iterations: int = UNLIMITED
    max_evaluations: int = UNLIMITED
    line_search_trials: int = 40
    step_min: float = 1e-16
    step_max: float = 1e16
    blas_dot: bool = False  # np.dot (BLAS) instead of the row loop
    keep_best: bool = False  # end at the lowest cost evaluated, not the last iterate
    nan_passes_armijo: bool = False  # PGO's ``f > bound`` test

    def __post_init__(self):
        for name in ("memory", "max_iterations", "max_evaluations", "line_search_trials"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"LbfgsRules.{name} must be a positive integer, got {v!r}")
        if not isinstance(self.stop, StopRule):
            raise TypeError(f"LbfgsRules.stop must be a StopRule, got {self.stop!r}")
        if not (math.isfinite(self.tolerance) and self.tolerance > 0):
            raise ValueError(f"LbfgsRules.tolerance must be positive, got {self.tolerance!r}")
        if not 0 < self.step_min < 1 < self.step_max:
            raise ValueError(f"LbfgsRules: need 0 < step_min < 1 < step_max, got "
                             f"{self.step_min!r}, {self.step_max!r}")

    def start(self, x0) -> LbfgsState:
        """A solve from ``x0`` (copied; flat)."""
        x = np.array(x0, dtype=np.float64).reshape(-1)
        nv = x.shape[0]
        ints = np.zeros(14, dtype=np.int64)
        ints[_MAX_ITER] = self.max_iterations
        ints[_MAX_EVALS] = self.max_evaluations
        ints[_LS_TRIALS] = self.line_search_trials
        ints[_RULE] = int(self.stop)
        ints[_BLAS] = int(self.blas_dot)
        ints[_KEEP_BEST] = int(self.keep_best)
        ints[_NAN_PASSES] = int(self.nan_passes_armijo)
        reals = np.zeros(10)
        reals[_TOL] = self.tolerance
        reals[_STEP_MIN] = self.step_min
        reals[_STEP_MAX] = self.step_max
        m = self.memory
        return LbfgsState(ints, reals, x, np.zeros(nv), np.zeros(nv), np.zeros(nv),
                          np.zeros(nv), x.copy(), np.zeros((m, nv)), np.zeros((m, nv)),
                          np.zeros(m), np.zeros(m))


@njit(cache=True)
def put_rows(x, q, lo, hi):
    """Rows ``lo:hi`` of the ``(N, 3)`` array ``q`` set from the flat vector ``x``."""
    k = 0
    for i in range(lo, hi):
        for a in range(3):
            q[i, a] = x[k]
            k += 1


@njit(cache=True)
def take_rows(q, x, lo, hi):
    """The flat vector ``x`` set from rows ``lo:hi`` of the ``(N, 3)`` array ``q``."""
    k = 0
    for i in range(lo, hi):
        for a in range(3):
            x[k] = q[i, a]
            k += 1


@njit(cache=True)
def _dot(a, b, blas):
    """``a . b``: numpy's (BLAS ddot) or summed in index order."""
    if blas:
        return np.dot(a, b)
    s = 0.0
    for i in range(a.shape[0]):
        s += a[i] * b[i]
    return s


@njit(cache=True)
def _copy(src, dst):
    for i in range(src.shape[0]):
        dst[i] = src[i]


@njit(cache=True)
def _direction(st, blas):
    """``d = -H g`` by the two-loop recursion over the stored pairs, initial Hessian scaled
    by the newest pair. Returns ``d . g``."""
    g, d, S, Y, rho, alpha = st.g, st.d, st.S, st.Y, st.rho, st.alpha
    count, head = st.ints[COUNT], st.ints[HEAD]
    m = S.shape[0]
    n = g.shape[0]
    for i in range(n):
        d[i] = -g[i]
    for c in range(count):
        j = (head - 1 - c) % m
        a = rho[j] * _dot(S[j], d, blas)
        alpha[j] = a
        for i in range(n):
            d[i] -= a * Y[j, i]
    if count > 0:
        j = (head - 1) % m
        gamma = 1.0 / (rho[j] * _dot(Y[j], Y[j], blas))
        for i in range(n):
            d[i] *= gamma
    for c in range(count - 1, -1, -1):
        j = (head - 1 - c) % m
        b = rho[j] * _dot(Y[j], d, blas)
        for i in range(n):
            d[i] += S[j, i] * (alpha[j] - b)
    return _dot(d, g, blas)


@njit(cache=True)
def _gradient_small(st, blas):
    """``GRADIENT``'s test at the current point."""
    return math.sqrt(_dot(st.g, st.g, blas)) <= st.reals[_TOL] * max(
        1.0, math.sqrt(_dot(st.x, st.x, blas)))


@njit(cache=True)
def _stop(st, code):
    st.ints[PHASE] = _DONE
    st.ints[CODE] = code
    return code


@njit(cache=True)
def _search_failed(st):
    """The line search gave up: the point stays where it was."""
    return _stop(st, MAX_EVALUATIONS if st.ints[EVALUATIONS] >= st.ints[_MAX_EVALS]
                 else LINE_SEARCH)


@njit(cache=True)
def _next_trial(st):
    """The line search's next trial ``x + step d`` (or its failure)."""
    ints = st.ints
    if ints[TRIALS] >= ints[_LS_TRIALS] or ints[EVALUATIONS] >= ints[_MAX_EVALS]:
        return _search_failed(st)
    x, d, xn = st.x, st.d, st.xn
    step = st.reals[_STEP]
    for i in range(x.shape[0]):
        xn[i] = x[i] + step * d[i]
    ints[TRIALS] += 1
    ints[PHASE] = _TRIAL
    return EVALUATE


@njit(cache=True)
def _iterate(st):
    """Start an iteration: budgets, direction, first step, then its first trial."""
    ints, reals = st.ints, st.reals
    blas = ints[_BLAS] != 0
    rule = ints[_RULE]
    if ints[ITERATIONS] >= ints[_MAX_ITER]:
        return _stop(st, MAX_ITERATIONS)
    if ints[EVALUATIONS] >= ints[_MAX_EVALS]:
        return _stop(st, MAX_EVALUATIONS)
    if rule == _STEP_NORM and _dot(st.g, st.g, blas) <= _ZERO_GG:
        return _stop(st, ZERO_GRADIENT)
    dg = _direction(st, blas)
    if not dg < 0.0:  # not a descent direction: drop the memory
        ints[COUNT] = 0
        g, d = st.g, st.d
        for i in range(g.shape[0]):
            d[i] = -g[i]
        dg = -_dot(g, g, blas)
    if rule == _VARIABLES and dg == 0.0:
        return _stop(st, ZERO_GRADIENT)
    reals[_DG] = dg
    reals[_STEP] = 1.0 if ints[COUNT] > 0 else min(1.0, 1.0 / math.sqrt(-dg))
    reals[_S_LO] = 0.0
    reals[_S_HI] = math.inf
    ints[TRIALS] = 0
    return _next_trial(st)


@njit(cache=True)
def _accept(st, fn, blas):
    """Take the trial: the memory update, the move, the stop rule."""
    ints, reals = st.ints, st.reals
    x, g, xn, gn, S, Y = st.x, st.g, st.xn, st.gn, st.S, st.Y
    rule = ints[_RULE]
    tol = reals[_TOL]
    m = S.shape[0]
    j = ints[HEAD]
    ys = 0.0
    ss = 0.0
    moved = False
    for i in range(x.shape[0]):
        S[j, i] = xn[i] - x[i]
        Y[j, i] = gn[i] - g[i]
        ys += S[j, i] * Y[j, i]
        ss += S[j, i] * S[j, i]
        if abs(S[j, i]) > tol * 0.5 * (abs(xn[i]) + abs(x[i])):
            moved = True
    if ys > _MIN_YS:
        st.rho[j] = 1.0 / ys
        ints[HEAD] = (j + 1) % m
        ints[COUNT] = min(ints[COUNT] + 1, m)
    _copy(xn, x)
    _copy(gn, g)
    reals[F] = fn
    ints[ITERATIONS] += 1
    ints[PHASE] = _DIRECTION
    if rule == _GRADIENT:
        if _gradient_small(st, blas):
            return _stop(st, CONVERGED)
    elif rule == _STEP_NORM:
        if math.sqrt(ss) <= tol * math.sqrt(_dot(x, x, blas)):
            return _stop(st, CONVERGED)
    elif not moved:  # _VARIABLES
        return _stop(st, CONVERGED)
    return ITERATED


@njit(cache=True)
def advance(st):
    """Move the solve on (module docstring): returns ``EVALUATE``, ``ITERATED`` or a stop
    code (again on every later call)."""
    ints, reals = st.ints, st.reals
    phase = ints[PHASE]
    blas = ints[_BLAS] != 0
    if phase == _DONE:
        return ints[CODE]
    if phase == _START:
        _copy(st.x, st.xn)
        ints[PHASE] = _STARTED
        return EVALUATE
    if phase == _DIRECTION:
        return _iterate(st)
    fn = reals[F_TRIAL]
    ints[EVALUATIONS] += 1
    if ints[_KEEP_BEST] != 0 and (phase == _STARTED or fn < reals[F_BEST]):
        reals[F_BEST] = fn
        _copy(st.xn, st.best)
    if phase == _STARTED:
        reals[F] = fn
        _copy(st.gn, st.g)
        ints[PHASE] = _DIRECTION
        if ints[_RULE] == _GRADIENT and _gradient_small(st, blas):
            return _stop(st, CONVERGED)
        return _iterate(st)
    # phase == _TRIAL: the line search's test of the trial just evaluated
    dg = reals[_DG]
    step = reals[_STEP]
    bound = reals[F] + _C1 * step * dg
    above = fn > bound if ints[_NAN_PASSES] != 0 else not (fn <= bound)
    if above:
        reals[_S_HI] = step
    elif _dot(st.gn, st.d, blas) < _C2 * dg:
        reals[_S_LO] = step
    else:
        return _accept(st, fn, blas)
    s_lo, s_hi = reals[_S_LO], reals[_S_HI]
    step = 0.5 * (s_lo + s_hi) if s_hi < math.inf else 2.0 * step
    if step < reals[_STEP_MIN] or step > reals[_STEP_MAX]:
        return _search_failed(st)
    reals[_STEP] = step
    return _next_trial(st)
