"""Spline waypoints: ArduCopter's MAV_CMD_NAV_SPLINE_WAYPOINT flown as a curve.

The rule is ArduCopter's (facts from AP_Math/SplineCurve, AC_WPNav and ModeAuto; the code is
ours). Each spline leg is the cubic Hermite curve ``p(t)``, ``t`` in [0, 1], from an origin
``o`` to a destination ``d`` whose derivatives at the ends are ``v0`` and ``v1``:

* ``v0`` is the previous leg's ``v1`` when that leg was a spline, the previous straight leg's
  ``d - o`` when the vehicle flew on through its end (a waypoint without a delay), else zero
  (after a stop: a take-off, a delay, a mission (re)started).
* ``v1`` is zero when the leg ends in a stop (the item has a delay, or no navigation item
  follows, or the next one has no location of its own); toward a following spline it is
  ``n - o`` (the chord from this leg's origin to the next destination ``n``), toward any
  other next item ``n - d`` (parallel to the next leg).
* When ``|v0| + |v1|`` exceeds four times ``|d - o|`` both are scaled down to that sum, so a
  short leg does not overshoot.

A target moves along the curve; the vehicle follows it. Its speed is capped by the speed
limits in the direction of travel (WPNAV_SPEED horizontally, the climb and descent speeds
vertically), by the curvature (the lateral acceleration at most half the acceleration limit
normal to the path) and by the distance left (to stop at the destination, or to reach it at
the speed the next leg can take, with half the acceleration limit); it changes by at most
half the acceleration limit along the path. When the vehicle falls behind, the target slows
(ArduCopter's track time scalar: the speed the vehicle makes good along the track, less the
position gain times how far behind it is, as a share of the target's speed, filtered with
the time constant acceleration limit / WPNAV_JERK). A leg is reached when the target reaches
its end; a leg that ends in a stop also needs the vehicle within WPNAV_RADIUS of it.

:class:`SplineLegs` is the mission's side (the executor calls it for a spline item); the
rest is geometry without state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.autopilot.status import VehicleState

if TYPE_CHECKING:  # the commander owns the executor that owns this object
    from ft_sitl.autopilot.commander import Commander
    from ft_sitl.autopilot.mission import MissionItem

#: how long the end derivatives may be against the chord (SplineCurve's SPLINE_FACTOR)
SPLINE_FACTOR = 4.0
#: the shares of the acceleration limit used along the path and normal to it
TANGENTIAL_ACCEL_SHARE, LATERAL_ACCEL_SHARE = 0.5, 0.5
#: ArduCopter's WPNAV_JERK default (m/s^3): the track scalar's time constant is accel / jerk
WPNAV_JERK_M_S3 = 1.0
#: the navigation commands (MAV_CMD_NAV_* ids are up to 95, AP_Mission::is_nav_cmd)
NAV_LAST = 95
#: the items whose location is not a destination to fly through: their altitude is the
#: destination's (ArduCopter's loc_from_cmd for an altitude of 0, as RTL and LAND give)
_ALTITUDE_FREE = (20, 21)
#: the items whose end is where the next leg begins (waypoint, take-off, delay)
_CMD_WAYPOINT = 16
_LEG_ENDS = (_CMD_WAYPOINT, 22, 93)
_CMD_DO_JUMP = 177


@dataclass(frozen=True)
class SplineLimits:
    """Speed (m/s) and acceleration (m/s^2) limits of the target on the curve."""

    speed_xy: float
    speed_up: float
    speed_down: float
    accel_xy: float
    accel_z: float


def kinematic_limit(direction: np.ndarray, max_xy: float, max_up: float,
                    max_down: float) -> float:
    """The largest magnitude along ``direction`` whose horizontal part stays within
    ``max_xy`` and vertical part within ``max_up`` (rising) or ``max_down`` (falling);
    0 for a zero direction."""
    n = float(np.linalg.norm(direction))
    if n == 0.0:
        return 0.0
    u = direction / n
    h, z = math.hypot(u[0], u[1]), float(u[2])
    caps = [max_xy / h] if h > 0.0 else []
    if z != 0.0:
        caps.append((max_up if z > 0 else max_down) / abs(z))
    return min(caps)


@dataclass(frozen=True)
class HermiteLeg:
    """One leg: ``p(t) = c0 + c1 t + c2 t^2 + c3 t^3`` from origin (t = 0) to destination
    (t = 1); ``v0``/``v1`` the end derivatives asked (before any scaling)."""

    origin: np.ndarray
    destination: np.ndarray
    v0: np.ndarray
    v1: np.ndarray
    coeffs: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]

    @classmethod
    def between(cls, origin, destination, v0, v1) -> HermiteLeg:
        o, d = np.asarray(origin, float), np.asarray(destination, float)
        a, b = np.asarray(v0, float), np.asarray(v1, float)
        chord = SPLINE_FACTOR * float(np.linalg.norm(d - o))
        total = float(np.linalg.norm(a) + np.linalg.norm(b))
        k = chord / total if total > chord else 1.0
        sa, sb = a * k, b * k
        coeffs = (o, sa, 3.0 * (d - o) - 2.0 * sa - sb, 2.0 * (o - d) + sa + sb)
        return cls(o, d, a, b, coeffs)

    @property
    def zero_length(self) -> bool:
        return bool(np.all(self.origin == self.destination))

    def at(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Position and its first three derivatives with respect to ``t``."""
        c0, c1, c2, c3 = self.coeffs
        return (c0 + t * (c1 + t * (c2 + t * c3)), c1 + t * (2.0 * c2 + 3.0 * t * c3),
                2.0 * c2 + 6.0 * t * c3, 6.0 * c3)


@dataclass(frozen=True)
class CurvePoint:
    """What the target may do at one point of a leg: direction of travel, the largest speed
    and the acceleration along the path allowed there, and the rate of ``t`` per metre."""

    position: np.ndarray
    direction: np.ndarray
    normal_accel: np.ndarray  # d2p/dt2 normal to the path, per (dp/dt)^2: the curvature
    speed_max: float
    accel_max: float
    t_per_m: float


def curve_point(leg: HermiteLeg, t: float, limits: SplineLimits,
                end_speed_max: float) -> CurvePoint:
    """The limits at ``t`` (see the module's rule); ``end_speed_max`` the speed the target
    may keep at the destination."""
    p, dp, ddp, dddp = leg.at(t)
    ds = float(np.linalg.norm(dp))
    if ds > 1e-9:
        u = dp / ds
    else:  # a leg starting or ending at rest: the curve leaves along its acceleration
        lead = ddp if float(np.linalg.norm(ddp)) > 1e-9 else dddp
        u = lead / max(float(np.linalg.norm(lead)), 1e-12)
    a_n = ddp - float(ddp @ u) * u
    an = float(np.linalg.norm(a_n))
    v_max = kinematic_limit(u, limits.speed_xy, limits.speed_up, limits.speed_down)
    an_max = LATERAL_ACCEL_SHARE * kinematic_limit(a_n, limits.accel_xy, limits.accel_z,
                                                   limits.accel_z)
    speed = v_max
    if an_max > 0.0 and an > 0.0 and ds > 0.0 and an / an_max > (ds / v_max) ** 2:
        speed = ds * math.sqrt(an_max / an)  # lateral acceleration v^2 * an / ds^2 = an_max
    acc = TANGENTIAL_ACCEL_SHARE * kinematic_limit(u, limits.accel_xy, limits.accel_z,
                                                   limits.accel_z)
    left = float(np.linalg.norm(leg.destination - p))
    speed = min(speed, math.sqrt(2.0 * acc * left + end_speed_max ** 2))
    curv = a_n / (ds * ds) if ds > 1e-9 else np.zeros(3)
    return CurvePoint(p, u, curv, speed, acc, 1.0 / ds if ds > 1e-9 else 0.0)


def end_speed_max(leg: HermiteLeg, limits: SplineLimits) -> float:
    """The speed the leg allows at its destination (0 when it ends at rest)."""
    if not np.any(leg.v1) or leg.zero_length:
        return 0.0
    return curve_point(leg, 1.0, limits, math.inf).speed_max


@dataclass
class _Flight:
    """A leg in flight: the target's place ``t``, speed, and the track scalar."""

    leg: HermiteLeg
    stops: bool
    end_speed: float
    t: float = 0.0
    speed: float = 0.0
    last_us: int | None = None


class SplineLegs:
    """Spline items of one commander's mission: builds each leg when it starts flying and
    moves its target; :meth:`step` gives the setpoint and whether the leg is reached."""

    def __init__(self, cmdr: Commander):
        self.cmdr = cmdr
        self.flight: _Flight | None = None
        #: the leg before: (item, its origin (None: unknown), its destination); None after
        #: a (re)start, when a spline leg starts from where the vehicle is, at rest
        self.prev: tuple[MissionItem, np.ndarray, np.ndarray] | None = None
        #: the leg flown now, started by :meth:`leg_started`
        self._now: tuple[MissionItem, int, np.ndarray] | None = None
        #: the previous spline leg's end derivative (its v1), for the next one's v0
        self._spline_v1 = np.zeros(3)
        self._track_scalar = 1.0
        #: the target's speed when the last spline leg ended (m/s)
        self._carry_speed = 0.0
        #: the yaw the curve gave last (ENU rad)
        self.yaw = math.nan

    def reset(self) -> None:
        """The mission was (re)started or changed: the next leg starts at rest."""
        self.flight = None
        self.prev = None
        self._now = None
        self._spline_v1 = np.zeros(3)
        self._track_scalar = 1.0
        self._carry_speed = 0.0

    def leg_started(self, item: MissionItem, index: int, target: np.ndarray) -> None:
        """The executor starts item ``index`` toward ``target``: the leg before it ends."""
        if item.command > NAV_LAST:  # (DO items run between legs)
            return
        if self._now is not None:
            prev_item, _, prev_target = self._now
            origin = self.prev[2] if self.prev is not None else None
            self.prev = (prev_item, origin, prev_target)
        self._now = (item, index, np.asarray(target, float).copy())
        self.flight = None

    def limits(self) -> SplineLimits:
        c = self.cmdr
        p = c.params
        return SplineLimits(c.auto.cruise(), p["MPC_Z_VEL_MAX_UP"], p["MPC_Z_VEL_MAX_DN"],
                            p["MPC_ACC_HOR_MAX"],
                            min(p["MPC_ACC_UP_MAX"], p["MPC_ACC_DOWN_MAX"]))

    # --- the legs ----------------------------------------------------------------------
    def _next_nav(self, index: int) -> tuple[int, MissionItem] | None:
        """The navigation item flown after ``index`` and its index (DO items skipped, a
        DO_JUMP with repeats left followed), None at the end."""
        mission, jumps = self.cmdr.mission, self.cmdr.mission_exec.jumps
        k = index + 1
        for _ in range(len(mission) + 1):  # (a loop of jumps alone ends)
            if not 0 <= k < len(mission):
                return None
            it = mission[k]
            if it.command <= NAV_LAST:
                return k, it
            if it.command == _CMD_DO_JUMP and 0 <= it.jump_to < len(mission) and \
                    (it.repeat < 0 or jumps.get(k, 0) < it.repeat):
                k = it.jump_to
            else:
                k += 1
        return None

    @staticmethod
    def _toward(item: MissionItem, dest: np.ndarray) -> np.ndarray:
        """The point an item flies to, its missing coordinates the destination's."""
        p = np.array([item.position[i] if math.isfinite(item.position[i]) else dest[i]
                      for i in range(3)])
        if item.command in _ALTITUDE_FREE:
            p[2] = dest[2]
        return p

    def _end_derivative(self, item: MissionItem, index: int, origin: np.ndarray,
                        dest: np.ndarray) -> tuple[np.ndarray, tuple | None]:
        """v1 of a leg from ``origin`` to ``dest`` for item ``index``, and the next
        navigation item (index, item) when the vehicle flies on into it."""
        nxt = self._next_nav(index) if item.hold_s <= 0.0 else None
        if nxt is None:
            return np.zeros(3), None
        n = self._toward(nxt[1], dest)
        return (n - origin if nxt[1].spline else n - dest), nxt

    def _build(self, s: VehicleState) -> _Flight:
        item, index, dest = self._now
        lim = self.limits()
        v0 = np.zeros(3)
        flew_on = False
        if self.prev is None or self.prev[0].command not in _LEG_ENDS:
            origin = s.position.copy()  # (a start, a restart, a circle: from here, at rest)
        else:
            prev_item, prev_origin, origin = self.prev
            flew_on = prev_item.command == _CMD_WAYPOINT and prev_item.hold_s <= 0.0
            if flew_on and prev_item.spline:
                v0 = self._spline_v1
            elif flew_on and prev_origin is not None:
                v0 = origin - prev_origin
        v1, nxt = self._end_derivative(item, index, origin, dest)
        leg = HermiteLeg.between(origin, dest, v0, v1)
        end = end_speed_max(leg, lim)
        if nxt is not None and nxt[1].spline and end > 0.0:
            # the next spline leg's entry speed caps this one's exit speed
            n = self._toward(nxt[1], dest)
            after = HermiteLeg.between(dest, n, v1, self._end_derivative(nxt[1], nxt[0],
                                                                         dest, n)[0])
            if not after.zero_length:
                end = min(end, curve_point(after, 0.0, lim, end_speed_max(after, lim)
                                           ).speed_max)
        self._spline_v1 = v1
        f = _Flight(leg, stops=not np.any(v1), end_speed=end)
        if flew_on and self.prev[0].spline:
            f.speed = self._carry_speed  # (the target's speed goes on from leg to leg)
        else:  # the speed the vehicle brings along the curve's first direction
            f.speed = max(0.0, float(s.velocity @ curve_point(leg, 0.0, lim, end).direction))
        return f

    def step(self, s: VehicleState, yaw: float) -> tuple[Setpoint, bool]:
        """The setpoint toward the spline item now flown and whether it is reached
        (``yaw``: the heading to fly, NaN: along the curve)."""
        c = self.cmdr
        if self.flight is None:
            self.flight = self._build(s)
        f = self.flight
        lim = self.limits()
        dt = 0.0 if f.last_us is None else (c.time_us - f.last_us) * 1e-6
        f.last_us = c.time_us
        dest = f.leg.destination
        if f.leg.zero_length:
            return Setpoint.position(dest, yaw=self._yaw(yaw)), True
        if f.t < 1.0 and dt > 0.0:
            here = curve_point(f.leg, f.t, lim, f.end_speed)
            # ArduCopter's track scalar: slow the target when the vehicle lags behind it
            if f.speed > 1e-6:
                err = float((here.position - s.position) @ here.direction)
                made = float(s.velocity @ here.direction)
                k = min(1.0, max(0.0, 0.05 + (made - c.params["MPC_XY_P"] * err) / f.speed))
                tc = lim.accel_xy / WPNAV_JERK_M_S3
                self._track_scalar += (k - self._track_scalar) * min(1.0, dt / tc)
            dts = self._track_scalar * dt
            f.speed = min(max(here.speed_max, f.speed - here.accel_max * dts),
                          f.speed + here.accel_max * dts)
            if here.t_per_m > 0.0:
                f.t = min(1.0, f.t + f.speed * dts * here.t_per_m)
            else:  # at rest on the curve: leave along the acceleration
                _, _, ddp, _ = f.leg.at(f.t)
                f.t = min(1.0, f.t + math.sqrt(2.0 * f.speed * dts /
                                               max(float(np.linalg.norm(ddp)), 1e-9)))
        pt = curve_point(f.leg, f.t, lim, f.end_speed)
        self._carry_speed = f.speed
        if f.t >= 1.0:
            reached = not f.stops or \
                float(np.linalg.norm(s.position - dest)) <= c.params["NAV_ACC_RAD"]
            if f.stops:
                return Setpoint.position(dest, yaw=self._yaw(yaw)), reached
            return Setpoint.trajectory(position=dest, velocity=pt.direction * f.speed,
                                       yaw=self._yaw(yaw, pt.direction)), reached
        vel = pt.direction * f.speed
        acc = pt.normal_accel * f.speed ** 2  # the curve's centripetal acceleration
        return Setpoint.trajectory(position=pt.position, velocity=vel, acceleration=acc,
                                   yaw=self._yaw(yaw, pt.direction)), False

    def _yaw(self, yaw: float, direction: np.ndarray | None = None) -> float:
        """``yaw`` when given, else the curve's heading (the last one when it has none)."""
        if math.isfinite(yaw):
            return yaw
        if direction is not None and math.hypot(direction[0], direction[1]) > 0.1:
            self.yaw = math.atan2(direction[1], direction[0])
        if not math.isfinite(self.yaw):
            self.yaw = self.cmdr.yaw_now()
        return self.yaw
