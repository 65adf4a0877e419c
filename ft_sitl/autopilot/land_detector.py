"""Landed-state detection and the auto-disarm that times itself on it.

The landed state is what MAVLink reports (EXTENDED_SYS_STATE) and what several rules
read: a take-off and a landing are in-air states of their own, so a ground station sees
the phase and not only "in air". Auto-disarm follows PX4: a vehicle on the ground for
``COM_DISARM_LAND`` after a flight, or for ``COM_DISARM_PRFLT`` after an arming that never
took off, disarms itself, except while a take-off, a mission or offboard control is
still about to lift it.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ft_sitl.autopilot.modes import (
    MAIN_AUTO,
    MAIN_OFFBOARD,
    SUB_LAND,
    SUB_MISSION,
    SUB_RTL,
    SUB_TAKEOFF,
)
from ft_sitl.autopilot.status import LandedState, Severity, VehicleState

if TYPE_CHECKING:  # the commander owns this object; only its type is needed here
    from ft_sitl.autopilot.commander import Commander


class LandDetector:
    """A commander's landed state, and when it last landed."""

    def __init__(self, cmdr: Commander):
        self.cmdr = cmdr
        #: when the vehicle came to rest on the ground (None: in the air)
        self.landed_since_us: int | None = 0
        #: the vehicle left the ground since it was armed
        self.took_off = False

    def on_arm(self) -> None:
        c = self.cmdr
        self.took_off = False
        self.landed_since_us = c.time_us if c.landed_state == LandedState.ON_GROUND \
            else None

    def update(self, s: VehicleState) -> None:
        c = self.cmdr
        if s.on_ground:
            if c.landed_state != LandedState.ON_GROUND:
                c.landed_state = LandedState.ON_GROUND
                self.landed_since_us = c.time_us
                if self.took_off:
                    c.text(Severity.INFO, "Landing detected")
        elif c.armed:
            if c.landed_state == LandedState.ON_GROUND:
                self.took_off = True
                self.landed_since_us = None
            if c.main_mode == MAIN_AUTO and c.sub_mode == SUB_TAKEOFF:
                c.landed_state = LandedState.TAKEOFF
            elif c.main_mode == MAIN_AUTO and (
                c.sub_mode == SUB_LAND or (c.sub_mode == SUB_RTL
                                           and c.auto.nav.phase == "rtl_land")):
                c.landed_state = LandedState.LANDING
            else:
                c.landed_state = LandedState.IN_AIR
        else:
            c.landed_state = LandedState.IN_AIR

    def auto_disarm(self) -> bool:
        """Disarm a vehicle that has rested on the ground long enough (True: it did)."""
        c = self.cmdr
        if c.landed_state != LandedState.ON_GROUND or self.landed_since_us is None:
            return False
        waited = (c.time_us - self.landed_since_us) * 1e-6
        if self.took_off:
            limit = c.params["COM_DISARM_LAND"]
            why = "Disarmed by landing"
        else:
            limit = c.params["COM_DISARM_PRFLT"]
            why = "Disarmed: no takeoff"
            if c.main_mode == MAIN_AUTO and c.sub_mode in (SUB_TAKEOFF, SUB_MISSION):
                return False
            if c.main_mode == MAIN_OFFBOARD:
                return False
        if limit >= 0 and waited > limit:
            c.disarm_now(why)
            return True
        return False
