"""A navigator's setpoint (world ENU, radians) as a MAVSDK offboard command (local NED
relative to the vehicle's origin, degrees), and MAVSDK telemetry back into ENU.

PX4's local frame has its origin where the vehicle's estimator started: in ft-sitl, the
vehicle's spawn (takeoff) point. A component that is NaN stays NaN: PX4 then controls that
axis at the next level (a NaN position with a velocity is velocity control), which is how a
navigator mixes levels (e.g. NavRL: horizontal velocity, altitude as a position).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ft_sitl import frames
from ft_sitl.autopilot import cascade as cs
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.autopilot.wire_setpoint import local_ned_fields
from ft_sitl.physics.quaternion import qto_euler


@dataclass(frozen=True)
class OffboardCommand:
    """What to send: ``kind`` names the MAVSDK Offboard call, the fields its arguments
    (local NED metres, m/s, m/s^2, degrees)."""

    kind: str  # "pva" (set_position_velocity_acceleration_ned), "attitude", "rates"
    position: tuple = (math.nan,) * 3
    velocity: tuple = (math.nan,) * 3
    acceleration: tuple = (math.nan,) * 3
    yaw_deg: float = math.nan
    euler_deg: tuple = (math.nan,) * 3
    rates_deg_s: tuple = (math.nan,) * 3
    thrust: float = math.nan


def _t(v) -> tuple:
    return tuple(float(x) for x in v)


def to_offboard(sp: Setpoint, origin_enu) -> OffboardCommand:
    """The MAVSDK offboard command for ``sp``; ``origin_enu`` is the local frame's origin."""
    row = sp.row
    kind = int(row[cs.SP_KIND])
    if kind == cs.KIND_TRAJECTORY:
        p, v, a, yaw_deg = local_ned_fields(sp, origin_enu)
        return OffboardCommand("pva", position=_t(p), velocity=_t(v), acceleration=_t(a),
                               yaw_deg=yaw_deg)
    if kind == cs.KIND_ATTITUDE:

        q = frames.q_enu_flu_to_ned_frd(row[cs.SP_Q:cs.SP_Q + 4])
        return OffboardCommand("attitude", euler_deg=_t(np.degrees(qto_euler(q))),
                               thrust=float(row[cs.SP_THRUST]))
    if kind == cs.KIND_RATES:
        rates = frames.flu_to_frd(row[cs.SP_RATES:cs.SP_RATES + 3])
        return OffboardCommand("rates", rates_deg_s=_t(np.degrees(rates)),
                               thrust=float(row[cs.SP_THRUST]))
    raise ValueError(f"setpoint kind {kind} cannot be sent as an offboard setpoint")


async def send(offboard, cmd: OffboardCommand) -> None:
    """Send ``cmd`` with a MAVSDK 4.x ``OffboardAsync``."""
    # MAVSDK: loaded only by the navigator client that flies over it
    from mavsdk.plugins.offboard import (
        AccelerationNed,
        Attitude,
        AttitudeRate,
        PositionNedYaw,
        VelocityNedYaw,
    )

    if cmd.kind == "pva":
        await offboard.set_position_velocity_acceleration_ned(
            PositionNedYaw(*cmd.position, cmd.yaw_deg),
            VelocityNedYaw(*cmd.velocity, cmd.yaw_deg), AccelerationNed(*cmd.acceleration))
    elif cmd.kind == "attitude":
        await offboard.set_attitude(Attitude(*cmd.euler_deg, cmd.thrust))
    else:
        await offboard.set_attitude_rate(AttitudeRate(*cmd.rates_deg_s, cmd.thrust))


def ned_to_world(p_ned, origin_enu) -> np.ndarray:
    """A local NED position as world ENU."""
    return frames.ned_to_enu(np.asarray(p_ned, dtype=float)) + np.asarray(origin_enu, float)
