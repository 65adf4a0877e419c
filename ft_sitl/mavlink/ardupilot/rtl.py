"""RTL as ArduCopter flies it (ArduCopter/mode_rtl.cpp): climb to RTL_ALT above home (or
stay higher), return at RTL_SPEED (0: WPNAV_SPEED), loiter over home for RTL_LOIT_TIME,
then the final descent: land (RTL_ALT_FINAL 0, disarming on touch-down) or descend to
RTL_ALT_FINAL above home and hold there, still in RTL.

The climb and the return are the flight controller's own return (its RTL_RETURN_ALT is
RTL_ALT, :mod:`.params`); this module takes over where that return would start landing
over home, and runs the loiter and the final leg through the commander's hold, goto and
landing, so whichever way RTL began (a mode change, a failsafe) it ends ArduCopter's way.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ft_sitl.autopilot import commander as cm
from ft_sitl.mavlink.ardupilot import modes

if TYPE_CHECKING:  # the vehicle owns this object; only its type is needed here
    from ft_sitl.mavlink.ardupilot.agent import ArduCopterVehicle

# the legs after the flight controller's return
RETURN, LOITER, FINAL = "return", "loiter", "final"


class RtlPhases:
    """One vehicle's RTL beyond the return: its leg and when it began."""

    def __init__(self, v: ArduCopterVehicle):
        self.v = v
        self.leg: str | None = None
        self.t_leg_us = 0
        #: DO_CHANGE_SPEED's speed before RTL_SPEED replaced it (restored on leaving RTL)
        self._cruise_before = math.nan

    def _leave(self) -> None:
        if self.leg is not None and self.leg != FINAL:
            self.v.cmd.cruise_speed = self._cruise_before
        self.leg = None

    def tick(self) -> None:
        v, c = self.v, self.v.cmd
        if v.modes.number != modes.RTL or not c.armed:
            self._leave()
            return
        key = (c.main_mode, c.sub_mode)
        now = v.fleet.time_us
        if self.leg is None:
            if key != (cm.MAIN_AUTO, cm.SUB_RTL):
                return
            self.leg, self.t_leg_us = RETURN, now
            self._cruise_before = c.cruise_speed
            speed = v.ap_params["RTL_SPEED"]
            if speed > 0:
                c.cruise_speed = speed * 0.01
        if self.leg == RETURN and key == (cm.MAIN_AUTO, cm.SUB_RTL) and \
                c.auto.nav.phase == "rtl_land":
            # over home at the return altitude: loiter there (ArduCopter's LoiterAtHome)
            c.cruise_speed = self._cruise_before
            c.switch_mode(cm.MAIN_AUTO, cm.SUB_LOITER)
            c.auto.hold_here()
            dest = c.auto.rtl_dest
            c.auto.nav.target = np.array([dest[0], dest[1], c.position_now()[2]])
            self.leg, self.t_leg_us = LOITER, now
            return
        if self.leg == LOITER and now - self.t_leg_us >= v.ap_params["RTL_LOIT_TIME"] * 1e3:
            final = v.ap_params["RTL_ALT_FINAL"] * 0.01
            self.leg, self.t_leg_us = FINAL, now
            if final <= 0:
                c.land()  # (the commander's landing: RTL's family, disarms on touch-down)
                return
            target = c.auto.nav.target.copy()
            target[2] = c.home[2] + final
            c.reposition(target)
