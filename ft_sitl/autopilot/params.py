"""PX4-named parameters of the virtual flight controller, each with a unit and bounds.

Defaults are PX4's, except where the FLYINGTRUST protocol fixes a value (marked
"benchmark"). ``FT_*`` parameters are ft-sitl's own (gain mode, rate-loop bandwidths).
Setting an unknown name or an out-of-bounds value raises :class:`ParamError`; PX4 refuses
such a PARAM_SET the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ft_sitl.config import did_you_mean


class ParamError(ValueError):
    """An unknown parameter, or a value outside its bounds."""


@dataclass(frozen=True)
class ParamSpec:
    name: str
    default: float
    lo: float
    hi: float
    unit: str
    doc: str
    is_int: bool = False


_SPECS = [
    # --- position / velocity control -------------------------------------------------
    ParamSpec("MPC_XY_VEL_MAX", 4.0, 0.0, 20.0, "m/s", "maximum horizontal speed (benchmark: 4)"),
    ParamSpec("MPC_Z_VEL_MAX_UP", 3.0, 0.5, 8.0, "m/s", "maximum climb rate"),
    ParamSpec("MPC_Z_VEL_MAX_DN", 1.5, 0.5, 4.0, "m/s", "maximum descent rate"),
    ParamSpec("MPC_ACC_HOR_MAX", 3.0, 1.0, 15.0, "m/s^2", "maximum horizontal acceleration"),
    ParamSpec("MPC_ACC_UP_MAX", 4.0, 1.0, 15.0, "m/s^2", "maximum upward acceleration"),
    ParamSpec("MPC_ACC_DOWN_MAX", 3.0, 1.0, 15.0, "m/s^2", "maximum downward acceleration"),
    ParamSpec("MPC_TILTMAX_AIR", 45.0, 20.0, 89.0, "deg", "maximum tilt in the air"),
    ParamSpec("MPC_THR_MIN", 0.12, 0.05, 0.5, "norm", "minimum collective thrust in the air"),
    ParamSpec("MPC_THR_MAX", 1.0, 0.1, 1.0, "norm", "maximum collective thrust"),
    ParamSpec("MPC_XY_P", 0.95, 0.0, 2.0, "1/s", "horizontal position gain"),
    ParamSpec("MPC_Z_P", 1.0, 0.1, 1.5, "1/s", "vertical position gain"),
    ParamSpec("MPC_XY_VEL_P_ACC", 1.8, 1.2, 5.0, "1/s", "horizontal velocity P gain"),
    ParamSpec("MPC_XY_VEL_I_ACC", 0.4, 0.0, 60.0, "1/s^2", "horizontal velocity I gain"),
    ParamSpec("MPC_XY_VEL_D_ACC", 0.2, 0.0, 2.0, "-", "horizontal velocity D gain"),
    ParamSpec("MPC_Z_VEL_P_ACC", 4.0, 2.0, 15.0, "1/s", "vertical velocity P gain"),
    ParamSpec("MPC_Z_VEL_I_ACC", 2.0, 0.2, 3.0, "1/s^2", "vertical velocity I gain"),
    ParamSpec("MPC_Z_VEL_D_ACC", 0.0, 0.0, 2.0, "-", "vertical velocity D gain"),
    # --- attitude control --------------------------------------------------------------
    ParamSpec("MC_ROLL_P", 6.5, 0.0, 12.0, "1/s", "roll attitude gain"),
    ParamSpec("MC_PITCH_P", 6.5, 0.0, 12.0, "1/s", "pitch attitude gain"),
    ParamSpec("MC_YAW_P", 2.8, 0.0, 5.0, "1/s", "yaw attitude gain"),
    ParamSpec("MC_YAW_WEIGHT", 0.4, 0.0, 1.0, "-", "yaw priority against roll/pitch"),
    ParamSpec("MC_ROLLRATE_MAX", 220.0, 0.0, 1800.0, "deg/s", "maximum roll rate"),
    ParamSpec("MC_PITCHRATE_MAX", 220.0, 0.0, 1800.0, "deg/s", "maximum pitch rate"),
    ParamSpec("MC_YAWRATE_MAX", 200.0, 0.0, 1800.0, "deg/s", "maximum yaw rate"),
    ParamSpec(
        "MC_AIRMODE", 0, 0, 1, "enum",
        "0: collective may only be lowered to keep roll/pitch authority; "
        "1: it may also be raised (roll/pitch airmode)",
        is_int=True,
    ),
    # --- rate control, PX4 normalised gains (used when FT_GAIN_MODE = 1) ---------------
    ParamSpec("MC_ROLLRATE_P", 0.15, 0.01, 0.5, "norm s/rad", "roll rate P (normalised mode)"),
    ParamSpec("MC_ROLLRATE_I", 0.2, 0.0, 10.0, "norm/rad", "roll rate I (normalised mode)"),
    ParamSpec("MC_ROLLRATE_D", 0.003, 0.0, 0.01, "norm s^2/rad", "roll rate D (normalised)"),
    ParamSpec("MC_PITCHRATE_P", 0.15, 0.01, 0.6, "norm s/rad", "pitch rate P (normalised)"),
    ParamSpec("MC_PITCHRATE_I", 0.2, 0.0, 10.0, "norm/rad", "pitch rate I (normalised)"),
    ParamSpec("MC_PITCHRATE_D", 0.003, 0.0, 0.01, "norm s^2/rad", "pitch rate D (normalised)"),
    ParamSpec("MC_YAWRATE_P", 0.2, 0.0, 0.6, "norm s/rad", "yaw rate P (normalised mode)"),
    ParamSpec("MC_YAWRATE_I", 0.1, 0.0, 10.0, "norm/rad", "yaw rate I (normalised mode)"),
    ParamSpec("MC_YAWRATE_D", 0.0, 0.0, 0.01, "norm s^2/rad", "yaw rate D (normalised mode)"),
    ParamSpec("MC_RR_INT_LIM", 0.3, 0.0, 1.0, "norm", "roll rate integrator limit"),
    ParamSpec("MC_PR_INT_LIM", 0.3, 0.0, 1.0, "norm", "pitch rate integrator limit"),
    ParamSpec("MC_YR_INT_LIM", 0.3, 0.0, 1.0, "norm", "yaw rate integrator limit"),
    # --- commander, navigator, failsafes ---------------------------------------------
    ParamSpec("MIS_TAKEOFF_ALT", 2.5, 0.0, 80.0, "m", "take-off altitude above home"),
    ParamSpec("RTL_RETURN_ALT", 60.0, 0.0, 150.0, "m", "return altitude above home"),
    ParamSpec("MPC_TKO_SPEED", 1.5, 1.0, 5.0, "m/s", "take-off climb rate"),
    ParamSpec("MPC_LAND_SPEED", 0.7, 0.6, 3.0, "m/s", "landing descent rate"),
    ParamSpec("MPC_XY_CRUISE", 5.0, 3.0, 20.0, "m/s", "horizontal speed in auto modes"),
    ParamSpec("NAV_ACC_RAD", 2.0, 0.05, 200.0, "m", "default waypoint acceptance radius"),
    ParamSpec("COM_OF_LOSS_T", 1.0, 0.0, 60.0, "s", "offboard setpoint loss timeout"),
    ParamSpec("COM_DISARM_LAND", 2.0, -1.0, 20.0, "s", "auto-disarm after landing (<0: off)"),
    ParamSpec("COM_DISARM_PRFLT", 10.0, -1.0, 20.0, "s", "auto-disarm if no take-off (<0: off)"),
    ParamSpec("BAT_LOW_THR", 0.15, 0.12, 0.5, "norm", "low battery warning level"),
    ParamSpec("BAT_CRIT_THR", 0.07, 0.05, 0.25, "norm", "critical battery level (RTL)"),
    ParamSpec("BAT_EMERGEN_THR", 0.05, 0.03, 0.1, "norm", "emergency battery level (land)"),
    ParamSpec("SYS_FAILURE_EN", 0, 0, 1, "bool", "failure injection (MAV_CMD_INJECT_FAILURE) "
              "allowed", is_int=True),
    ParamSpec("COM_POS_FS_DELAY", 1.0, 1.0, 100.0, "s",
              "position loss (GPS failure) time before the failsafe lands"),
    ParamSpec("GF_ACTION", 2, 0, 5, "enum", "geofence breach action: 0 none, 1 warning, "
              "2 hold, 3 return, 4 terminate, 5 land", is_int=True),
    ParamSpec("GF_MAX_HOR_DIST", 0.0, 0.0, 10000.0, "m",
              "geofence: maximum horizontal distance from home (0: off)"),
    ParamSpec("GF_MAX_VER_DIST", 0.0, 0.0, 10000.0, "m",
              "geofence: maximum height above home (0: off)"),
    ParamSpec(
        "FT_BAT_ENDURANCE", 1200.0, 10.0, 36000.0, "s",
        "hover endurance that sizes the simulated battery (ft-sitl)",
    ),
    # --- ft-sitl: offboard acceleration limits (protocol 1 compatibility) -------------
    ParamSpec(
        "FT_OFFB_ACC_LIM", 0, 0, 1, "enum",
        "0: MPC_ACC_* bound only the flight controller's own trajectories (take-off, hold, "
        "goto, missions, RTL, land) and an offboard trajectory setpoint only the tilt and "
        "thrust limits, as in PX4; 1: they clamp offboard acceleration too (ft-sitl before "
        "protocol 2)",
        is_int=True,
    ),
    # --- ft-sitl: gain mode and rate-loop bandwidths (FT_GAIN_MODE = 0) ----------------
    ParamSpec(
        "FT_GAIN_MODE",
        0,
        0,
        1,
        "enum",
        "0: rate loop as closed-loop bandwidths scaled by each platform's inertia; "
        "1: PX4 normalised rate gains (MC_*RATE_P/I/D) scaled by each platform's torque",
        is_int=True,
    ),
    ParamSpec("FT_RATE_BW_RP", 18.0, 2.0, 200.0, "rad/s", "roll/pitch rate-loop bandwidth"),
    ParamSpec("FT_RATE_BW_Y", 8.0, 1.0, 100.0, "rad/s", "yaw rate-loop bandwidth"),
    ParamSpec(
        "FT_RATE_I_RATIO", 0.1, 0.0, 1.0, "-", "rate integrator corner as a fraction of bandwidth"
    ),
    ParamSpec(
        "FT_RATE_INT_LIM", 30.0, 0.0, 1000.0, "rad/s^2", "rate integrator limit (bandwidth mode)"
    ),
    ParamSpec("FT_POS_LOOP_HZ", 50.0, 10.0, 1000.0, "Hz", "position/velocity loop rate"),
]

PARAMS: dict[str, ParamSpec] = {s.name: s for s in _SPECS}

#: the controller-gain modes by name: FT_GAIN_MODE's values as a campaign's ``gains`` key and
#: a trial spec's ``gains`` field name them (docs/control.md, "Gain modes")
GAIN_MODES: dict[str, int] = {"bandwidth": 0, "px4": 1}
#: the name of FT_GAIN_MODE's default (what a spec without ``gains`` flies)
DEFAULT_GAINS: str = next(k for k, v in GAIN_MODES.items() if v == PARAMS["FT_GAIN_MODE"].default)


class ParamSet:
    """Current parameter values, with bounds checking on every set."""

    def __init__(self, overrides: dict[str, float] | None = None):
        self._values = {name: spec.default for name, spec in PARAMS.items()}
        for name, value in (overrides or {}).items():
            self.set(name, value)

    @staticmethod
    def spec(name: str) -> ParamSpec:
        try:
            return PARAMS[name]
        except KeyError:
            hint = did_you_mean(name, PARAMS, n=2)
            raise ParamError(f"unknown parameter {name!r}{hint}") from None

    def get(self, name: str) -> float:
        self.spec(name)
        return self._values[name]

    def __getitem__(self, name: str) -> float:
        return self.get(name)

    def set(self, name: str, value: float) -> float:
        spec = self.spec(name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParamError(f"{name}: {value!r} is not a number")
        if not math.isfinite(value):
            raise ParamError(f"{name}: {value!r} is not finite")
        if spec.is_int and value != int(value):
            raise ParamError(f"{name}: {value!r} must be an integer")
        if not spec.lo <= value <= spec.hi:
            raise ParamError(
                f"{name}: {value!r} {spec.unit} is outside [{spec.lo:g}, {spec.hi:g}] {spec.unit}"
            )
        self._values[name] = int(value) if spec.is_int else float(value)
        return self._values[name]

    def items(self):
        return self._values.items()

    def as_dict(self) -> dict[str, float]:
        return dict(self._values)
