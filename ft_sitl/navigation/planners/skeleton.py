"""Pieces the planners share: angle wrapping, a B-spline trajectory started at a time, yaw
pursuit, the NaN guard on every setpoint, and :class:`ReplanningPlanner`, the skeleton of
the three optimisation planners (parameters, depth camera, map, the pending plan and its
latency, failure back-off and giving up). The depth cameras themselves (the benchmark's
presets, :func:`~ft_sitl.scenarios.camera.camera_config`) live with the camera."""

from __future__ import annotations

import math
import time

import numpy as np

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.navigation.base import GiveUp, Navigator, Observation, Task
from ft_sitl.navigation.maps.mapping import local_map_for
from ft_sitl.scenarios.camera import CAMERA_PARAMS, camera_of
from ft_sitl.schema import Param, Schema

#: after a failed plan, the next attempt waits this long (simulated s), doubling with each
#: further failure in a row up to RETRY_MAX_S
RETRY_S = 0.05
RETRY_MAX_S = 1.0
#: failed attempts in a row from the same start with an unchanged map before a planner
#: gives up (its deterministic planning would fail the same way until the timeout)
GIVE_UP_AFTER = 8


def wrap_angle(a: float) -> float:
    """a wrapped into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class SplineTrajectory:
    """A B-spline trajectory started at navigation time ``t0`` (s)."""

    def __init__(self, spline, t0: float):
        self.spline = spline
        self.t0 = t0
        self.start = spline.position(0.0)

    def state(self, t: float):
        """Position, velocity, acceleration at time t (clamped to the trajectory)."""
        tau = min(max(t - self.t0, 0.0), self.spline.duration)
        pva = getattr(self.spline, "pva", None)
        if pva is not None:
            return pva(tau)
        return (self.spline.position(tau), self.spline.velocity(tau),
                self.spline.acceleration(tau))

    @property
    def end_time(self) -> float:
        return self.t0 + self.spline.duration


def pursue_yaw(yaw: float, direction, rate_hz: float) -> float:
    """One step of the planners' yaw: toward the horizontal ``direction`` (unchanged when it
    is shorter than 0.1 m), rate-limited to pi rad/s at ``rate_hz``, low-pass 0.5."""
    if float(np.hypot(direction[0], direction[1])) <= 0.1:
        return yaw
    step = wrap_angle(math.atan2(direction[1], direction[0]) - yaw)
    limit = math.pi / rate_hz
    return wrap_angle(yaw + 0.5 * max(-limit, min(limit, step)))


def checked_setpoint(t: float, p, v, a, yaw: float, yaw_rate: float | None = None) -> Setpoint:
    """The position + velocity + acceleration setpoint, or FloatingPointError when any part
    is not finite: a planner never commands NaN (the trial fails as a navigator error)."""
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(v)) and np.all(np.isfinite(a))
            and math.isfinite(yaw) and (yaw_rate is None or math.isfinite(yaw_rate))):
        raise FloatingPointError(f"non-finite setpoint at t = {t:.2f} s: p {p}, v {v}, "
                                 f"a {a}, yaw {yaw}, yaw rate {yaw_rate}")
    return Setpoint.position(p, velocity=v, acceleration=a, yaw=yaw, yaw_rate=yaw_rate)


MAX_ACC = Param("max_acc_m_s2", 2.0, "m/s^2", (0.5, 20.0),
                doc="acceleration limit of the planned trajectories (protocol 3 on: the "
                    "campaign's limits.max_acc_m_s2 instead)")
LATENCY = Param("latency_s", 0.01, "s", (0.0, 1.0),
                doc="a plan takes effect this long (simulated) after it was asked for: the "
                    "original's compute time on a desktop CPU")
MEASURED_LATENCY = Param("measured_latency", False,
                         doc="use this process's measured compute time instead of latency_s")
NO_REPLAN_THRESHOLD = Param("no_replan_threshold_m", 2.0, "m", (0.0, 10.0),
                            doc="no new plan once the goal is this close")


class DelayedCommands:
    """A command computed every ``1 / rate_hz`` s (simulated) from the observation of that
    moment and put in force ``latency_s`` later, or after its measured compute time with
    ``measured``: how the learned navigators (NavRL, learned) turn a policy's output into
    the setpoint of each step. ``compute_s`` keeps each computation's wall-clock time."""

    def __init__(self, rate_hz: float, latency_s: float, measured: bool):
        self.period = 1.0 / float(rate_hz)
        self.latency = float(latency_s)
        self.measured = bool(measured)
        self.next_t = 0.0
        self.current = None
        self.pending: tuple[float, object] | None = None
        self.compute_s: list[float] = []

    def step(self, t: float, compute):
        """The command in force at ``t``: a pending one whose time has come takes over;
        when a period is due, ``compute()`` gives the next (None: no new command). None
        before the first command is in force."""
        if self.pending is not None and t >= self.pending[0] - 1e-9:
            self.current, self.pending = self.pending[1], None
        if t >= self.next_t - 1e-9:
            self.next_t = t + self.period
            t0 = time.perf_counter()
            cmd = compute()
            dt = time.perf_counter() - t0
            self.compute_s.append(dt)
            if cmd is not None:
                lat = dt if self.measured else self.latency
                if lat <= 0.0:
                    self.current = cmd
                else:
                    self.pending = (t + lat, cmd)
        return self.current


def planner_schema(*own: Param, **defaults) -> Schema:
    """A replanning planner's parameters: ``max_acc_m_s2``, the planner's ``own``, the
    latency ones and the camera's, with ``defaults`` replacing the declared ones."""
    return Schema((MAX_ACC, *own, LATENCY, MEASURED_LATENCY,
                   *CAMERA_PARAMS)).with_defaults(**defaults)


class ReplanningPlanner(Navigator):
    """What EGO, Fast and PGO share around their own planning: the parameters every one of
    them takes, the local map, the plan that takes effect ``latency_s`` after it was asked
    for (or after its measured compute time), retries with a doubling back-off after a
    failed plan, and giving up after :data:`GIVE_UP_AFTER` failures with nothing changed.

    Subclasses implement ``_plan(obs)`` (ending in :meth:`_adopt_at` or :meth:`_failed`)
    and their ``step``, which starts with :meth:`_perceive`.
    """

    rate_hz = 100.0

    schema = planner_schema()

    def __init__(self, **params):
        super().__init__(**params)
        p = self.settings
        self.max_acc = float(p["max_acc_m_s2"])
        self.latency = float(p["latency_s"])
        self.measured_latency = bool(p["measured_latency"])
        self.camera = camera_of(p)

    def reset(self, task: Task) -> None:
        super().reset(task)
        self.vmax = task.limits.max_speed_m_s
        # the protocol's acceleration limit when the trial has one (protocol 3 on), else
        # the planner's own parameter
        self.max_acc = (task.limits.max_acc_m_s2 if task.limits.max_acc_m_s2 is not None
                        else float(self.settings["max_acc_m_s2"]))
        self.map = local_map_for(task, self.camera)
        self.bounds = (np.array(task.bounds_min, dtype=float),
                       np.array(task.bounds_max, dtype=float))
        self.traj = None  # flying this (None: holding stop_at or the current position)
        self.pending = None  # the next plan, in effect from pending_at
        self.pending_at = math.inf
        self.plan_now = True
        self.from_rest = True  # the next plan starts at rest (at stop_at when set)
        self.stop_at: np.ndarray | None = None
        self.next_check = 0.0
        self.yaw = float(task.start_yaw)
        self.failures = 0  # failed plans in a row
        self.retry_at = 0.0
        self.fail_sig = None
        self.same_failures = 0  # ... of them from the same start with the same map
        self.compute_s: list[float] = []  # wall-clock compute time of every plan

    def observe(self, obs: Observation) -> None:
        """Before navigation: fuse the depth frame into the map."""
        if obs.depth is not None:
            self.map.fuse(obs.depth)

    def _perceive(self, obs: Observation) -> bool:
        """Fuse the frame, if any, and switch to the pending plan when its time has come;
        True when it switched."""
        if obs.depth is not None:
            self.map.fuse(obs.depth)
        if self.pending is not None and obs.time_s >= self.pending_at:
            self.traj, self.pending, self.pending_at = self.pending, None, math.inf
            return True
        return False

    def _compute_time(self, t_start: float) -> float:
        """Record the plan's compute time; the latency the plan takes effect after."""
        dt = time.perf_counter() - t_start
        self.compute_s.append(dt)
        return dt if self.measured_latency else self.latency

    def _adopt_at(self, traj, obs: Observation, latency: float) -> None:
        """``traj`` (None: no new plan) takes effect ``latency`` s after ``obs``."""
        self.plan_now = False
        if traj is None:
            return
        traj.t0 = obs.time_s + latency
        self.pending = traj
        self.pending_at = obs.time_s + latency
        self.from_rest = False

    def _failed(self, obs: Observation, p0: np.ndarray, why: str, t_start: float) -> None:
        """A failed plan from ``p0``: retry after a back-off doubling with each failure in a
        row up to RETRY_MAX_S (a hovering vehicle's map barely changes between attempts);
        GiveUp after GIVE_UP_AFTER of them from the same start with an unchanged map."""
        self.failures += 1
        sig = (self.map.occupied_count, tuple(np.round(np.asarray(p0) / 0.05).astype(int)))
        self.same_failures = self.same_failures + 1 if sig == self.fail_sig else 1
        self.fail_sig = sig
        self._compute_time(t_start)
        if self.same_failures >= GIVE_UP_AFTER:
            raise GiveUp(f"no plan: {GIVE_UP_AFTER} attempts in a row failed ({why}) with an "
                         f"unchanged map")
        self.plan_now = True
        self.retry_at = obs.time_s + min(RETRY_S * 2.0 ** (self.failures - 1), RETRY_MAX_S)

    def _succeeded(self) -> None:
        self.failures = self.same_failures = 0

    def _hold(self, obs: Observation, yaw: float) -> Setpoint:
        """Hover at stop_at (or where the vehicle is) while there is no trajectory."""
        hold = self.stop_at if self.stop_at is not None else obs.position
        return Setpoint.position(hold, yaw=yaw)


class HorizonPlanner(ReplanningPlanner):
    """EGO's and Fast-Planner's replanning rule: a plan reaches ``planning_horizon_m``
    ahead; replan when the vehicle is ``replan_threshold_m`` along the current trajectory
    unless the goal is within ``no_replan_threshold_m``; a collision less than
    ``emergency_time_s`` ahead is an emergency."""

    schema = planner_schema(
        Param("planning_horizon_m", 7.5, "m", (2.0, 20.0),
              doc="a plan reaches this far ahead along the global reference"),
        Param("replan_threshold_m", 1.5, "m", (0.2, 10.0),
              doc="replan once the vehicle is this far along the current trajectory"),
        NO_REPLAN_THRESHOLD,
        Param("emergency_time_s", 0.8, "s", (0.0, 5.0),
              doc="a collision less than this far ahead on the trajectory is an emergency "
                  "(stop, then plan from rest)"),
    )

    def __init__(self, **params):
        super().__init__(**params)
        p = self.settings
        self.horizon = float(p["planning_horizon_m"])
        self.replan_threshold = float(p["replan_threshold_m"])
        self.no_replan_threshold = float(p["no_replan_threshold_m"])
        self.emergency_time = float(p["emergency_time_s"])
