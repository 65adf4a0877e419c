"""EGO's initial parametrisation of a B-spline: samples of a path, then a least-squares fit.

:func:`fit_samples` samples a trajectory the way EGO's planner manager does;
:func:`fit_control_points` solves ``parameterizeToBspline``'s system for the control points,
which :meth:`BSpline.fit <ft_sitl.navigation.trajectories.bspline.BSpline.fit>` turns into a
uniform ``MATRIX`` spline.
"""

from __future__ import annotations

import numpy as np


def fit_control_points(pts: np.ndarray, dt: float, v0, v1, a0, a1,
                       m: np.ndarray) -> np.ndarray:
    """Control points ``(K - 1 + p, d)`` of the uniform spline with basis matrix ``m``
    (``(p + 1, p + 1)``, :func:`~ft_sitl.navigation.trajectories.bspline.basis_matrix`;
    ``p >= 2``) and knot span ``dt`` through the ``K`` samples ``pts`` ``(K, d)`` with
    start/end velocity ``v0``/``v1`` and acceleration ``a0``/``a1``: the K position equations
    and the 4 derivative equations solved jointly, unweighted, in the least-squares sense
    (the original's QR solve)."""
    degree = m.shape[0] - 1
    n_pts, dim = pts.shape
    n_seg = n_pts - 1
    n_cp = n_seg + degree
    a = np.zeros((n_pts + 4, n_cp))
    b = np.zeros((n_pts + 4, dim))
    # positions at the start of every segment (s = 0) ...
    for k in range(n_seg):
        a[k, k:k + degree + 1] = m[0]
    # ... and at the end of the last one (s = 1)
    last = n_seg - 1
    ones = np.ones(degree + 1)
    a[n_seg, last:last + degree + 1] = ones @ m
    b[:n_pts] = pts
    ds = np.arange(degree + 1, dtype=float)  # d/ds s^i at s=1 is i; d2 is i (i-1)
    rows = (
        (m[1] / dt, 0, v0),
        ((ds @ m) / dt, last, v1),
        (2.0 * m[2] / dt ** 2, 0, a0),
        (((ds * (ds - 1)) @ m) / dt ** 2, last, a1),
    )
    for r, (w, k, rhs) in enumerate(rows):
        a[n_pts + r, k:k + degree + 1] = w
        b[n_pts + r] = np.asarray(rhs, dtype=float).reshape(dim)
    q, *_ = np.linalg.lstsq(a, b, rcond=None)
    return q


def fit_samples(position_fn, duration: float, max_vel: float, ctrl_pt_dist: float = 0.4,
                min_points: int = 7) -> tuple[np.ndarray, float]:
    """Sample a trajectory for :meth:`BSpline.fit
    <ft_sitl.navigation.trajectories.bspline.BSpline.fit>` the way EGO's planner does.

    EGO takes the knot span ``dt = ctrl_pt_dist / max_vel * 1.2`` (0.4 m control-point
    spacing at 1/1.2 of the speed cap) and samples the initial polynomial every ``dt``;
    while two samples are more than ``1.5 ctrl_pt_dist`` apart, or there are fewer than
    ``min_points`` (7) samples, it divides ``dt`` by 1.5 and samples again.

    Difference from the original: EGO samples ``t = 0, dt, ... < duration`` and so drops the
    end of the polynomial (the local target) unless it falls on a sample; here the number
    of spans is rounded up so that the last sample is the end point exactly
    (``dt = duration / ceil(duration / dt)``, never longer than the nominal span).
    ``position_fn(t_array) -> (M, 3)``. Returns ``(points (K, 3), dt)``.
    """
    if not (duration > 0 and max_vel > 0 and ctrl_pt_dist > 0):
        raise ValueError("duration, max_vel and ctrl_pt_dist must be positive")
    if min_points < 2:
        raise ValueError(f"min_points must be >= 2, got {min_points}")
    dt_nominal = ctrl_pt_dist / max_vel * 1.2
    for _ in range(64):
        n_seg = max(min_points - 1, int(np.ceil(duration / dt_nominal - 1e-9)), 1)
        t = np.linspace(0.0, duration, n_seg + 1)
        pts = np.asarray(position_fn(t), dtype=float)
        gaps = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        if gaps.size == 0 or float(gaps.max()) <= 1.5 * ctrl_pt_dist:
            return pts, duration / n_seg
        dt_nominal /= 1.5
    raise ValueError("fit_samples: the trajectory moves too fast to sample "
                     f"(> {1.5 * ctrl_pt_dist} m per {dt_nominal:.3g} s)")
