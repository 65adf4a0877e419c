"""Uniform B-splines in R^3: the trajectory representation of EGO-Planner and Fast-Planner.

A :class:`UniformBSpline` of degree ``p`` has ``N`` control points ``Q[0..N-1]`` (rows of an
``(N, 3)`` array, world ENU metres) and the uniform knot vector ``u_i = (i - p) * dt`` for
``i = 0 .. N + p`` (the originals' convention), so the curve is defined on
``[0, (N - p) * dt]`` and has ``N - p`` segments ("knot spans") of ``dt`` seconds each.

Evaluation uses the matrix form: on segment ``k`` (``t`` in ``[k dt, (k+1) dt]``) with
``s = t / dt - k`` in ``[0, 1]``::

    p(t) = [1, s, s^2, ..., s^p] @ M_p @ Q[k : k + p + 1]

where ``M_p`` is the uniform basis matrix (Qin 2000, "General matrix representations for
B-splines"); derivatives differentiate the power row (``d/dt = (1/dt) d/ds``). For the cubic
``M_3 = [[1, 4, 1, 0], [-3, 0, 3, 0], [3, -6, 3, 0], [-1, 3, -3, 1]] / 6``.

The derivative of the spline is again a uniform B-spline of degree ``p - 1`` with the same
``dt`` and control points ``(Q[i+1] - Q[i]) / dt`` (:meth:`UniformBSpline.derivative`); the
originals' feasibility checks look at these velocity and acceleration control points, which
bound the curve's derivatives per axis (convex hull property).

:meth:`UniformBSpline.fit` is EGO's ``parameterizeToBspline``: a least-squares fit to points
sampled at the knots plus start/end velocity and acceleration. :func:`fit_samples` produces
those samples from a trajectory the way EGO's planner manager does (see its docstring).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from math import comb, factorial

import numpy as np
from numba import njit
from scipy.interpolate import BSpline

from ft_sitl.navigation.trajectories.base import Trajectory

__all__ = ["Feasibility", "UniformBSpline", "basis_matrix", "fit_samples"]


@lru_cache(maxsize=16)
def _basis_matrix_cached(degree: int) -> np.ndarray:
    k = degree + 1  # order
    m = np.zeros((k, k))
    for i in range(k):
        for j in range(k):
            acc = 0.0
            for s in range(j, k):
                acc += (k - s - 1) ** (k - 1 - i) * (-1) ** (s - j) * comb(k, s - j)
            m[i, j] = comb(k - 1, i) * acc / factorial(k - 1)
    m.setflags(write=False)
    return m


def basis_matrix(degree: int) -> np.ndarray:
    """The ``(p+1, p+1)`` uniform B-spline basis matrix ``M_p``: row ``i`` multiplies
    ``s^i``, column ``j`` the ``j``-th control point of the segment (read-only)."""
    if not isinstance(degree, (int, np.integer)) or degree < 0:
        raise ValueError(f"degree must be a non-negative integer, got {degree!r}")
    return _basis_matrix_cached(int(degree))


def _power_rows(s: np.ndarray, degree: int, order: int, dt: float) -> np.ndarray:
    """Rows ``d^order/dt^order [1, s, ..., s^p]`` for each ``s``: shape (len(s), p + 1)."""
    out = np.zeros((s.shape[0], degree + 1))
    for i in range(order, degree + 1):
        coef = factorial(i) / factorial(i - order)
        out[:, i] = coef * s ** (i - order)
    if order:
        out /= dt ** order
    return out


@njit(cache=True)
def _pva_kernel(q, dt, degree, m, t, out):
    """Position, velocity, acceleration (rows of ``out`` (3, 3)) at one time ``t``: the
    same clamping, segment and arithmetic order as :meth:`UniformBSpline.evaluate`."""
    n_seg = q.shape[0] - degree
    tt = min(max(t, 0.0), n_seg * dt)
    u = tt / dt
    k = min(int(np.floor(u)), n_seg - 1)
    s = u - k
    for order in range(3):
        for d in range(3):
            out[order, d] = 0.0
        if order > degree:
            continue
        scale = dt ** order
        for j in range(degree + 1):
            w = 0.0
            for i in range(order, degree + 1):
                coef = 1.0
                for f in range(i - order + 1, i + 1):
                    coef *= f
                w += (coef * s ** (i - order)) / scale * m[i, j]
            for d in range(3):
                out[order, d] += w * q[k + j, d]


@dataclass(frozen=True)
class Feasibility:
    """Result of :meth:`UniformBSpline.feasibility`.

    ``ok`` is True when every velocity control point is within ``vmax (1 + tol)`` and every
    acceleration control point within ``amax (1 + tol)`` on each axis. ``ratio`` is EGO's
    time-stretch factor ``max(max|v| / vmax, sqrt(max|a| / amax))`` over all control points
    (> 1 means the limits are exceeded; stretching time by ``ratio`` fixes both).
    """

    ok: bool
    ratio: float
    max_vel: float
    max_acc: float


class UniformBSpline(Trajectory):
    """A uniform B-spline of degree ``degree`` in R^3 with knot span ``dt`` (seconds).

    Immutable: the control points are copied and made read-only; operations that change
    the curve (:meth:`stretch_time`, :meth:`with_control_points`) return a new spline.
    """

    __slots__ = ("_q", "_dt", "_p")

    def __init__(self, control_points, dt: float, degree: int = 3):
        q = np.array(control_points, dtype=float)
        if q.ndim != 2 or q.shape[1] != 3:
            raise ValueError(f"control_points must have shape (N, 3), got {q.shape}")
        degree = int(degree)
        if degree < 0:
            raise ValueError(f"degree must be >= 0, got {degree}")
        if q.shape[0] < degree + 1:
            raise ValueError(f"a degree-{degree} spline needs at least {degree + 1} control "
                             f"points, got {q.shape[0]}")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        if not np.all(np.isfinite(q)):
            raise ValueError("control_points must be finite")
        q.setflags(write=False)
        self._q = q
        self._dt = float(dt)
        self._p = degree

    # ---- parametrisation ---------------------------------------------------------------
    @property
    def control_points(self) -> np.ndarray:
        """``(N, 3)`` read-only array of control points."""
        return self._q

    @property
    def dt(self) -> float:
        """Knot span in seconds."""
        return self._dt

    @property
    def degree(self) -> int:
        return self._p

    @property
    def num_control_points(self) -> int:
        return self._q.shape[0]

    @property
    def num_segments(self) -> int:
        """Number of knot spans the curve is defined on (``N - p``)."""
        return self._q.shape[0] - self._p

    @property
    def duration(self) -> float:
        """Length of the curve's time domain ``[0, (N - p) dt]`` in seconds."""
        return self.num_segments * self._dt

    @property
    def knots(self) -> np.ndarray:
        """Full knot vector ``u_i = (i - p) dt``, ``i = 0 .. N + p`` (length ``N + p + 1``)."""
        n = self._q.shape[0]
        return (np.arange(n + self._p + 1) - self._p) * self._dt

    def knot_times(self) -> np.ndarray:
        """Times of the knots inside the domain: ``0, dt, ..., duration`` (``N - p + 1``)."""
        return np.arange(self.num_segments + 1) * self._dt

    def knot_points(self) -> np.ndarray:
        """Curve positions at :meth:`knot_times`, shape ``(N - p + 1, 3)``."""
        return self.evaluate(self.knot_times())

    def with_control_points(self, control_points) -> UniformBSpline:
        """Same ``dt`` and degree, new control points."""
        return UniformBSpline(control_points, self._dt, self._p)

    def stretch_time(self, ratio: float) -> UniformBSpline:
        """Time re-allocation: the same geometric curve flown ``ratio`` times slower
        (``dt *= ratio``; velocity scales by ``1/ratio``, acceleration by ``1/ratio^2``)."""
        if not (np.isfinite(ratio) and ratio > 0):
            raise ValueError(f"ratio must be a positive number, got {ratio!r}")
        return UniformBSpline(self._q, self._dt * float(ratio), self._p)

    # ---- evaluation --------------------------------------------------------------------
    def _segment(self, t) -> tuple[np.ndarray, np.ndarray, bool]:
        scalar = np.ndim(t) == 0
        tt = np.atleast_1d(np.asarray(t, dtype=float))
        if tt.ndim != 1:
            raise ValueError(f"t must be a scalar or a 1-D array, got shape {tt.shape}")
        # clamp to the domain: evaluation outside [0, duration] extrapolates the end spans'
        # polynomials, which is meaningless for a trajectory
        tt = np.clip(tt, 0.0, self.duration)
        u = tt / self._dt
        k = np.minimum(np.floor(u).astype(np.int64), self.num_segments - 1)
        return k, u - k, scalar

    def evaluate(self, t, order: int = 0) -> np.ndarray:
        """The ``order``-th time derivative at times ``t`` (clamped to ``[0, duration]``).

        Returns shape ``(3,)`` for a scalar ``t``, else ``(len(t), 3)``. Derivatives above
        the degree are zero.
        """
        order = int(order)
        if order < 0:
            raise ValueError(f"order must be >= 0, got {order}")
        k, s, scalar = self._segment(t)
        if order > self._p:
            out = np.zeros((k.shape[0], 3))
        else:
            w = _power_rows(s, self._p, order, self._dt) @ basis_matrix(self._p)  # (M, p+1)
            idx = k[:, None] + np.arange(self._p + 1)[None, :]
            out = np.einsum("mj,mjd->md", w, self._q[idx])
        return out[0] if scalar else out

    def pva(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at one time ``t`` (clamped to the domain):
        :meth:`evaluate` for orders 0-2 in one call (the setpoint path calls this at 100 Hz)."""
        out = np.empty((3, 3))
        _pva_kernel(self._q, self._dt, self._p, basis_matrix(self._p), float(t), out)
        return out[0], out[1], out[2]

    # ---- derivative splines ------------------------------------------------------------
    def derivative_control_points(self, order: int = 1) -> np.ndarray:
        """Control points of the ``order``-th derivative spline: ``order`` finite
        differences of ``Q`` divided by ``dt^order`` (uniform knots), ``(N - order, 3)``."""
        order = int(order)
        if not 0 <= order <= self._p:
            raise ValueError(f"order must be in [0, {self._p}], got {order}")
        return np.diff(self._q, n=order, axis=0) / self._dt ** order

    def velocity_control_points(self) -> np.ndarray:
        return self.derivative_control_points(1)

    def acceleration_control_points(self) -> np.ndarray:
        return self.derivative_control_points(2)

    def derivative(self, order: int = 1) -> UniformBSpline:
        """The ``order``-th derivative as a spline of degree ``p - order`` (same ``dt`` and
        time domain)."""
        return UniformBSpline(self.derivative_control_points(order), self._dt,
                              self._p - int(order))

    # ---- checks ------------------------------------------------------------------------
    def feasibility(self, vmax: float, amax: float, tolerance: float = 0.0) -> Feasibility:
        """Per-axis check of the velocity and acceleration control points against
        ``vmax``/``amax`` (m/s, m/s^2), allowing ``tolerance`` (EGO's
        ``feasibility_tolerance``, 0.05 in its launch files) plus 1e-4 as EGO does."""
        if not (vmax > 0 and amax > 0):
            raise ValueError(f"vmax and amax must be positive, got {vmax!r}, {amax!r}")
        vel = self.velocity_control_points()
        max_v = float(np.max(np.abs(vel))) if vel.size else 0.0
        if self._p >= 2:
            acc = self.acceleration_control_points()
            max_a = float(np.max(np.abs(acc))) if acc.size else 0.0
        else:
            max_a = 0.0
        ok = (max_v <= vmax * (1.0 + tolerance) + 1e-4) and \
             (max_a <= amax * (1.0 + tolerance) + 1e-4)
        ratio = max(max_v / vmax, float(np.sqrt(max_a / amax)))
        return Feasibility(ok=bool(ok), ratio=ratio, max_vel=max_v, max_acc=max_a)

    def to_scipy(self):
        """The same curve as a ``scipy.interpolate.BSpline`` (for checks and plotting)."""

        return BSpline(self.knots, np.array(self._q), self._p, extrapolate=False)

    # ---- fitting -----------------------------------------------------------------------
    @classmethod
    def fit(cls, points, dt: float, v0, v1, a0, a1, degree: int = 3) -> UniformBSpline:
        """EGO's initial parametrisation (``parameterizeToBspline``): control points that
        put the curve through ``points`` (K >= 2 samples of a path taken at times
        ``0, dt, ..., (K-1) dt``) with start/end velocity ``v0``/``v1`` and acceleration
        ``a0``/``a1``, in the least-squares sense.

        The curve gets ``K - 1`` segments and ``K - 1 + p`` control points; the K position
        equations and the 4 derivative equations (K + 4 rows) are solved jointly, unweighted,
        like the original's QR solve, so the samples and end derivatives are met only
        approximately when the system is over-determined (always, for the cubic).
        """
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 2:
            raise ValueError(f"points must have shape (K >= 2, 3), got {pts.shape}")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        degree = int(degree)
        if degree < 2:
            raise ValueError("fit needs degree >= 2 (acceleration constraints)")
        m = basis_matrix(degree)
        n_pts = pts.shape[0]
        n_seg = n_pts - 1
        n_cp = n_seg + degree
        a = np.zeros((n_pts + 4, n_cp))
        b = np.zeros((n_pts + 4, 3))
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
            b[n_pts + r] = np.asarray(rhs, dtype=float).reshape(3)
        q, *_ = np.linalg.lstsq(a, b, rcond=None)
        return cls(q, dt, degree)


def fit_samples(position_fn, duration: float, max_vel: float, ctrl_pt_dist: float = 0.4,
                min_points: int = 7) -> tuple[np.ndarray, float]:
    """Sample a trajectory for :meth:`UniformBSpline.fit` the way EGO's planner does.

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
