"""A trajectory setpoint as it reaches the flight controller over MAVLink.

A MAVSDK client sends a navigator's setpoint (world ENU, radians, float64) with
``Offboard.set_position_velocity_acceleration_ned``: local NED relative to the vehicle's
origin, yaw in degrees (:func:`ft_sitl.wire.convert.to_offboard`), every field a float32 in
MAVSDK's structs and in SET_POSITION_TARGET_LOCAL_NED, the yaw turned into radians by MAVSDK
in float32 (``pi / 180 * deg``, its ``to_rad_from_deg``); the flight controller turns the
message back into ENU (:meth:`ft_sitl.mavlink.offboard.Offboard.on_local_ned`). Protocol
10 passes every in-process setpoint through :func:`through_local_ned`, the same
arithmetic, so a navigator flown in-process and one flown over MAVLink in lockstep command
the same numbers (docs/missions.md, "Protocol versions").
"""

from __future__ import annotations

import math

import numpy as np

from ft_sitl import frames
from ft_sitl.autopilot import cascade as cs
from ft_sitl.autopilot.setpoints import Setpoint

_F32 = np.float32
#: MAVSDK's float32 degrees-to-radians factor (static_cast<float>(PI) / 180.0f)
_DEG_TO_RAD_F32 = _F32(_F32(math.pi) / _F32(180.0))


def local_ned_fields(sp: Setpoint, origin_enu) -> tuple:
    """(position, velocity, acceleration, yaw_deg) of a trajectory setpoint in the local NED
    frame with origin ``origin_enu`` (float64; NaN where the setpoint has none), as a
    MAVSDK client hands them to ``Offboard``."""
    row = sp.row
    p = row[cs.SP_POS:cs.SP_POS + 3] - np.asarray(origin_enu, dtype=float)
    yaw = row[cs.SP_YAW]
    return (frames.enu_to_ned(p), frames.enu_to_ned(row[cs.SP_VEL:cs.SP_VEL + 3]),
            frames.enu_to_ned(row[cs.SP_ACC:cs.SP_ACC + 3]),
            math.nan if math.isnan(yaw) else math.degrees(
                frames.wrap_pi(frames.yaw_enu_to_ned(float(yaw)))))


def float32_on_the_wire(position, velocity, acceleration, yaw_deg) -> tuple:
    """What SET_POSITION_TARGET_LOCAL_NED carries for those MAVSDK arguments: x..z, vx..vz,
    afx..afz and yaw (radians), each a float32 read back as a Python float."""
    def f32(v):
        return [float(_F32(x)) for x in v]
    yaw = float(_DEG_TO_RAD_F32 * _F32(yaw_deg))
    return f32(position), f32(velocity), f32(acceleration), yaw


def from_local_ned(position, velocity, acceleration, yaw, origin_enu) -> Setpoint:
    """The ENU trajectory setpoint of a SET_POSITION_TARGET_LOCAL_NED's fields (position
    relative to ``origin_enu``; None for a part the type mask ignores; a NaN yaw is not
    controlled), as the flight controller reads a LOCAL_NED message."""
    pos = None if position is None else frames.ned_to_enu(
        np.asarray(position, dtype=float)) + np.asarray(origin_enu, dtype=float)
    vel = None if velocity is None else frames.ned_to_enu(np.asarray(velocity, dtype=float))
    acc = None if acceleration is None else frames.ned_to_enu(
        np.asarray(acceleration, dtype=float))
    if yaw is not None and math.isnan(yaw):
        yaw = None
    return Setpoint.trajectory(pos, vel, acc,
                               yaw=None if yaw is None else frames.yaw_ned_to_enu(yaw))


def through_local_ned(sp: Setpoint, origin_enu, home_enu) -> Setpoint:
    """``sp`` as the flight controller receives it from a MAVSDK client over MAVLink
    (module docstring): ``origin_enu`` the client's local origin, ``home_enu`` the flight
    controller's. Setpoints other than trajectories are returned as they are (attitude
    and rate setpoints pass MAVSDK's own Euler conversions, not modelled here)."""
    if int(sp.row[cs.SP_KIND]) != cs.KIND_TRAJECTORY:
        return sp
    p, v, a, yaw = float32_on_the_wire(*local_ned_fields(sp, origin_enu))
    return from_local_ned(p, v, a, yaw, home_enu)
