"""Follow-target ("follow me"): PX4's AUTO.FOLLOW_TARGET mode, transport-free.

Two parts, used by the commander (:meth:`Commander.follow_target_measurement`, mode
AUTO.FOLLOW_TARGET):

* :class:`TargetEstimator`: the target's position and velocity from FOLLOW_TARGET
  measurements. An alpha-beta filter, one correction per fused measurement: the position
  moves a fraction ``1 - FLW_TGT_RS`` (RS held in [0.1, 1] as PX4 does) of the way to
  the measurement, the velocity takes ``beta / dt`` of the position innovation
  (``beta = alpha^2 / (2 - alpha)``) and the same fraction ``alpha`` of a measured
  velocity's innovation. Between measurements the estimate moves on at its velocity.
  As PX4's estimator: positions are fused at most every 0.5 s, an unchanged position only
  after 1 s (clients repeat the last fix), velocities at most every 0.1 s; after 3 s
  without a measurement the target is lost and its estimate stops where it is. PX4 uses
  an alpha-beta-gamma filter (with acceleration) followed by a second-order smoothing of
  the estimate in the flight task; neither is modelled.
* :class:`FollowTask`: where the vehicle should be. It keeps ``FLW_TGT_DST`` horizontally
  from the target at ``FLW_TGT_FA`` (degrees, clockwise from the target's course, 0 in
  front, 180 behind), ``FLW_TGT_HT`` above home (``FLW_TGT_ALT_M`` 0 and 1, the ground is
  flat) or above the target's altitude (2), facing the target; the course follows the
  target's velocity when it moves at 1 m/s or more and is held otherwise (north at
  first). The angle around the target changes at most at ``FLW_TGT_MAX_VEL`` tangential
  speed (2 m/s^2 tangential acceleration); the vehicle's own speed is bounded by the
  cascade (``MPC_XY_VEL_MAX``). More than 3 m below or above its height, it only climbs
  or descends. PX4 starts its angle at 0 (north of the target); here it starts where the
  vehicle is.

* :class:`FollowMode`: the two above as the commander flies them: a fresh task (and a
  fresh estimate, when the old target is lost) each time the mode is entered, a hold
  until the first fix, and the status texts when the target is lost or found again.

Positions are local ENU metres (as the commander's), times integer microseconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ft_sitl.autopilot.modes import MAIN_AUTO, SUB_FOLLOW_TARGET
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.autopilot.status import Severity, VehicleState

if TYPE_CHECKING:  # the commander owns the mode object; only its type is needed here
    from ft_sitl.autopilot.commander import Commander

#: PX4 (TargetEstimator): without a FOLLOW_TARGET for this long the target is lost
TARGET_TIMEOUT_US = 3_000_000
#: PX4: positions fused at most every 0.5 s, an unchanged one only after 1 s
POS_FUSION_MIN_US, POS_FUSION_REPEAT_US = 500_000, 1_000_000
#: PX4: velocities fused at most every 0.1 s
VEL_FUSION_MIN_US = 100_000
#: PX4 (FlightTaskAutoFollowTarget): the course is tracked from this target speed up
COURSE_MIN_SPEED_M_S = 1.0
#: PX4: further than this from the follow height, the vehicle only climbs or descends
ALT_ACCEPTANCE_M = 3.0
#: PX4: closer than this to the target, the heading is held
YAW_MIN_DISTANCE_M = 1.0
#: PX4: tangential acceleration of the angle around the target
ORBIT_MAX_ACC_M_S2 = 2.0


def _wrap(a: float) -> float:
    return math.remainder(a, 2.0 * math.pi)


@dataclass
class TargetEstimator:
    """The target's estimated position and velocity (see the module docstring)."""

    pos: np.ndarray | None = None
    vel: np.ndarray = field(default_factory=lambda: np.zeros(3))
    t_us: int = 0
    t_meas_us: int = 0
    _t_pos_us: int = 0
    _t_vel_us: int = 0
    _last_pos: np.ndarray | None = None

    @property
    def valid(self) -> bool:
        return self.pos is not None

    def lost(self, t_us: int) -> bool:
        return self.pos is None or t_us - self.t_meas_us >= TARGET_TIMEOUT_US

    def estimate(self, t_us: int) -> tuple[np.ndarray, np.ndarray]:
        """(position, velocity) at t_us; a lost target stands where it was when lost."""
        if self.pos is None:
            raise ValueError("no target yet")
        end = min(t_us, self.t_meas_us + TARGET_TIMEOUT_US)
        dt = max(0, end - self.t_us) * 1e-6
        vel = np.where(np.isfinite(self.vel), self.vel, 0.0)
        pos = self.pos + vel * dt
        return pos, (vel.copy() if not self.lost(t_us) else np.zeros(3))

    def measure(self, t_us: int, pos: np.ndarray, vel: np.ndarray | None,
                responsiveness: float) -> None:
        """One measurement: ``pos`` ENU (z NaN: altitude unknown), ``vel`` ENU or None."""
        pos = np.asarray(pos, dtype=float)
        if self.pos is None:
            self.pos = pos.copy()
            self.vel = np.zeros(3) if vel is None else np.asarray(vel, dtype=float).copy()
            self.t_us = self.t_meas_us = self._t_pos_us = self._t_vel_us = t_us
            self._last_pos = pos.copy()
            return
        self.pos, self.vel = self.estimate(t_us)
        self.t_us = self.t_meas_us = t_us
        alpha = 1.0 - min(max(responsiveness, 0.1), 1.0)
        beta = alpha * alpha / (2.0 - alpha)
        since = t_us - self._t_pos_us
        last = self._last_pos
        changed = bool(np.any(np.abs(np.nan_to_num(pos - last, nan=1.0)) > 1e-6))
        if since >= POS_FUSION_MIN_US and (changed or since >= POS_FUSION_REPEAT_US):
            dt = min(max(since * 1e-6, 1e-3), 20.0)
            if not math.isfinite(self.pos[2]):
                self.pos[2] = pos[2]
            innov = np.where(np.isfinite(pos), pos - self.pos, 0.0)
            innov = np.nan_to_num(innov)
            self.pos = self.pos + alpha * innov
            self.vel = self.vel + beta / dt * innov
            self._t_pos_us = t_us
            self._last_pos = pos.copy()
        if vel is not None and t_us - self._t_vel_us >= VEL_FUSION_MIN_US:
            self.vel = self.vel + alpha * (np.asarray(vel, dtype=float) - self.vel)
            self._t_vel_us = t_us


@dataclass
class FollowTask:
    """The follow-target flight task's state: the target's course and the angle around
    it (ENU, counter-clockwise from east) with its rate."""

    course: float = math.pi / 2  # north
    angle: float | None = None
    rate: float = 0.0
    yaw: float = math.nan

    def setpoint(self, dt: float, position: np.ndarray, target: np.ndarray,
                 target_vel: np.ndarray, params, home_z: float) -> tuple[list, list, list, float]:
        """(position, velocity, acceleration, yaw) for the cascade (NaN: not controlled)."""
        dist = params["FLW_TGT_DST"]
        if float(np.hypot(*target_vel[:2])) >= COURSE_MIN_SPEED_M_S:
            self.course = math.atan2(target_vel[1], target_vel[0])
        # FLW_TGT_FA is clockwise (NED); ENU angles turn the other way
        wanted = self.course - math.radians(params["FLW_TGT_FA"])
        rel = position[:2] - target[:2]
        if self.angle is None:
            self.angle = math.atan2(rel[1], rel[0]) if np.hypot(*rel) > 0.1 else wanted
            self.rate = 0.0
        self._step_angle(dt, _wrap(wanted - self.angle), dist, params["FLW_TGT_MAX_VEL"])
        a = self.angle
        radial, tangent = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a),
                                                                          math.cos(a)])
        xy = target[:2] + dist * radial
        mode = int(params["FLW_TGT_ALT_M"])
        if mode == 2 and math.isfinite(target[2]):
            z = target[2] + params["FLW_TGT_HT"]
        else:
            z = home_z + params["FLW_TGT_HT"]
        to_target = target[:2] - position[:2]
        if np.hypot(*to_target) > YAW_MIN_DISTANCE_M or not math.isfinite(self.yaw):
            self.yaw = math.atan2(to_target[1], to_target[0])
        if abs(z - position[2]) >= ALT_ACCEPTANCE_M:
            return [math.nan, math.nan, z], [0.0, 0.0, math.nan], [math.nan] * 3, self.yaw
        vel = self.rate * dist * tangent + target_vel[:2]
        acc = -self.rate * self.rate * dist * radial
        return ([xy[0], xy[1], z], [vel[0], vel[1], math.nan], [acc[0], acc[1], math.nan],
                self.yaw)

    def _step_angle(self, dt: float, remaining: float, dist: float, max_vel: float) -> None:
        """Move the angle toward the wanted one: rate at most max_vel / dist, angular
        acceleration ORBIT_MAX_ACC / dist, braking in time."""
        acc = ORBIT_MAX_ACC_M_S2 / dist
        limit = min(max(max_vel, 0.0) / dist, math.sqrt(2.0 * acc * abs(remaining)))
        goal = math.copysign(limit, remaining)
        step = acc * dt
        self.rate = goal if abs(goal - self.rate) <= step else \
            self.rate + math.copysign(step, goal - self.rate)
        move = self.rate * dt
        if remaining == 0.0 or (move * remaining > 0 and abs(move) >= abs(remaining)):
            self.angle = _wrap(self.angle + remaining)  # there: stop turning
            self.rate = 0.0
        else:
            self.angle = _wrap(self.angle + move)


class FollowMode:
    """AUTO.FOLLOW_TARGET for one commander: its target estimate and flight task."""

    def __init__(self, cmdr: Commander):
        self.cmdr = cmdr
        #: the follow-target estimate (FOLLOW_TARGET messages) and flight task
        self.target = TargetEstimator()
        self.task = FollowTask()
        self.t_us = 0
        self.lost_said = False

    @property
    def active(self) -> bool:
        return self.cmdr.main_mode == MAIN_AUTO and self.cmdr.sub_mode == SUB_FOLLOW_TARGET

    def measurement(self, t_us: int, position: np.ndarray,
                    velocity: np.ndarray | None) -> None:
        """See :meth:`Commander.follow_target_measurement`."""
        self.target.measure(t_us, position, velocity, self.cmdr.params["FLW_TGT_RS"])

    def start(self) -> None:
        """AUTO.FOLLOW_TARGET: a fresh flight task; a target lost (or never heard) starts
        a fresh estimate too, as PX4 starts its estimator with the task."""
        c = self.cmdr
        if self.target.lost(c.time_us):
            self.target = TargetEstimator()
        self.task = FollowTask(yaw=c.yaw_now())
        self.t_us = c.time_us
        self.lost_said = False
        c.auto.hold_here()
        c.text(Severity.INFO, "Follow target: following")

    def setpoint(self, s: VehicleState) -> Setpoint:
        c = self.cmdr
        if s.on_ground:  # PX4 refuses arming in it; on the ground it stays idle here
            return Setpoint.idle()
        dt = max(c.time_us - self.t_us, 0) * 1e-6
        self.t_us = c.time_us
        est = self.target
        if not est.valid:  # no target yet: hold where the mode was entered
            if c.auto.nav.target is None:
                c.auto.hold_here()
            return Setpoint.position(c.auto.nav.target, yaw=c.auto.nav.yaw)
        lost = est.lost(c.time_us)
        if lost and not self.lost_said:
            c.text(Severity.WARNING, "Follow target lost: holding")
        elif not lost and self.lost_said:
            c.text(Severity.INFO, "Follow target found again")
        self.lost_said = lost
        target, target_vel = est.estimate(c.time_us)
        pos, vel, acc, yaw = self.task.setpoint(dt, s.position, target, target_vel,
                                                c.params, c.home[2])
        return Setpoint.trajectory(pos, vel, acc, yaw=yaw)
