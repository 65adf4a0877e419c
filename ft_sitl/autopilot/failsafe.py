"""The commander's failsafes other than manual control loss (that one is manual.py's).

Each tick, in this order, as the commander calls them: the battery (``BAT_LOW_THR``
warns, ``BAT_CRIT_THR`` returns, ``BAT_EMERGEN_THR`` lands), the geofence (a breach
takes ``GF_ACTION`` once, on entering it), and the loss of the position estimate (an
injected GPS failure lands after ``COM_POS_FS_DELAY``). Each acts once per cause and
then leaves the vehicle to the mode it chose, so a user can take over from a failsafe
without it taking the vehicle back at the next tick.

Injected failures (:meth:`Failsafes.record_failure`) are recorded here because they are
what the position-loss and battery failsafes react to; their physics is the fleet's.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ft_sitl.autopilot.geofence import GF_ACTIONS
from ft_sitl.autopilot.modes import MAIN_AUTO, SUB_LAND, SUB_LOITER
from ft_sitl.autopilot.status import LandedState, Severity, VehicleState

if TYPE_CHECKING:  # the commander owns this object; only its type is needed here
    from ft_sitl.autopilot.commander import Commander


class Failsafes:
    """Battery, geofence and position-loss failsafes of one commander."""

    def __init__(self, cmdr: Commander):
        self.cmdr = cmdr
        #: the battery level already acted on: 0 none, 1 low, 2 critical, 3 emergency
        self.bat_warned = 0
        #: the vehicle is outside its geofence (the breach has been acted on)
        self.fence_breached = False
        #: when the GPS failed (None: it has not, or the failsafe has acted)
        self.gps_lost_us: int | None = None

    def battery(self) -> None:
        c = self.cmdr
        rem = c.battery.remaining
        if rem < c.params["BAT_EMERGEN_THR"] and self.bat_warned < 3:
            self.bat_warned = 3
            c.text(Severity.EMERGENCY, "Battery emergency: landing")
            if c.armed and c.landed_state != LandedState.ON_GROUND:
                c.land()
        elif rem < c.params["BAT_CRIT_THR"] and self.bat_warned < 2:
            self.bat_warned = 2
            c.text(Severity.CRITICAL, "Battery critical: returning")
            if c.armed and c.landed_state != LandedState.ON_GROUND:
                c.return_to_launch()
        elif rem < c.params["BAT_LOW_THR"] and self.bat_warned < 1:
            self.bat_warned = 1
            c.text(Severity.WARNING, "Battery low")

    def geofence(self, s: VehicleState) -> None:
        """PX4's geofence: in the air, a breach (entering it, not staying in it) takes
        GF_ACTION once; back inside, the next breach acts again."""
        c = self.cmdr
        if not c.armed or s.on_ground or c.terminated:
            return
        reason = c.fence.breach(s.position, c.home, c.params["GF_MAX_HOR_DIST"],
                                c.params["GF_MAX_VER_DIST"])
        if reason is None:
            self.fence_breached = False
            return
        if self.fence_breached:
            return
        self.fence_breached = True
        action = int(c.params["GF_ACTION"])
        name = GF_ACTIONS.get(action, "none")
        c.fence_events.append((c.time_us, reason, name))
        if action == 0:
            return
        c.text(Severity.CRITICAL, f"Geofence breached: {reason}")
        self.act(name)

    def act(self, action: str) -> None:
        """Take a failsafe action by its name (GF_ACTIONS', NAV_RCL_ACTIONS'): "hold",
        "return", "land", "terminate" or "disarm"; any other ("none", "warning") does
        nothing. One place for what each means, whichever failsafe asks."""
        c = self.cmdr
        if action == "hold":
            c.switch_mode(MAIN_AUTO, SUB_LOITER)
            c.auto.hold_here()
        elif action == "return":
            c.return_to_launch()
        elif action == "land":
            c.land()
        elif action == "terminate":
            c.terminate()
        elif action == "disarm":
            if c.armed:
                c.disarm_now("Disarmed by failsafe")

    def position_loss(self, s: VehicleState) -> None:
        """PX4: no position (GPS lost) for COM_POS_FS_DELAY in the air: land."""
        c = self.cmdr
        lost = self.gps_lost_us
        if lost is None or not c.armed or s.on_ground or c.terminated:
            return
        if c.time_us - lost < c.params["COM_POS_FS_DELAY"] * 1e6:
            return
        self.gps_lost_us = None  # (once)
        if c.main_mode == MAIN_AUTO and c.sub_mode == SUB_LAND:
            return
        c.text(Severity.CRITICAL, "Failsafe: no position estimate, landing")
        c.land()

    def record_failure(self, unit: str, ftype: str, instance: int) -> None:
        """See :meth:`Commander.record_failure`."""
        c = self.cmdr
        if ftype == "ok":
            if c.failures.pop(unit, None) is not None:
                c.text(Severity.INFO, f"Failure injection: {unit} ok")
            if unit == "gps":
                self.gps_lost_us = None
            if unit == "battery":
                c.battery.failed = False
            return
        c.failures[unit] = (ftype, instance)
        which = f" {instance}" if instance else ""
        c.text(Severity.WARNING, f"Failure injection: {unit}{which} {ftype}")
        if unit == "gps":
            self.gps_lost_us = c.time_us
        if unit == "battery":
            c.battery.failed = True
