"""ArduCopter's flight modes (numbers and names of ArduCopter/mode.h) onto the behaviours
of the virtual flight controller, whose commander speaks PX4's (main, sub) modes.

The mode a client chose is remembered (:class:`FlightModes`); the commander flies it with
the PX4 mode of the same behaviour (GUIDED: hold, take-off, goto and offboard setpoints;
LOITER/POSHOLD: position control; ...). When the commander leaves that behaviour on its own
(a failsafe returns or lands) the reported mode follows it, as ArduCopter's failsafes
change its mode.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import Result

# ArduCopter's mode numbers (ArduCopter/mode.h, enum class Mode::Number)
STABILIZE, ACRO, ALT_HOLD, AUTO, GUIDED, LOITER, RTL, CIRCLE, LAND = 0, 1, 2, 3, 4, 5, 6, 7, 9
POSHOLD, BRAKE, SMART_RTL = 16, 17, 21

#: the modes this face flies, by number (ArduCopter's names, as pymavlink's
#: mode_mapping_acm and MAVProxy spell them)
NAMES = {STABILIZE: "STABILIZE", ACRO: "ACRO", ALT_HOLD: "ALT_HOLD", AUTO: "AUTO",
         GUIDED: "GUIDED", LOITER: "LOITER", RTL: "RTL", LAND: "LAND", POSHOLD: "POSHOLD",
         BRAKE: "BRAKE"}
BY_NAME = {v: k for k, v in NAMES.items()}

_A = cm.MAIN_AUTO
#: the commander mode each ArduCopter mode is entered with
ENTRY = {
    STABILIZE: (cm.MAIN_STABILIZED, 0), ACRO: (cm.MAIN_ACRO, 0), ALT_HOLD: (cm.MAIN_ALTCTL, 0),
    AUTO: (_A, cm.SUB_MISSION), GUIDED: (_A, cm.SUB_LOITER), LOITER: (cm.MAIN_POSCTL, 0),
    RTL: (_A, cm.SUB_RTL), LAND: (_A, cm.SUB_LAND), POSHOLD: (cm.MAIN_POSCTL, 0),
    BRAKE: (_A, cm.SUB_LOITER),
}
#: the commander modes that still fly each ArduCopter mode (GUIDED's take-off and
#: setpoints; the hold a landing or a finished mission ends in)
FAMILY = {
    STABILIZE: {(cm.MAIN_STABILIZED, 0), (cm.MAIN_MANUAL, 0)},
    ACRO: {(cm.MAIN_ACRO, 0)},
    ALT_HOLD: {(cm.MAIN_ALTCTL, 0)},
    AUTO: {(_A, s) for s in (cm.SUB_MISSION, cm.SUB_LOITER, cm.SUB_TAKEOFF, cm.SUB_LAND,
                             cm.SUB_RTL)},
    GUIDED: {(_A, cm.SUB_LOITER), (_A, cm.SUB_TAKEOFF), (cm.MAIN_OFFBOARD, 0)},
    LOITER: {(cm.MAIN_POSCTL, 0)},
    RTL: {(_A, cm.SUB_RTL), (_A, cm.SUB_LAND), (_A, cm.SUB_LOITER)},
    LAND: {(_A, cm.SUB_LAND), (_A, cm.SUB_LOITER)},
    POSHOLD: {(cm.MAIN_POSCTL, 0)},
    BRAKE: {(_A, cm.SUB_LOITER)},
}
#: the ArduCopter mode a commander mode reads as when the commander chose it itself
FROM_COMMANDER = {
    (cm.MAIN_STABILIZED, 0): STABILIZE, (cm.MAIN_MANUAL, 0): STABILIZE,
    (cm.MAIN_ACRO, 0): ACRO, (cm.MAIN_ALTCTL, 0): ALT_HOLD, (cm.MAIN_POSCTL, 0): LOITER,
    (_A, cm.SUB_MISSION): AUTO, (_A, cm.SUB_RTL): RTL, (_A, cm.SUB_LAND): LAND,
    (_A, cm.SUB_LOITER): BRAKE, (_A, cm.SUB_TAKEOFF): GUIDED, (cm.MAIN_OFFBOARD, 0): GUIDED,
}
#: the modes arming is allowed in (ArduCopter's Mode::allows_arming: not AUTO, RTL, LAND,
#: BRAKE, ...)
ARMABLE = (STABILIZE, ACRO, ALT_HOLD, GUIDED, LOITER, POSHOLD)
#: the modes that need a position estimate (Mode::requires_position)
NEEDS_POSITION = (AUTO, GUIDED, LOITER, RTL, CIRCLE, POSHOLD, BRAKE, SMART_RTL)
#: the modes whose throttle is the pilot's own (Mode::has_manual_throttle)
MANUAL_THROTTLE = (STABILIZE, ACRO)
#: the modes whose HEARTBEAT carries MAV_MODE_FLAG_GUIDED_ENABLED (ArduCopter's
#: GCS_MAVLINK_Copter::base_mode)
GUIDED_FLAG_MODES = (AUTO, GUIDED, LOITER, RTL, CIRCLE, POSHOLD, BRAKE, SMART_RTL)


class FlightModes:
    """The ArduCopter mode of one vehicle over its commander (``cmd``); ``velocity``
    gives the vehicle's ENU velocity (m/s) now, for BRAKE's stopping point."""

    def __init__(self, cmd: cm.Commander, velocity: Callable[[], np.ndarray] | None = None):
        self.cmd = cmd
        self.velocity = velocity
        if not cmd.armed and (cmd.main_mode, cmd.sub_mode) == (cm.MAIN_POSCTL, 0):
            # ArduCopter boots in STABILIZE (Copter's mode at start, as the parity run
            # against a real ArduCopter saw, docs/mavlink.md); the commander's own boot
            # mode is POSCTL. A client sets its mode (GUIDED) before it flies.
            cmd.switch_mode(*ENTRY[STABILIZE])
        self._chosen = FROM_COMMANDER.get((cmd.main_mode, cmd.sub_mode), STABILIZE)

    @property
    def number(self) -> int:
        """The mode now (HEARTBEAT.custom_mode): the one chosen while the commander flies
        it, else what the commander's own switch (a failsafe) reads as."""
        key = (self.cmd.main_mode, self.cmd.sub_mode)
        if key not in FAMILY[self._chosen]:
            self._chosen = FROM_COMMANDER.get(key, self._chosen)
        return self._chosen

    @property
    def name(self) -> str:
        return NAMES[self.number]

    def set(self, number: int) -> Result:
        """Switch to ArduCopter mode ``number``: ACCEPTED, or FAILED with ArduCopter's
        STATUSTEXT ("No such mode 99", "Flight mode change failed AUTO").

        Disarmed, every mode is accepted (Copter::set_mode ignores the modes' checks while
        the motors are off): AUTO without a mission too, holding where the vehicle is
        (ModeAuto::init's LOITER sub mode; the mission starts when there is one). Armed,
        AUTO needs a mission (ModeAuto::init: more than the home item)."""
        if number not in NAMES:
            self.cmd.text(cm.Severity.WARNING, f"No such mode {number}")
            return Result.FAILED
        if number == self.number:
            return Result.ACCEPTED
        main, sub = ENTRY[number]
        if number == AUTO and not self.cmd.mission:
            if self.cmd.armed:
                self.cmd.text(cm.Severity.WARNING,
                              f"Flight mode change failed {NAMES[number]}")
                return Result.FAILED
            main, sub = _A, cm.SUB_LOITER  # (AUTO with nothing to fly yet: a hold)
        result = self.cmd.set_mode(main, sub)
        if result != Result.ACCEPTED:
            self.cmd.text(cm.Severity.WARNING, f"Flight mode change failed {NAMES[number]}")
            return Result.FAILED
        if (self.cmd.main_mode, self.cmd.sub_mode) == (main, sub) and \
                (main, sub) == (_A, cm.SUB_LOITER):
            self.cmd.auto.hold_here()  # GUIDED/BRAKE entered from another hold: stop here
        if number == BRAKE:
            self._brake()
        self._chosen = number
        return Result.ACCEPTED

    def _brake(self) -> None:
        """BRAKE (mode_brake.cpp): stop as fast as the horizontal acceleration limit
        allows and hold where the vehicle comes to rest (the point v|v| / 2a ahead), at
        the altitude it had."""
        nav = self.cmd.auto.nav
        if self.velocity is None or nav.target is None:
            return
        v = np.asarray(self.velocity(), dtype=float)
        acc = self.cmd.params["MPC_ACC_HOR_MAX"]
        if not np.all(np.isfinite(v)) or acc <= 0:
            return
        nav.target = nav.target.copy()
        nav.target[:2] += v[:2] * float(np.linalg.norm(v[:2])) / (2.0 * acc)

    def chose(self, number: int) -> None:
        """The commander was put in ``number``'s behaviour by a command (take-off, land)."""
        self._chosen = number

    @property
    def in_guided(self) -> bool:
        return self.number == GUIDED
