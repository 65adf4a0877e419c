"""ArduCopter's arming checks (ArduCopter/AP_Arming_Copter.cpp, libraries/AP_Arming,
AP_BattMonitor's arming_checks, AC_Fence's pre_arm_check) as far as ft-sitl has what they
look at, each failure worded as ArduCopter words it: "PreArm: ..." for the pre-arm checks
(every failing one is reported), "Arm: ..." for the final arm checks (the first).

ARMING_CHECK is 4.5's bitmask: bit 0 (1) every check, 0 none; otherwise the checks of the
set bits (8 GPS, 64 RC, 128 board voltage, 256 battery level). Mandatory whatever it says:
a position estimate in the modes that need one, and the mode allowing arming. The fence
and the GCS failsafe are checked whenever the checks run. A forced arming (param2 2989)
skips all of them, as ArduPilot's does.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.arming import arming_denial
from ft_sitl.mavlink.ardupilot import modes
from ft_sitl.mavlink.ardupilot.failsafe import BATT_CRITICAL, BATT_LOW, BATT_OK

if TYPE_CHECKING:  # the vehicle asks; only its type is needed here
    from ft_sitl.mavlink.ardupilot.agent import ArduCopterVehicle

# ARMING_CHECK bits (AP_Arming::Check)
CHECK_ALL, CHECK_GPS, CHECK_RC, CHECK_VOLTAGE, CHECK_BATTERY = 1, 8, 64, 128, 256
#: the modes a ground station may arm with the throttle up (allows_GCS_or_SCR_arming_
#: with_throttle_high)
THROTTLE_HIGH_OK = (modes.GUIDED, modes.AUTO)


def enabled(v: ArduCopterVehicle, bit: int) -> bool:
    mask = int(v.ap_params["ARMING_CHECK"])
    return bool(mask & CHECK_ALL or mask & bit)


def _battery(v: ArduCopterVehicle) -> str:
    """AP_BattMonitor_Backend::arming_checks' first failing condition, for battery 1."""
    bf = v.battery_fs
    low_v, low_mah = bf.conditions(BATT_LOW)
    crt_v, crt_mah = bf.conditions(BATT_CRITICAL)
    for bad, what in ((low_v, "low voltage failsafe"), (low_mah, "low capacity failsafe"),
                      (crt_v, "critical voltage failsafe"),
                      (crt_mah, "critical capacity failsafe")):
        if bad:
            return f"Battery 1 {what}"
    return ""


def prearm_failures(v: ArduCopterVehicle) -> list[str]:
    """The failing pre-arm checks' texts (empty: they pass)."""
    c, mode = v.cmd, v.modes.number
    out = []
    if c.terminated or c.landed_state != cm.LandedState.ON_GROUND:
        denial = arming_denial(c)  # (the flight controller's own: no ArduCopter text)
        reason = denial.split(": ", 1)[-1]
        out.append(f"PreArm: {reason[:1].upper()}{reason[1:]}")
    no_gps = not c.sensor_ok("gps") or v.ap_params["SIM_GPS_DISABLE"]  # (set this chunk)
    if mode in modes.NEEDS_POSITION and no_gps:
        out.append("PreArm: Need Position Estimate")
    mask = int(v.ap_params["ARMING_CHECK"])
    if mask == 0:
        return out
    if v.gcs_fs.active:
        out.append("PreArm: GCS failsafe on")
    if v.ap_params["FENCE_ENABLE"] and c.fence_breach_here() is not None:
        out.append("PreArm: vehicle outside fence")
    if enabled(v, CHECK_VOLTAGE) and v.battery_fs.level != BATT_OK:
        out.append("PreArm: Battery failsafe")
    if enabled(v, CHECK_BATTERY):
        text = _battery(v)
        if text:
            out.append(f"PreArm: {text}")
    return out


def arm_failure(v: ArduCopterVehicle, from_gcs: bool = True) -> str:
    """The final arm checks' first failure ("" when they pass)."""
    mode = v.modes.number
    if mode not in modes.ARMABLE:
        return f"Arm: {v.modes.name} mode not armable"  # (AP_Arming_Copter: the name)
    if int(v.ap_params["ARMING_CHECK"]) == 0 or not enabled(v, CHECK_RC):
        return ""
    rc = v.rc
    if not rc.radio_on or (from_gcs and mode in THROTTLE_HIGH_OK):
        return ""
    throttle = rc.throttle()
    # above the middle's dead band is always too high; in the manual-throttle modes any
    # throttle is
    climbs = mode not in modes.MANUAL_THROTTLE and \
        2.0 * throttle - 1.0 > v.params["MPC_HOLD_DZ"]
    if climbs or (mode in modes.MANUAL_THROTTLE and throttle > 0):
        return "Arm: Throttle too high"
    return ""


def refusals(v: ArduCopterVehicle) -> list[str]:
    """Why arming is refused now, as the texts ArduCopter sends (empty: it may arm)."""
    pre = prearm_failures(v)
    if pre:
        return pre
    final = arm_failure(v)
    return [final] if final else []
