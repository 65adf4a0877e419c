"""ArduCopter's GCS and battery failsafes (ArduCopter/events.cpp, failsafe_gcs_check in
ArduCopter.cpp, libraries/AP_BattMonitor/AP_BattMonitor.cpp), with their texts and mode
changes. The actions are ArduCopter's FailsafeAction numbers, taken through the face's modes
(:mod:`.modes`) and, for disarming, the flight controller's one failsafe-action home
(:meth:`Failsafes.act <ft_sitl.autopilot.failsafe.Failsafes.act>`).

**GCS failsafe** (FS_GCS_ENABLE, FS_GCS_TIMEOUT, FS_OPTIONS): once the ground station
SYSID_MYGCS has been heard (HEARTBEAT, RC_CHANNELS_OVERRIDE or MANUAL_CONTROL from it),
silence for FS_GCS_TIMEOUT seconds triggers it once: "GCS Failsafe", the RC overrides
released, and the FS_GCS_ENABLE action (1 RTL, 2 RTL but a mission in AUTO continues, 3
SmartRTL or RTL, 4 SmartRTL or land, 5 land, 6 DO_LAND_START or RTL, 7 brake or land); on
the ground it disarms instead ("GCS Failsafe: Disarming"), disarmed it only reports. Its
return clears it ("GCS Failsafe Cleared"); the mode is not given back.

**Battery failsafe** (BATT_LOW_VOLT with BATT_LOW_TIMER, BATT_LOW_MAH, BATT_CRT_VOLT,
BATT_CRT_MAH, BATT_FS_LOW_ACT, BATT_FS_CRT_ACT, BATT_CAPACITY): checked while armed; a
voltage below its threshold for BATT_LOW_TIMER seconds, or remaining capacity below its,
raises the level (low, then critical) once each: "Battery 1 is low 10.40V used 1234 mAh",
"Battery Failsafe" and the level's action. The level stays until the vehicle restarts
(arming is refused meanwhile, :mod:`.prearm`).

The battery is the flight controller's model (:class:`~ft_sitl.autopilot.battery.Battery`):
its resting voltage, and BATT_CAPACITY times its remaining charge as the capacity left.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ft_sitl.autopilot import commander as cm
from ft_sitl.mavlink.ardupilot import modes

if TYPE_CHECKING:  # the vehicle owns these objects; only its type is needed here
    from ft_sitl.mavlink.ardupilot.agent import ArduCopterVehicle

# ArduCopter's FailsafeAction (ArduCopter/Copter.h), the values of BATT_FS_*_ACT
NONE, LAND, RTL, SMARTRTL, SMARTRTL_LAND, TERMINATE, AUTO_DO_LAND_START, BRAKE_LAND = range(8)
#: FS_GCS_ENABLE -> FailsafeAction (2: RTL, AUTO continues: see GcsFailsafe)
GCS_ACTIONS = {1: RTL, 2: RTL, 3: SMARTRTL, 4: SMARTRTL_LAND, 5: LAND,
               6: AUTO_DO_LAND_START, 7: BRAKE_LAND}
# FS_OPTIONS bits (ArduCopter's FailsafeOption)
OPT_GCS_CONTINUE_IF_AUTO, OPT_CONTINUE_IF_LANDING, OPT_GCS_CONTINUE_IF_PILOT = 2, 8, 16
#: the modes a pilot flies (not is_autopilot())
PILOT_MODES = (modes.STABILIZE, modes.ACRO, modes.ALT_HOLD, modes.LOITER, modes.POSHOLD)
#: battery failsafe levels
BATT_OK, BATT_LOW, BATT_CRITICAL = 0, 1, 2


def announce(v: ArduCopterVehicle, kind: str, action: str | None = None) -> None:
    """Copter::announce_failsafe's text."""
    v.cmd.text(cm.Severity.WARNING, f"{kind} Failsafe: {action}" if action else
               f"{kind} Failsafe")


def landed(v: ArduCopterVehicle) -> bool:
    return v.cmd.landed_state == cm.LandedState.ON_GROUND


def is_landing(v: ArduCopterVehicle) -> bool:
    """LAND, or RTL in its final descent."""
    c = v.cmd
    return v.modes.number in (modes.LAND, modes.RTL) and \
        (c.main_mode, c.sub_mode) == (cm.MAIN_AUTO, cm.SUB_LAND)


def do_action(v: ArduCopterVehicle, action: int) -> None:
    """Copter::do_failsafe_action. SmartRTL (not flown by this face) falls back as
    ArduCopter's does when it has no path: to RTL, or land; DO_LAND_START (no such item
    is flown) to RTL; the landings start at once (ArduCopter pauses 4 s first)."""
    if action == NONE:
        return
    if action == TERMINATE:
        v.cmd.failsafes.act("disarm")
        return
    if action in (RTL, SMARTRTL, AUTO_DO_LAND_START):
        if v.modes.set(modes.RTL) == cm.Result.ACCEPTED:
            return
    if action == BRAKE_LAND:
        if v.modes.set(modes.BRAKE) == cm.Result.ACCEPTED:
            return
    v.modes.set(modes.LAND)


class GcsFailsafe:
    """One vehicle's GCS failsafe."""

    def __init__(self, v: ArduCopterVehicle):
        self.v = v
        #: sim time (us) SYSID_MYGCS was last heard (None: never)
        self.last_seen_us: int | None = None
        self.active = False

    def heard(self, sysid: int) -> None:
        if sysid == self.v.ap_params["SYSID_MYGCS"]:
            self.last_seen_us = self.v.fleet.time_us

    def tick(self) -> None:
        ap = self.v.ap_params
        if int(ap["FS_GCS_ENABLE"]) == 0 or self.last_seen_us is None:
            return
        silent_us = self.v.fleet.time_us - self.last_seen_us
        timeout_us = ap["FS_GCS_TIMEOUT"] * 1e6
        if silent_us < timeout_us:
            if self.active:
                self.active = False
                self.v.cmd.text(cm.Severity.WARNING, "GCS Failsafe Cleared")
            return
        if not self.active:
            self.active = True
            self._on_event()

    def _on_event(self) -> None:
        """Copter::failsafe_gcs_on_event."""
        v = self.v
        v.rc.clear()
        enable, options = int(v.ap_params["FS_GCS_ENABLE"]), int(v.ap_params["FS_OPTIONS"])
        action = GCS_ACTIONS.get(enable, RTL)
        mode = v.modes.number
        if enable == 2:  # (ArduPilot converts it to 1 with FS_OPTIONS' continue-in-AUTO)
            options |= OPT_GCS_CONTINUE_IF_AUTO
        if not v.cmd.armed:
            action = NONE
            announce(v, "GCS")
        elif landed(v):
            v.cmd.failsafes.act("disarm")
            action = NONE
            announce(v, "GCS", "Disarming")
        elif is_landing(v) and options & OPT_CONTINUE_IF_LANDING:
            announce(v, "GCS", "Continuing Landing")
            action = NONE
        elif mode == modes.AUTO and options & OPT_GCS_CONTINUE_IF_AUTO:
            announce(v, "GCS", "Continuing Auto Mode")
            action = NONE
        elif options & OPT_GCS_CONTINUE_IF_PILOT and mode in PILOT_MODES:
            announce(v, "GCS", "Continuing Pilot Control")
            action = NONE
        else:
            announce(v, "GCS")
        do_action(v, action)


class BatteryFailsafe:
    """One vehicle's battery monitor failsafes (one battery: "Battery 1")."""

    def __init__(self, v: ArduCopterVehicle):
        self.v = v
        self.level = BATT_OK
        #: sim time (us) the voltage went below each level's threshold (None: it is not)
        self._below_since: dict[int, int | None] = {BATT_LOW: None, BATT_CRITICAL: None}

    def voltage(self) -> float:
        return self.v.cmd.battery.voltage()

    def consumed_mah(self) -> float:
        """Charge used (mAh): BATT_CAPACITY times the model's charge used."""
        return self.v.ap_params["BATT_CAPACITY"] * (1.0 - self.v.cmd.battery.remaining)

    def remaining_mah(self) -> float:
        return self.v.ap_params["BATT_CAPACITY"] - self.consumed_mah()

    def conditions(self, level: int) -> tuple[bool, bool]:
        """(voltage below its threshold, capacity below its threshold) for the level;
        a threshold of 0 is off."""
        ap = self.v.ap_params
        volt, mah = (("BATT_LOW_VOLT", "BATT_LOW_MAH") if level == BATT_LOW else
                     ("BATT_CRT_VOLT", "BATT_CRT_MAH"))
        return (ap[volt] > 0 and self.voltage() < ap[volt],
                ap[mah] > 0 and self.remaining_mah() < ap[mah])

    def tick(self) -> None:
        """AP_BattMonitor::check_failsafes, while armed."""
        v = self.v
        now = v.fleet.time_us
        timer_us = v.ap_params["BATT_LOW_TIMER"] * 1e6
        level = BATT_OK
        for lvl in (BATT_LOW, BATT_CRITICAL):
            low_v, low_mah = self.conditions(lvl)
            if not low_v:
                self._below_since[lvl] = None
            elif self._below_since[lvl] is None:
                self._below_since[lvl] = now
            timed_out = low_v and now - self._below_since[lvl] >= timer_us
            if timed_out or low_mah:
                level = lvl
        if not v.cmd.armed or level <= self.level:
            return
        self.level = level
        name = "low" if level == BATT_LOW else "critical"
        v.cmd.text(cm.Severity.WARNING, f"Battery 1 is {name} {self.voltage():.2f}V used "
                   f"{self.consumed_mah():.0f} mAh")
        act_param = "BATT_FS_LOW_ACT" if level == BATT_LOW else "BATT_FS_CRT_ACT"
        action = int(v.ap_params[act_param])
        if landed(v):
            v.cmd.failsafes.act("disarm")
            announce(v, "Battery", "Disarming")
            return
        if is_landing(v) and action != NONE and \
                int(v.ap_params["FS_OPTIONS"]) & OPT_CONTINUE_IF_LANDING:
            announce(v, "Battery", "Continuing Landing")
            return
        announce(v, "Battery")
        do_action(v, action)
