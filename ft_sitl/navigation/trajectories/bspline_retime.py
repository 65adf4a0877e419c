"""Fast-Planner's re-timings of a cubic B-spline, as new knot vectors.

:meth:`BSpline.reallocate_time <ft_sitl.navigation.trajectories.bspline.BSpline.reallocate_time>`
and :meth:`BSpline.lengthen_time
<ft_sitl.navigation.trajectories.bspline.BSpline.lengthen_time>` build their ``DE_BOOR``
splines over the knots these functions compute from the control points and the old knots.
"""

from __future__ import annotations

import math

import numpy as np

#: the degree Fast-Planner's re-timings are written for
CUBIC = 3
#: knot intervals 0 .. 4 of a cubic B-spline shape its state (position, velocity,
#: acceleration) at the start of its domain, u[3]
START_INTERVALS = 5


def reallocated_knots(c: np.ndarray, u: np.ndarray, vmax: float, amax: float,
                      limit_ratio: float, vel_norm: bool,
                      keep_start: bool) -> tuple[np.ndarray, bool]:
    """One pass of Fast-Planner's ``reallocateTime`` over the cubic with control points ``c``
    ``(N, d)`` and knots ``u``: the new knots and whether this pass found everything
    feasible (nothing changed).

    Every velocity control point ``p (Q[i+1] - Q[i]) / (u[i+4] - u[i+1])`` beyond ``vmax``
    on an axis lengthens the three knot intervals it spans, together by ``min(max|V| / vmax
    + 1e-4, limit_ratio)``; every acceleration control point beyond ``amax`` its two
    intervals by ``min(sqrt(max|A| / amax) + 1e-4, limit_ratio)`` (the original's special
    case for ``i = 1, 2`` included: it lengthens the first four intervals); later knots
    shift. One interval belongs to up to three control points, so one pass can lengthen it
    by more than ``limit_ratio``. ``vel_norm`` bounds the velocity control points' norm
    instead of each axis; ``keep_start`` leaves the knot intervals that shape the start
    state (the first :data:`START_INTERVALS`) as they are, so the re-timed curve starts in
    the same position, velocity and acceleration (the original stretches them too)."""
    h = np.diff(u)  # knot intervals; interval k is [u[k], u[k+1]]
    n = c.shape[0]
    p = CUBIC
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
    return np.concatenate([[u[0]], u[0] + np.cumsum(h)]), feasible


def lengthened_knots(u: np.ndarray, ratio: float) -> np.ndarray:
    """Fast-Planner's ``lengthenTime`` on the cubic's knots ``u``: the knot spans between
    the first two and the last two are stretched so that the duration grows by
    ``(ratio - 1)`` times theirs; with too few knots to keep the ends, all knots are scaled
    by ``ratio``."""
    knots = np.array(u)
    num1, num2 = 5, knots.shape[0] - 1 - 5
    if num2 > num1:
        delta = (float(ratio) - 1.0) * (knots[num2] - knots[num1])
        inc = delta / (num2 - num1)
        knots[num1 + 1:num2 + 1] += np.arange(1, num2 - num1 + 1) * inc
        knots[num2 + 1:] += delta
    else:  # too few knots to keep the ends: stretch uniformly
        knots = knots * float(ratio)
    return knots
