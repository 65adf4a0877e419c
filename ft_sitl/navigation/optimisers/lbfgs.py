"""The L-BFGS pieces EGO's and Fast-Planner's optimisers share, on the free rows
``lo:hi`` of ``(N, 3)`` control-point arrays (numba): the dot product, the two-loop
recursion for the search direction, and the memory update. Each optimiser keeps its own
loop around them: its cost function, line search and stopping rules are the original's.

Not yet one L-BFGS (issue 42, point 3, left open): EGO's loop (resumable for the rebound
check, gradient-norm stop) and Fast-Planner's (evaluation cap, best point, xtol on the step
norm) share these kernels, and PGO's (planners/pgo.py ``_lbfgs``) minimises the same cost
(:func:`~ft_sitl.navigation.optimisers.penalties.fast_planner_cost`) on a flat vector
whose dot products are numpy's ``np.dot`` (BLAS ddot: blocked, several partial sums, so a
different summation order from :func:`dot_rows`' row loop) with a per-variable xtol stop.
One loop for all three must take the dot product and the stop rule as parameters to keep
each one's rows bit for bit; that was not done in this change."""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def dot_rows(a, b, lo, hi):
    """Sum of ``a[i, k] * b[i, k]`` over rows ``lo:hi`` (row by row, axis by axis)."""
    s = 0.0
    for i in range(lo, hi):
        for k in range(3):
            s += a[i, k] * b[i, k]
    return s


@njit(cache=True)
def search_direction(g, d, S, Y, rho, alpha, count, head, lo, hi):
    """``d = -H g`` by the two-loop recursion over the ``count`` stored pairs ending before
    slot ``head`` of the ring ``S``/``Y``/``rho`` (``alpha``: scratch), initial Hessian
    scaled by the newest pair. Returns ``d . g``."""
    m = S.shape[0]
    for i in range(lo, hi):
        for k in range(3):
            d[i, k] = -g[i, k]
    for c in range(count):
        j = (head - 1 - c) % m
        a = rho[j] * dot_rows(S[j], d, lo, hi)
        alpha[j] = a
        for i in range(lo, hi):
            for k in range(3):
                d[i, k] -= a * Y[j, i, k]
    if count > 0:
        j = (head - 1) % m
        gamma = 1.0 / (rho[j] * dot_rows(Y[j], Y[j], lo, hi))
        for i in range(lo, hi):
            for k in range(3):
                d[i, k] *= gamma
    for c in range(count - 1, -1, -1):
        j = (head - 1 - c) % m
        b = rho[j] * dot_rows(Y[j], d, lo, hi)
        for i in range(lo, hi):
            for k in range(3):
                d[i, k] += S[j, i, k] * (alpha[j] - b)
    return dot_rows(d, g, lo, hi)


@njit(cache=True)
def store_pair(q, q0, g, g0, S, Y, slot, lo, hi):
    """Store ``s = q - q0``, ``y = g - g0`` in ``slot``; returns ``(y . s, s . s)``. The
    caller keeps the pair (``rho[slot] = 1 / (y . s)``) only when ``y . s`` is positive
    enough."""
    ys = 0.0
    ss = 0.0
    for i in range(lo, hi):
        for k in range(3):
            S[slot, i, k] = q[i, k] - q0[i, k]
            Y[slot, i, k] = g[i, k] - g0[i, k]
            ys += S[slot, i, k] * Y[slot, i, k]
            ss += S[slot, i, k] * S[slot, i, k]
    return ys, ss
