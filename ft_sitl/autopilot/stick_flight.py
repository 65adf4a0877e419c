"""The stick modes' flight tasks: what POSCTL, ALTCTL, MANUAL and STABILIZED fly.

PX4 turns stick positions into setpoints in its manual flight tasks; this module does
the same for the cascade (see docs/mavlink.md, Manual control): POSCTL commands a
horizontal velocity, ALTCTL a tilt (as an acceleration), both a climb rate from the
throttle around its centre, and both lock position, altitude and heading when the
sticks centre, so a vehicle left alone holds where it is instead of drifting on its
last velocity. MANUAL and STABILIZED command an attitude and pass the throttle through,
scaled so that the stick's centre is a hover.

The locks belong to one mode: a mode change, or sticks that paused for more than
200 ms, starts them afresh.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ft_sitl import G
from ft_sitl.autopilot.modes import MAIN_ALTCTL, MAIN_POSCTL
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.autopilot.status import VehicleState
from ft_sitl.physics.platform import Platform
from ft_sitl.physics.quaternion import qfrom_axis_angle, qmul

if TYPE_CHECKING:  # the commander owns this object; only its type is needed here
    from ft_sitl.autopilot.commander import Commander

#: a pause of the stick flight longer than this (us) starts the locks afresh
LOCK_RESET_US = 200_000


def hover_thrust(platform: Platform) -> float:
    """Normalised collective thrust that holds a hover."""
    return platform.mass_kg * G / platform.thrust_max_n


def deadzone(v: float, dz: float) -> float:
    """A stick value with the dead zone ``dz`` around the centre cut out, rescaled so the
    full deflection is still 1."""
    if dz >= 1.0 or abs(v) <= dz:
        return 0.0
    return (v - math.copysign(dz, v)) / (1.0 - dz)


def _wrap_pi(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class StickFlight:
    """The stick modes' setpoints and their position, altitude and heading locks."""

    def __init__(self, cmdr: Commander):
        self.cmdr = cmdr
        #: position/altitude/yaw locks of the stick modes, and the mode and time they are for
        self.lock_xy: np.ndarray | None = None
        self.lock_z: float | None = None
        self.yaw: float | None = None
        self.key: tuple = ()
        self.tick_us = 0

    def reset(self) -> None:
        """Start the locks afresh at the next tick (arming, a mode given back)."""
        self.key = ()

    def climb_rate(self, dz: float) -> float:
        """Climb rate (m/s, up +) from the throttle around its centre."""
        p = self.cmdr.params
        t = deadzone(2.0 * self.cmdr.manual.sticks[2] - 1.0, dz)
        return t * (p["MPC_Z_VEL_MAX_UP"] if t > 0 else p["MPC_Z_VEL_MAX_DN"])

    def setpoint(self, s: VehicleState) -> Setpoint:
        """The setpoint of the stick mode in force, from the latest sticks."""
        c = self.cmdr
        params = c.params
        sticks = c.manual.sticks
        key = (c.main_mode, c.sub_mode)
        if key != self.key or c.time_us - self.tick_us > LOCK_RESET_US:
            self.key = key
            self.lock_xy, self.lock_z, self.yaw = None, None, None
        dt = min(max(c.time_us - self.tick_us, 0), LOCK_RESET_US) * 1e-6
        self.tick_us = c.time_us
        x, y, _, r = sticks
        dz = params["MPC_HOLD_DZ"]
        xs, ys, rs = deadzone(x, dz), deadzone(y, dz), deadzone(r, dz)
        norm = math.hypot(xs, ys)
        if norm > 1.0:
            xs, ys, norm = xs / norm, ys / norm, 1.0
        yaw_rate = -rs * math.radians(params["MPC_MAN_Y_MAX"])  # ENU: counter-clockwise
        cy, sy = math.cos(s.yaw), math.sin(s.yaw)

        def body_to_enu(fwd: float, right: float) -> tuple[float, float]:
            return fwd * cy + right * sy, fwd * sy - right * cy

        if c.main_mode in (MAIN_POSCTL, MAIN_ALTCTL):
            vz = self.climb_rate(dz)
            if s.on_ground:
                self.lock_xy, self.lock_z, self.yaw = None, None, None
                if 2.0 * sticks[2] - 1.0 <= 0.3:  # PX4 takes off above 65 % throttle
                    return Setpoint.idle()
                return Setpoint.trajectory(position=[s.position[0], s.position[1], math.nan],
                                           velocity=[math.nan, math.nan, max(vz, 0.0)],
                                           yaw=s.yaw)
            pos, vel, acc = [math.nan] * 3, [math.nan] * 3, [math.nan] * 3
            if c.main_mode == MAIN_POSCTL:
                vmax = min(params["MPC_VEL_MANUAL"], params["MPC_XY_VEL_MAX"])
                if xs or ys:
                    self.lock_xy = None
                    vel[0], vel[1] = body_to_enu(xs * vmax, ys * vmax)
                else:
                    hold = params["MPC_HOLD_MAX_XY"]
                    if self.lock_xy is None and (
                            hold <= 0 or math.hypot(*s.velocity[:2]) < hold):
                        self.lock_xy = s.position[:2].copy()
                    if self.lock_xy is None:
                        vel[0], vel[1] = 0.0, 0.0
                    else:
                        pos[0], pos[1] = self.lock_xy
            else:  # ALTCTL: the sticks tilt the vehicle, as an acceleration
                scale = G * math.tan(norm * math.radians(params["MPC_MAN_TILT_MAX"])) \
                    / norm if norm else 0.0
                acc[0], acc[1] = body_to_enu(xs * scale, ys * scale)
            if vz:
                self.lock_z = None
                vel[2] = vz
            else:
                hold_z = params["MPC_HOLD_MAX_Z"]
                if self.lock_z is None and (hold_z <= 0 or abs(s.velocity[2]) < hold_z):
                    self.lock_z = float(s.position[2])
                if self.lock_z is None:
                    vel[2] = 0.0
                else:
                    pos[2] = self.lock_z
            if rs:
                self.yaw = None
                yaw, yr = None, yaw_rate
            else:
                if self.yaw is None:
                    self.yaw = s.yaw
                yaw, yr = self.yaw, None
            sp = Setpoint.trajectory(position=pos, velocity=vel, acceleration=acc, yaw=yaw,
                                     yaw_rate=yr)
            # the tilt of ALTCTL is bound by the tilt limit only, not by MPC_ACC_HOR_MAX
            return sp.offboard() if c.main_mode == MAIN_ALTCTL else sp
        # MANUAL / STABILIZED: attitude from the sticks, throttle direct
        t = 2.0 * sticks[2] - 1.0
        hover = min(max(hover_thrust(c.platform), 0.05), 0.95)
        lo, hi = params["MPC_MANTHR_MIN"], params["MPC_THR_MAX"]
        thrust = lo + (hover - lo) * (t + 1.0) if t < 0 else hover + (hi - hover) * t
        thrust = min(max(thrust, 0.0), 1.0)
        if self.yaw is None or s.on_ground:
            self.yaw = s.yaw
        if s.on_ground and thrust <= hover:
            return Setpoint.idle()
        self.yaw = _wrap_pi(self.yaw + yaw_rate * dt)
        tmax = math.radians(params["MPC_MAN_TILT_MAX"])
        # FLU: forward stick pitches the nose down (+y rotation), right stick rolls right
        rv = np.array([ys * tmax, xs * tmax, 0.0])
        angle = float(np.linalg.norm(rv))
        q_yaw = np.array([math.cos(self.yaw / 2), 0.0, 0.0, math.sin(self.yaw / 2)])
        q_tilt = qfrom_axis_angle(rv, angle) if angle > 0 else np.array([1.0, 0, 0, 0])
        return Setpoint.attitude(qmul(q_yaw, q_tilt), thrust)
