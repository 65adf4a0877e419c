"""The one trajectory protocol: a curve over ``[0, duration]`` seconds that gives its
derivatives of any order, and :class:`SplineTrajectory`, a planned curve (with an optional
yaw curve) started at a navigation time.

Every curve a planner makes (the B-spline, :mod:`.bspline`; the piecewise polynomial,
:mod:`.minsnap`) implements :meth:`Trajectory.evaluate`; the named accessors
(:meth:`~Trajectory.position`, ...) are written here once."""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np


class Trajectory(ABC):
    """A curve in time over ``[0, duration]`` (s): :meth:`evaluate` gives its ``order``-th
    derivative at times ``t`` (clamped to the domain; a scalar gives one point, an array
    one row per time)."""

    __slots__ = ()

    @property
    @abstractmethod
    def duration(self) -> float:
        """Length of the time domain (s)."""

    @abstractmethod
    def evaluate(self, t, order: int = 0) -> np.ndarray:
        """The ``order``-th time derivative at ``t``."""

    def position(self, t) -> np.ndarray:
        return self.evaluate(t, 0)

    def velocity(self, t) -> np.ndarray:
        return self.evaluate(t, 1)

    def acceleration(self, t) -> np.ndarray:
        return self.evaluate(t, 2)

    def jerk(self, t) -> np.ndarray:
        return self.evaluate(t, 3)

    def pva(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at one time ``t`` (a curve with a faster
        one-point path overrides this)."""
        return self.evaluate(t, 0), self.evaluate(t, 1), self.evaluate(t, 2)


class SplineTrajectory:
    """The curve ``spline`` flown from navigation time ``t0`` (s), with the yaw curve
    ``yaw`` (1-D, continuous, not wrapped) when the planner plans one."""

    def __init__(self, spline: Trajectory, t0: float, yaw: Trajectory | None = None):
        self.spline = spline
        self.yaw = yaw
        self.t0 = t0
        self.start = spline.position(0.0)

    @property
    def duration(self) -> float:
        return self.spline.duration

    @property
    def end_time(self) -> float:
        return self.t0 + self.spline.duration

    def state(self, t: float):
        """Position, velocity, acceleration at time t (clamped to the trajectory)."""
        tau = min(max(t - self.t0, 0.0), self.spline.duration)
        return self.spline.pva(tau)

    def yaw_state(self, t: float) -> np.ndarray:
        """Yaw, yaw rate and yaw acceleration at time t (clamped to the yaw curve)."""
        tau = min(max(t - self.t0, 0.0), self.yaw.duration)
        return np.array([v[0] for v in self.yaw.pva(tau)])
