"""One trial of the FLYINGTRUST protocol, in-process and in lockstep.

``run_trial(spec)`` flies one :class:`~ft_sitl.missions.spec.TrialSpec` with the same
flight-controller code the MAVLink layer serves (a :class:`~ft_sitl.sim.fleet.Fleet` with
its commander, cascade and plant, and the scenario's collision guard) and returns the
trial's row of the results table (:mod:`ft_sitl.missions.results`). The protocol itself
(phases, judges, metrics, the row) is :mod:`ft_sitl.missions.protocol`, shared with the
MAVLink transport (:mod:`ft_sitl.transport.mavlink_trial`); this module is the in-process driver:

1. *Approach.* Arm, take off (PX4 AUTO.TAKEOFF) to the start altitude, reposition to the
   start waypoint, checked every :data:`~ft_sitl.missions.protocol.TICK_S` of simulated
   time until the protocol finds the vehicle stable there.
2. *Navigation.* Offboard mode; every ``1 / navigator.rate_hz`` s of simulated time the
   navigator gets an :class:`~ft_sitl.navigation.base.Observation` (and a depth frame when
   its camera is due) and returns a setpoint, checked with
   :func:`~ft_sitl.autopilot.setpoints.offboard_problem`. The protocol judges after every
   advance (at least every commander tick); a navigator that raises, returns no valid
   setpoint or overruns the wall-clock budget (:mod:`ft_sitl.missions.watchdog`) fails
   the trial as a navigator error, one that gives up (``GiveUp``) as a timeout.

Everything but ``wall_time_s`` and ``planner_time_s`` is a pure function of the spec:
the same spec gives the same row (``ft-sitl trial rerun`` checks this).
"""

from __future__ import annotations

import math
import time

import numpy as np

from ft_sitl.autopilot.commander import MAIN_OFFBOARD
from ft_sitl.autopilot.setpoints import Setpoint, offboard_problem
from ft_sitl.autopilot.wire_setpoint import through_local_ned
from ft_sitl.missions.perception import Perception
from ft_sitl.missions.plan import TrialPlan, plan_trial
from ft_sitl.missions.protocol import (
    STABLE_POS_M,
    TICK_S,
    Phase,
    TrialFailure,
    TrialOutcome,
    TrialReferee,
    arming_failure,
    trial_vehicle,
)
from ft_sitl.missions.resources import RESOURCES
from ft_sitl.missions.results import Outcome
from ft_sitl.missions.spec import TrialSpec, TrialSpecError, platform_for
from ft_sitl.missions.watchdog import TRIAL_WALL_BUDGET_S, WallBudgetExceeded, WallWatchdog
from ft_sitl.navigation.base import GiveUp, Observation, ObstacleStates
from ft_sitl.navigation.registry import create

__all__ = ["TrialSpec", "TrialSpecError", "TrialOutcome", "run_trial", "platform_for",
           "load_scenario_for", "fly", "InProcessPilot"]


def load_scenario_for(spec: TrialSpec):
    """The spec's scenario (cached per process)."""
    return RESOURCES.scenario(spec)


def run_trial(spec: TrialSpec, *, record: bool = False, navigator=None,
              wall_budget_s: float | None = TRIAL_WALL_BUDGET_S,
              monitor=None) -> TrialOutcome:
    """Fly one trial; the row of the results table (and the trajectory when ``record``).
    ``navigator`` overrides the registry lookup (an instance; tests). A trial still running
    ``wall_budget_s`` of wall-clock time after it started (None: no limit) ends as a
    navigator error. ``monitor(fleet, t_nav_us)``, when given, is called after every
    advance of the navigation phase (it reads the simulation; it must not change it):
    what tools record beyond the row, e.g. scripts/tracking_replay.py."""
    if wall_budget_s is not None and not (isinstance(wall_budget_s, (int, float))
                                          and not isinstance(wall_budget_s, bool)
                                          and wall_budget_s > 0):
        raise ValueError(f"wall_budget_s must be a positive number of seconds or None, got "
                         f"{wall_budget_s!r}")
    wall0 = time.perf_counter()
    plan = plan_trial(spec, navigator=navigator)
    nav = navigator if navigator is not None else create(spec.algorithm,
                                                         dict(plan.navigator_params))
    guard, fleet = trial_vehicle(plan)
    ref = TrialReferee(fleet, guard, plan, record=record)
    fly(plan, fleet, ref, InProcessPilot(nav, plan, fleet),
        WallWatchdog(wall0, wall_budget_s), monitor=monitor)
    row = ref.finish(replans=replan_count(getattr(nav, "replans", 0)), wall0=wall0)
    return TrialOutcome(row, ref.trajectory(), plan.scenario)


class InProcessPilot:
    """Who answers the trial driver's navigator calls (:func:`fly`): the navigator itself,
    called in this process. A transport's pilot answers them from another process
    (:mod:`ft_sitl.transport.lockstep`); the driver around them is the same.

    ``navigator`` is what the driver reads the navigator's camera, rate and wishes from;
    ``reset`` / ``observe`` are its calls; ``tick`` hands it a navigation tick's
    observation and puts its setpoint (and, the first time, offboard mode) into the
    flight controller; ``advanced`` is called after every advance of the simulation."""

    def __init__(self, nav, plan: TrialPlan, fleet):
        self.navigator = nav
        wire = plan.rules.setpoints_as_on_the_wire
        self._origin = plan.task().origin if wire else None
        self._home = np.asarray(fleet.commanders[0].home, dtype=float) if wire else None

    def reset(self, task, m) -> None:
        _call(self.navigator.reset, task, "reset", m)

    def observe(self, obs, m) -> None:
        _call(self.navigator.observe, obs, "observe", m)

    def tick(self, fleet, obs, m) -> None:
        sp = _ask(self.navigator, obs, m)
        if self._origin is not None:  # protocol 10: as over MAVLink
            sp = through_local_ned(sp, self._origin, self._home)
        cmd = fleet.commanders[0]
        fleet.offboard_setpoint(0, sp)
        if cmd.main_mode != MAIN_OFFBOARD:  # PX4: a setpoint first, then the mode
            res = cmd.set_mode(MAIN_OFFBOARD)
            if res.name != "ACCEPTED" or cmd.main_mode != MAIN_OFFBOARD:
                raise TrialFailure(Outcome.NAVIGATOR_ERROR,
                                   "the flight controller refused offboard mode")
            fleet.offboard_setpoint(0, sp)

    def advanced(self, fleet) -> None:
        pass


def fly(plan: TrialPlan, fleet, ref: TrialReferee, pilot, watchdog: WallWatchdog, *,
        monitor=None) -> None:
    """The protocol's driver: approach and navigation of ``fleet`` under the referee
    ``ref`` until its outcome, the navigator's calls answered by ``pilot``
    (:class:`InProcessPilot` or a transport's); failures end the trial in ``ref``."""
    nav = pilot.navigator
    try:
        eyes = _Eyes(nav, plan)
        with watchdog:
            if plan.rules.observe_approach:  # the navigator sees from arming on (protocol 3)
                pilot.reset(plan.task(), ref.metrics)
            _approach(fleet, plan.scenario, ref,
                      pilot if plan.rules.observe_approach else None, eyes)
            if ref.phase is Phase.NAVIGATION:
                _navigate(pilot, fleet, plan, ref, watchdog, eyes,
                          reset=not plan.rules.observe_approach, monitor=monitor)
    except TrialFailure as f:
        ref.end(f.reason, f.detail)
    except WallBudgetExceeded:
        ref.end(Outcome.NAVIGATOR_ERROR, watchdog.detail(ref.nav_time_s()))


class _Eyes:
    """The navigator's depth camera in this trial (None without one), the random stream of
    its noise, and when its frames are rendered and handed over.

    Up to protocol 5 every frame goes to the navigator as it is captured. From protocol 6
    the navigator's map takes the latest frame on its own timer
    (:attr:`~ft_sitl.missions.spec.ProtocolRules.map_fusion_hz`), as the originals' grid
    maps do: a frame is rendered at its capture time only when the map's next update
    comes before the next frame, and handed over at that update; the others would never
    be fused, so they are not rendered.
    """

    def __init__(self, nav, plan: TrialPlan):
        if getattr(nav, "camera", None) != plan.camera:
            raise TrialFailure(Outcome.NAVIGATOR_ERROR,
                               f"the navigator's camera {getattr(nav, 'camera', None)!r} is "
                               f"not the one its camera_for() gives for its settings "
                               f"({plan.camera!r}): the trial plan could not know it")
        cfg = plan.frame_camera
        self.camera = RESOURCES.camera(cfg, plan.scenario) if cfg is not None else None
        self.period_us = round(1e6 / cfg.rate_hz) if cfg is not None else 0
        fuse_hz = plan.rules.map_fusion_hz
        self.fuse_period_us = round(1e6 / fuse_hz) if cfg is not None and fuse_hz else 0
        self.rng = plan.streams.rng("camera")
        self.start(1, floor=False)

    def start(self, quantum_us: int, *, floor: bool) -> None:
        """A new clock (arming, navigation start): the camera and the map's timer fire at
        0; the driver serves an event at a multiple of ``quantum_us``: the last one at or
        before its time (``floor``: the approach, on the physics steps) or the first one
        at or after it (the navigator's steps)."""
        self.quantum_us = int(quantum_us)
        self.floor = floor
        self.next_cam_us = 0
        self.next_fuse_us = 0
        self.held = None

    def _served(self, t_us: int) -> int:
        q = self.quantum_us
        return (t_us // q if self.floor else -(-t_us // q)) * q

    def next_event_us(self) -> int:
        """Clock time at which the next capture or map update is served."""
        if self.fuse_period_us:
            return self._served(min(self.next_cam_us, self.next_fuse_us))
        return self._served(self.next_cam_us)

    def due(self, fleet, t_us: int):
        """At clock time ``t_us`` (a served instant): capture when the camera is due; the
        frame the navigator gets now (None: none)."""
        if self.camera is None or self._served(self.next_cam_us) > t_us and (
                not self.fuse_period_us or self._served(self.next_fuse_us) > t_us):
            return None
        if not self.fuse_period_us:  # protocols 1-5: every frame, at its capture
            self.next_cam_us += self.period_us
            return self.frame(fleet, t_us)
        if self._served(self.next_cam_us) <= t_us:
            # to the first camera tick served after now (a navigator stepping slower than
            # the camera sees only the frames of its steps)
            while self._served(self.next_cam_us) <= t_us:
                self.next_cam_us += self.period_us
            if self._served(self.next_fuse_us) < self._served(self.next_cam_us):
                self.held = self.frame(fleet, t_us)
            else:  # a newer frame replaces it before the map's next update
                self.held = None
        if self._served(self.next_fuse_us) > t_us:
            return None
        while self._served(self.next_fuse_us) <= t_us:
            self.next_fuse_us += self.fuse_period_us
        frame, self.held = self.held, None
        return frame

    def frame(self, fleet, t_us: int):
        guard = fleet.sim.guard
        return self.camera.capture(t_us, fleet.sim.position(0), fleet.sim.attitude(0),
                                   rng=self.rng, movers=guard.movers if guard else None,
                                   movers_time_us=fleet.time_us)


def _observation(fleet, t_us: int, s, depth, nav) -> Observation:
    """What the navigator ``nav`` is told at ``t_us`` (its clock) with state ``s``: the
    flight controller's estimate (the truth without an estimator), as PX4 publishes it;
    the moving obstacles' ground truth too when the navigator asks for it."""
    return Observation(time_s=t_us * 1e-6, position=s.position, velocity=s.velocity,
                       yaw=s.yaw, attitude=fleet.attitude(0),
                       angular_velocity=fleet.body_rates(0),
                       depth=depth, movers=_mover_truth(fleet) if getattr(
                           nav, "needs_mover_truth", False) else None)


def _mover_truth(fleet) -> ObstacleStates:
    """The moving obstacles now (simulation time): their boxes and velocities (empty in a
    static world)."""
    guard = fleet.sim.guard
    movers = guard.movers if guard is not None else None
    if movers is None or movers.count == 0:
        return ObstacleStates.empty()
    return ObstacleStates(*movers.boxes(fleet.time_us))


def _approach(fleet, sc, ref: TrialReferee, observer, eyes: _Eyes) -> None:
    """Arm, take off to the start altitude, reposition to the start waypoint; until the
    protocol finds the vehicle stable there (or ends the trial). ``observer`` (a navigator,
    protocol 3 on) gets the camera frames on the way (its clock starts at arming; every
    frame, or from protocol 6 the frames its map's timer takes: :class:`_Eyes`)."""
    cmd = fleet.commanders[0]
    res = cmd.arm()
    if res.name != "ACCEPTED":
        raise arming_failure(cmd, res.name)
    cmd.takeoff(float(sc.start[2]))
    t_arm_us = fleet.time_us
    ref.approach.start(t_arm_us)
    tick_us = round(TICK_S * 1e6)
    repositioned = False
    seeing = observer is not None and eyes.camera is not None
    eyes.start(fleet.sim.dt_us, floor=True)
    while ref.phase is Phase.APPROACH:
        tick_end_us = fleet.time_us + tick_us
        while seeing and t_arm_us + eyes.next_event_us() < tick_end_us:
            fleet.run_us(t_arm_us + eyes.next_event_us() - fleet.time_us)
            observer.advanced(fleet)
            t_us = fleet.time_us - t_arm_us
            frame = eyes.due(fleet, t_us)
            if frame is not None:
                obs = _observation(fleet, t_us, fleet.state(0), frame, observer.navigator)
                observer.observe(obs, ref.metrics)
        fleet.run_us(tick_end_us - fleet.time_us)
        if observer is not None:
            observer.advanced(fleet)
        if not repositioned and abs(fleet.state(0).position[2] - sc.start[2]) < STABLE_POS_M:
            cmd.reposition(sc.start.copy(), sc.start_yaw)
            repositioned = True
        ref.after_step()


def _navigate(pilot, fleet, plan: TrialPlan, ref: TrialReferee, watchdog: WallWatchdog,
              eyes: _Eyes, *, reset: bool, monitor=None) -> None:
    """Offboard flight with the navigator in the loop until the protocol's outcome
    (``reset``: the navigator is reset now, as before protocol 3)."""
    nav = pilot.navigator
    m = ref.metrics
    t_nav0_us = ref.t_nav0_us
    spec = plan.spec
    if reset:
        pilot.reset(plan.task(), m)
    period_us = _period_us(nav, fleet.sim.dt_us)
    next_nav_us = t_nav0_us
    eyes.start(period_us, floor=False)
    seen = Perception(spec.perception)
    seen.start(plan.streams.rng("perception"))
    judge = ref.judge
    tick_us = round(TICK_S * 1e6)
    while True:
        now = fleet.time_us
        t_nav_us = now - t_nav0_us
        if now >= next_nav_us:
            # (the judge's state is the truth: with an estimator, the estimate instead)
            s = fleet.state(0) if fleet.sim.estimating(0) else judge.state_at(now)
            depth = eyes.due(fleet, t_nav_us)
            obs = _observation(fleet, t_nav_us, s, depth, nav)
            if spec.perception is not None:
                (p, v, yaw, att, rates), depth = seen.pass_through(
                    t_nav_us, (obs.position, obs.velocity, obs.yaw, obs.attitude,
                               obs.angular_velocity), depth)
                obs = Observation(time_s=obs.time_s, position=p, velocity=v, yaw=yaw,
                                  attitude=att, angular_velocity=rates, depth=depth,
                                  movers=obs.movers)
            pilot.tick(fleet, obs, m)
            next_nav_us += period_us
        # to the next navigator step or commander tick, at least one physics step
        fleet.run_us(max(fleet.sim.dt_us, min(tick_us, next_nav_us - fleet.time_us)))
        pilot.advanced(fleet)
        if monitor is not None:
            monitor(fleet, fleet.time_us - t_nav0_us)
        if ref.after_step():
            return
        watchdog.check()


def replan_count(v) -> int:
    """A navigator's replan counter as an integer (-1 if it is not a count)."""
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
        return -1
    return int(v)


def _period_us(nav, dt_us: int) -> int:
    """The navigator's step period, a whole number of physics steps (at least one)."""
    rate = getattr(nav, "rate_hz", None)
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not (
            math.isfinite(rate) and rate > 0):
        raise TrialFailure(Outcome.NAVIGATOR_ERROR,
                           f"rate_hz must be a positive number, got {rate!r}")
    return max(1, round(1e6 / float(rate) / dt_us)) * dt_us


def _call(method, arg, what: str, m):
    """A navigator call, timed into the planner time; GiveUp fails the trial as a timeout,
    any other exception (even sys.exit()) as a navigator error."""
    t = time.perf_counter()
    try:
        return method(arg)
    except GiveUp as exc:
        raise TrialFailure(Outcome.TIMEOUT, f"navigator gave up: {exc}") from None
    except (KeyboardInterrupt, WallBudgetExceeded):
        raise
    except BaseException as exc:  # noqa: BLE001 - even sys.exit() only fails the trial
        raise TrialFailure(Outcome.NAVIGATOR_ERROR,
                           f"{what} raised {type(exc).__name__}: {exc}") from None
    finally:
        m.planner_s += time.perf_counter() - t


def _ask(nav, obs, m) -> Setpoint:
    m.planner_calls += 1
    sp = _call(nav.step, obs, "step", m)
    why = offboard_problem(sp)
    if why:
        raise TrialFailure(Outcome.NAVIGATOR_ERROR, f"step returned {why}")
    return sp
