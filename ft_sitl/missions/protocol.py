"""The FLYINGTRUST trial protocol, once, for every transport.

Both ways of flying a trial drive this module: in-process (:mod:`ft_sitl.missions.trial`,
the navigator called directly in lockstep) and over MAVLink
(:mod:`ft_sitl.transport.mavlink_trial`, the navigator a MAVSDK client in another
process). A transport advances the simulation
and calls :meth:`TrialReferee.after_step` after every advance; the referee runs the
phases, judges the outcome and keeps the metrics; :meth:`TrialReferee.finish` writes the
results row (:mod:`ft_sitl.missions.results`).

Phases (``../shared/docs/benchmark-protocol.md``, paper Sec. IV-B):

1. *Approach* (:class:`ApproachJudge`). The vehicle is armed on the takeoff point facing
   the goal and flown to the start waypoint (in-process the runner does it with PX4's
   AUTO.TAKEOFF and a reposition; over the wire the navigator's client does). It must be
   stable there -- within :data:`STABLE_POS_M` of it and slower than
   :data:`STABLE_SPEED_M_S` for :data:`STABLE_FOR_S` -- within :data:`APPROACH_TIMEOUT_S`
   of arming, else ``loss_of_control`` "could not reach the start". A collision, leaving
   the flight volume, a tilt beyond 90 deg, a non-finite state or a geofence breach the
   flight controller acts on end the trial here too.
2. *Navigation* (:class:`NavigationJudge`), from the moment the vehicle is stable. The
   outcome is the first of

   - ``collision``: the collision sphere touched an obstacle (the guard's event);
   - ``out_of_bounds``: the centre left the flight volume (area sides, ceiling), or the
     vehicle touched the floor;
   - ``loss_of_control``: tilt beyond 90 deg or a non-finite state;
   - ``geofence``: the vehicle breached the trial's geofence (``spec.fence``) and the
     flight controller took it from the navigator (GF_ACTION hold, return, terminate,
     land); a breach under "none" or "warning" is only counted (``fence_breaches``);
   - ``navigator_error``: the navigator failed (raised, returned no valid setpoint, its
     process died; decided by the transport);
   - ``timeout``: not in the goal sphere ``limits.timeout_s`` after navigation start, or
     the navigator gave up ("no plan");
   - ``unstable``: entered the goal sphere but left it within the ``limits.hold_s`` hold;
   - ``success``: entered the goal sphere in time and stayed in it for the hold.
"""

from __future__ import annotations

import datetime
import json
import math
import time
from dataclasses import dataclass, replace
from enum import Enum

import numpy as np

from ft_sitl import __version__
from ft_sitl.autopilot import failures
from ft_sitl.autopilot.cascade import C_SAT_STEPS, SP_POS
from ft_sitl.autopilot.geofence import TAKEOVER_ACTIONS
from ft_sitl.missions.resources import RESOURCES, TrialResources
from ft_sitl.missions.results import Outcome
from ft_sitl.missions.spec import TrialSpecError, fence_of
from ft_sitl.navigation.base import STABLE_FOR_S, STABLE_POS_M, STABLE_SPEED_M_S
from ft_sitl.physics.wind import Wind
from ft_sitl.provenance import software
from ft_sitl.scenarios.movers import NOT_STARTED
from ft_sitl.schema import SchemaError
from ft_sitl.sim.fleet import Fleet
from ft_sitl.sim.guard import CollisionGuard, GuardEventKind

APPROACH_TIMEOUT_S = 30.0
#: the progress toward the goal (m) that resets the stall clock of a protocol with
#: ``stall_timeout_s`` (ProtocolRules)
STALL_PROGRESS_M = 0.5
#: the in-process runner's check interval (the commander's tick, s)
TICK_S = 0.02
MAX_TILT_RAD = math.pi / 2


class TrialFailure(Exception):
    """A trial ended without success: ``reason`` (an :class:`Outcome`) and ``detail``."""

    def __init__(self, reason: Outcome, detail: str = ""):
        super().__init__(f"{reason}: {detail}")
        self.reason, self.detail = Outcome(reason), detail


class Phase(Enum):
    APPROACH = "approach"
    NAVIGATION = "navigation"
    DONE = "done"


def norm(v: np.ndarray) -> float:
    """np.linalg.norm of a float vector (it computes sqrt(v.dot(v)): the same bits) without
    its argument handling, which cost more than the arithmetic at every step."""
    return math.sqrt(v.dot(v))


def identity_row(spec, platform, scenario) -> dict:
    """The identity columns of a trial's row (results.IDENTITY)."""
    ind = platform.indicators()
    return {
        "trial_id": spec.trial_id, "campaign": spec.campaign,
        "algorithm": spec.label or spec.algorithm,
        "algorithm_params": json.dumps(spec.algorithm_params, sort_keys=True),
        "platform": platform.name, "platform_category": platform.category,
        "mass_kg": platform.mass_kg, "twr_max": ind.twr_max,
        "alpha_xy_max": ind.alpha_xy_max_rad_s2, "alpha_z_max": ind.alpha_z_max_rad_s2,
        "family": scenario.family, "scenario_category": scenario.category,
        "scenario_index": scenario.index, "scenario_seed": scenario.seed,
        "scenario": scenario.name, "trial": spec.trial, "seed": spec.seed,
        **wind_columns(spec.wind),
        "params": json.dumps(spec.params, sort_keys=True, separators=(",", ":"))
        if spec.params else "",
        "actuators": json.dumps(spec.actuators, sort_keys=True, separators=(",", ":"))
        if spec.actuators else "",
        "perception": json.dumps(spec.perception, sort_keys=True, separators=(",", ":"))
        if spec.perception else "",
        "estimator": json.dumps(spec.estimator, sort_keys=True, separators=(",", ":"))
        if spec.estimator else "",
        "failures": json.dumps(spec.failures, sort_keys=True, separators=(",", ":"))
        if spec.failures else "",
        "fence": json.dumps(spec.fence, sort_keys=True, separators=(",", ":"))
        if spec.fence else "",
        **mover_columns(spec.movers, scenario.movers),
        **limit_columns(spec.aggressiveness, spec.limits),
    }


def limit_columns(level: str | None, limits) -> dict:
    """The aggressiveness columns of a row (results.AXES): the level's name ("" without
    the axis), the speed cap and the acceleration limit the trial flew under (NaN: none,
    before protocol 3)."""
    return {"aggressiveness": level or "", "speed_limit_m_s": limits.max_speed_m_s,
            "acc_limit_m_s2": limits.max_acc_m_s2 if limits.max_acc_m_s2 is not None
            else math.nan}


def mover_columns(settings: dict | None, movers) -> dict:
    """The moving-obstacle columns of a row (results.AXES): how many were placed, their
    speed, and every non-default setting as JSON (0, 0 and "" in a static world)."""
    return {"mover_count": movers.count if movers is not None else 0,
            "mover_speed_m_s": float(movers.settings["speed_m_s"])
            if movers is not None and movers.count else 0.0,
            "movers": json.dumps(settings, sort_keys=True, separators=(",", ":"))
            if settings else ""}


def wind_columns(wind: dict | None) -> dict:
    """The wind columns of a row (results.AXES): the mean speed, the turbulence
    intensity, the gust amplitude, and every non-default setting as JSON ("" in calm
    air)."""
    w = Wind(wind).values
    return {"wind_speed_m_s": w["speed_m_s"], "turbulence": w["turbulence"],
            "gust_m_s": w["gust_m_s"],
            "wind": json.dumps(wind, sort_keys=True, separators=(",", ":")) if wind else ""}


def failed_row(spec, platform, scenario, reason: Outcome, detail: str) -> dict:
    """The row of a trial that never flew to an outcome (e.g. its process died): identity,
    outcome and provenance; the metrics are left out (NaN in the table)."""
    row = identity_row(spec, platform, scenario)
    row.update({"success": False, "reason": Outcome(reason).value, "detail": detail,
                "code_version": __version__, "software": software(),
                "protocol_version": spec.protocol,
                "gains": spec.gains, "scenario_version": spec.scenario_version,
                "spec": spec.to_json(),
                "finished_utc": utc_now()})
    return row


def utc_now() -> str:
    return datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")


def check_flight(fleet, n_events: int, s) -> None:
    """The checks of every navigation step: the guard's events since ``n_events``
    (collision, leaving the volume), a non-finite state, the tilt, touching the floor."""
    check_events(fleet, n_events, "")
    failure = flight_failure(bool(np.all(np.isfinite(fleet.sim.x[0]))), s.tilt, s.on_ground)
    if failure is not None:
        raise failure


def arming_failure(cmd, result_name: str = "refused") -> TrialFailure:
    """How a refused arming ends the trial (the flight controller's last status text in
    the detail): ``geofence`` when the fence refused it (protocol 8 on:
    ``Commander.arm_fence_check``), ``loss_of_control`` otherwise."""
    texts = [t for _, t in cmd.statustexts]
    detail = f"arming refused: {texts[-1] if texts else result_name}"
    if cmd.arm_fence_check and cmd.fence_breach_here() is not None:
        return TrialFailure(Outcome.GEOFENCE, detail)
    return TrialFailure(Outcome.LOSS_OF_CONTROL, detail)


def flight_failure(finite: bool, tilt: float, on_ground: bool) -> TrialFailure | None:
    """How the vehicle's true state ends the flight, if it does: a non-finite state or a
    tilt beyond :data:`MAX_TILT_RAD` (loss of control), touching the floor (out of
    bounds). The rule every navigation step applies (:func:`check_flight`, and
    ``ft_sitl.gym`` for each of its vehicles)."""
    if not finite:
        return TrialFailure(Outcome.LOSS_OF_CONTROL, "non-finite state")
    if tilt > MAX_TILT_RAD:
        return TrialFailure(Outcome.LOSS_OF_CONTROL, f"tilt {math.degrees(tilt):.0f} deg")
    if on_ground:
        return TrialFailure(Outcome.OUT_OF_BOUNDS, "touched the floor")
    return None


def check_events(fleet, n_events: int, when: str) -> None:
    """A collision or the centre leaving the flight volume among the guard's events since
    ``n_events`` ends the trial; ``when`` ("" or " before navigation started") is said."""
    for ev in fleet.events[n_events:]:
        failure = event_failure(ev, when)
        if failure is not None:
            raise failure


def event_failure(ev, when: str = "") -> TrialFailure | None:
    """How a collision guard event ends the flight, if it does: a collision (with an
    obstacle, or with a moving one) or the centre leaving the flight volume; ``when`` is
    appended to the detail. The rule :func:`check_events` applies (and ``ft_sitl.gym``, to
    each vehicle's events)."""
    if ev.kind == GuardEventKind.COLLISION:
        speed = f" at {ev.speed_m_s:.1f} m/s" if not when else ""
        return TrialFailure(Outcome.COLLISION, f"hit {ev.what}{speed}{when}")
    if ev.kind == GuardEventKind.MOVER_COLLISION:
        return TrialFailure(Outcome.MOVER_COLLISION, f"hit {ev.what} (moving) at "
                            f"{ev.speed_m_s:.1f} m/s relative{when}")
    if ev.kind == GuardEventKind.LEFT_VOLUME:
        return TrialFailure(Outcome.OUT_OF_BOUNDS,
                            f"left the flight volume past the {ev.what}{when}"
                            if ev.what != "ceiling" else f"climbed above the ceiling{when}")
    return None


class GoalRule:
    """The navigation phase's goal and time limit for one vehicle (``limits``: a
    :class:`~ft_sitl.navigation.base.Limits`). :meth:`update` after every check, with the
    distance to the goal and the time since navigation started: True once the vehicle has
    stayed in the goal sphere (``goal_radius_m``) for ``hold_s`` since it entered it;
    raises :class:`TrialFailure` ``unstable`` when it leaves within the hold, ``timeout``
    when it is not in the sphere ``timeout_s`` after the start. The rules of
    :class:`NavigationJudge` (and of ``ft_sitl.gym``'s episodes)."""

    def __init__(self, limits):
        self.limits = limits
        self.radius_m = limits.goal_radius_m
        self.hold_us = round(limits.hold_s * 1e6)
        self.timeout_us = round(limits.timeout_s * 1e6)
        #: the time (since navigation started) the vehicle entered the sphere, or None
        self.entered_us: int | None = None

    def update(self, dist: float, t_nav_us: int) -> bool:
        if dist <= self.radius_m:
            if self.entered_us is None:
                self.entered_us = t_nav_us
            elif t_nav_us - self.entered_us >= self.hold_us:
                return True
        elif self.entered_us is not None:
            raise TrialFailure(Outcome.UNSTABLE,
                               f"left the goal sphere "
                               f"{(t_nav_us - self.entered_us) * 1e-6:.2f} s after "
                               f"entering it (hold {self.limits.hold_s:g} s)")
        if self.entered_us is None and t_nav_us >= self.timeout_us:
            raise TrialFailure(Outcome.TIMEOUT,
                               f"not in the goal sphere after {self.limits.timeout_s:g} s "
                               f"({dist:.1f} m away)")
        return False


def check_fence(fleet, n_breaches: int, when: str) -> None:
    """A geofence breach among the commander's ``fence_events`` since ``n_breaches`` on
    which the flight controller took the vehicle (geofence.TAKEOVER_ACTIONS: hold, return,
    terminate, land) ends the trial; ``when`` as in :func:`check_events`."""
    for _, reason, action in fleet.commanders[0].fence_events[n_breaches:]:
        if action in TAKEOVER_ACTIONS:
            raise TrialFailure(Outcome.GEOFENCE,
                               f"breached: {reason} (GF_ACTION {action}){when}")


class Metrics:
    """The navigation phase's metrics, sampled after every advance of the simulation."""

    def __init__(self):
        self.path = 0.0
        self.speed_sum = 0.0
        self.time_s = 0.0
        self.n = 0
        self.max_speed = 0.0
        self.min_clear = math.inf
        self.max_tilt = 0.0
        self.planner_s = 0.0
        self.planner_calls = 0
        self.time_to_goal_s = math.nan
        self.track_sq = 0.0  # time-weighted squared position error over commanded axes
        self.track_s = 0.0   # the time with a commanded position

    def sample(self, guard, prev, s, dt_s: float, commanded=None) -> None:
        """One sample after an advance of ``dt_s``: the state ``s``, the position before
        (``prev``) and the flight controller's position setpoint now (``commanded``: a
        3-vector, NaN on the axes it does not command; None: none)."""
        self.path += norm(s.position - prev)
        if commanded is not None:
            axes = np.isfinite(commanded)
            if axes.any():
                err = s.position[axes] - commanded[axes]
                self.track_sq += float(err @ err) * dt_s
                self.track_s += dt_s
        v = norm(s.velocity)
        self.speed_sum += v * dt_s  # time-weighted: samples are not evenly spaced
        self.time_s += dt_s
        self.n += 1
        self.max_speed = max(self.max_speed, v)
        self.max_tilt = max(self.max_tilt, s.tilt)
        # an exact (fcl) clearance only when the guard's lower bound does not rule out a
        # new minimum
        if not guard.clearance_bound(0) > self.min_clear:
            self.min_clear = min(self.min_clear, guard.clearance(0))

    def row(self) -> dict:
        return {
            "time_to_goal_s": self.time_to_goal_s,
            "path_length_m": self.path,
            "mean_speed_m_s": self.speed_sum / self.time_s if self.time_s > 0 else math.nan,
            "max_speed_m_s": self.max_speed if self.n else math.nan,
            "min_clearance_m": self.min_clear if math.isfinite(self.min_clear) else math.nan,
            "max_tilt_deg": math.degrees(self.max_tilt) if self.n else math.nan,
            "tracking_rms_m": (math.sqrt(self.track_sq / self.track_s) if self.track_s > 0
                               else math.nan),
            "planner_time_s": self.planner_s,
            "planner_calls": self.planner_calls,
        }


class ApproachJudge:
    """Phase 1: from arming (:meth:`start`, or the first step that finds the vehicle
    armed) until the vehicle is stable at the start waypoint. :meth:`after_step` returns
    True once it is, raises :class:`TrialFailure` when the approach fails."""

    def __init__(self, fleet, scenario):
        self.fleet, self.sc = fleet, scenario
        self.n_events = len(fleet.events)
        self.n_breaches = len(fleet.commanders[0].fence_events)
        self.start_us: int | None = None
        self.last_us: int | None = None
        self.stable_since_us: int | None = None
        self.timeout_us = round(APPROACH_TIMEOUT_S * 1e6)
        self.stable_for_us = round(STABLE_FOR_S * 1e6)

    def start(self, time_us: int) -> None:
        """The vehicle was armed at ``time_us``: the approach's clock starts."""
        self.start_us = self.last_us = time_us

    def after_step(self) -> bool:
        fleet = self.fleet
        check_events(fleet, self.n_events, " before navigation started")
        check_fence(fleet, self.n_breaches, " before navigation started")
        now = fleet.time_us
        if self.start_us is None:
            if not fleet.commanders[0].armed:
                return False
            self.start(now)
        # stable where the flight controller believes the start is (its estimate), upright
        # as the vehicle truly is
        s = fleet.state(0)
        if not s.on_ground:
            if not np.all(np.isfinite(fleet.sim.x[0])):
                raise TrialFailure(Outcome.LOSS_OF_CONTROL, "non-finite state")
            tilt = fleet.true_state(0).tilt if fleet.sim.estimating(0) else s.tilt
            if tilt > MAX_TILT_RAD:
                raise TrialFailure(Outcome.LOSS_OF_CONTROL,
                                   f"tilt {math.degrees(tilt):.0f} deg")
        err = float(np.linalg.norm(s.position - self.sc.start))
        if err < STABLE_POS_M and float(np.linalg.norm(s.velocity)) < STABLE_SPEED_M_S:
            # stable since the previous check: the interval up to this one counts
            if self.stable_since_us is None:
                self.stable_since_us = self.last_us
            if now - self.stable_since_us >= self.stable_for_us:
                return True
        else:
            self.stable_since_us = None
        self.last_us = now
        if now - self.start_us >= self.timeout_us:
            raise TrialFailure(Outcome.LOSS_OF_CONTROL,
                               f"could not reach the start in {APPROACH_TIMEOUT_S:g} s "
                               f"({err:.2f} m off)")
        return False


class NavigationJudge:
    """Phase 2: the outcome checks after every advance of the simulation: metrics, the
    trajectory record, collision / bounds / control checks, the goal sphere with its hold,
    the timeout. :meth:`after_step` raises :class:`TrialFailure` with the outcome, or
    returns True on success."""

    def __init__(self, fleet, guard, plan, metrics: Metrics, traj: list | None = None):
        self.fleet, self.guard, self.spec, self.sc = fleet, guard, plan.spec, plan.scenario
        self.m = metrics
        self.n_events = len(fleet.events)
        self.n_breaches = len(fleet.commanders[0].fence_events)
        self.traj = traj
        self.t_nav0_us = fleet.time_us
        self.t_sample_us = fleet.time_us
        self._state = fleet.true_state(0)
        self._state_us = fleet.time_us
        self.prev = self._state.position.copy()
        self.goal = GoalRule(plan.spec.limits)
        stall_s = plan.rules.stall_timeout_s
        self.stall_us = None if stall_s is None else round(stall_s * 1e6)
        self.best_dist = math.inf  # the closest to the goal so far, less STALL_PROGRESS_M
        self.best_us = 0

    def state_at(self, time_us: int):
        """The vehicle's state at ``time_us``: the one the last check read when the
        simulation has not moved since (it is used read-only here), else a fresh one."""
        if time_us == self._state_us:
            return self._state
        return self.fleet.true_state(0)

    def after_step(self) -> bool:
        fleet, m = self.fleet, self.m
        s = fleet.true_state(0)
        self._state, self._state_us = s, fleet.time_us
        sp = fleet.commanders[0].last_setpoint.row
        m.sample(self.guard, self.prev, s, (fleet.time_us - self.t_sample_us) * 1e-6,
                 sp[SP_POS:SP_POS + 3])
        self.t_sample_us = fleet.time_us
        self.prev = s.position.copy()
        t_nav_us = fleet.time_us - self.t_nav0_us
        if self.traj is not None:
            self.traj.append((t_nav_us * 1e-6, *s.position))
        check_flight(fleet, self.n_events, s)
        check_fence(fleet, self.n_breaches, "")
        dist = norm(s.position - self.sc.goal)
        goal = self.goal
        outside = goal.entered_us is None
        if goal.update(dist, t_nav_us):
            return True
        if outside and goal.entered_us is not None:
            m.time_to_goal_s = t_nav_us * 1e-6
        if self.stall_us is not None and goal.entered_us is None:
            if dist < self.best_dist:
                self.best_dist = dist - STALL_PROGRESS_M
                self.best_us = t_nav_us
            elif t_nav_us - self.best_us >= self.stall_us:
                raise TrialFailure(Outcome.TIMEOUT,
                                   f"stalled: no {STALL_PROGRESS_M:g} m of progress toward "
                                   f"the goal in {self.stall_us * 1e-6:g} s ({dist:.1f} m "
                                   f"away)")
        return False


class TrialReferee:
    """One trial's protocol state machine: the approach, then navigation, then the
    outcome. The transport calls :meth:`after_step` after every advance of the simulation
    (it returns True once the trial has an outcome), :meth:`end` for an outcome only it
    can see (the navigator failed), and :meth:`finish` for the row."""

    def __init__(self, fleet, guard, plan, *, record: bool = False):
        self.fleet, self.guard, self.plan = fleet, guard, plan
        self.spec, self.sc = plan.spec, plan.scenario
        self.metrics = Metrics()
        self.traj: list = []
        self.record = record
        self.phase = Phase.APPROACH
        self.approach = ApproachJudge(fleet, plan.scenario)
        self.judge: NavigationJudge | None = None
        # navigation-phase baselines: time, saturated steps, physics steps, energy
        self.t_nav0_us: int | None = None
        self._sat0, self._steps0, self._e0 = 0.0, 0, math.nan
        self.outcome: Outcome | None = None
        self.detail = ""
        self.on_start = None  # called when navigation starts

    def after_step(self) -> bool:
        if self.outcome is not None:
            return True
        try:
            if self.phase is Phase.APPROACH:
                if self.approach.after_step():
                    self.start_navigation()
            elif self.judge.after_step():
                self.end(Outcome.SUCCESS)
        except TrialFailure as f:
            self.end(f.reason, f.detail)
        return self.outcome is not None

    def start_navigation(self) -> None:
        fleet = self.fleet
        self.t_nav0_us = fleet.time_us
        self._sat0 = float(fleet.sim.ctrl[0, C_SAT_STEPS])
        self._steps0 = fleet.sim.steps
        self._e0 = fleet.sim.energy_j(0)
        self.judge = NavigationJudge(fleet, self.guard, self.plan, self.metrics,
                                     self.traj if self.record else None)
        self.phase = Phase.NAVIGATION
        if self.guard.movers is not None:  # the movers set off as navigation starts
            self.guard.movers.start(fleet.time_us)
        if self.on_start is not None:
            self.on_start()

    def end(self, reason: Outcome, detail: str = "") -> None:
        """The trial's outcome (the first one given counts)."""
        if self.outcome is None:
            self.outcome, self.detail = Outcome(reason), detail
            self.phase = Phase.DONE

    def nav_time_s(self) -> float:
        """Simulated time since navigation started (0 before)."""
        if self.t_nav0_us is None:
            return 0.0
        return (self.fleet.time_us - self.t_nav0_us) * 1e-6

    def trajectory(self) -> np.ndarray | None:
        """(K, 4): t_s from navigation start, x, y, z (when recording)."""
        return np.array(self.traj) if self.record else None

    def finish(self, *, replans: int, wall0: float) -> dict:
        """The trial's row: identity, outcome, metrics, navigation-phase totals."""
        fleet, m = self.fleet, self.metrics
        reason = self.outcome if self.outcome is not None else Outcome.NAVIGATOR_ERROR
        detail = self.detail if self.outcome is not None else "no outcome"
        if reason == Outcome.COLLISION:
            m.min_clear = 0.0  # it touched (the contact response leaves it 1 mm off)
        navigated = self.t_nav0_us is not None
        nav_steps = fleet.sim.steps - self._steps0 if navigated else 0
        breaches = (fleet.commanders[0].fence_events[self.judge.n_breaches:]
                    if navigated else [])
        row = identity_row(self.spec, self.plan.platform, self.sc)
        row.update(m.row())
        row.update({
            "fence_breaches": len(breaches),
            "fence_breach_s": (breaches[0][0] - self.t_nav0_us) * 1e-6 if breaches
            else math.nan,
        })
        row.update({
            "success": reason == Outcome.SUCCESS, "reason": reason.value, "detail": detail,
            "nav_time_s": self.nav_time_s(),
            "saturation_fraction": (float(fleet.sim.ctrl[0, C_SAT_STEPS] - self._sat0)
                                    / nav_steps if nav_steps else math.nan),
            "energy_j": fleet.sim.energy_j(0) - self._e0 if navigated else math.nan,
            "replans": replans,
            "sim_time_s": fleet.time_us * 1e-6,
            "wall_time_s": time.perf_counter() - wall0,
            "code_version": __version__,
            "software": software(),
            "protocol_version": self.spec.protocol,
            "gains": self.spec.gains,
            "scenario_version": self.spec.scenario_version,
            "finished_utc": utc_now(),
            "spec": self.spec.to_json(),
        })
        return row


@dataclass
class TrialOutcome:
    """What flying a trial gives: its row, the trajectory when recorded ((K, 4): t_s from
    navigation start, x, y, z) and the scenario it flew in."""

    row: dict
    trajectory: np.ndarray | None = None
    scenario: object = None


def trial_vehicle(plan, resources: TrialResources = RESOURCES):
    """The trial's collision guard and its one-vehicle Fleet, on the takeoff point facing
    the goal, with the plan's flight parameters (the speed cap as MPC_XY_VEL_MAX, the
    controller-gain mode as FT_GAIN_MODE, the geofence as GF_*) and the commander's fence,
    wind, actuators, estimator and failures, each seeded from its stream (in-process and
    over the wire alike)."""
    spec, scenario, platform, rules = plan.spec, plan.scenario, plan.platform, plan.rules
    world, grid = resources.world_and_grid(scenario)
    guard = CollisionGuard(world, [plan.guard_radius_m], grid=grid,
                           names=scenario.obstacle_name,
                           bodies=[plan.body] if plan.body is not None else None)
    fleet = Fleet([platform], params=[plan.param_set()], spawn=[scenario.takeoff],
                  spawn_yaw=[scenario.start_yaw], physics_hz=spec.physics_hz, guard=guard)
    fleet.commanders[0].arm_fence_check = rules.arm_fence_check
    if spec.fence is not None:  # the flight controller's, from the start (PX4: uploaded)
        fleet.commanders[0].set_fence(fence_of(spec.fence))
    streams = plan.streams
    if spec.wind is not None:  # from the trial's first step (the gust timed from it)
        fleet.sim.set_wind(0, spec.wind, seed=streams.seed("wind"))
    if spec.actuators is not None:  # likewise (a failure timed from it)
        try:
            fleet.sim.set_actuators(0, spec.actuators, seed=streams.seed("actuators"))
        except SchemaError as exc:
            raise TrialSpecError(f"actuators: {exc}") from None
    if spec.estimator is not None:  # the flight controller's estimate, from the start
        fleet.sim.set_estimator(0, spec.estimator, seed=streams.seed("estimator"))
    for f in spec.failures or ():  # timed from the trial's first step, PX4's way
        try:
            failures.check(failures.UNIT_CODES[f["unit"]], failures.TYPE_CODES[f["type"]],
                           f["instance"], platform.n_rotors)
        except failures.FailureError as exc:
            raise TrialSpecError(f"failures: {exc}") from None
        fleet.params[0].set("SYS_FAILURE_EN", 1)
        fleet.schedule_failure(0, fleet.time_us + round(f["at_s"] * 1e6),
                               failures.UNIT_CODES[f["unit"]], failures.TYPE_CODES[f["type"]],
                               f["instance"])
    if scenario.movers is not None:  # waiting where they start until navigation starts
        guard.set_movers(replace(scenario.movers, clock=np.array([NOT_STARTED])))
    return guard, fleet
