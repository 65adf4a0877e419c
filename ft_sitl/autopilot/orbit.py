"""Orbit (MAV_CMD_DO_ORBIT): PX4's POSCTL.ORBIT flight task, transport-free.

The vehicle circles a centre at a fixed radius and tangential speed. The setpoint is a
velocity along the tangent plus a proportional pull back onto the circle, with the
centripetal acceleration fed forward once the vehicle is near the circle (far from it,
the feed-forward would pull it the wrong way). The speed is capped where the command
arrives, so the centripetal acceleration stays within ``MPC_ACC_HOR_MAX`` and the
cascade never has to saturate to hold the circle.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ft_sitl.autopilot.modes import MAIN_POSCTL, SUB_POSCTL_ORBIT
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.autopilot.status import LandedState, Result, Severity, VehicleState

if TYPE_CHECKING:  # the commander owns this object; only its type is needed here
    from ft_sitl.autopilot.commander import Commander

#: DO_ORBIT's limits and default speed (PX4: MC_ORBIT_RAD_MAX's default, its 1 m minimum)
ORBIT_MIN_RADIUS_M, ORBIT_MAX_RADIUS_M, ORBIT_DEFAULT_SPEED_M_S = 1.0, 1000.0, 1.0


class OrbitTask:
    """The orbit a commander flies in POSCTL.ORBIT."""

    def __init__(self, cmdr: Commander):
        self.cmdr = cmdr
        #: an orbit: (centre, signed radius, speed, yaw behaviour, initial yaw)
        self.state: tuple | None = None

    def start(self, center: np.ndarray, radius_m: float, speed_m_s: float,
              yaw_behaviour: int) -> Result:
        """See :meth:`Commander.orbit`."""
        cmdr = self.cmdr
        if not cmdr.armed or cmdr.landed_state == LandedState.ON_GROUND:
            return cmdr.deny("Orbit denied: not flying", Result.TEMPORARILY_REJECTED)
        if not math.isfinite(radius_m) or not ORBIT_MIN_RADIUS_M <= abs(radius_m) \
                <= ORBIT_MAX_RADIUS_M:
            return cmdr.deny(f"Orbit denied: radius must be {ORBIT_MIN_RADIUS_M:g} to "
                             f"{ORBIT_MAX_RADIUS_M:g} m", Result.DENIED)
        p = cmdr.position_now()
        c = np.array([center[i] if math.isfinite(center[i]) else p[i] for i in range(3)])
        speed = abs(speed_m_s) if math.isfinite(speed_m_s) and speed_m_s != 0 \
            else ORBIT_DEFAULT_SPEED_M_S
        speed = circle_speed(cmdr, radius_m, speed)
        self.state = (c, float(radius_m), speed, int(yaw_behaviour), cmdr.yaw_now())
        cmdr.switch_mode(MAIN_POSCTL, SUB_POSCTL_ORBIT)
        cmdr.text(Severity.INFO, f"Orbit: radius {abs(radius_m):.1f} m at {speed:.1f} m/s")
        return Result.ACCEPTED

    def setpoint(self, s: VehicleState) -> Setpoint:
        return circle_setpoint(self.cmdr, s, *self.state)


def circle_setpoint(cmdr: Commander, s: VehicleState, c: np.ndarray, r: float, v: float,
                    yaw_mode: int, yaw0: float) -> Setpoint:
    """The setpoint that holds ``s`` on the circle of centre ``c`` and signed radius ``r``
    (positive: clockwise seen from above) at tangential speed ``v``, its heading by
    MAVLink's ORBIT_YAW_BEHAVIOUR ``yaw_mode`` (``yaw0``: the initial heading). The one
    circle law: DO_ORBIT's and a mission's NAV_LOITER_TURNS."""
    d = s.position[:2] - c[:2]
    dist = float(np.hypot(*d))
    er = d / dist if dist > 1e-3 else np.array([1.0, 0.0])
    # positive radius: clockwise seen from above (east-north plane: -90 deg from e_r)
    et = np.array([er[1], -er[0]]) if r > 0 else np.array([-er[1], er[0]])
    radial = _clamp_abs(cmdr.params["MPC_XY_P"] * (abs(r) - dist), cmdr.auto.cruise())
    vel = v * et + radial * er
    acc = -(v * v / abs(r)) * er if abs(abs(r) - dist) < 0.2 * abs(r) else np.zeros(2)
    if yaw_mode == 0:  # front to the centre
        yaw = math.atan2(-er[1], -er[0])
    elif yaw_mode == 3:  # front along the tangent
        yaw = math.atan2(et[1], et[0])
    elif yaw_mode == 2:  # uncontrolled: wherever it points
        yaw = math.nan
    else:  # the initial heading (1; RC-controlled, 4, without RC)
        yaw = yaw0
    return Setpoint.trajectory(position=[math.nan, math.nan, c[2]],
                               velocity=[vel[0], vel[1], math.nan],
                               acceleration=[acc[0], acc[1], math.nan], yaw=yaw)


def circle_speed(cmdr: Commander, radius_m: float, speed_m_s: float) -> float:
    """``speed_m_s`` within the speed cap and with the centripetal acceleration within
    MPC_ACC_HOR_MAX on a circle of ``radius_m``."""
    return min(speed_m_s, cmdr.params["MPC_XY_VEL_MAX"],
               math.sqrt(cmdr.params["MPC_ACC_HOR_MAX"] * abs(radius_m)))


def _clamp_abs(v: float, limit: float) -> float:
    return max(-limit, min(limit, v))
