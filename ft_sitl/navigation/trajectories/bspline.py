"""B-splines: the trajectory representation of EGO-Planner, Fast-Planner and PGO.

One class, :class:`BSpline`: a B-spline of degree ``p`` with ``N`` control points
``Q[0..N-1]`` (rows of an ``(N, d)`` array: world ENU metres for a path, ``d = 1`` for
Fast-Planner's yaw curve) and a non-decreasing knot vector ``u[0 .. N + p]``. Time ``t``
runs from 0 at ``u[p]`` to ``duration = u[N] - u[p]``; evaluation clamps to that domain.
Built from a knot span ``dt`` the knots are uniform, ``u_i = (i - p) * dt`` (the originals'
convention), and the curve has ``N - p`` segments of ``dt`` seconds each; built from a knot
vector (Fast-Planner's re-timed curves) they are whatever it says.

How the curve is evaluated is chosen at construction (:class:`Evaluation`), never inferred
from the knots, because the two ways are the same curve in different floating-point
operations and the committed benchmark rows were flown with one or the other:

- ``MATRIX`` (uniform knots only; EGO, PGO and Fast-Planner's optimiser): on segment ``k``
  (``t`` in ``[k dt, (k+1) dt]``) with ``s = t / dt - k`` in ``[0, 1]``::

      p(t) = [1, s, s^2, ..., s^p] @ M_p @ Q[k : k + p + 1]

  where ``M_p`` is the uniform basis matrix (Qin 2000, "General matrix representations for
  B-splines"); derivatives differentiate the power row (``d/dt = (1/dt) d/ds``). For the
  cubic ``M_3 = [[1, 4, 1, 0], [-3, 0, 3, 0], [3, -6, 3, 0], [-1, 3, -3, 1]] / 6``. The
  derivative control points are finite differences over ``dt``: ``(Q[i+1] - Q[i]) / dt``,
  ``(Q[i+2] - 2 Q[i+1] + Q[i]) / dt^2``, ...
- ``DE_BOOR`` (any knots; Fast-Planner's flown trajectory and yaw, even on uniform knots):
  de Boor's recursion (scipy's ``BSpline`` for arrays of times, :func:`_deboor` for the
  100 Hz one-point path), and the derivative control points from knot differences,
  ``p (Q[i+1] - Q[i]) / (u[i+p+1] - u[i+1])`` and so on (Fast-Planner's
  ``getDerivativeControlPoints``).

The derivative of the spline is again a B-spline of degree ``p - 1`` over those derivative
control points (:meth:`BSpline.derivative`); the originals' feasibility checks look at the
velocity and acceleration control points, which bound the curve's derivatives per axis
(convex hull property): :meth:`BSpline.feasibility`.

Re-timing, one method for each way the planners change a curve's time:

- :meth:`BSpline.stretch_time` (EGO): uniform knots, ``dt *= ratio``;
- :meth:`BSpline.reallocate_time` / :meth:`BSpline.retimed` (Fast-Planner's
  ``reallocateTime`` and the planner manager's loop around it): the knot intervals under
  each velocity / acceleration control point beyond the limits are lengthened, cubic only
  (the method's docstring);
- :meth:`BSpline.lengthen_time` (Fast-Planner's ``lengthenTime``, PGO's refinement): the
  inner knot spans are stretched, cubic only.

The two non-uniform re-timings return ``DE_BOOR`` splines (the matrix form needs uniform
knots).

:meth:`BSpline.fit` is EGO's ``parameterizeToBspline``: a least-squares fit to points
sampled at the knots plus start/end velocity and acceleration. :func:`fit_samples` produces
those samples from a trajectory the way EGO's planner manager does (see its docstring).
Both are in :mod:`~ft_sitl.navigation.trajectories.bspline_fit`; the knots of
Fast-Planner's re-timings are computed in :mod:`~ft_sitl.navigation.trajectories.bspline_retime`.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from functools import lru_cache
from math import comb, factorial

import numpy as np
from numba import njit
from scipy.interpolate import BSpline as ScipyBSpline

from ft_sitl.navigation.trajectories.base import Trajectory
from ft_sitl.navigation.trajectories.bspline_fit import fit_control_points, fit_samples
from ft_sitl.navigation.trajectories.bspline_retime import (
    CUBIC,
    START_INTERVALS,
    lengthened_knots,
    reallocated_knots,
)

__all__ = ["START_INTERVALS", "BSpline", "Evaluation", "Feasibility", "basis_matrix",
           "fit_samples"]


class Evaluation(Enum):
    """How a :class:`BSpline` is evaluated (module docstring)."""

    MATRIX = "matrix"
    DE_BOOR = "de_boor"


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
    """Position, velocity, acceleration (rows of ``out`` (3, d)) at one time ``t``: the
    same clamping, segment and arithmetic order as the matrix form of
    :meth:`BSpline.evaluate`."""
    n_seg = q.shape[0] - degree
    dim = q.shape[1]
    tt = min(max(t, 0.0), n_seg * dt)
    u = tt / dt
    k = min(int(np.floor(u)), n_seg - 1)
    s = u - k
    for order in range(3):
        for d in range(dim):
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
            for d in range(dim):
                out[order, d] += w * q[k + j, d]


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


@dataclass(frozen=True)
class Feasibility:
    """Result of :meth:`BSpline.feasibility`.

    ``ok`` is True when every velocity control point is within ``vmax (1 + tol)`` and every
    acceleration control point within ``amax (1 + tol)`` on each axis (the velocity's norm
    with ``vel_norm``). ``ratio`` is EGO's time-stretch factor ``max(max|v| / vmax,
    sqrt(max|a| / amax))`` over all control points (> 1 means the limits are exceeded;
    stretching time by ``ratio`` fixes both).
    """

    ok: bool
    ratio: float
    max_vel: float
    max_acc: float


class BSpline(Trajectory):
    """A B-spline of degree ``degree`` over ``(N, d)`` control points (a 1-D array is one
    column), evaluated as ``evaluation`` says (module docstring).

    Give either ``dt`` (uniform knots ``(i - p) dt``; evaluation ``MATRIX`` unless told
    otherwise) or ``knots`` (``N + p + 1`` strictly increasing knots; ``DE_BOOR``, the only
    evaluation arbitrary knots allow). Immutable: the control points and knots are copied and
    made read-only; operations that change the curve return a new spline with the same
    evaluation.
    """

    __slots__ = ("_q", "_u", "_p", "_dt", "_eval", "_duration", "_b", "_tck")

    def __init__(self, control_points, dt: float | None = None, degree: int = 3, *,
                 knots=None, evaluation: Evaluation | str | None = None):
        q = np.array(control_points, dtype=float)
        if q.ndim == 1:
            q = q[:, None]
        if q.ndim != 2 or q.shape[1] < 1:
            raise ValueError(f"control_points must have shape (N, d), got {q.shape}")
        degree = int(degree)
        if degree < 0:
            raise ValueError(f"degree must be >= 0, got {degree}")
        n = q.shape[0]
        if n < degree + 1:
            raise ValueError(f"a degree-{degree} spline needs at least {degree + 1} control "
                             f"points, got {n}")
        if not np.all(np.isfinite(q)):
            raise ValueError("control_points must be finite")
        if (dt is None) == (knots is None):
            raise ValueError("give either dt (uniform knots) or knots")
        if dt is not None:
            if not (np.isfinite(dt) and dt > 0):
                raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
            dt = float(dt)
            u = (np.arange(n + degree + 1) - degree) * dt
            how = Evaluation(evaluation) if evaluation is not None else Evaluation.MATRIX
        else:
            u = np.array(knots, dtype=np.float64).reshape(-1)
            if u.shape != (n + degree + 1,):
                raise ValueError(f"knots: need {n + degree + 1}, got {u.shape}")
            if not np.all(np.isfinite(u)):
                raise ValueError("knots must be finite")
            if np.any(np.diff(u) <= 0.0):
                raise ValueError("knots must be strictly increasing")
            how = Evaluation(evaluation) if evaluation is not None else Evaluation.DE_BOOR
            if how is Evaluation.MATRIX:
                raise ValueError("the matrix form needs uniform knots: give dt, not knots")
        q.setflags(write=False)
        u.setflags(write=False)
        self._q, self._u, self._p, self._dt, self._eval = q, u, degree, dt, how
        self._duration = float(u[n] - u[degree])
        self._b = self._tck = None
        if how is Evaluation.DE_BOOR:
            b0 = ScipyBSpline(u, q, degree, extrapolate=False)
            self._b = (b0, *(b0.derivative(k) for k in range(1, degree + 1)))
            # knots, coefficients (n, d) and degree of the spline and its first two
            # derivatives: the one-point path (:meth:`pva`). scipy pads a derivative's
            # coefficients with zeros; at the domain's right end :func:`_deboor` then steps
            # into the padded span, where the padding has zero weight for degree >= 1 (the
            # arithmetic the cubic's rows were flown with) but not for a piecewise constant,
            # whose padding is cut
            self._tck = tuple((np.ascontiguousarray(b.t),
                               np.ascontiguousarray(b.c if b.k else b.c[:len(b.t) - 1]),
                               int(b.k)) for b in self._b[:3])

    # ---- parametrisation ---------------------------------------------------------------
    @property
    def control_points(self) -> np.ndarray:
        """``(N, d)`` read-only array of control points."""
        return self._q

    @property
    def evaluation(self) -> Evaluation:
        """How the curve is evaluated (chosen at construction, kept by every operation that
        makes a new spline from this one, except the non-uniform re-timings)."""
        return self._eval

    @property
    def uniform(self) -> bool:
        """Whether the spline was built from a knot span ``dt`` (uniform knots)."""
        return self._dt is not None

    @property
    def dt(self) -> float:
        """Knot span in seconds (uniform knots only)."""
        if self._dt is None:
            raise ValueError("a spline built from a knot vector has no single knot span")
        return self._dt

    @property
    def degree(self) -> int:
        """Polynomial degree ``p`` of each piece (3 for the planners' curves)."""
        return self._p

    @property
    def dim(self) -> int:
        """Dimension of the control points (3 for a path, 1 for a yaw curve)."""
        return self._q.shape[1]

    @property
    def num_control_points(self) -> int:
        return self._q.shape[0]

    @property
    def num_segments(self) -> int:
        """Number of knot spans the curve is defined on (``N - p``)."""
        return self._q.shape[0] - self._p

    @property
    def duration(self) -> float:
        """Length of the curve's time domain ``u[N] - u[p]`` in seconds (``(N - p) dt`` for
        uniform knots)."""
        return self._duration

    @property
    def knots(self) -> np.ndarray:
        """Full knot vector ``u[0 .. N + p]`` (read-only)."""
        return self._u

    def knot_times(self) -> np.ndarray:
        """Times of the knots inside the domain: ``0, dt, ..., duration`` (``N - p + 1``)."""
        if self._dt is not None:
            return np.arange(self.num_segments + 1) * self._dt
        return self._u[self._p:self._q.shape[0] + 1] - self._u[self._p]

    def knot_points(self) -> np.ndarray:
        """Curve positions at :meth:`knot_times`, shape ``(N - p + 1, d)``."""
        return self.evaluate(self.knot_times())

    def _like(self, control_points, degree: int | None = None,
              evaluation: Evaluation | str | None = None) -> BSpline:
        """A spline with this one's knots (or knot span) and evaluation unless given."""
        p = self._p if degree is None else degree
        how = self._eval if evaluation is None else evaluation
        if self._dt is not None:
            return BSpline(control_points, self._dt, p, evaluation=how)
        trim = self._p - p
        return BSpline(control_points, degree=p, evaluation=how,
                       knots=self._u[trim:self._u.shape[0] - trim])

    def with_control_points(self, control_points) -> BSpline:
        """Same knots, degree and evaluation, new control points."""
        return self._like(control_points)

    def with_evaluation(self, evaluation: Evaluation | str) -> BSpline:
        """The same curve (same knots and control points) evaluated the other way."""
        return self._like(self._q, evaluation=evaluation)

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

        Returns shape ``(d,)`` for a scalar ``t``, else ``(len(t), d)``. Derivatives above
        the degree are zero.
        """
        order = int(order)
        if order < 0:
            raise ValueError(f"order must be >= 0, got {order}")
        if self._eval is Evaluation.DE_BOOR:
            n = self._q.shape[0]
            x = np.clip(np.asarray(t, dtype=np.float64), 0.0, self.duration) + self._u[self._p]
            x = np.minimum(x, self._u[n])
            if order > self._p:
                return np.zeros(np.shape(x) + (self._q.shape[1],))
            return self._b[order](x)
        k, s, scalar = self._segment(t)
        if order > self._p:
            out = np.zeros((k.shape[0], self._q.shape[1]))
        else:
            w = _power_rows(s, self._p, order, self._dt) @ basis_matrix(self._p)  # (M, p+1)
            idx = k[:, None] + np.arange(self._p + 1)[None, :]
            out = np.einsum("mj,mjd->md", w, self._q[idx])
        return out[0] if scalar else out

    def pva(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at one time ``t`` (clamped to the domain):
        :meth:`evaluate` for orders 0-2 in one compiled call (the 100 Hz setpoint path)."""
        out = np.empty((3, self._q.shape[1]))
        if self._eval is Evaluation.MATRIX:
            _pva_kernel(self._q, self._dt, self._p, basis_matrix(self._p), float(t), out)
            return out[0], out[1], out[2]
        n = self._q.shape[0]
        x = min(min(max(float(t), 0.0), self.duration) + self._u[self._p], self._u[n])
        out[len(self._tck):] = 0.0
        for order, (tk, ck, k) in enumerate(self._tck):
            _deboor(tk, ck, k, x, out[order])
        return out[0], out[1], out[2]

    # ---- derivative splines ------------------------------------------------------------
    def derivative_control_points(self, order: int = 1) -> np.ndarray:
        """Control points of the ``order``-th derivative spline, ``(N - order, d)``:
        ``order`` finite differences of ``Q`` over ``dt^order`` (``MATRIX``), or from knot
        differences (``DE_BOOR``, module docstring)."""
        order = int(order)
        if not 0 <= order <= self._p:
            raise ValueError(f"order must be in [0, {self._p}], got {order}")
        if self._eval is Evaluation.MATRIX:
            return np.diff(self._q, n=order, axis=0) / self._dt ** order
        c, u, p = self._q, self._u, self._p
        n = c.shape[0]
        for r in range(1, order + 1):
            span = u[p + 1:n + p + 1 - r] - u[r:n]
            c = (p - r + 1) * np.diff(c, axis=0) / span[:, None]
        return c

    def velocity_control_points(self) -> np.ndarray:
        return self.derivative_control_points(1)

    def acceleration_control_points(self) -> np.ndarray:
        return self.derivative_control_points(2)

    def derivative(self, order: int = 1) -> BSpline:
        """The ``order``-th derivative as a spline of degree ``p - order`` (same time domain
        and evaluation)."""
        order = int(order)
        return self._like(self.derivative_control_points(order), degree=self._p - order)

    # ---- checks ------------------------------------------------------------------------
    def feasibility(self, vmax: float, amax: float, tolerance: float = 0.0,
                    vel_norm: bool = False) -> Feasibility:
        """Check of the velocity and acceleration control points against ``vmax``/``amax``
        (m/s, m/s^2) per axis, allowing ``tolerance`` (EGO's ``feasibility_tolerance``, 0.05
        in its launch files) plus 1e-4 as EGO and Fast-Planner (``checkFeasibility``) do.
        ``vel_norm`` bounds the velocity control points' Euclidean norm instead (the
        benchmark's speed cap is a speed)."""
        if not (vmax > 0 and amax > 0):
            raise ValueError(f"vmax and amax must be positive, got {vmax!r}, {amax!r}")
        vel = self.velocity_control_points()
        vm = np.linalg.norm(vel, axis=1) if vel_norm else np.abs(vel)
        max_v = float(np.max(vm)) if vel.size else 0.0
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
        return ScipyBSpline(self._u, np.array(self._q), self._p, extrapolate=False)

    # ---- re-timing ---------------------------------------------------------------------
    def stretch_time(self, ratio: float) -> BSpline:
        """Time re-allocation on uniform knots: the same geometric curve flown ``ratio``
        times slower (``dt *= ratio``; velocity scales by ``1/ratio``, acceleration by
        ``1/ratio^2``)."""
        if not (np.isfinite(ratio) and ratio > 0):
            raise ValueError(f"ratio must be a positive number, got {ratio!r}")
        return BSpline(self._q, self.dt * float(ratio), self._p, evaluation=self._eval)

    def _require_cubic(self, what: str) -> None:
        if self._p != CUBIC:
            raise ValueError(f"{what} is Fast-Planner's re-timing of cubic B-splines, got "
                             f"degree {self._p}")

    def reallocate_time(self, vmax: float, amax: float, limit_ratio: float = 1.1,
                        vel_norm: bool = False,
                        keep_start: bool = True) -> tuple[BSpline, bool]:
        """One pass of Fast-Planner's ``reallocateTime`` (cubic only): returns the re-timed
        spline (``DE_BOOR``, non-uniform knots) and whether this pass found everything
        feasible (nothing changed). The knot intervals under each velocity or acceleration
        control point beyond ``vmax`` / ``amax`` are lengthened, by at most ``limit_ratio``
        each (:func:`~ft_sitl.navigation.trajectories.bspline_retime.reallocated_knots`);
        ``keep_start`` keeps the start state. The control points' arithmetic is that
        function's own whatever the spline's evaluation."""
        self._require_cubic("reallocate_time")
        u, feasible = reallocated_knots(self._q, self._u, vmax, amax, limit_ratio, vel_norm,
                                        keep_start)
        return BSpline(self._q, degree=CUBIC, knots=u, evaluation=Evaluation.DE_BOOR), feasible

    def retimed(self, vmax: float, amax: float, limit_ratio: float = 1.1, passes: int = 3,
                vel_norm: bool = False, keep_start: bool = True) -> tuple[BSpline, int]:
        """Fast-Planner's planner-manager loop: :meth:`reallocate_time` while infeasible
        (:meth:`feasibility` with no tolerance), at most ``passes`` times. Returns the
        spline (this one when already feasible) and the number of passes made."""
        out = self
        if out.feasibility(vmax, amax, vel_norm=vel_norm).ok:
            return out, 0
        k = 0
        while k < passes:
            out, ok = out.reallocate_time(vmax, amax, limit_ratio, vel_norm, keep_start)
            k += 1
            if ok:
                break
        return out, k

    def lengthen_time(self, ratio: float) -> BSpline:
        """Fast-Planner's ``lengthenTime`` (cubic only): the knot spans between the first two
        and the last two are stretched so that the duration grows by ``(ratio - 1)`` times
        theirs (the curve's shape is unchanged and its start and end keep their speed); with
        too few knots to keep the ends, all knots are scaled by ``ratio``. Returns a
        ``DE_BOOR`` spline over the new knots."""
        self._require_cubic("lengthen_time")
        if not (np.isfinite(ratio) and ratio > 0):
            raise ValueError(f"ratio must be a positive number, got {ratio!r}")
        return BSpline(self._q, degree=CUBIC, knots=lengthened_knots(self._u, ratio),
                       evaluation=Evaluation.DE_BOOR)

    # ---- fitting -----------------------------------------------------------------------
    @classmethod
    def fit(cls, points, dt: float, v0, v1, a0, a1, degree: int = 3) -> BSpline:
        """EGO's initial parametrisation (``parameterizeToBspline``): control points that
        put the curve through ``points`` (K >= 2 samples ``(K, d)`` of a path taken at times
        ``0, dt, ..., (K-1) dt``) with start/end velocity ``v0``/``v1`` and acceleration
        ``a0``/``a1``, in the least-squares sense. A uniform ``MATRIX`` spline.

        The curve gets ``K - 1`` segments and ``K - 1 + p`` control points; the K position
        equations and the 4 derivative equations (K + 4 rows) are solved jointly, unweighted,
        like the original's QR solve, so the samples and end derivatives are met only
        approximately when the system is over-determined (always, for the cubic).
        """
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[0] < 2:
            raise ValueError(f"points must have shape (K >= 2, d), got {pts.shape}")
        if not (np.isfinite(dt) and dt > 0):
            raise ValueError(f"dt must be a positive number of seconds, got {dt!r}")
        degree = int(degree)
        if degree < 2:
            raise ValueError("fit needs degree >= 2 (acceleration constraints)")
        return cls(fit_control_points(pts, dt, v0, v1, a0, a1, basis_matrix(degree)), dt,
                   degree)
