"""The pre-arm checks: whether the vehicle may arm now, and if not, why.

PX4 runs its health and arming checks before every arming that is not forced; the first
that fails is the status text the ground station shows. The order matters for that text
only, and is kept as it was so a refusal reads the same in every release.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ft_sitl.autopilot.modes import MAIN_AUTO, MAIN_OFFBOARD, SUB_MISSION
from ft_sitl.autopilot.status import LandedState

if TYPE_CHECKING:  # the commander asks; only its type is needed here
    from ft_sitl.autopilot.commander import Commander

#: the status text of an arming the geofence refused (Commander.arm_fence_check), PX4's
FENCE_ARM_DENIAL = "Preflight Fail: Geofence violation"


def arming_denial(cmdr: Commander) -> str:
    """Why ``cmdr`` may not arm now ("" when it may)."""
    if cmdr.terminated:
        return "Arming denied: flight terminated, reboot required"
    if cmdr.landed_state != LandedState.ON_GROUND:
        return "Arming denied: vehicle not landed"
    if cmdr.battery.remaining < cmdr.params["BAT_CRIT_THR"]:
        return "Arming denied: battery critically low"
    if cmdr.main_mode == MAIN_OFFBOARD and not cmdr.offboard_fresh():
        return "Arming denied: no offboard setpoints"
    if cmdr.main_mode == MAIN_AUTO and cmdr.sub_mode == SUB_MISSION and not cmdr.mission:
        return "Arming denied: no valid mission"
    if cmdr.follow.active:
        return "Arming denied: mode not suitable for arming"
    if cmdr.arm_fence_check and cmdr.fence_breach_here() is not None:
        return FENCE_ARM_DENIAL
    return cmdr.manual.arm_check()
