"""Manual control: the sticks (MAVLink MANUAL_CONTROL) and what their loss does.

:class:`ManualControl` keeps the latest stick positions and when they came, applies
PX4's throttle checks at arming in a manual mode, and runs PX4's manual-control-loss
failsafe: sticks that came and then stopped for ``COM_RC_LOSS_T`` take ``NAV_RCL_ACT``,
after a hold of ``COM_FAIL_ACT_T`` for the actions that keep flying, unless the mode is
exempt (``COM_RCL_EXCEPT``) or there were no sticks at arming (a vehicle flown without a
joystick must not fail safe for lacking one). Sticks that come back give the vehicle back
to the mode it was in, except after a return, which flies on until the user changes mode.
What the sticks fly is :mod:`~ft_sitl.autopilot.stick_flight`'s.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from ft_sitl.autopilot.modes import (
    MAIN_ALTCTL,
    MAIN_AUTO,
    MAIN_OFFBOARD,
    MAIN_POSCTL,
    MANUAL_MODES,
    SUB_LAND,
    SUB_LOITER,
    SUB_MISSION,
    SUB_RTL,
    SUB_TAKEOFF,
)
from ft_sitl.autopilot.status import Severity, VehicleState

if TYPE_CHECKING:  # the commander owns this object; only its type is needed here
    from ft_sitl.autopilot.commander import Commander

#: NAV_RCL_ACT's values (PX4's manual control loss actions), by name
NAV_RCL_ACTIONS = {1: "hold", 2: "return", 3: "land", 5: "terminate", 6: "disarm"}


class ManualControl:
    """A commander's stick input and its manual-control-loss failsafe."""

    def __init__(self, cmdr: Commander):
        self.cmdr = cmdr
        #: the latest sticks (x pitch, y roll, z throttle 0..1, r yaw) and when they came
        self.sticks: tuple[float, float, float, float] = (0.0, 0.0, 0.5, 0.0)
        self.t_us: int | None = None
        self.lost = False
        self.lost_at_arming = True
        #: the failsafe in force: (action, mode it set, due time of a delayed action or None)
        self.failsafe: tuple | None = None
        #: the mode the failsafe took the vehicle out of, given back when the sticks return
        self.user_mode: tuple[int, int] = (MAIN_POSCTL, 0)

    def input(self, x: float, y: float, z: float, r: float) -> bool:
        """See :meth:`Commander.manual_control`."""
        c = self.cmdr
        if int(c.params["COM_RC_IN_MODE"]) not in (1, 2, 3):
            return False
        vals = (x, y, z, r)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in vals):
            return False
        self.sticks = (min(1.0, max(-1.0, float(x))), min(1.0, max(-1.0, float(y))),
                       min(1.0, max(0.0, float(z))), min(1.0, max(-1.0, float(r))))
        self.t_us = c.time_us
        return True

    def fresh(self) -> bool:
        """Sticks arrived within COM_RC_LOSS_T."""
        c = self.cmdr
        return (self.t_us is not None and
                c.time_us - self.t_us <= c.params["COM_RC_LOSS_T"] * 1e6)

    def arm_check(self) -> str:
        """PX4's stick checks at arming in a manual mode (Commander.cpp): with a climb-rate
        mode (ALTCTL, POSCTL) the throttle must not be above centre (> 0.6 of 0..1), in the
        others it must be low (< 0.1)."""
        c = self.cmdr
        if c.main_mode not in MANUAL_MODES or not self.fresh():
            return ""
        throttle = 2.0 * self.sticks[2] - 1.0
        if c.main_mode in (MAIN_POSCTL, MAIN_ALTCTL):
            return "Arming denied: throttle above center" if throttle > 0.2 else ""
        return "Arming denied: high throttle" if throttle >= -0.8 else ""

    def on_arm(self) -> None:
        # PX4: without manual control at arming, its loss is no failsafe until it comes
        self.lost_at_arming = not self.fresh()
        self.cmdr.stick_flight.reset()

    def check(self, s: VehicleState) -> None:
        """The failsafe, each tick: notice a loss or a return of the sticks, and take a
        delayed action when it is due (unless the user changed mode meanwhile)."""
        c = self.cmdr
        if self.t_us is None:
            return
        if self.fresh():
            if self.lost:
                self.lost = False
                gap = (c.time_us - self.t_us) * 1e-6
                c.text(Severity.INFO, f"Manual control regained after {gap:.1f} s")
                self._regained()
            self.lost_at_arming = False
            return
        if not self.lost:
            self.lost = True
            c.text(Severity.INFO, "Manual control lost")
            self._lost(s)
        if self.failsafe is not None:
            action, mode, due = self.failsafe
            if (c.main_mode, c.sub_mode) != mode:  # the user changed mode: over
                self.failsafe = None
            elif due is not None and c.time_us >= due:
                self._act(action)

    def _lost(self, s: VehicleState) -> None:
        c = self.cmdr
        if not c.armed or c.terminated or self.lost_at_arming:
            return
        mode = (c.main_mode, c.sub_mode)
        exc = int(c.params["COM_RCL_EXCEPT"])
        if ((mode == (MAIN_AUTO, SUB_MISSION) and exc & 1)
                or (mode in ((MAIN_AUTO, SUB_LOITER), (MAIN_AUTO, SUB_TAKEOFF)) and exc & 2)
                or (mode == (MAIN_OFFBOARD, 0) and exc & 4)
                or mode in ((MAIN_AUTO, SUB_RTL), (MAIN_AUTO, SUB_LAND))):
            return
        action = int(c.params["NAV_RCL_ACT"])
        if action in (5, 6):  # terminate, disarm: at once, wherever it is
            self.user_mode = mode
            self._act(action)
            return
        if action not in (1, 2, 3) or s.on_ground:
            return
        self.user_mode = mode
        delay = c.params["COM_FAIL_ACT_T"]
        c.switch_mode(MAIN_AUTO, SUB_LOITER)
        c.auto.hold_here()
        if delay > 0.1 and action != 1:
            c.text(Severity.CRITICAL,
                   f"Failsafe activated: entering Hold for {round(delay)} seconds")
            self.failsafe = (action, (MAIN_AUTO, SUB_LOITER), c.time_us + int(delay * 1e6))
        else:
            self._act(action)

    def _act(self, action: int) -> None:
        c = self.cmdr
        name = NAV_RCL_ACTIONS.get(action, "none")
        c.text(Severity.CRITICAL, f"Manual control lost: failsafe {name}")
        c.failsafes.act(name)
        self.failsafe = (action, (c.main_mode, c.sub_mode), None) \
            if action in (1, 2, 3) else None

    def _regained(self) -> None:
        """PX4 clears a hold or land failsafe (and the hold before a delayed action) when
        the sticks come back: the vehicle returns to the mode it was in. A return goes on
        until the user changes mode."""
        c = self.cmdr
        if self.failsafe is None:
            return
        action, mode, due = self.failsafe
        self.failsafe = None
        if (c.main_mode, c.sub_mode) != mode or (action == 2 and due is None):
            return
        if not c.armed:
            return
        main, sub = self.user_mode
        c.switch_mode(main, sub)
        c.stick_flight.reset()
        if main == MAIN_AUTO:
            c.auto.enter(sub)
        else:
            c.auto.hold_here()
