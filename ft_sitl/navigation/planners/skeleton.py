"""The replanning skeleton the three optimisation planners (EGO, Fast-Planner, PGO) share:
:class:`ReplanningPlanner` (parameters, depth camera, map, the replanning loop with its two
hooks, the trigger and the emergency action, the pending plan and its latency, failure
back-off and giving up), :class:`HorizonPlanner` (EGO's and Fast-Planner's trigger
parameters), yaw pursuit and the NaN guard on every setpoint. The depth cameras themselves
(the benchmark's presets, :func:`~ft_sitl.scenarios.camera.camera_config`) live with the
camera."""

from __future__ import annotations

import math
import time

import numpy as np

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.frames import wrap_pi
from ft_sitl.navigation.base import GiveUp, Navigator, Observation, Task
from ft_sitl.navigation.latency import LATENCY, MEASURED_LATENCY
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


def pursue_yaw(yaw: float, direction, rate_hz: float) -> float:
    """One step of the planners' yaw: toward the horizontal ``direction`` (unchanged when it
    is shorter than 0.1 m), rate-limited to pi rad/s at ``rate_hz``, low-pass 0.5."""
    if float(np.hypot(direction[0], direction[1])) <= 0.1:
        return yaw
    step = wrap_pi(math.atan2(direction[1], direction[0]) - yaw)
    limit = math.pi / rate_hz
    return wrap_pi(yaw + 0.5 * max(-limit, min(limit, step)))


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
NO_REPLAN_THRESHOLD = Param("no_replan_threshold_m", 2.0, "m", (0.0, 10.0),
                            doc="no new plan once the goal is this close")


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

    :meth:`step` is the replanning loop all three run: perceive (and switch to a pending
    plan whose time has come), then, while flying a trajectory with no plan pending, ask
    the replanning trigger (:meth:`_replan_due`) and, at :attr:`safety_check_hz`, the
    safety check (:meth:`_collision_ahead`), whose finding asks for a plan and goes to the
    emergency action (:meth:`_emergency`); plan when asked and the back-off allows; the
    setpoint. Subclasses implement ``_plan(obs)`` (ending in :meth:`_adopt_at` or
    :meth:`_failed`) and the three hooks; :meth:`_setpoint` follows the trajectory with
    the pursued yaw (Fast-Planner's yaw curve overrides it).
    """

    rate_hz = 100.0
    #: the rate of the safety check of the trajectory ahead (the originals' 20 Hz timer)
    safety_check_hz = 20.0
    #: the pursued yaw points at the trajectory this far ahead (s)
    yaw_lookahead_s = 1.0

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

    # --- the replanning loop ------------------------------------------------------------
    def step(self, obs: Observation) -> Setpoint:
        t = obs.time_s
        if self._perceive(obs):
            # a stopped vehicle holds its point until the new plan acts (EGO and Fast clear
            # stop_at when they adopt a plan, so for them this changes nothing)
            self.stop_at = None
        if self.traj is not None and self.pending is None and self.stop_at is None:
            if self._replan_due(obs):
                self.plan_now = True
            if t >= self.next_check:
                self.next_check = t + 1.0 / self.safety_check_hz
                ahead = self._collision_ahead(t)
                if ahead is not None:
                    self.plan_now = True
                    self._emergency(obs, ahead)
        if self.plan_now and self.pending is None and t >= self.retry_at:
            self._plan(obs)
        return self._setpoint(obs)

    def _replan_due(self, obs: Observation) -> bool:
        """The replanning trigger: whether the current trajectory wants a new plan now."""
        raise NotImplementedError

    def _collision_ahead(self, t: float) -> float | None:
        """The safety check: how far ahead (in the planner's measure: s or m) the current
        trajectory meets an obstacle, or None."""
        raise NotImplementedError

    def _emergency(self, obs: Observation, ahead: float) -> None:
        """The emergency action on a collision ``ahead`` (a plan is already asked for)."""
        raise NotImplementedError

    def _stop(self, point: np.ndarray) -> None:
        """Hover at ``point`` (where the vehicle is), then plan from rest there."""
        self.stop_at = point
        self.from_rest = True
        self.traj = None

    def _setpoint(self, obs: Observation) -> Setpoint:
        """Position + velocity + acceleration of the trajectory (velocity and acceleration
        0 past its end), yaw pursuing the trajectory :attr:`yaw_lookahead_s` ahead."""
        t = obs.time_s
        if self.traj is None:
            return self._hold(obs, self.yaw)
        p, v, a = self.traj.state(t)
        self.yaw = pursue_yaw(self.yaw, self.traj.state(t + self.yaw_lookahead_s)[0] - p,
                              self.rate_hz)
        if t > self.traj.end_time:
            v = np.zeros(3)
            a = np.zeros(3)
        return checked_setpoint(t, p, v, a, self.yaw)

    def _hold(self, obs: Observation, yaw: float) -> Setpoint:
        """Hover at stop_at (or where the vehicle is) while there is no trajectory."""
        hold = self.stop_at if self.stop_at is not None else obs.position
        return Setpoint.position(hold, yaw=yaw)


class HorizonPlanner(ReplanningPlanner):
    """EGO's and Fast-Planner's replanning rule: a plan reaches ``planning_horizon_m``
    ahead; replan when the vehicle is ``replan_threshold_m`` along the current trajectory
    unless the goal is within ``no_replan_threshold_m``; a collision less than
    ``emergency_time_s`` ahead is an emergency (the planner says what it does)."""

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

    def _adopt_plan(self, traj, obs: Observation, latency: float) -> None:
        """``traj`` (None: no new plan) takes effect after ``latency``; a plan ends a stop."""
        self._adopt_at(traj, obs, latency)
        if traj is not None:
            self.stop_at = None
