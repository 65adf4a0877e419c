"""Minimum-snap piecewise polynomials: EGO-Planner's global reference and local target.

:func:`min_snap` solves for the piecewise polynomial through waypoints ``w_0 .. w_M`` with
segment durations ``T_i`` that minimises ``sum_i int ||d^r p / dt^r||^2 dt`` (``r = 4``:
snap; ``r = 3``: jerk) with the derivatives ``1 .. r-1`` fixed at both ends (velocity and
acceleration given, higher ones zero) and free at the interior waypoints. The minimiser has
segments of degree ``2r - 1`` with continuous derivatives up to ``2r - 2`` at the interior
waypoints (Euler-Lagrange: ``p^(2r) = 0`` on each segment, natural conditions at the free
waypoints), so it is the solution of one square, banded linear system: two position
conditions per segment, ``r - 1`` boundary conditions at each end and ``2r - 2``
continuity conditions per interior waypoint (``2r M`` equations for ``2r M``
coefficients), solved with a sparse LU for all three axes at once. Coefficients are kept in
each segment's normalised time ``s = (t - t_i) / T_i`` for conditioning.

Note on the original: EGO's ``PolynomialTraj::minSnapTraj``, despite its name, uses
quintics and minimises the integral of squared jerk (``r = 3``); its local initial path
(``one_segment_traj_gen``) is the one-segment quintic with given end velocity and
acceleration. ``order=3`` reproduces both; the default here is true minimum snap
(``order=4``), as specified for this project. For EGO's global reference the waypoints are
collinear (start -> goal), so the order only changes the speed profile along the line.

EGO's global reference (:func:`global_reference`): waypoints every <= 4 m on the straight
start -> goal line (``floor(d / 4) + 1`` equal pieces), durations ``d_i / vmax`` with the
first and last doubled (EGO's allowance for accelerating from and braking to rest; see
:func:`ego_time_allocation`), zero
velocity and acceleration at the goal. The local target (:meth:`PiecewisePolynomial
.local_target`) is EGO's ``getLocalTarget``: the first point of the reference, scanning
forward from the last progress time, at least ``horizon`` (7.5 m) from the vehicle, with
the reference's velocity there, or zero velocity when the goal is within the braking
distance ``vmax^2 / (2 amax)`` of the target.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from math import factorial

import numpy as np
from scipy.sparse import csc_matrix
from scipy.sparse.linalg import splu

from ft_sitl.navigation.trajectories.base import Trajectory

__all__ = [
    "LocalTarget", "PiecewisePolynomial", "ego_time_allocation", "ego_waypoints",
    "global_reference", "min_snap", "one_segment_time",
]


def _falling(k: int, m: int) -> float:
    """k! / (k - m)! (0 when m > k)."""
    return 0.0 if m > k else factorial(k) / factorial(k - m)


@dataclass(frozen=True)
class LocalTarget:
    point: np.ndarray  # (3,) world position of the local target
    velocity: np.ndarray  # (3,) velocity to arrive with
    time_s: float  # reference time of the target
    progress_time_s: float  # reference time nearest the vehicle during the scan
    at_goal: bool  # the scan ran off the end: the target is the goal


class PiecewisePolynomial(Trajectory):
    """Polynomial segments in R^3 stored in normalised time.

    ``coeffs[i, k]`` multiplies ``s^k`` on segment ``i`` (``s = (t - t_i) / T_i``);
    ``durations[i] = T_i``. Evaluation clamps ``t`` to ``[0, duration]``.
    """

    def __init__(self, coeffs, durations):
        c = np.array(coeffs, dtype=float)
        d = np.array(durations, dtype=float).reshape(-1)
        if c.ndim != 3 or c.shape[2] != 3 or c.shape[0] != d.shape[0] or c.shape[0] < 1:
            raise ValueError(f"coeffs must be (M, D+1, 3) with M = len(durations), got "
                             f"{c.shape} and {d.shape}")
        if not np.all(np.isfinite(d)) or np.any(d <= 0):
            raise ValueError("durations must be positive and finite")
        c.setflags(write=False)
        d.setflags(write=False)
        self._c = c
        self._T = d
        self._t0 = np.concatenate([[0.0], np.cumsum(d)])
        self._arc: tuple[np.ndarray, np.ndarray] | None = None

    @property
    def coeffs(self) -> np.ndarray:
        return self._c

    @property
    def durations(self) -> np.ndarray:
        return self._T

    @property
    def degree(self) -> int:
        return self._c.shape[1] - 1

    @property
    def num_segments(self) -> int:
        return self._c.shape[0]

    @property
    def duration(self) -> float:
        return float(self._t0[-1])

    @property
    def segment_times(self) -> np.ndarray:
        """Start times of the segments plus the end time (``M + 1``)."""
        return self._t0.copy()

    def waypoints(self) -> np.ndarray:
        """Positions at the segment boundaries, ``(M + 1, 3)``."""
        return self.evaluate(self._t0)

    def evaluate(self, t, order: int = 0) -> np.ndarray:
        """``order``-th time derivative at ``t`` (scalar -> (3,), array -> (len, 3))."""
        order = int(order)
        if order < 0:
            raise ValueError(f"order must be >= 0, got {order}")
        scalar = np.ndim(t) == 0
        tt = np.clip(np.atleast_1d(np.asarray(t, dtype=float)), 0.0, self.duration)
        seg = np.clip(np.searchsorted(self._t0, tt, side="right") - 1, 0, self.num_segments - 1)
        T = self._T[seg]
        s = (tt - self._t0[seg]) / T
        deg = self.degree
        rows = np.zeros((tt.shape[0], deg + 1))
        for k in range(order, deg + 1):
            rows[:, k] = _falling(k, order) * s ** (k - order)
        out = np.einsum("mk,mkd->md", rows, self._c[seg]) / (T ** order)[:, None]
        return out[0] if scalar else out

    # ---- arc length --------------------------------------------------------------------
    def _arc_table(self) -> tuple[np.ndarray, np.ndarray]:
        if self._arc is None:
            n = 64 * self.num_segments + 1
            t = np.linspace(0.0, self.duration, n)
            # cumulative trapezoid of the speed
            speed = np.linalg.norm(self.velocity(t), axis=1)
            s = np.concatenate([[0.0], np.cumsum(0.5 * (speed[1:] + speed[:-1]) * np.diff(t))])
            self._arc = (t, s)
        return self._arc

    def arc_length(self, t) -> np.ndarray | float:
        """Path length from ``t = 0`` to ``t`` (table of 64 samples per segment)."""
        tab_t, tab_s = self._arc_table()
        out = np.interp(np.clip(t, 0.0, self.duration), tab_t, tab_s)
        return float(out) if np.ndim(t) == 0 else out

    @property
    def length(self) -> float:
        return float(self._arc_table()[1][-1])

    def time_at_arc_length(self, s) -> np.ndarray | float:
        """Inverse of :meth:`arc_length` (clamped to the path)."""
        tab_t, tab_s = self._arc_table()
        out = np.interp(np.clip(s, 0.0, tab_s[-1]), tab_s, tab_t)
        return float(out) if np.ndim(s) == 0 else out

    def point_ahead(self, t_from: float, distance: float) -> tuple[float, np.ndarray]:
        """Time and position ``distance`` metres further along the path than at ``t_from``
        (the end of the path if it is shorter)."""
        t = self.time_at_arc_length(self.arc_length(t_from) + distance)
        return t, self.position(t)

    def local_target(self, position, t_from: float, horizon: float = 7.5,
                     vmax: float = 4.0, amax: float = 3.0) -> LocalTarget:
        """EGO's ``getLocalTarget`` (module docstring): scan the reference from ``t_from``
        every ``horizon / 20 / vmax`` seconds for the first point at least ``horizon``
        from ``position``."""
        if not (horizon > 0 and vmax > 0 and amax > 0):
            raise ValueError("horizon, vmax and amax must be positive")
        pos = np.asarray(position, dtype=float).reshape(3)
        t_step = horizon / 20.0 / vmax
        t_from = float(np.clip(t_from, 0.0, self.duration))
        ts = t_from + t_step * np.arange(int(math.floor((self.duration - t_from) / t_step)) + 1)
        pts = self.position(ts)
        dist = np.linalg.norm(pts - pos, axis=1)
        far = np.flatnonzero(dist >= horizon)
        goal = self.position(self.duration)
        if far.size:
            k = int(far[0])
            t_target = float(ts[k])
            point = pts[k]
            progress = float(ts[int(np.argmin(dist[:k + 1]))])
            at_goal = False
        else:
            t_target = self.duration
            point = goal
            progress = float(ts[int(np.argmin(dist))])
            at_goal = True
        if np.linalg.norm(goal - point) < vmax * vmax / (2.0 * amax):
            vel = np.zeros(3)
        else:
            vel = self.velocity(t_target)
        return LocalTarget(point=np.array(point), velocity=vel, time_s=t_target,
                           progress_time_s=progress, at_goal=at_goal)


def min_snap(waypoints, durations, v0=None, a0=None, v1=None, a1=None,
             order: int = 4) -> PiecewisePolynomial:
    """The minimum-``order``-derivative piecewise polynomial through ``waypoints``
    ``(M + 1, 3)`` with segment ``durations`` ``(M,)`` (module docstring). End velocity and
    acceleration default to zero; for ``order > 3`` the derivatives 3 .. order-1 are zero
    at both ends."""
    w = np.asarray(waypoints, dtype=float)
    T = np.asarray(durations, dtype=float).reshape(-1)
    if w.ndim != 2 or w.shape[1] != 3 or w.shape[0] < 2:
        raise ValueError(f"waypoints must have shape (M + 1 >= 2, 3), got {w.shape}")
    m = w.shape[0] - 1
    if T.shape[0] != m or not np.all(np.isfinite(T)) or np.any(T <= 0):
        raise ValueError(f"durations must be {m} positive numbers, got {T}")
    r = int(order)
    if r < 2:
        raise ValueError(f"order must be >= 2, got {order}")
    n_c = 2 * r  # coefficients per segment (degree 2r - 1)

    def _vec(x):
        return np.zeros(3) if x is None else np.asarray(x, dtype=float).reshape(3)

    start = {1: _vec(v0), 2: _vec(a0)}
    end = {1: _vec(v1), 2: _vec(a1)}
    if r == 2 and (np.any(start[2]) or np.any(end[2])):
        raise ValueError("order 2 (minimum acceleration) cannot fix the end accelerations")

    rows, cols, vals = [], [], []
    rhs = np.zeros((m * n_c, 3))
    eq = 0

    def put(col, val):
        rows.append(eq)
        cols.append(col)
        vals.append(val)

    for i in range(m):
        base = i * n_c
        put(base, 1.0)  # p_i(0) = w_i
        rhs[eq] = w[i]
        eq += 1
        for k in range(n_c):  # p_i(1) = w_{i+1}
            put(base + k, 1.0)
        rhs[eq] = w[i + 1]
        eq += 1
    for mth in range(1, r):  # start derivatives: T0^-m m! c_{0,m} = b
        put(mth, float(factorial(mth)))
        rhs[eq] = start.get(mth, np.zeros(3)) * T[0] ** mth
        eq += 1
    last = (m - 1) * n_c
    for mth in range(1, r):  # end derivatives: T^-m sum_k falling(k, m) c_k = b
        for k in range(mth, n_c):
            put(last + k, _falling(k, mth))
        rhs[eq] = end.get(mth, np.zeros(3)) * T[-1] ** mth
        eq += 1
    for i in range(m - 1):  # continuity of derivatives 1 .. 2r-2, scaled by T_i^m
        a_base, b_base = i * n_c, (i + 1) * n_c
        for mth in range(1, 2 * r - 1):
            for k in range(mth, n_c):
                put(a_base + k, _falling(k, mth))
            put(b_base + mth, -float(factorial(mth)) * (T[i] / T[i + 1]) ** mth)
            eq += 1
    assert eq == m * n_c

    a = csc_matrix((vals, (rows, cols)), shape=(eq, eq))
    sol = splu(a).solve(rhs)
    return PiecewisePolynomial(sol.reshape(m, n_c, 3), T)


def ego_waypoints(start, goal, spacing: float = 4.0) -> np.ndarray:
    """Start, goal and the equally spaced points EGO inserts when they are more than
    ``spacing`` apart (``floor(d / spacing) + 1`` pieces), ``(K, 3)``."""
    a = np.asarray(start, dtype=float).reshape(3)
    b = np.asarray(goal, dtype=float).reshape(3)
    if not spacing > 0:
        raise ValueError(f"spacing must be positive, got {spacing!r}")
    d = float(np.linalg.norm(b - a))
    pieces = int(math.floor(d / spacing)) + 1 if d > spacing else 1
    f = np.linspace(0.0, 1.0, pieces + 1)[:, None]
    return a + f * (b - a)


def ego_time_allocation(waypoints, vmax: float) -> np.ndarray:
    """EGO's global-reference durations: ``distance / vmax`` per piece, the first and the
    last doubled (EGO doubles ``time(0)`` and ``time(last)``, so a single piece gets 4x)."""
    w = np.asarray(waypoints, dtype=float)
    if not vmax > 0:
        raise ValueError(f"vmax must be positive, got {vmax!r}")
    T = np.linalg.norm(np.diff(w, axis=0), axis=1) / vmax
    T[0] *= 2.0
    T[-1] *= 2.0
    return T


def one_segment_time(distance: float, vmax: float, amax: float) -> float:
    """EGO's duration for the local initial polynomial over ``distance`` metres:
    ``sqrt(d / amax)`` when ``d < vmax^2 / amax``, else ``(d - vmax^2 / amax) / vmax +
    2 vmax / amax`` (a rest-to-rest ramp-cruise-ramp estimate)."""
    if not (vmax > 0 and amax > 0 and distance >= 0):
        raise ValueError("vmax and amax must be positive and distance non-negative")
    ramp = vmax * vmax / amax
    if distance < ramp:
        return math.sqrt(distance / amax)
    return (distance - ramp) / vmax + 2.0 * vmax / amax


def global_reference(start, goal, vmax: float, v0=None, a0=None, spacing: float = 4.0,
                     order: int = 4) -> PiecewisePolynomial:
    """EGO's global reference start -> goal (module docstring); ends at rest."""
    w = ego_waypoints(start, goal, spacing)
    if np.linalg.norm(w[-1] - w[0]) <= 0:
        raise ValueError("start and goal coincide")
    return min_snap(w, ego_time_allocation(w, vmax), v0=v0, a0=a0, order=order)
