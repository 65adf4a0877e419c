"""The AUTO modes PX4's navigator flies: take-off, hold and reposition, land, return.

:class:`AutoFlight` owns the current automatic target (:class:`NavTarget`) and turns it
into a setpoint each tick. The target is one object every automatic behaviour shares (a
hold, a reposition, a take-off, a landing, the legs of a return, a mission item), so
switching from one to another only replaces it, and a mode that finds no target (entered
before the vehicle had a position) starts from where the vehicle is. Mission items are
:mod:`~ft_sitl.autopilot.mission`'s and follow-target is
:mod:`~ft_sitl.autopilot.follow`'s; this module dispatches to them.

The commander decides *which* mode flies (arming, mode switches, failsafes); this module
only decides *how*. Positions are local ENU metres, times integer microseconds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ft_sitl.autopilot.modes import (
    MAIN_AUTO,
    SUB_FOLLOW_TARGET,
    SUB_LAND,
    SUB_LOITER,
    SUB_MISSION,
    SUB_RTL,
    SUB_TAKEOFF,
)
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.autopilot.status import LandedState, Result, Severity, VehicleState

if TYPE_CHECKING:  # the commander owns this object; only its type is needed here
    from ft_sitl.autopilot.commander import Commander


@dataclass
class NavTarget:
    """The current automatic target: where to, facing where, and which leg of it."""

    target: np.ndarray | None = None
    yaw: float = math.nan
    phase: str = ""
    t_phase_us: int = 0


class AutoFlight:
    """Take-off, hold, reposition, land and return to launch for one commander."""

    def __init__(self, cmdr: Commander):
        self.cmdr = cmdr
        self.nav = NavTarget()
        #: where a return goes: home or the nearest rally point, chosen when it starts
        self.rtl_dest = cmdr.home.copy()

    # --- entering a mode ---------------------------------------------------------------
    def hold_here(self) -> None:
        c = self.cmdr
        self.nav = NavTarget(target=c.position_now(), yaw=c.yaw_now(), phase="hold",
                             t_phase_us=c.time_us)

    def enter(self, sub: int) -> None:
        """Start AUTO's sub mode ``sub`` from where the vehicle is (the mode is set)."""
        c = self.cmdr
        if sub == SUB_LOITER:
            self.hold_here()
        elif sub == SUB_TAKEOFF:
            self.start_takeoff(self.default_takeoff_alt())
        elif sub == SUB_LAND:
            self.nav = NavTarget(target=c.position_now(), yaw=c.yaw_now(), phase="land",
                                 t_phase_us=c.time_us)
            c.text(Severity.INFO, "Landing at current position")
        elif sub == SUB_RTL:
            self.start_rtl()
        elif sub == SUB_FOLLOW_TARGET:
            c.follow.start()
        elif sub == SUB_MISSION:
            c.mission_exec.enter()

    def takeoff(self, altitude_m: float | None = None) -> Result:
        """Climb to the altitude (local z, m; never down) or, if None or not finite,
        MIS_TAKEOFF_ALT above the current altitude, at the current horizontal position."""
        if altitude_m is not None and not math.isfinite(altitude_m):
            altitude_m = None
        alt = self.default_takeoff_alt() if altitude_m is None else altitude_m
        self.cmdr.switch_mode(MAIN_AUTO, SUB_TAKEOFF)
        self.start_takeoff(alt)
        return Result.ACCEPTED

    def nav_takeoff(self, altitude_m: float | None = None) -> Result:
        """MAV_CMD_NAV_TAKEOFF as PX4's navigator takes it (takeoff.cpp, up to v1.14): the
        target (local z, m) is at least MIS_TAKEOFF_ALT above the current altitude. A lower
        one (e.g. a height above home sent as param7, which is AMSL) is raised to that
        minimum with a critical message; None or NaN means the minimum."""
        minimum = self.default_takeoff_alt()
        if altitude_m is not None and math.isfinite(altitude_m) and altitude_m < minimum:
            if altitude_m < minimum - 0.1:  # PX4: no complaint within 10 cm
                self.cmdr.text(Severity.CRITICAL, "Using minimum takeoff altitude: "
                               f"{self.cmdr.params['MIS_TAKEOFF_ALT']:.2f} m")
            altitude_m = minimum
        return self.takeoff(altitude_m)

    def default_takeoff_alt(self) -> float:
        """MIS_TAKEOFF_ALT above the current altitude (PX4: global altitude + MIS_TAKEOFF_ALT;
        on the ground at home, above home)."""
        return float(self.cmdr.position_now()[2]) + self.cmdr.params["MIS_TAKEOFF_ALT"]

    def start_takeoff(self, alt: float) -> None:
        c = self.cmdr
        p = c.position_now()
        p[2] = max(alt, p[2])
        self.nav = NavTarget(target=p, yaw=c.yaw_now(), phase="takeoff", t_phase_us=c.time_us)
        c.text(Severity.INFO, f"Takeoff to {alt - c.home[2]:.1f} m above home")

    def land(self) -> Result:
        self.cmdr.switch_mode(MAIN_AUTO, SUB_LAND)
        self.enter(SUB_LAND)
        return Result.ACCEPTED

    def return_to_launch(self) -> Result:
        self.cmdr.switch_mode(MAIN_AUTO, SUB_RTL)
        self.start_rtl()
        return Result.ACCEPTED

    def start_rtl(self) -> None:
        c = self.cmdr
        p = c.position_now()
        # PX4: the nearest safe point, home or a rally point (the commander's rally_rule)
        self.rtl_dest = c.rally_rule(p, c.home, c.rally)
        climb = max(p[2], c.home[2] + c.params["RTL_RETURN_ALT"])
        self.nav = NavTarget(target=np.array([p[0], p[1], climb]), yaw=c.yaw_now(),
                             phase="rtl_climb", t_phase_us=c.time_us)
        where = "home" if self.rtl_to_home() else "rally point"
        c.text(Severity.INFO, f"RTL: start return to {where} at "
               f"{climb - c.home[2]:.0f} m above home")

    def rtl_to_home(self) -> bool:
        return bool(np.allclose(self.rtl_dest[:2], self.cmdr.home[:2]))

    def reposition(self, position: np.ndarray, yaw: float = math.nan) -> Result:
        """DO_REPOSITION: fly to a local position and hold there (mode AUTO.LOITER)."""
        c = self.cmdr
        if not c.armed or c.landed_state == LandedState.ON_GROUND:
            return c.deny("Reposition denied: not flying", Result.TEMPORARILY_REJECTED)
        target = c.position_now()
        for i in range(3):
            if math.isfinite(position[i]):
                target[i] = position[i]
        c.switch_mode(MAIN_AUTO, SUB_LOITER)
        self.nav = NavTarget(target=target, yaw=yaw if math.isfinite(yaw) else c.yaw_now(),
                             phase="goto", t_phase_us=c.time_us)
        return Result.ACCEPTED

    # --- flying it ---------------------------------------------------------------------
    def cruise(self) -> float:
        """The horizontal cruise speed: DO_CHANGE_SPEED's, else MPC_XY_CRUISE, capped."""
        p = self.cmdr.params
        v = p["MPC_XY_CRUISE"] if not math.isfinite(self.cmdr.cruise_speed) \
            else self.cmdr.cruise_speed
        return min(v, p["MPC_XY_VEL_MAX"])

    def fly_to(self, s: VehicleState, target: np.ndarray, yaw: float) -> Setpoint:
        """Approach a point along the straight line at cruise speed, then hold it."""
        err = target - s.position
        dist = float(np.linalg.norm(err[:2]))
        acc = self.cmdr.params["MPC_ACC_HOR_MAX"]
        speed = min(self.cruise(), math.sqrt(2.0 * 0.5 * acc * dist),
                    self.cmdr.params["MPC_XY_P"] * dist)
        if dist > 0.3:
            vel = np.array([err[0] / dist * speed, err[1] / dist * speed, math.nan])
            return Setpoint.trajectory(position=[math.nan, math.nan, target[2]],
                                       velocity=vel, yaw=yaw)
        return Setpoint.position(target, yaw=yaw)

    def setpoint(self, s: VehicleState) -> Setpoint:
        """The setpoint of the AUTO sub mode in force."""
        c = self.cmdr
        nav = self.nav
        sub = c.sub_mode
        if sub == SUB_TAKEOFF:
            if nav.target is None:
                self.start_takeoff(self.default_takeoff_alt())
                nav = self.nav
            if s.position[2] >= nav.target[2] - 0.1 and not s.on_ground:
                c.text(Severity.INFO, "Takeoff complete: holding")
                c.switch_mode(MAIN_AUTO, SUB_LOITER)
                self.nav = NavTarget(target=nav.target.copy(), yaw=nav.yaw, phase="hold")
                return Setpoint.position(nav.target, yaw=nav.yaw)
            climb = c.params["MPC_TKO_SPEED"]
            return Setpoint.trajectory(position=[nav.target[0], nav.target[1], math.nan],
                                       velocity=[math.nan, math.nan, climb], yaw=nav.yaw)
        if sub == SUB_LAND:
            return self.land_setpoint(s, nav.target)
        if sub == SUB_RTL:
            return self.rtl_setpoint(s)
        if sub == SUB_MISSION:
            return c.mission_exec.setpoint(s)
        if sub == SUB_FOLLOW_TARGET:
            return c.follow.setpoint(s)
        # LOITER (hold, reposition)
        if s.on_ground and not c.took_off:
            return Setpoint.idle()
        if nav.target is None:
            self.hold_here()
            nav = self.nav
        if nav.phase == "goto":
            return self.fly_to(s, nav.target, nav.yaw)
        return Setpoint.position(nav.target, yaw=nav.yaw)

    def land_setpoint(self, s: VehicleState, xy: np.ndarray | None) -> Setpoint:
        if s.on_ground:
            return Setpoint.idle()
        xy = s.position if xy is None else xy
        return Setpoint.trajectory(
            position=[xy[0], xy[1], math.nan],
            velocity=[math.nan, math.nan, -self.cmdr.params["MPC_LAND_SPEED"]],
            yaw=self.nav.yaw if math.isfinite(self.nav.yaw) else s.yaw)

    def rtl_setpoint(self, s: VehicleState) -> Setpoint:
        nav = self.nav
        if nav.target is None:
            self.start_rtl()
            nav = self.nav
        if nav.phase == "rtl_climb":
            if s.position[2] >= nav.target[2] - 0.3:
                nav.phase = "rtl_return"
                nav.target = np.array([self.rtl_dest[0], self.rtl_dest[1], nav.target[2]])
            else:
                return Setpoint.position(nav.target, yaw=nav.yaw)
        if nav.phase == "rtl_return":
            if np.linalg.norm(nav.target[:2] - s.position[:2]) < 0.5:
                nav.phase = "rtl_land"
                self.cmdr.text(Severity.INFO, "RTL: land at " + (
                    "home" if self.rtl_to_home() else "rally point"))
            else:
                return self.fly_to(s, nav.target, nav.yaw)
        return self.land_setpoint(s, self.rtl_dest)
