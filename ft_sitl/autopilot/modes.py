"""PX4's flight modes as the virtual PX4 numbers and names them.

A mode is a (main, sub) pair of PX4's custom mode: the main mode, and a sub mode that
only AUTO (and POSCTL's orbit) uses. The numbers are PX4's own, so the MAVLink layer sends
them in HEARTBEAT.custom_mode unchanged and a ground station shows the mode it expects.
The groups at the end are the rules that depend on the mode's kind rather than on one
mode: which modes the sticks fly, and which ones the arming checks treat as manual.
"""

from __future__ import annotations

# PX4 custom modes: main mode, and the sub mode for AUTO
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO, MAIN_ACRO, MAIN_OFFBOARD, MAIN_STABILIZED = (
    1, 2, 3, 4, 5, 6, 7,
)
SUB_READY, SUB_TAKEOFF, SUB_LOITER, SUB_MISSION, SUB_RTL, SUB_LAND = 1, 2, 3, 4, 5, 6
#: PX4's position-mode sub mode of an orbit (MAV_CMD_DO_ORBIT)
SUB_POSCTL_ORBIT = 1
#: PX4's AUTO sub mode of follow-target (follow me)
SUB_FOLLOW_TARGET = 8

MODE_NAMES = {
    (MAIN_MANUAL, 0): "MANUAL",
    (MAIN_ALTCTL, 0): "ALTCTL",
    (MAIN_POSCTL, 0): "POSCTL",
    (MAIN_POSCTL, SUB_POSCTL_ORBIT): "POSCTL.ORBIT",
    (MAIN_AUTO, SUB_READY): "AUTO.READY",
    (MAIN_AUTO, SUB_TAKEOFF): "AUTO.TAKEOFF",
    (MAIN_AUTO, SUB_LOITER): "AUTO.LOITER",
    (MAIN_AUTO, SUB_MISSION): "AUTO.MISSION",
    (MAIN_AUTO, SUB_RTL): "AUTO.RTL",
    (MAIN_AUTO, SUB_LAND): "AUTO.LAND",
    (MAIN_AUTO, SUB_FOLLOW_TARGET): "AUTO.FOLLOW_TARGET",
    (MAIN_ACRO, 0): "ACRO",
    (MAIN_OFFBOARD, 0): "OFFBOARD",
    (MAIN_STABILIZED, 0): "STABILIZED",
}
MODE_BY_NAME = {v: k for k, v in MODE_NAMES.items()}

#: the modes flown with the sticks (PX4 multicopters fly MANUAL as STABILIZED)
STICK_MODES = (MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_STABILIZED)
#: the modes PX4 calls manual (its arming checks look at the throttle stick in them)
MANUAL_MODES = STICK_MODES + (MAIN_ACRO,)
