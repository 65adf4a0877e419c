"""The B-spline penalties the planners share (numba), on ``(N, 3)`` control-point arrays.

Each kernel returns its unweighted cost and adds ``w`` times its gradient to ``grad``:

- :func:`smoothness`: ``sum ||Q[i+3] - 3 Q[i+2] + 3 Q[i+1] - Q[i]||^2`` (jerk form,
  unscaled): EGO's, Fast-Planner's and PGO's;
- :func:`feasibility`: Fast-Planner's per-axis ``(V^2 - vmax^2)^2`` where ``|V| > vmax`` and
  ``(A^2 - amax^2)^2`` where ``|A| > amax`` on the velocity and acceleration control points
  (Fast-Planner's and PGO's; EGO's own form, ``(|V| - vmax)^2``, is EGO's cost's);
- :func:`esdf_distance`: ``sum (d - d0)^2`` over the control points whose ESDF distance
  ``d`` is below ``d0``; its gradient is the interpolated ESDF's exact one (Fast-Planner's
  navigator) or, with ``unit_gradient``, normalised to unit length as Fast-Planner's code
  does (PGO);
- :func:`endpoint`: ``||(Q[N-3] + 4 Q[N-2] + Q[N-1]) / 6 - p_end||^2`` (Fast-Planner's free
  end);

and :func:`fast_planner_cost`, Fast-Planner's ``NORMAL_PHASE`` cost (+ ``ENDPOINT``), the
weighted sum both Fast-Planner's and PGO's optimisers minimise. :func:`as_points` and
:func:`smoothness_cost` are the Python faces EGO's and Fast-Planner's modules share.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ft_sitl.navigation.maps.map_esdf import trilinear_point

ORDER = 3  # cubic B-splines; the first (and last) ORDER control points are fixed


@njit(cache=True)
def smoothness(q, w, grad):
    f = 0.0
    for i in range(q.shape[0] - 3):
        for d in range(3):
            j = q[i + 3, d] - 3.0 * q[i + 2, d] + 3.0 * q[i + 1, d] - q[i, d]
            f += j * j
            g2 = 2.0 * w * j
            grad[i + 3, d] += g2
            grad[i + 2, d] -= 3.0 * g2
            grad[i + 1, d] += 3.0 * g2
            grad[i, d] -= g2
    return f


@njit(cache=True)
def feasibility(q, ts, vmax, amax, w, grad):
    f = 0.0
    n = q.shape[0]
    inv2 = 1.0 / (ts * ts)
    inv4 = inv2 * inv2
    vm2 = vmax * vmax
    am2 = amax * amax
    for i in range(n - 1):
        for a in range(3):
            dv = q[i + 1, a] - q[i, a]
            ex = dv * dv * inv2 - vm2
            if ex > 0.0:
                f += ex * ex
                g = w * 4.0 * ex * inv2 * dv
                grad[i + 1, a] += g
                grad[i, a] -= g
    for i in range(n - 2):
        for a in range(3):
            da = q[i + 2, a] - 2.0 * q[i + 1, a] + q[i, a]
            ex = da * da * inv4 - am2
            if ex > 0.0:
                f += ex * ex
                g = w * 4.0 * ex * inv4 * da
                grad[i, a] += g
                grad[i + 1, a] -= 2.0 * g
                grad[i + 2, a] += g
    return f


@njit(cache=True)
def esdf_distance(q, first, last, field, origin, inv_res, d0, w, grad, unit_gradient):
    """The ESDF term over control points ``first .. last - 1`` (a non-finite point adds
    nothing)."""
    f = 0.0
    g = np.empty(3)
    for i in range(first, last):
        if not (np.isfinite(q[i, 0]) and np.isfinite(q[i, 1]) and np.isfinite(q[i, 2])):
            continue
        dist = trilinear_point(field, origin, inv_res, q[i, 0], q[i, 1], q[i, 2], g)
        if unit_gradient:
            gn = math.sqrt(g[0] * g[0] + g[1] * g[1] + g[2] * g[2])
            if gn > 1e-4:
                for a in range(3):
                    g[a] /= gn
        e = dist - d0
        if e < 0.0:
            f += e * e
            for a in range(3):
                grad[i, a] += w * 2.0 * e * g[a]
    return f


@njit(cache=True)
def endpoint(q, end_pt, w, grad):
    n = q.shape[0]
    f = 0.0
    for a in range(3):
        e = (q[n - 3, a] + 4.0 * q[n - 2, a] + q[n - 1, a]) / 6.0 - end_pt[a]
        f += e * e
        g = w * 2.0 * e / 6.0
        grad[n - 3, a] += g
        grad[n - 2, a] += 4.0 * g
        grad[n - 1, a] += g
    return f


@njit(cache=True)
def fast_planner_cost(q, grad, w, ts, vmax, amax, d0, free_end, end_pt, field, origin,
                      inv_res, unit_gradient, terms):
    """``w`` = [smooth, distance, feasibility, endpoint]; ``terms`` receives the unweighted
    terms. The distance term covers ``Q[3] .. Q[N-4]`` (``.. Q[N-1]`` with a free end);
    the endpoint term only with a free end. Fills ``grad`` (all rows)."""
    n = q.shape[0]
    grad[:, :] = 0.0
    terms[0] = smoothness(q, w[0], grad)
    last = n if free_end else n - ORDER
    terms[1] = esdf_distance(q, ORDER, last, field, origin, inv_res, d0, w[1], grad,
                             unit_gradient)
    terms[2] = feasibility(q, ts, vmax, amax, w[2], grad)
    terms[3] = endpoint(q, end_pt, w[3], grad) if free_end else 0.0
    return w[0] * terms[0] + w[1] * terms[1] + w[2] * terms[2] + w[3] * terms[3]


def as_points(q) -> np.ndarray:
    """``q`` as a contiguous float ``(N, 3)`` array (a ValueError for any other shape)."""
    q = np.ascontiguousarray(q, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != 3:
        raise ValueError(f"control points must have shape (N, 3), got {q.shape}")
    return q


def smoothness_cost(q) -> tuple[float, np.ndarray]:
    """``sum ||Q[i+3] - 3 Q[i+2] + 3 Q[i+1] - Q[i]||^2`` and its gradient ``(N, 3)``."""
    q = as_points(q)
    grad = np.zeros_like(q)
    return float(smoothness(q, 1.0, grad)), grad
