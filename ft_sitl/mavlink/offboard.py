"""Offboard setpoints on the wire: SET_POSITION_TARGET_LOCAL_NED, SET_POSITION_TARGET_
GLOBAL_INT and SET_ATTITUDE_TARGET, turned into the autopilot's ENU/FLU Setpoint.

A setpoint that cannot be flown is refused with a STATUSTEXT saying why, so a client is
not left guessing; one that can goes to the fleet, which hands it to the cascade at once
while the vehicle is in OFFBOARD.
"""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.setpoints import Setpoint, SetpointError
from ft_sitl.autopilot.wire_setpoint import from_local_ned
from ft_sitl.mavlink.vehicle import Vehicle

#: type_mask bits (POSITION_TARGET_TYPEMASK, ATTITUDE_TARGET_TYPEMASK)
_POSITION, _VELOCITY, _ACCEL = 0b111, 0b111000, 0b111000000
_YAW, _YAW_RATE = 1 << 10, 1 << 11
_THRUST_IGNORED, _ATTITUDE_IGNORED = 1 << 6, 1 << 7
_LOCAL_FRAMES = (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_BODY_NED,
                 mav.MAV_FRAME_LOCAL_OFFSET_NED, mav.MAV_FRAME_BODY_OFFSET_NED)


def _no_inf3(v, name: str) -> list[float]:
    """A local-NED vector where NaN components stay NaN: PX4 controls such an axis at the
    next level (position NaN -> velocity), as in its trajectory_setpoint; the setpoint is
    refused later if an axis ends up controlled at no level. Infinities are refused."""
    if any(math.isinf(x) for x in v):
        raise SetpointError(f"{name} has infinite components")
    return [float(x) for x in v]


def _finite3(v, name: str) -> list[float]:
    if not all(math.isfinite(x) for x in v):
        raise SetpointError(f"{name} has non-finite components")
    return [float(x) for x in v]


class Offboard:
    """One vehicle's offboard setpoint messages."""

    def __init__(self, vehicle: Vehicle):
        self.v = vehicle

    def _reject(self, why: str) -> list:
        self.v.cmd.text(cm.Severity.WARNING, f"Offboard setpoint rejected: {why}"[:50])
        return []

    def on_local_ned(self, m, link, peer, wall_us):
        mask = m.type_mask
        frame = m.coordinate_frame
        if frame not in _LOCAL_FRAMES:
            return self._reject(f"frame {frame} not supported")
        pos = None if mask & _POSITION == _POSITION else [m.x, m.y, m.z]
        vel = None if mask & _VELOCITY == _VELOCITY else [m.vx, m.vy, m.vz]
        acc = None if mask & _ACCEL == _ACCEL else [m.afx, m.afy, m.afz]
        s = self.v.fleet.state(self.v.index)
        try:
            pos, vel, acc = (None if v is None else _no_inf3(v, name)
                             for v, name in ((pos, "position"), (vel, "velocity"),
                                             (acc, "acceleration")))
        except SetpointError as exc:
            return self._reject(str(exc))
        body = frame in (mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED)
        offset = frame in (mav.MAV_FRAME_LOCAL_OFFSET_NED, mav.MAV_FRAME_BODY_OFFSET_NED)
        yaw_ned = frames.yaw_enu_to_ned(s.yaw)

        def to_enu(v, is_position):
            if v is None:
                return None
            v = np.asarray(v, dtype=float)
            # body frames turn vectors with the heading (x forward, y right); a BODY_NED
            # position is still a local position (MAVLink), only offsets are relative
            if body and not (is_position and not offset):
                c, sn = math.cos(yaw_ned), math.sin(yaw_ned)
                v = np.array([c * v[0] - sn * v[1], sn * v[0] + c * v[1], v[2]])
            out = frames.ned_to_enu(v)
            if is_position:
                return out + (s.position if offset else self.v.origin)
            return out

        yaw = None if mask & _YAW else m.yaw
        yaw_rate = None if mask & _YAW_RATE else m.yaw_rate
        if yaw is not None and math.isnan(yaw):
            yaw = None  # PX4: a NaN yaw is not controlled (heading held)
        if yaw is not None and not math.isfinite(yaw):
            return self._reject("yaw is not finite")
        if yaw_rate is not None and not math.isfinite(yaw_rate):
            return self._reject("yaw rate is not finite")
        if pos is None and vel is None and acc is None:
            return self._reject("type_mask ignores position, velocity and accel")
        try:
            if frame == mav.MAV_FRAME_LOCAL_NED and yaw_rate is None:
                # what a MAVSDK client's offboard setpoint is (autopilot.wire_setpoint:
                # protocol 10 flies in-process setpoints through the same arithmetic)
                self.v.fleet.offboard_setpoint(
                    self.v.index, from_local_ned(pos, vel, acc, yaw, self.v.origin))
                return []
            sp = Setpoint.trajectory(
                to_enu(pos, True), to_enu(vel, False), to_enu(acc, False),
                yaw=None if yaw is None else frames.yaw_ned_to_enu(yaw),
                yaw_rate=None if yaw_rate is None else -yaw_rate)
        except SetpointError as exc:
            return self._reject(str(exc))
        self.v.fleet.offboard_setpoint(self.v.index, sp)
        return []

    def on_global_int(self, m, link, peer, wall_us):
        mask = m.type_mask
        pos = None
        if mask & _POSITION != _POSITION:
            lat, lon = m.lat_int * 1e-7, m.lon_int * 1e-7
            if not math.isfinite(m.alt):
                return self._reject("altitude is not finite")
            p = self.v.geo.to_local(lat, lon, self.v.geo.alt_m)
            p[2] = self.v.alt_to_local(m.alt, m.coordinate_frame)
            pos = p
        try:
            vel = None if mask & _VELOCITY == _VELOCITY else frames.ned_to_enu(
                _finite3([m.vx, m.vy, m.vz], "velocity"))
            acc = None if mask & _ACCEL == _ACCEL else frames.ned_to_enu(
                _finite3([m.afx, m.afy, m.afz], "acceleration"))
            yaw = None if mask & _YAW else frames.yaw_ned_to_enu(m.yaw)
            yaw_rate = None if mask & _YAW_RATE else -m.yaw_rate
            if pos is None and vel is None and acc is None:
                return self._reject("type_mask ignores everything")
            sp = Setpoint.trajectory(pos, vel, acc, yaw=yaw, yaw_rate=yaw_rate)
        except SetpointError as exc:
            return self._reject(str(exc))
        self.v.fleet.offboard_setpoint(self.v.index, sp)
        return []

    def on_attitude_target(self, m, link, peer, wall_us):
        mask = m.type_mask
        thrust = m.thrust
        if mask & _THRUST_IGNORED or not math.isfinite(thrust) or not 0.0 <= thrust <= 1.0:
            return self._reject("thrust must be within 0..1")
        try:
            if mask & _ATTITUDE_IGNORED:  # attitude ignored: body rates
                rates = _finite3([m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate], "rates")
                sp = Setpoint.body_rates(frames.frd_to_flu(rates), thrust)
            else:
                q = np.asarray(m.q, dtype=float)
                if not np.isfinite(q).all() or abs(np.linalg.norm(q) - 1.0) > 1e-2:
                    return self._reject("attitude quaternion is not a unit quaternion")
                q_enu = frames.q_ned_frd_to_enu_flu(q / np.linalg.norm(q))
                sp = Setpoint.attitude(q_enu, thrust)
        except SetpointError as exc:
            return self._reject(str(exc))
        self.v.fleet.offboard_setpoint(self.v.index, sp)
        return []
