"""Failure injection, PX4's way: ``SYS_FAILURE_EN`` and ``MAV_CMD_INJECT_FAILURE``.

The units and types are MAVLink's (FAILURE_UNIT, FAILURE_TYPE). What each injected
failure does here (:meth:`ft_sitl.sim.fleet.Fleet.inject_failure` applies it):

========================  ======================  =========================================
unit                      types                   effect
========================  ======================  =========================================
motor (instance 1..n)     off, stuck, wrong/slow  off: the motor stops; stuck: its speed
                                                  command freezes; wrong or slow: it gives
                                                  half its thrust (the physics' actuator
                                                  stage; the allocation keeps flying what
                                                  it can). ok: nominal again
gps                       off                     no fix (GPS_RAW_INT, the GPS health bit);
                                                  after ``COM_POS_FS_DELAY`` the commander
                                                  takes PX4's position-loss failsafe: land.
                                                  The estimate itself is not degraded
gyro, accel, mag, baro    off                     the sensor's health bit is cleared and a
                                                  warning sent; flight goes on (PX4 SITL
                                                  switches to a redundant sensor)
battery                   off                     the battery reads empty: the battery
                                                  emergency failsafe lands
mavlink signal            off                     offboard setpoints and client heartbeats
                                                  are dropped (commands still pass, so
                                                  "ok" can restore it): the offboard-loss
                                                  failsafe follows
========================  ======================  =========================================

Every other unit or type is answered UNSUPPORTED. ``ok`` clears the unit's failure.
Injection is refused (DENIED, "Failure injection disabled") unless ``SYS_FAILURE_EN``
is 1, as PX4 does.
"""

from __future__ import annotations

from ft_sitl.schema import Param, Schema

UNITS = {0: "gyro", 1: "accel", 2: "mag", 3: "baro", 4: "gps", 5: "optical_flow", 6: "vio",
         7: "distance_sensor", 8: "airspeed", 100: "battery", 101: "motor", 102: "servo",
         103: "avoidance", 104: "rc_signal", 105: "mavlink_signal"}
TYPES = {0: "ok", 1: "off", 2: "stuck", 3: "garbage", 4: "wrong", 5: "slow", 6: "delayed",
         7: "intermittent"}

#: what each unit supports here (besides "ok")
SUPPORTED = {"motor": ("off", "stuck", "wrong", "slow"), "gps": ("off",),
             "gyro": ("off",), "accel": ("off",), "mag": ("off",), "baro": ("off",),
             "battery": ("off",), "mavlink_signal": ("off",)}
#: a motor's thrust efficiency under a "wrong" or "slow" failure
DEGRADED_EFFICIENCY = 0.5


#: a scheduled injection (a trial's ``failures``, a campaign's failure axis): what and when
SCHEDULE_SCHEMA = Schema((
    Param("at_s", 0.0, "s", (0.0, 3600.0), doc="when, after the trial's first step"),
    Param("unit", "motor", choices=tuple(SUPPORTED), doc="what fails (FAILURE_UNIT)"),
    Param("type", "off", choices=("off", "stuck", "wrong", "slow", "ok"),
          doc="how it fails (FAILURE_TYPE)"),
    Param("instance", 1, "-", (0, 16), doc="which one (a motor: 1..n; 0: all / none)"),
))
UNIT_CODES = {v: k for k, v in UNITS.items()}
TYPE_CODES = {v: k for k, v in TYPES.items()}


class FailureError(ValueError):
    """An injection this simulator does not do (the message says why)."""


def check(unit: int, ftype: int, instance: int, n_motors: int) -> tuple[str, str, int]:
    """(unit name, type name, instance) of a supported injection; FailureError naming what
    is not."""
    u = UNITS.get(unit)
    t = TYPES.get(ftype)
    if u is None or t is None:
        raise FailureError(f"unknown failure unit {unit} or type {ftype}")
    if u not in SUPPORTED or (t != "ok" and t not in SUPPORTED[u]):
        raise FailureError(f"failure {t} of {u} is not simulated")
    if u == "motor" and not 0 <= instance <= n_motors:
        raise FailureError(f"motor {instance}: the vehicle has motors 1..{n_motors}")
    if u == "motor" and instance == 0 and t != "ok":
        raise FailureError("name one motor (instance 1..n) to fail")
    return u, t, instance
