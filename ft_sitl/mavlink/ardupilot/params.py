"""ArduCopter's parameters for the subsystems ft-sitl emulates, declared once each: name,
default, range, unit and doc as ArduCopter 4.x publishes them, its wire type, and (when
ft-sitl acts on it) the PX4-named parameter of the virtual flight controller it sets.

Three kinds: **honoured one to one** (``px4`` and ``scale``: WPNAV_SPEED in cm/s sets
MPC_XY_CRUISE in m/s), **honoured as a group** (the FENCE_* set GF_*: :func:`fence_px4`)
and **stored**: accepted within range, remembered and echoed, with no effect (SRn_* are
read by the streams). A value outside the declared range, or one the mapped parameter
cannot take, is refused (:class:`~ft_sitl.autopilot.params.ParamError`); where ft-sitl's
range is narrower than ArduCopter's the declaration says so in its doc.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ft_sitl.autopilot.params import ParamError, ParamSet, ParamSpec

#: ArduPilot's parameter types (MAV_PARAM_TYPE) by name
INT8, INT16, INT32, FLOAT = 2, 4, 6, 9


@dataclass(frozen=True)
class ApParam(ParamSpec):
    """One ArduCopter parameter: the flight controller's declaration (name, default,
    bounds, unit, doc, is_int, honoured) with ArduPilot's wire type ``ptype`` and
    ``px4``/``scale``: the PX4-named parameter it sets, as value * scale (None: stored, or
    honoured as a group)."""

    ptype: int = FLOAT
    px4: str | None = None
    scale: float = 1.0


def _P(name: str, default: float, lo: float, hi: float, unit: str, doc: str,
       ptype: int = FLOAT, *, px4: str | None = None, scale: float = 1.0) -> ApParam:
    """One declaration: honoured when it sets a PX4 parameter or is one of the fence's
    group (FENCE_*), stored otherwise."""
    return ApParam(name, default, lo, hi, unit, doc, is_int=ptype != FLOAT,
                   honoured=px4 is not None or name.startswith("FENCE_"), group="ArduCopter",
                   ptype=ptype, px4=px4, scale=scale)


_SPECS = [
    # --- waypoint navigation (libraries/AC_WPNav/AC_WPNav.cpp) ------------------------
    _P("WPNAV_SPEED", 1000, 10, 2000, "cm/s", "horizontal speed of waypoints and GUIDED "
       "targets (ft-sitl: MPC_XY_CRUISE, which takes 300..2000)", px4="MPC_XY_CRUISE",
       scale=0.01),
    _P("WPNAV_SPEED_UP", 250, 10, 1000, "cm/s", "climb speed in auto modes (ft-sitl: "
       "MPC_Z_VEL_MAX_UP, 50..800)", px4="MPC_Z_VEL_MAX_UP", scale=0.01),
    _P("WPNAV_SPEED_DN", 150, 10, 500, "cm/s", "descent speed in auto modes (ft-sitl: "
       "MPC_Z_VEL_MAX_DN, 50..400)", px4="MPC_Z_VEL_MAX_DN", scale=0.01),
    _P("WPNAV_ACCEL", 250, 50, 500, "cm/s/s", "horizontal acceleration in auto modes "
       "(ft-sitl: MPC_ACC_HOR_MAX, 100..500)", px4="MPC_ACC_HOR_MAX", scale=0.01),
    _P("WPNAV_ACCEL_Z", 100, 50, 500, "cm/s/s", "vertical acceleration in auto modes"),
    _P("WPNAV_RADIUS", 200, 5, 1000, "cm", "waypoint acceptance radius", px4="NAV_ACC_RAD",
       scale=0.01),
    _P("WPNAV_RFND_USE", 1, 0, 1, "", "use a rangefinder for terrain following", INT8),
    _P("LOIT_SPEED", 1250, 20, 3500, "cm/s", "largest horizontal speed in LOITER"),
    _P("LOIT_ACC_MAX", 500, 100, 981, "cm/s/s", "largest acceleration in LOITER"),
    # --- position control (libraries/AC_AttitudeControl/AC_PosControl.cpp) ------------
    _P("PSC_POSXY_P", 1.0, 0.5, 2.0, "", "horizontal position gain", px4="MPC_XY_P"),
    _P("PSC_VELXY_P", 2.0, 0.1, 6.0, "", "horizontal velocity P gain (ft-sitl: "
       "MPC_XY_VEL_P_ACC, 1.2..5)", px4="MPC_XY_VEL_P_ACC"),
    _P("PSC_VELXY_I", 1.0, 0.02, 1.0, "", "horizontal velocity I gain",
       px4="MPC_XY_VEL_I_ACC"),
    _P("PSC_VELXY_D", 0.5, 0.0, 1.0, "", "horizontal velocity D gain",
       px4="MPC_XY_VEL_D_ACC"),
    _P("PSC_POSZ_P", 1.0, 1.0, 3.0, "", "vertical position gain (ft-sitl: MPC_Z_P, "
       "up to 1.5)", px4="MPC_Z_P"),
    _P("PSC_VELZ_P", 5.0, 1.0, 8.0, "", "vertical velocity P gain (ft-sitl: "
       "MPC_Z_VEL_P_ACC, from 2)", px4="MPC_Z_VEL_P_ACC"),
    _P("PSC_ACCZ_P", 0.5, 0.2, 1.5, "", "vertical acceleration P gain"),
    _P("PSC_ACCZ_I", 1.0, 0.0, 3.0, "", "vertical acceleration I gain"),
    _P("PSC_ACCZ_D", 0.0, 0.0, 0.4, "", "vertical acceleration D gain"),
    # --- attitude limits (ArduCopter/Parameters.cpp) ----------------------------------
    _P("ANGLE_MAX", 3000, 1000, 8000, "cdeg", "largest lean angle in all modes (ft-sitl: "
       "MPC_TILTMAX_AIR, 2000..8000)", INT16, px4="MPC_TILTMAX_AIR", scale=0.01),
    # --- pilot input (ArduCopter/Parameters.cpp) --------------------------------------
    _P("PILOT_SPEED_UP", 250, 50, 500, "cm/s", "largest climb rate from the sticks", INT16),
    _P("PILOT_SPEED_DN", 0, 0, 500, "cm/s", "largest descent rate from the sticks "
       "(0: PILOT_SPEED_UP)", INT16),
    _P("PILOT_ACCEL_Z", 250, 50, 500, "cm/s/s", "vertical acceleration from the sticks",
       INT16),
    # --- return to launch (ArduCopter/mode_rtl.cpp parameters) ------------------------
    _P("RTL_ALT", 1500, 30, 300000, "cm", "return altitude above home (ft-sitl: "
       "RTL_RETURN_ALT, up to 15000)", INT32, px4="RTL_RETURN_ALT", scale=0.01),
    _P("RTL_SPEED", 0, 0, 2000, "cm/s", "horizontal return speed (0: WPNAV_SPEED)", INT16),
    _P("RTL_ALT_FINAL", 0, 0, 1000, "cm", "altitude the return ends at (0: lands)", INT16),
    _P("RTL_LOIT_TIME", 5000, 0, 60000, "ms", "time over home before the final descent",
       INT32),
    _P("RTL_CLIMB_MIN", 0, 0, 3000, "cm", "least climb before the return", INT16),
    # --- landing (ArduCopter/Parameters.cpp) ------------------------------------------
    _P("LAND_SPEED", 60, 60, 200, "cm/s", "final descent speed (ArduCopter: default 50, "
       "30..200; ft-sitl's MPC_LAND_SPEED takes 60..300)", INT16, px4="MPC_LAND_SPEED",
       scale=0.01),
    _P("LAND_SPEED_HIGH", 0, 0, 2500, "cm/s", "descent speed above 10 m (0: "
       "WPNAV_SPEED_DN)", INT16),
    # --- GUIDED (ArduCopter/Parameters.cpp) -------------------------------------------
    _P("GUID_TIMEOUT", 3.0, 0.1, 5.0, "s", "GUIDED velocity/acceleration target timeout "
       "(ft-sitl: COM_OF_LOSS_T)", px4="COM_OF_LOSS_T"),
    # --- fence (libraries/AC_Fence/AC_Fence.cpp): honoured as a group ------------------
    _P("FENCE_ENABLE", 0, 0, 1, "", "fence on", INT8),
    _P("FENCE_TYPE", 7, 0, 15, "", "fence kinds (bitmask): 1 maximum altitude, 2 circle, "
       "4 polygon, 8 minimum altitude", INT8),
    _P("FENCE_ACTION", 1, 0, 5, "", "breach action: 0 report, 1 RTL or land, 2 land, "
       "3 SmartRTL or RTL or land, 4 brake or land, 5 SmartRTL or land", INT8),
    _P("FENCE_ALT_MAX", 100.0, 10.0, 1000.0, "m", "fence's maximum altitude above home"),
    _P("FENCE_RADIUS", 300.0, 30.0, 10000.0, "m", "fence's circle radius around home"),
    _P("FENCE_MARGIN", 2.0, 1.0, 10.0, "m", "distance inside the fence a return aims for"),
    _P("FENCE_ALT_MIN", -10.0, -100.0, 100.0, "m", "fence's minimum altitude above home "
       "(FENCE_TYPE 8; ft-sitl: stored, not enforced)"),
    # --- rally points (libraries/AP_Rally/AP_Rally.cpp): read by .rally ---------------
    _P("RALLY_LIMIT_KM", 0.3, 0.0, 1000.0, "km", "a rally point farther than this is not "
       "returned to, home is (0: no limit)"),
    _P("RALLY_INCL_HOME", 1, 0, 1, "", "RTL may return home when it is nearer than every "
       "rally point (0: the nearest rally point whatever home's distance)", INT8),
    # --- motor outputs (libraries/SRV_Channel): read by SERVO_OUTPUT_RAW ----------------
    *(_P(f"SERVO{n}_{end}", pwm, 800, 2200, "PWM", f"motor {n}'s output at {what} rotor "
         "speed command (ArduCopter's SERVOn default 1100/1900; ft-sitl 1000/2000, the "
         "range ArduCopter SITL's motors span: MOT_PWM_MIN/MAX 0 take RC3_MIN/MAX, "
         "1000/2000 in its copter.parm)", INT16)
      for n in range(1, 5) for end, pwm, what in (("MIN", 1000, "zero"),
                                                   ("MAX", 2000, "full"))),
    # --- identity and arming (ArduCopter/Parameters.cpp, AP_Arming) --------------------
    _P("SYSID_THISMAV", 1, 1, 255, "", "this vehicle's MAVLink system id (ft-sitl: vehicle "
       "i is i+1 whatever is set)", INT16),
    _P("SYSID_MYGCS", 255, 1, 255, "", "the ground station's system id", INT16),
    _P("ARMING_CHECK", 1, 0, 2147483647, "", "pre-arm checks (bitmask; 1 all)", INT32),
    _P("DISARM_DELAY", 10, 0, 127, "s", "disarm after this long landed and idle", INT8),
]
#: the stream groups of SRn_* in ArduPilot's order (GCS_MAVLINK streams)
STREAM_GROUPS = ("RAW_SENS", "EXT_STAT", "RC_CHAN", "RAW_CTRL", "POSITION", "EXTRA1",
                 "EXTRA2", "EXTRA3", "PARAMS", "ADSB")
#: serial ports with stream-rate parameters (SR0 is SERIAL0, the first TCP port)
STREAM_PORTS = 3
_SPECS += [
    _P(f"SR{n}_{g}", 0, 0, 50, "Hz", f"SERIAL{n}'s {g} stream rate (ArduCopter's default 0: "
       "none until a client asks)", INT16)
    for n in range(STREAM_PORTS) for g in STREAM_GROUPS
]

# --- RC input (libraries/RC_Channel: RCMAP_*, RC_OVERRIDE_TIME, RCn_*), read by .rc ---
_SPECS += [
    _P("RCMAP_ROLL", 1, 1, 16, "", "the roll channel", INT8),
    _P("RCMAP_PITCH", 2, 1, 16, "", "the pitch channel", INT8),
    _P("RCMAP_THROTTLE", 3, 1, 16, "", "the throttle channel", INT8),
    _P("RCMAP_YAW", 4, 1, 16, "", "the yaw channel", INT8),
    _P("RC_OVERRIDE_TIME", 3.0, -1.0, 120.0, "s", "RC_CHANNELS_OVERRIDE's timeout per "
       "channel (0: overrides off, -1: never times out)"),
]
#: ArduCopter's default dead zones of the channels RCMAP points at (Copter::init_rc_in)
_RC_DZ = {1: 20, 2: 20, 3: 30, 4: 20}
for _n in range(1, 17):
    _SPECS += [
        _P(f"RC{_n}_MIN", 1100, 800, 2200, "PWM", f"channel {_n}'s lowest value", INT16),
        _P(f"RC{_n}_TRIM", 1500, 800, 2200, "PWM", f"channel {_n}'s centre", INT16),
        _P(f"RC{_n}_MAX", 1900, 800, 2200, "PWM", f"channel {_n}'s highest value", INT16),
        _P(f"RC{_n}_DZ", _RC_DZ.get(_n, 0), 0, 200, "PWM", f"channel {_n}'s dead zone "
           "around its trim (the throttle's: above its minimum)", INT16),
    ]
# --- failsafes (ArduCopter/Parameters.cpp, AP_BattMonitor_Params.cpp), read by .failsafe
_SPECS += [
    _P("FS_GCS_ENABLE", 0, 0, 7, "", "GCS failsafe action: 0 off, 1 RTL, 2 RTL (AUTO "
       "continues), 3 SmartRTL or RTL, 4 SmartRTL or land, 5 land, 6 DO_LAND_START or RTL, "
       "7 brake or land (ft-sitl: SmartRTL and DO_LAND_START fall back to RTL)", INT8),
    _P("FS_GCS_TIMEOUT", 5.0, 2.0, 120.0, "s", "silence of the ground station (SYSID_MYGCS) "
       "before the GCS failsafe"),
    _P("FS_OPTIONS", 16, 0, 63, "", "failsafe options (bitmask): 2 GCS failsafe continues "
       "AUTO, 8 any failsafe continues a landing, 16 GCS failsafe continues pilot modes "
       "(ArduCopter's default)", INT32),
    _P("BATT_CAPACITY", 3300, 0, 1000000, "mAh", "battery capacity (ft-sitl: the model's "
       "charge fraction in these units)", INT32),
    _P("BATT_LOW_VOLT", 10.5, 0.0, 100.0, "V", "low battery voltage (0: off), held for "
       "BATT_LOW_TIMER"),
    _P("BATT_LOW_TIMER", 10, 0, 120, "s", "time below a voltage threshold before its "
       "failsafe", INT8),
    _P("BATT_LOW_MAH", 0, 0, 1000000, "mAh", "low remaining capacity (0: off; a float, as "
       "AP_BattMonitor_Params' AP_Float)"),
    _P("BATT_CRT_VOLT", 0.0, 0.0, 100.0, "V", "critical battery voltage (0: off)"),
    _P("BATT_CRT_MAH", 0, 0, 1000000, "mAh", "critical remaining capacity (0: off; a "
       "float, as AP_BattMonitor_Params' AP_Float)"),
    _P("BATT_FS_LOW_ACT", 0, 0, 7, "", "low battery action: 0 none, 1 land, 2 RTL, "
       "3 SmartRTL or RTL, 4 SmartRTL or land, 5 terminate, 6 DO_LAND_START or RTL, 7 brake "
       "or land", INT8),
    _P("BATT_FS_CRT_ACT", 0, 0, 7, "", "critical battery action (as BATT_FS_LOW_ACT)", INT8),
    # --- ArduPilot SITL's simulated sensors (libraries/SITL/SITL.cpp), read by .copter ---
    _P("SIM_GPS_DISABLE", 0, 0, 1, "", "the simulated GPS off (ft-sitl: the GPS failure "
       "MAV_CMD_INJECT_FAILURE injects: no position estimate)", INT8),
]

#: every ArduCopter parameter this face serves, in PARAM_VALUE index order
AP_PARAMS: dict[str, ApParam] = {s.name: s for s in _SPECS}
#: FENCE_ACTION -> GF_ACTION (PX4: 1 warning, 2 hold, 3 return, 5 land)
_FENCE_ACTIONS = {0: 1, 1: 3, 2: 5, 3: 3, 4: 2, 5: 5}


def fence_px4(v: dict[str, float]) -> dict[str, float]:
    """The PX4 geofence parameters the FENCE_* values ``v`` mean: the altitude and circle
    limits when the fence is on and of those kinds (0: off), and the breach action."""
    on = bool(v["FENCE_ENABLE"])
    kinds = int(v["FENCE_TYPE"])
    return {"GF_MAX_VER_DIST": v["FENCE_ALT_MAX"] if on and kinds & 1 else 0.0,
            "GF_MAX_HOR_DIST": v["FENCE_RADIUS"] if on and kinds & 2 else 0.0,
            "GF_ACTION": _FENCE_ACTIONS[int(v["FENCE_ACTION"])]}


class ApParamSet(ParamSet):
    """One vehicle's ArduCopter parameters over its PX4-named ``px4`` ParamSet: the
    honoured ones are written through, so the controller flies what they say."""

    table = AP_PARAMS

    def __init__(self, px4: ParamSet, sysid: int):
        super().__init__()
        self.px4 = px4
        #: counts the sets (the streams re-read SRn_* when it moves)
        self.version = 0
        #: called after every FENCE_* set (the face's fence re-applies its areas)
        self.on_fence = lambda: None
        self._values["SYSID_THISMAV"] = sysid
        for name, s in AP_PARAMS.items():
            if s.px4 is not None:
                self._write_px4({s.px4: s.default * s.scale}, name, s.default)
        self._write_px4(fence_px4(self._values), "FENCE_ENABLE", self._values["FENCE_ENABLE"])

    def set(self, name: str, value: float) -> float:
        """Set one parameter, writing through to the controller: ParamError (nothing
        changed) for an unknown name, a value outside the declared range or one the
        controller's parameter refuses. An integer parameter's value is rounded first, as
        ArduPilot stores it."""
        s = self.spec(name)
        if s.is_int and isinstance(value, float) and math.isfinite(value):
            value = round(value)
        value = s.check(value)
        if s.px4 is not None:
            self._write_px4({s.px4: value * s.scale}, name, value)
        elif name.startswith("FENCE_"):
            self._write_px4(fence_px4({**self._values, name: value}), name, value)
        self._values[name] = value
        self.version += 1
        if name.startswith("FENCE_"):
            self.on_fence()
        return value

    def _write_px4(self, values: dict[str, float], name: str, value: float) -> None:
        old = {k: self.px4[k] for k in values}
        try:
            for k, v in values.items():
                self.px4.set(k, int(v) if self.px4.spec(k).is_int else float(v))
        except ParamError as exc:
            for k, v in old.items():
                self.px4.set(k, v)
            raise ParamError(f"{name}: {value:g} is outside what ft-sitl flies ({exc})") \
                from None
