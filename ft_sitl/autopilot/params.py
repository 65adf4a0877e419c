"""PX4-named parameters of the virtual flight controller, each with a unit and bounds.

Two kinds, one declaration each:

* **honoured** (:data:`HONOURED`): the :class:`ParamSpec` list below, the parameters
  ft-sitl acts on (the cascade's gains and limits, the commander's and navigator's
  thresholds). Defaults are PX4's, except where the FLYINGTRUST protocol fixes a value
  (marked "benchmark") or ft-sitl deliberately differs; ``FT_*`` are ft-sitl's own (gain
  mode, rate-loop bandwidths).
* **stored**: every other parameter of the PX4 modules ft-sitl emulates, from the table
  ``data/px4_params.json`` (PX4 :data:`PX4_RELEASE`; built by
  ``scripts/px4_params_table.py``): accepted, range-checked, remembered and echoed, with
  no effect on the flight.

A name in both is declared by its ParamSpec; its table row (:data:`PX4_TABLE`) only tells
where ft-sitl differs from PX4 (:func:`px4_differences`). Setting an unknown name or an
out-of-bounds value raises :class:`ParamError`; ft-sitl refuses such a PARAM_SET the same
way.
"""

from __future__ import annotations

import json
import math
import struct
from dataclasses import dataclass, replace
from pathlib import Path

from ft_sitl.config import did_you_mean

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
_TABLE = Path(__file__).with_name("data") / "px4_params.json"


class ParamError(ValueError):
    """An unknown parameter, or a value outside its bounds."""


@dataclass(frozen=True)
class ParamSpec:
    """One parameter. ``lo``/``hi`` are the bounds a set is checked against (for a PX4
    parameter without a published range: the INT32 range, or +-inf for a FLOAT; 0..1 for a
    boolean). ``honoured``: ft-sitl acts on it (else it is only stored). ``group`` is
    PX4's parameter group ("ft-sitl" for ft-sitl's own), ``kind`` "enum", "bitmask",
    "boolean" or ""."""

    name: str
    default: float
    lo: float
    hi: float
    unit: str
    doc: str
    is_int: bool = False
    honoured: bool = True
    group: str = ""
    kind: str = ""

    @property
    def px4_type(self) -> str:
        """PX4's type name: INT32 or FLOAT."""
        return "INT32" if self.is_int else "FLOAT"

    @property
    def bounded_lo(self) -> bool:
        """Whether the lower bound is a real limit (not the type's own range)."""
        return self.lo > (INT32_MIN if self.is_int else -math.inf)

    @property
    def bounded_hi(self) -> bool:
        return self.hi < (INT32_MAX if self.is_int else math.inf)

    def check(self, value) -> float:
        """The value as stored (int for an integer parameter), or ParamError naming the
        parameter, the value and the bounds: not a finite number, not an integer, out of
        bounds. A FLOAT is compared in float32, as it travels: 0.6 sent over MAVLink
        arrives as 0.6000000238 and must still pass a bound of 0.6."""
        name = self.name
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ParamError(f"{name}: {value!r} is not a number")
        if not math.isfinite(value):
            raise ParamError(f"{name}: {value!r} is not finite")
        if self.is_int and value != int(value):
            raise ParamError(f"{name}: {value!r} must be an integer")
        v, lo, hi = (value, self.lo, self.hi) if self.is_int else \
            (_f32(value), _f32(self.lo), _f32(self.hi))
        if not lo <= v <= hi:
            unit = f" {self.unit}" if self.unit else ""
            raise ParamError(f"{name}: {value!r}{unit} is outside {_bounds(self)}")
        return int(value) if self.is_int else float(value)


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
    ParamSpec("SYS_FAILURE_EN", 0, 0, 1, "", "failure injection (MAV_CMD_INJECT_FAILURE) "
              "allowed", is_int=True),
    ParamSpec("COM_POS_FS_DELAY", 1, 1, 100, "s",
              "position loss (GPS failure) time before the failsafe lands", is_int=True),
    ParamSpec("GF_ACTION", 2, 0, 5, "", "geofence breach action: 0 none, 1 warning, "
              "2 hold, 3 return, 4 terminate, 5 land", is_int=True),
    ParamSpec("GF_MAX_HOR_DIST", 0.0, 0.0, 10000.0, "m",
              "geofence: maximum horizontal distance from home (0: off)"),
    ParamSpec("GF_MAX_VER_DIST", 0.0, 0.0, 10000.0, "m",
              "geofence: maximum height above home (0: off)"),
    # --- follow target (AUTO.FOLLOW_TARGET, ft_sitl/autopilot/follow.py) ---------------
    ParamSpec("FLW_TGT_DST", 8.0, 1.0, math.inf, "m", "horizontal distance kept from the target"),
    ParamSpec("FLW_TGT_HT", 8.0, 8.0, math.inf, "m",
              "follow height: above home (FLW_TGT_ALT_M 0, 1) or the target (2)"),
    ParamSpec("FLW_TGT_FA", 180.0, -180.0, 180.0, "",
              "follow angle (deg) clockwise from the target's course: 0 in front, 180 behind"),
    ParamSpec("FLW_TGT_ALT_M", 0, INT32_MIN, INT32_MAX, "",
              "follow altitude: 0 above home, 1 above the (flat) ground, 2 above the target",
              is_int=True),
    ParamSpec("FLW_TGT_MAX_VEL", 5.0, 0.0, 20.0, "",
              "largest tangential speed (m/s) when circling the target to a new angle"),
    ParamSpec("FLW_TGT_RS", 0.1, 0.0, 1.0, "",
              "target estimate: 1 - RS of each position innovation taken (lower: more "
              "responsive)"),
    # --- manual control (MANUAL_CONTROL sticks) and its loss ------------------------------
    ParamSpec("COM_RC_IN_MODE", 3, 0, 4, "", "stick input: 0 RC only (MAVLink sticks ignored), "
              "1 joystick only, 2 RC and joystick with fallback, 3 RC or joystick, keep first, "
              "4 stick input disabled", is_int=True),
    ParamSpec("COM_RC_LOSS_T", 0.5, 0.0, 35.0, "s",
              "time without manual control before it counts as lost"),
    ParamSpec("NAV_RCL_ACT", 2, 1, 6, "", "manual control loss action: 1 hold, 2 return, "
              "3 land, 5 terminate, 6 disarm", is_int=True),
    ParamSpec("COM_RCL_EXCEPT", 0, 0, 31, "", "modes without manual control loss failsafe "
              "(bitmask): 1 mission, 2 hold (and take-off), 4 offboard", is_int=True),
    ParamSpec("COM_FAIL_ACT_T", 5.0, 0.0, 25.0, "s",
              "hold time between a failsafe's trigger and its return or land"),
    ParamSpec("MPC_VEL_MANUAL", 10.0, 3.0, 20.0, "m/s",
              "largest horizontal speed from the sticks in POSCTL (capped by MPC_XY_VEL_MAX)"),
    ParamSpec("MPC_MAN_TILT_MAX", 35.0, 1.0, 70.0, "deg",
              "largest tilt from the sticks in STABILIZED and ALTCTL"),
    ParamSpec("MPC_MAN_Y_MAX", 150.0, 0.0, 400.0, "deg/s", "largest yaw rate from the sticks"),
    ParamSpec("MPC_HOLD_DZ", 0.1, 0.0, 1.0, "", "stick dead zone in the manual modes"),
    ParamSpec("MPC_HOLD_MAX_XY", 0.8, 0.0, 3.0, "m/s",
              "horizontal speed below which POSCTL locks the position (0: at once)"),
    ParamSpec("MPC_HOLD_MAX_Z", 0.6, 0.0, 3.0, "m/s",
              "vertical speed below which ALTCTL/POSCTL lock the altitude (0: at once)"),
    ParamSpec("MPC_MANTHR_MIN", 0.08, 0.0, 1.0, "norm",
              "lowest collective thrust from the throttle in STABILIZED"),
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


def _load_table(path: Path = _TABLE) -> tuple[dict[str, ParamSpec], dict]:
    """PX4's parameters as the table gives them (all marked stored), and its header."""
    doc = json.loads(path.read_text())
    fields = doc["fields"]
    out: dict[str, ParamSpec] = {}
    for row in doc["params"]:
        r = dict(zip(fields, row, strict=True))
        is_int = r["type"] == "INT32"
        lo, hi = r["min"], r["max"]
        if r["kind"] == "boolean":
            lo, hi = (0 if lo is None else lo), (1 if hi is None else hi)
        if lo is None:
            lo = INT32_MIN if is_int else -math.inf
        if hi is None:
            hi = INT32_MAX if is_int else math.inf
        out[r["name"]] = ParamSpec(
            r["name"], r["default"], lo, hi, r["unit"], r["description"], is_int=is_int,
            honoured=False, group=r["group"], kind=r["kind"] or "")
    return out, {k: v for k, v in doc.items() if k != "params"}


#: PX4's published parameters of the emulated modules (:data:`PX4_RELEASE`), as given
PX4_TABLE, _HEADER = _load_table()
#: the PX4 release (and commit) the table was read from
PX4_RELEASE: str = _HEADER["px4_release"]
PX4_COMMIT: str = _HEADER["px4_commit"]

#: the parameters ft-sitl acts on, in declaration order (PX4's group filled in; "ft-sitl"
#: for ft-sitl's own)
HONOURED: dict[str, ParamSpec] = {
    s.name: replace(s, group=PX4_TABLE[s.name].group if s.name in PX4_TABLE
                    else "ft-sitl" if s.name.startswith("FT_") else "")
    for s in _SPECS
}
#: every parameter: the honoured ones, then the stored ones by name (PARAM_VALUE's index)
PARAMS: dict[str, ParamSpec] = {
    **HONOURED, **{n: s for n, s in PX4_TABLE.items() if n not in HONOURED}
}


def px4_differences() -> dict[str, dict[str, tuple]]:
    """Where an honoured parameter differs from PX4's table: {name: {field: (ft-sitl,
    PX4)}} over type, default, min and max (None: PX4 publishes no bound); a name PX4's
    table lacks maps to {"name": (name, None)}. ``FT_*`` are ft-sitl's own and left out."""
    out: dict[str, dict[str, tuple]] = {}
    for name, s in HONOURED.items():
        if name.startswith("FT_"):
            continue
        p = PX4_TABLE.get(name)
        if p is None:
            out[name] = {"name": (name, None)}
            continue
        d = {}
        if s.is_int != p.is_int:
            d["type"] = (s.px4_type, p.px4_type)
        if s.default != p.default:
            d["default"] = (s.default, p.default)
        if s.lo != p.lo:
            d["min"] = (s.lo, p.lo if p.bounded_lo else None)
        if s.hi != p.hi:
            d["max"] = (s.hi, p.hi if p.bounded_hi else None)
        if d:
            out[name] = d
    return out


def _f32(x: float) -> float:
    """x rounded to float32, as PX4 stores a FLOAT (and MAVLink carries it)."""
    if not math.isfinite(x):
        return x
    return struct.unpack("<f", struct.pack("<f", x))[0]


#: the controller-gain modes by name: FT_GAIN_MODE's values as a campaign's ``gains`` key and
#: a trial spec's ``gains`` field name them (docs/control.md, "Gain modes")
GAIN_MODES: dict[str, int] = {"bandwidth": 0, "px4": 1}
#: the name of FT_GAIN_MODE's default (what a spec without ``gains`` flies)
DEFAULT_GAINS: str = next(k for k, v in GAIN_MODES.items() if v == PARAMS["FT_GAIN_MODE"].default)


class ParamSet:
    """Current parameter values, with bounds checking on every set. ``table``: the
    declarations (name -> ParamSpec) it holds, in PARAM_VALUE index order; a face with
    other names (the ArduCopter face) subclasses it with its own table."""

    table: dict[str, ParamSpec] = PARAMS

    def __init__(self, overrides: dict[str, float] | None = None):
        self._values = {name: spec.default for name, spec in self.table.items()}
        for name, value in (overrides or {}).items():
            self.set(name, value)

    @classmethod
    def spec(cls, name: str) -> ParamSpec:
        try:
            return cls.table[name]
        except KeyError:
            hint = did_you_mean(name, cls.table, n=2)
            raise ParamError(f"unknown parameter {name!r}{hint}") from None

    def get(self, name: str) -> float:
        self.spec(name)
        return self._values[name]

    def __getitem__(self, name: str) -> float:
        return self.get(name)

    def set(self, name: str, value: float) -> float:
        self._values[name] = self.spec(name).check(value)
        return self._values[name]

    def items(self):
        return self._values.items()

    def as_dict(self) -> dict[str, float]:
        return dict(self._values)


def _bounds(spec: ParamSpec) -> str:
    lo = f"{spec.lo:g}" if spec.bounded_lo else "-"
    hi = f"{spec.hi:g}" if spec.bounded_hi else "-"
    unit = f" {spec.unit}" if spec.unit else ""
    return f"[{lo}, {hi}]{unit}"
