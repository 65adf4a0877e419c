"""Payloads of the bus: JSON telemetry, events, status and config; binary depth and points.

Every encoder validates what it is given and every decoder validates what it reads; both
raise ``BusPayloadError`` (a ValueError) whose message names the payload, the field and
what was wrong. The schemas, with units, are in ``docs/mqtt.md``; in short:

JSON (UTF-8, compact, no NaN/Infinity, ``"v": 1`` = ``SCHEMA_VERSION``)
    telemetry  ``{"v", "t", "time_usec", "p_world_m", "v_world_m_s", "q_world_body",
               "w_body_rad_s", "motors"}``: position and velocity in world ENU (m, m/s),
               attitude quaternion (w, x, y, z) rotating body FLU into world ENU, body rates
               FLU (rad/s), motor outputs 0..1 in PX4 motor order.
    events     ``{"v", "type", "t", "time_usec", ...type-specific fields}``.
    status     ``{"v", "vehicle", "status": "online"|"offline"[, "reason"]}``.
    config     ``{["v",] "telemetry_rate_hz", "depth", "points"}`` (any non-empty subset).

``t`` is simulated time in seconds and always equals ``time_usec / 1e6`` (decoders check it).

Binary sensor frames (little-endian): a fixed ``HEADER_SIZE`` = 192 byte header (magic
``b"FTSF"``, version, kind, frame, size, time, camera pose, intrinsics, range, vehicle pose;
the byte table is in docs/mqtt.md and in ``_HEADER`` below) followed by either the depth
image as ``height x width`` uint16 millimetres, row-major, 0 = no return, or ``N x 3``
float32 points, row-major (x, y, z).
"""

from __future__ import annotations

import json
import math
import numbers
import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from ft_sitl.bus.topics import check_vehicle
from ft_sitl.rotations import matrix_from_quat, quat_from_matrix

if TYPE_CHECKING:  # the camera module pulls in trimesh; import it only when needed
    from ft_sitl.scenarios.camera import CameraConfig, DepthFrame

__all__ = [
    "CONFIG_FIELDS",
    "EVENT_TYPES",
    "FRAME_MAGIC",
    "FRAME_VERSION",
    "HEADER_SIZE",
    "SCHEMA_VERSION",
    "BusPayloadError",
    "Event",
    "SensorFrame",
    "Status",
    "Telemetry",
    "decode_config",
    "decode_event",
    "decode_frame",
    "decode_status",
    "decode_telemetry",
    "encode_config",
    "encode_depth",
    "encode_event",
    "encode_points",
    "encode_status",
    "encode_telemetry",
    "validate_config",
]

#: ``"v"`` of every JSON payload this library writes and the only one it reads.
SCHEMA_VERSION = 1
#: Largest JSON payload a decoder accepts (bytes).
MAX_JSON_BYTES = 64 * 1024
#: Largest time_usec (the binary header stores it as uint64; JSON keeps it to int64).
MAX_TIME_USEC = 2**63 - 1
#: Largest number of motors in telemetry.
MAX_MOTORS = 16
#: Largest allowed difference between ``t`` and ``time_usec / 1e6`` (s).
_T_TOL_S = 1e-6
#: Tolerance on a quaternion's norm in JSON telemetry (values are rounded to 1e-9).
_Q_NORM_TOL_JSON = 1e-3
#: Tolerance on a quaternion's norm in a binary header (float64, normalised on encode).
_Q_NORM_TOL_BIN = 1e-6
#: Decimal places kept in JSON telemetry: 1 um, 1 um/s, 1e-9, 1 urad/s, 1e-4.
_DECIMALS = {"p_world_m": 6, "v_world_m_s": 6, "q_world_body": 9, "w_body_rad_s": 6,
             "motors": 4}


class BusPayloadError(ValueError):
    """A payload (or the values to encode into one) is malformed; the message says how."""


# --- JSON helpers ---------------------------------------------------------------------------
def _reject_constant(name: str):
    raise BusPayloadError(f"JSON constant {name} is not allowed (numbers must be finite)")


def _loads(payload, what: str) -> dict:
    """Parse a JSON object payload (bytes or str) and check its ``"v"`` field."""
    if isinstance(payload, bytes | bytearray | memoryview):
        raw = bytes(payload)
        if len(raw) > MAX_JSON_BYTES:
            raise BusPayloadError(f"{what}: payload is {len(raw)} bytes, more than the "
                                  f"{MAX_JSON_BYTES} allowed for JSON")
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise BusPayloadError(f"{what}: payload is not UTF-8 ({exc.reason} at byte "
                                  f"{exc.start})") from None
    elif isinstance(payload, str):
        text = payload
        if len(text) > MAX_JSON_BYTES:
            raise BusPayloadError(f"{what}: payload is {len(text)} characters, more than the "
                                  f"{MAX_JSON_BYTES} allowed for JSON")
    else:
        raise BusPayloadError(f"{what}: payload must be bytes or str, got "
                              f"{type(payload).__name__}")
    try:
        obj = json.loads(text, parse_constant=_reject_constant)
    except BusPayloadError as exc:
        raise BusPayloadError(f"{what}: {exc}") from None
    except ValueError as exc:  # json.JSONDecodeError
        raise BusPayloadError(f"{what}: payload is not valid JSON ({exc})") from None
    if not isinstance(obj, dict):
        raise BusPayloadError(f"{what}: payload must be a JSON object, got a JSON "
                              f"{_json_type(obj)}")
    return obj


def _dumps(obj: dict) -> bytes:
    return json.dumps(obj, separators=(",", ":"), allow_nan=False).encode("utf-8")


def _json_type(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "boolean"
    if isinstance(value, int | float):
        return "number"
    if isinstance(value, str):
        return "string"
    if isinstance(value, list):
        return "array"
    if isinstance(value, dict):
        return "object"
    return type(value).__name__


def _check_schema_version(obj: dict, what: str, required: bool = True) -> None:
    if "v" not in obj:
        if required:
            raise BusPayloadError(f"{what}: missing schema version field \"v\" (expected "
                                  f"{SCHEMA_VERSION})")
        return
    v = obj["v"]
    if isinstance(v, bool) or not isinstance(v, int):
        raise BusPayloadError(f"{what}: \"v\" must be an integer, got {_json_type(v)} {v!r}")
    if v != SCHEMA_VERSION:
        raise BusPayloadError(f"{what}: unsupported schema version v={v} (this library reads "
                              f"v={SCHEMA_VERSION})")


def _check_keys(obj: dict, what: str, allowed, required) -> None:
    missing = [k for k in required if k not in obj]
    if missing:
        raise BusPayloadError(f"{what}: missing field(s) {', '.join(map(repr, missing))}")
    unknown = sorted(set(obj) - set(allowed))
    if unknown:
        raise BusPayloadError(f"{what}: unknown field(s) {', '.join(map(repr, unknown))} "
                              f"(allowed: {', '.join(allowed)})")


def _finite(value, what: str, name: str) -> float:
    """A finite real number (int or float, not bool; numpy scalars accepted)."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise BusPayloadError(f"{what}: {name} must be a number, got {_json_type(value)} "
                              f"{value!r}")
    f = float(value)
    if not math.isfinite(f):
        raise BusPayloadError(f"{what}: {name} must be finite, got {value!r}")
    return f


def _time_usec(value, what: str) -> int:
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Integral):
        raise BusPayloadError(f"{what}: time_usec must be an integer (microseconds), got "
                              f"{_json_type(value)} {value!r}")
    t = int(value)
    if not 0 <= t <= MAX_TIME_USEC:
        raise BusPayloadError(f"{what}: time_usec must be in [0, 2**63 - 1], got {t}")
    return t


def _check_t(obj: dict, time_usec: int, what: str) -> None:
    t = _finite(obj["t"], what, "t")
    if abs(t - time_usec * 1e-6) > _T_TOL_S:
        raise BusPayloadError(f"{what}: t = {t} s disagrees with time_usec = {time_usec} "
                              f"(t must be time_usec / 1e6 to within 1 us)")


def _vector(value, n: int | None, what: str, name: str) -> tuple[float, ...]:
    """A sequence of finite numbers, of length n (or 1..MAX_MOTORS when n is None)."""
    if isinstance(value, np.ndarray):
        if value.ndim != 1:
            raise BusPayloadError(f"{what}: {name} must be one-dimensional, got shape "
                                  f"{value.shape}")
        value = value.tolist()
    if not isinstance(value, list | tuple):
        raise BusPayloadError(f"{what}: {name} must be an array of numbers, got "
                              f"{_json_type(value)} {value!r}")
    if n is not None and len(value) != n:
        raise BusPayloadError(f"{what}: {name} must have {n} elements, got {len(value)}")
    return tuple(_finite(x, what, f"{name}[{i}]") for i, x in enumerate(value))


def _round(values: tuple[float, ...], decimals: int) -> list[float]:
    return [round(x, decimals) + 0.0 for x in values]  # + 0.0 turns -0.0 into 0.0


# --- telemetry ------------------------------------------------------------------------------
_TELEMETRY_FIELDS = ("v", "t", "time_usec", "p_world_m", "v_world_m_s", "q_world_body",
                     "w_body_rad_s", "motors")


@dataclass(frozen=True)
class Telemetry:
    """One telemetry sample, validated on construction (BusPayloadError naming the field).

    ``p_world_m`` position and ``v_world_m_s`` velocity in world ENU; ``q_world_body`` the
    attitude quaternion (w, x, y, z) rotating body FLU vectors into world ENU (unit norm
    within 1e-3); ``w_body_rad_s`` body rates (FLU); ``motors`` 1 to 16 motor outputs in
    [0, 1], PX4 motor order. Sequences are stored as tuples of floats.
    """

    time_usec: int
    p_world_m: tuple[float, float, float]
    v_world_m_s: tuple[float, float, float]
    q_world_body: tuple[float, float, float, float]
    w_body_rad_s: tuple[float, float, float]
    motors: tuple[float, ...]

    def __post_init__(self):
        what = "telemetry"
        set_ = object.__setattr__
        set_(self, "time_usec", _time_usec(self.time_usec, what))
        set_(self, "p_world_m", _vector(self.p_world_m, 3, what, "p_world_m"))
        set_(self, "v_world_m_s", _vector(self.v_world_m_s, 3, what, "v_world_m_s"))
        q = _vector(self.q_world_body, 4, what, "q_world_body")
        norm = math.sqrt(sum(c * c for c in q))
        if abs(norm - 1.0) > _Q_NORM_TOL_JSON:
            raise BusPayloadError(f"{what}: q_world_body must be a unit quaternion (w, x, y, "
                                  f"z) with norm 1 +- {_Q_NORM_TOL_JSON}, got norm {norm:.6g}")
        set_(self, "q_world_body", q)
        set_(self, "w_body_rad_s", _vector(self.w_body_rad_s, 3, what, "w_body_rad_s"))
        motors = _vector(self.motors, None, what, "motors")
        if not 1 <= len(motors) <= MAX_MOTORS:
            raise BusPayloadError(f"{what}: motors must have 1 to {MAX_MOTORS} elements, got "
                                  f"{len(motors)}")
        for i, m in enumerate(motors):
            if not 0.0 <= m <= 1.0:
                raise BusPayloadError(f"{what}: motors[{i}] must be in [0, 1], got {m!r}")
        set_(self, "motors", motors)

    @property
    def t(self) -> float:
        """Simulated time in seconds."""
        return self.time_usec * 1e-6


def encode_telemetry(sample: Telemetry) -> bytes:
    """Compact JSON of a Telemetry sample (values rounded: 1 um, 1 um/s, 1e-9, 1e-4)."""
    if not isinstance(sample, Telemetry):
        raise BusPayloadError(f"telemetry: expected a Telemetry, got {type(sample).__name__}")
    obj: dict[str, Any] = {"v": SCHEMA_VERSION, "t": sample.t, "time_usec": sample.time_usec}
    for name, decimals in _DECIMALS.items():
        obj[name] = _round(getattr(sample, name), decimals)
    return _dumps(obj)


def decode_telemetry(payload) -> Telemetry:
    """Telemetry from a JSON payload; BusPayloadError naming what was wrong."""
    what = "telemetry"
    obj = _loads(payload, what)
    _check_schema_version(obj, what)
    _check_keys(obj, what, _TELEMETRY_FIELDS, _TELEMETRY_FIELDS)
    time_usec = _time_usec(obj["time_usec"], what)
    _check_t(obj, time_usec, what)
    for name in _DECIMALS:  # JSON arrays only (the constructor also takes tuples/ndarrays)
        if not isinstance(obj[name], list):
            raise BusPayloadError(f"{what}: {name} must be an array of numbers, got "
                                  f"{_json_type(obj[name])} {obj[name]!r}")
    return Telemetry(time_usec=time_usec, p_world_m=obj["p_world_m"],
                     v_world_m_s=obj["v_world_m_s"], q_world_body=obj["q_world_body"],
                     w_body_rad_s=obj["w_body_rad_s"], motors=obj["motors"])


# --- events ---------------------------------------------------------------------------------
_NAME_RE = re.compile(r"[a-z][a-z0-9_]{0,63}")
_EVENT_RESERVED = ("v", "type", "t", "time_usec")
#: Longest string value in an event.
MAX_EVENT_STRING = 1024
#: Most fields (besides v, type, t, time_usec) in one event.
MAX_EVENT_FIELDS = 32


def _nonempty_str(value, what, name):
    if not isinstance(value, str) or not value:
        raise BusPayloadError(f"{what}: {name} must be a non-empty string, got "
                              f"{_json_type(value)} {value!r}")


def _nonneg_number(value, what, name):
    if _finite(value, what, name) < 0.0:
        raise BusPayloadError(f"{what}: {name} must be >= 0, got {value!r}")


#: Known event types and their required fields (name -> check). Other types are allowed
#: (names matching ``[a-z][a-z0-9_]*``) and carry whatever fields they like; every field
#: value must be a string, a finite number, a boolean, null, or an array of finite numbers.
EVENT_TYPES: dict[str, dict[str, Any]] = {
    "armed": {},
    "disarmed": {},
    "mode": {"mode": _nonempty_str},                 # PX4 mode name, e.g. "OFFBOARD"
    "collision": {"object": _nonempty_str,           # obstacle piece name
                  "speed_m_s": _nonneg_number},      # impact speed, m/s
    "trial_start": {},
    "trial_end": {"outcome": _nonempty_str},         # e.g. "success", "collision", "timeout"
}


def _event_value(value, what: str, name: str):
    """An event field value, normalised to a JSON type."""
    if value is None or isinstance(value, bool):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    if isinstance(value, str):
        if len(value) > MAX_EVENT_STRING:
            raise BusPayloadError(f"{what}: field {name!r} is a string of {len(value)} "
                                  f"characters, more than {MAX_EVENT_STRING}")
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        return _finite(value, what, f"field {name!r}")
    if isinstance(value, list | tuple | np.ndarray):
        vec = _vector(list(np.asarray(value).ravel()) if isinstance(value, np.ndarray)
                      else value, None, what, f"field {name!r}")
        if len(vec) > 64:
            raise BusPayloadError(f"{what}: field {name!r} has {len(vec)} elements, more "
                                  "than 64")
        return list(vec)
    raise BusPayloadError(f"{what}: field {name!r} must be a string, number, boolean, null "
                          f"or array of numbers, got {_json_type(value)}")


@dataclass(frozen=True)
class Event:
    """A discrete event at simulated time ``time_usec``: ``type`` plus its ``fields``.

    Validated on construction: ``type`` matches ``[a-z][a-z0-9_]*`` (at most 64
    characters); known types (``EVENT_TYPES``) must carry their required fields, e.g.
    ``Event("collision", 12_000_000, {"object": "tree_3", "speed_m_s": 2.1})``.
    """

    type: str
    time_usec: int
    fields: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        what = f"event {self.type!r}"
        if not isinstance(self.type, str) or not _NAME_RE.fullmatch(self.type):
            raise BusPayloadError(f"event: type must match [a-z][a-z0-9_]* (at most 64 "
                                  f"characters), got {self.type!r}")
        object.__setattr__(self, "time_usec", _time_usec(self.time_usec, what))
        if not isinstance(self.fields, Mapping):
            raise BusPayloadError(f"{what}: fields must be a mapping, got "
                                  f"{type(self.fields).__name__}")
        if len(self.fields) > MAX_EVENT_FIELDS:
            raise BusPayloadError(f"{what}: {len(self.fields)} fields, more than "
                                  f"{MAX_EVENT_FIELDS}")
        clean = {}
        for name, value in self.fields.items():
            if not isinstance(name, str) or not _NAME_RE.fullmatch(name):
                raise BusPayloadError(f"{what}: field name {name!r} must match "
                                      "[a-z][a-z0-9_]*")
            if name in _EVENT_RESERVED:
                raise BusPayloadError(f"{what}: field name {name!r} is reserved "
                                      f"({', '.join(_EVENT_RESERVED)})")
            clean[name] = _event_value(value, what, name)
        for name, check in EVENT_TYPES.get(self.type, {}).items():
            if name not in clean:
                raise BusPayloadError(f"{what}: missing required field {name!r}")
            check(clean[name], what, name)
        object.__setattr__(self, "fields", clean)

    @property
    def t(self) -> float:
        """Simulated time in seconds."""
        return self.time_usec * 1e-6


def encode_event(event: Event) -> bytes:
    """Compact JSON of an Event."""
    if not isinstance(event, Event):
        raise BusPayloadError(f"event: expected an Event, got {type(event).__name__}")
    obj = {"v": SCHEMA_VERSION, "type": event.type, "t": event.t, "time_usec": event.time_usec}
    obj.update(event.fields)
    return _dumps(obj)


def decode_event(payload) -> Event:
    """An Event from a JSON payload; BusPayloadError naming what was wrong."""
    what = "event"
    obj = _loads(payload, what)
    _check_schema_version(obj, what)
    missing = [k for k in ("type", "t", "time_usec") if k not in obj]
    if missing:
        raise BusPayloadError(f"{what}: missing field(s) {', '.join(map(repr, missing))}")
    time_usec = _time_usec(obj["time_usec"], what)
    _check_t(obj, time_usec, what)
    for name, value in obj.items():
        if isinstance(value, dict):
            raise BusPayloadError(f"{what}: field {name!r} must not be a JSON object")
    fields = {k: v for k, v in obj.items() if k not in _EVENT_RESERVED}
    return Event(type=obj["type"], time_usec=time_usec, fields=fields)


# --- status ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class Status:
    """A vehicle's bus status (retained on its status topic).

    ``online`` True while the simulator's publisher is connected. When it goes away the
    status becomes offline with ``reason`` "closed" (clean shutdown) or "connection lost"
    (the broker published the publisher's last will).
    """

    vehicle: str
    online: bool
    reason: str | None = None

    def __post_init__(self):
        try:
            check_vehicle(self.vehicle)
        except ValueError as exc:
            raise BusPayloadError(f"status: {exc}") from None
        if not isinstance(self.online, bool):
            raise BusPayloadError(f"status: online must be a boolean, got {self.online!r}")
        if self.reason is not None and (not isinstance(self.reason, str) or not self.reason
                                        or len(self.reason) > 200):
            raise BusPayloadError(f"status: reason must be a non-empty string of at most 200 "
                                  f"characters or absent, got {self.reason!r}")


def encode_status(status: Status) -> bytes:
    obj: dict[str, Any] = {"v": SCHEMA_VERSION, "vehicle": status.vehicle,
                           "status": "online" if status.online else "offline"}
    if status.reason is not None:
        obj["reason"] = status.reason
    return _dumps(obj)


def decode_status(payload) -> Status:
    what = "status"
    obj = _loads(payload, what)
    _check_schema_version(obj, what)
    _check_keys(obj, what, ("v", "vehicle", "status", "reason"), ("v", "vehicle", "status"))
    state = obj["status"]
    if state not in ("online", "offline"):
        raise BusPayloadError(f"{what}: status must be \"online\" or \"offline\", got "
                              f"{state!r}")
    return Status(vehicle=obj["vehicle"], online=state == "online", reason=obj.get("reason"))


# --- config ---------------------------------------------------------------------------------
#: Settings a client may request on the config topic: name -> (kind, low, high, meaning).
CONFIG_FIELDS: dict[str, tuple[str, float | None, float | None, str]] = {
    "telemetry_rate_hz": ("number", 0.0, 1000.0,
                          "telemetry rate in simulated Hz; 0 stops telemetry"),
    "depth": ("bool", None, None, "publish depth frames"),
    "points": ("bool", None, None, "publish point clouds"),
}


def validate_config(config: Mapping[str, Any], what: str = "config") -> dict[str, Any]:
    """A checked copy of a config request (without ``"v"``); BusPayloadError naming the
    setting and its allowed values. At least one setting is required; unknown ones are
    rejected; ``"v"``, if present, must be 1."""
    if not isinstance(config, Mapping):
        raise BusPayloadError(f"{what}: must be a JSON object / mapping, got "
                              f"{_json_type(config)}")
    _check_schema_version(dict(config), what, required=False)
    unknown = sorted(k for k in config if k != "v" and k not in CONFIG_FIELDS)
    if unknown:
        raise BusPayloadError(f"{what}: unknown setting(s) {', '.join(map(repr, unknown))} "
                              f"(known: {', '.join(CONFIG_FIELDS)})")
    out: dict[str, Any] = {}
    for name, (kind, lo, hi, _meaning) in CONFIG_FIELDS.items():
        if name not in config:
            continue
        value = config[name]
        if kind == "bool":
            if not isinstance(value, bool | np.bool_):
                raise BusPayloadError(f"{what}: {name} must be true or false, got "
                                      f"{_json_type(value)} {value!r}")
            out[name] = bool(value)
        else:
            f = _finite(value, what, name)
            if not lo <= f <= hi:
                raise BusPayloadError(f"{what}: {name} must be in [{lo:g}, {hi:g}], got "
                                      f"{value!r}")
            out[name] = f
    if not out:
        raise BusPayloadError(f"{what}: names no setting (known: {', '.join(CONFIG_FIELDS)})")
    return out


def encode_config(config: Mapping[str, Any]) -> bytes:
    """Compact JSON of a validated config request (with ``"v": 1``)."""
    return _dumps({"v": SCHEMA_VERSION, **validate_config(config)})


def decode_config(payload) -> dict[str, Any]:
    """The validated settings of a config payload (``"v"`` optional, dropped)."""
    return validate_config(_loads(payload, "config"))


# --- binary sensor frames -------------------------------------------------------------------
#: First four bytes of every binary frame.
FRAME_MAGIC = b"FTSF"
#: Layout version of the binary frames.
FRAME_VERSION = 1
#: kind byte
KIND_DEPTH, KIND_POINTS = 1, 2
_KIND_NAMES = {KIND_DEPTH: "depth", KIND_POINTS: "points"}
#: frame byte: the depth image is in the camera's optical frame; points are in world ENU or
#: body FLU coordinates
FRAME_OPTICAL, FRAME_WORLD, FRAME_BODY = 0, 1, 2
_FRAME_NAMES = {FRAME_OPTICAL: "optical", FRAME_WORLD: "world", FRAME_BODY: "body"}
#: Largest image side and largest depth range the uint16 millimetre encoding can carry.
MAX_SIDE = 16384
MAX_DEPTH_RANGE_M = 65.535

# offset  size  field
#   0      4    magic b"FTSF"
#   4      1    version (uint8) = 1
#   5      1    kind (uint8): 1 depth, 2 points
#   6      1    frame (uint8): 0 optical (depth), 1 world ENU, 2 body FLU (points)
#   7      1    reserved (uint8) = 0
#   8      4    width (uint32): image width; points: N
#  12      4    height (uint32): image height; points: 1
#  16      8    time_usec (uint64): simulated time, microseconds
#  24      8    t (float64): simulated time, seconds = time_usec / 1e6
#  32     24    p_world_camera (3 x float64): camera centre, world ENU, m
#  56     32    q_world_optical (4 x float64, w x y z): optical frame -> world ENU
#  88     32    fx, fy, cx, cy (4 x float64): intrinsics, pixels
# 120     16    min_range_m, max_range_m (2 x float64)
# 136     24    p_world_body (3 x float64): vehicle position, world ENU, m
# 160     32    q_world_body (4 x float64, w x y z): body FLU -> world ENU
# 192           payload: depth (height x width uint16 mm, 0 = no return) or N x 3 float32
_HEADER = struct.Struct("<4sBBBBIIQd3d4d4d2d3d4d")
#: Size of the fixed header (bytes).
HEADER_SIZE = _HEADER.size  # 192


@dataclass(frozen=True)
class SensorFrame:
    """A decoded binary frame: the header's fields plus ``depth_mm`` or ``points``.

    ``kind`` "depth": ``depth_mm`` (height, width) uint16 z-depth in millimetres, 0 = no
    return; ``depth_m`` gives metres with NaN for no return; ``to_depth_frame()`` rebuilds
    a ``scenarios.camera.DepthFrame`` (point clouds recomputed from depth and intrinsics).
    ``kind`` "points": ``points`` (N, 3) float32 in ``frame`` ("world" ENU or "body" FLU),
    metres. Poses: ``p_world_camera`` / ``q_world_optical`` (optical x right, y down, z
    forward -> world ENU) and ``p_world_body`` / ``q_world_body``; quaternions (w, x, y, z).
    """

    kind: str
    frame: str
    time_usec: int
    width: int
    height: int
    p_world_camera: np.ndarray
    q_world_optical: np.ndarray
    fx: float
    fy: float
    cx: float
    cy: float
    min_range_m: float
    max_range_m: float
    p_world_body: np.ndarray
    q_world_body: np.ndarray
    depth_mm: np.ndarray | None = field(default=None, repr=False)
    points: np.ndarray | None = field(default=None, repr=False)

    @property
    def t(self) -> float:
        """Simulated time in seconds."""
        return self.time_usec * 1e-6

    @property
    def depth_m(self) -> np.ndarray:
        """(height, width) float32 z-depth in metres, NaN where there was no return."""
        if self.depth_mm is None:
            raise ValueError(f"a {self.kind} frame has no depth image")
        out = self.depth_mm.astype(np.float32) / np.float32(1000.0)
        out[self.depth_mm == 0] = np.nan
        return out

    @property
    def r_world_optical(self) -> np.ndarray:
        """Rotation matrix taking optical-frame vectors to world ENU."""
        return matrix_from_quat(self.q_world_optical)

    def to_depth_frame(self) -> DepthFrame:
        """A ``DepthFrame`` as the camera would have produced it (depth to 0.5 mm)."""
        from ft_sitl.scenarios.camera import DepthFrame

        if self.kind != "depth":
            raise ValueError(f"to_depth_frame needs a depth frame, this is a {self.kind} frame")
        h, w = self.height, self.width
        mm = self.depth_mm.reshape(-1)
        idx = np.flatnonzero(mm)
        rows, cols = np.divmod(idx, w)
        z = mm[idx].astype(np.float64) * 1e-3
        p_opt = np.stack([(cols - self.cx) / self.fx * z, (rows - self.cy) / self.fy * z, z],
                         axis=1)
        r_wo = self.r_world_optical
        r_wb = matrix_from_quat(self.q_world_body)
        # einsum, not @: a multi-threaded BLAS is slow for (N, 3) x (3, 3) on a busy machine
        points_world = np.einsum("ij,kj->ik", p_opt, r_wo) + self.p_world_camera
        points_body = np.einsum("ij,jk->ik", points_world - self.p_world_body, r_wb)
        return DepthFrame(
            t_us=self.time_usec,
            depth=self.depth_m.reshape(h, w),
            points_body=points_body,
            points_world=points_world,
            pixels=np.stack([rows, cols], axis=1).astype(np.int32),
            p_world_body=self.p_world_body.copy(),
            q_world_body=self.q_world_body.copy(),
            p_world_camera=self.p_world_camera.copy(),
            r_world_optical=r_wo,
        )


def _pose3(value, what: str, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=np.float64)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise BusPayloadError(f"{what}: {name} must be 3 finite numbers, got {value!r}")
    return a


def _unit_quat(value, what: str, name: str) -> np.ndarray:
    q = np.asarray(value, dtype=np.float64)
    if q.shape != (4,) or not np.all(np.isfinite(q)):
        raise BusPayloadError(f"{what}: {name} must be 4 finite numbers (w, x, y, z), got "
                              f"{value!r}")
    n = float(np.linalg.norm(q))
    if not n > 0.0:
        raise BusPayloadError(f"{what}: {name} is the zero quaternion")
    return q / n


def _frame_header(frame: DepthFrame, config: CameraConfig, kind: int, frame_code: int,
                  width: int, height: int, what: str) -> bytes:
    for name in ("width", "height", "fx", "fy", "cx", "cy", "min_range_m", "max_range_m"):
        if not hasattr(config, name):
            raise BusPayloadError(f"{what}: config must be a CameraConfig (missing {name})")
    t_us = _time_usec(frame.t_us, what)
    p_wc = _pose3(frame.p_world_camera, what, "p_world_camera")
    r_wo = np.asarray(frame.r_world_optical, dtype=np.float64)
    if r_wo.shape != (3, 3) or not np.all(np.isfinite(r_wo)):
        raise BusPayloadError(f"{what}: r_world_optical must be a finite 3 x 3 matrix")
    if not np.allclose(r_wo @ r_wo.T, np.eye(3), atol=1e-6) or np.linalg.det(r_wo) <= 0:
        raise BusPayloadError(f"{what}: r_world_optical is not a rotation matrix")
    q_wo = quat_from_matrix(r_wo)
    p_wb = _pose3(frame.p_world_body, what, "p_world_body")
    q_wb = _unit_quat(frame.q_world_body, what, "q_world_body")
    intr = [_finite(getattr(config, n), what, n) for n in ("fx", "fy", "cx", "cy",
                                                            "min_range_m", "max_range_m")]
    return _HEADER.pack(FRAME_MAGIC, FRAME_VERSION, kind, frame_code, 0, width, height, t_us,
                        t_us * 1e-6, *p_wc, *q_wo, *intr, *p_wb, *q_wb)


def encode_depth(frame: DepthFrame, config: CameraConfig) -> bytes:
    """Binary depth frame of a camera ``DepthFrame`` taken with ``config``.

    Depth is rounded to whole millimetres (a valid depth below 1 mm becomes 1 mm so that 0
    keeps meaning "no return"); NaN / inf pixels become 0. ``config.max_range_m`` must not
    exceed 65.535 m, the uint16 limit.
    """
    what = "depth frame"
    depth = np.asarray(frame.depth)
    h, w = int(config.height), int(config.width)
    if depth.shape != (h, w):
        raise BusPayloadError(f"{what}: depth image has shape {depth.shape}, the camera "
                              f"config says (height, width) = {(h, w)}")
    if float(config.max_range_m) > MAX_DEPTH_RANGE_M:
        raise BusPayloadError(f"{what}: max_range_m = {config.max_range_m} m exceeds "
                              f"{MAX_DEPTH_RANGE_M} m, the largest uint16 millimetre depth")
    header = _frame_header(frame, config, KIND_DEPTH, FRAME_OPTICAL, w, h, what)
    valid = np.isfinite(depth)
    mm_f = np.rint(depth[valid].astype(np.float64) * 1000.0)
    if mm_f.size:
        if mm_f.min() < 0.0:
            raise BusPayloadError(f"{what}: depth has negative values (min "
                                  f"{float(depth[valid].min())} m)")
        if mm_f.max() > 65535.0:
            raise BusPayloadError(f"{what}: depth {float(depth[valid].max())} m exceeds "
                                  f"{MAX_DEPTH_RANGE_M} m")
    mm = np.zeros((h, w), dtype="<u2")
    mm[valid] = np.maximum(mm_f, 1.0)
    return header + mm.tobytes()


def encode_points(frame: DepthFrame, config: CameraConfig, frame_id: str = "world") -> bytes:
    """Binary point cloud of a ``DepthFrame``: ``points_world`` (``frame_id`` "world", ENU)
    or ``points_body`` ("body", FLU), as N x 3 float32."""
    what = "point cloud"
    if frame_id == "world":
        pts, code = frame.points_world, FRAME_WORLD
    elif frame_id == "body":
        pts, code = frame.points_body, FRAME_BODY
    else:
        raise BusPayloadError(f"{what}: frame_id must be 'world' or 'body', got {frame_id!r}")
    pts = np.asarray(pts)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise BusPayloadError(f"{what}: points must have shape (N, 3), got {pts.shape}")
    pts32 = np.ascontiguousarray(pts, dtype="<f4")
    if not np.all(np.isfinite(pts32)):
        raise BusPayloadError(f"{what}: points contain non-finite values (or values beyond "
                              "float32)")
    n = len(pts32)
    if n > MAX_SIDE * MAX_SIDE:
        raise BusPayloadError(f"{what}: {n} points, more than {MAX_SIDE * MAX_SIDE}")
    header = _frame_header(frame, config, KIND_POINTS, code, n, 1, what)
    return header + pts32.tobytes()


def decode_frame(payload, expect_kind: str | None = None) -> SensorFrame:
    """A SensorFrame from a binary depth or points payload; BusPayloadError naming what was
    wrong (magic, version, kind, truncation, size, non-finite or out-of-range values).
    ``expect_kind`` ("depth" / "points") also rejects the other kind."""
    what = "sensor frame"
    if not isinstance(payload, bytes | bytearray | memoryview):
        raise BusPayloadError(f"{what}: payload must be bytes, got {type(payload).__name__}")
    buf = memoryview(payload).cast("B")
    if len(buf) < HEADER_SIZE:
        raise BusPayloadError(f"{what}: truncated: {len(buf)} bytes, the header alone is "
                              f"{HEADER_SIZE}")
    (magic, version, kind, frame_code, reserved, width, height, time_usec, t,
     *rest) = _HEADER.unpack_from(buf, 0)
    if magic != FRAME_MAGIC:
        raise BusPayloadError(f"{what}: wrong magic {bytes(magic)!r} (expected "
                              f"{FRAME_MAGIC!r})")
    if version != FRAME_VERSION:
        raise BusPayloadError(f"{what}: unsupported layout version {version} (this library "
                              f"reads {FRAME_VERSION})")
    if kind not in _KIND_NAMES:
        raise BusPayloadError(f"{what}: unknown kind {kind} (1 = depth, 2 = points)")
    kind_name = _KIND_NAMES[kind]
    what = f"{kind_name} frame"
    if expect_kind is not None and kind_name != expect_kind:
        raise BusPayloadError(f"{what}: expected a {expect_kind} frame on this topic")
    if reserved != 0:
        raise BusPayloadError(f"{what}: reserved byte 7 must be 0, got {reserved}")
    allowed_frames = (FRAME_OPTICAL,) if kind == KIND_DEPTH else (FRAME_WORLD, FRAME_BODY)
    if frame_code not in allowed_frames:
        raise BusPayloadError(f"{what}: frame code {frame_code} is not valid for {kind_name} "
                              f"(allowed: {', '.join(str(c) for c in allowed_frames)})")
    if time_usec > MAX_TIME_USEC:
        raise BusPayloadError(f"{what}: time_usec {time_usec} exceeds 2**63 - 1")
    if not math.isfinite(t) or abs(t - time_usec * 1e-6) > _T_TOL_S:
        raise BusPayloadError(f"{what}: t = {t} s disagrees with time_usec = {time_usec} "
                              f"(t must be time_usec / 1e6 to within 1 us)")
    p_wc, q_wo, intr, rng_, p_wb, q_wb = (rest[0:3], rest[3:7], rest[7:11], rest[11:13],
                                          rest[13:16], rest[16:20])
    for name, vals in (("p_world_camera", p_wc), ("q_world_optical", q_wo),
                       ("fx/fy/cx/cy", intr), ("min_range_m/max_range_m", rng_),
                       ("p_world_body", p_wb), ("q_world_body", q_wb)):
        if not all(math.isfinite(x) for x in vals):
            raise BusPayloadError(f"{what}: {name} contains non-finite values {vals}")
    for name, q in (("q_world_optical", q_wo), ("q_world_body", q_wb)):
        norm = math.sqrt(sum(c * c for c in q))
        if abs(norm - 1.0) > _Q_NORM_TOL_BIN:
            raise BusPayloadError(f"{what}: {name} is not a unit quaternion (norm {norm:.9g})")
    fx, fy, cx, cy = intr
    lo, hi = rng_
    if not (fx > 0.0 and fy > 0.0):
        raise BusPayloadError(f"{what}: fx and fy must be > 0 pixels, got {fx}, {fy}")
    if not (0.0 <= lo < hi):
        raise BusPayloadError(f"{what}: range must satisfy 0 <= min_range_m < max_range_m, "
                              f"got {lo}, {hi}")

    body = buf[HEADER_SIZE:]
    depth_mm = points = None
    if kind == KIND_DEPTH:
        if not (1 <= width <= MAX_SIDE and 1 <= height <= MAX_SIDE):
            raise BusPayloadError(f"{what}: width and height must be in [1, {MAX_SIDE}], got "
                                  f"{width} x {height}")
        if not (-0.5 <= cx <= width - 0.5 and -0.5 <= cy <= height - 0.5):
            raise BusPayloadError(f"{what}: principal point ({cx}, {cy}) lies outside the "
                                  f"{width} x {height} image")
        if hi > MAX_DEPTH_RANGE_M:
            raise BusPayloadError(f"{what}: max_range_m {hi} exceeds {MAX_DEPTH_RANGE_M}")
        expected = width * height * 2
        if len(body) < expected:
            raise BusPayloadError(f"{what}: truncated: {len(body)} bytes of depth after the "
                                  f"header, {width} x {height} x 2 = {expected} expected")
        if len(body) != expected:
            raise BusPayloadError(f"{what}: size mismatch: {len(body)} bytes of depth after "
                                  f"the header, {width} x {height} x 2 = {expected} expected")
        depth_mm = np.frombuffer(body, dtype="<u2").reshape(height, width).astype(np.uint16)
        nz = depth_mm[depth_mm > 0]
        if nz.size:
            top, bottom = int(nz.max()), int(nz.min())
            if top > math.floor(hi * 1000.0) + 1:
                raise BusPayloadError(f"{what}: depth value {top} mm beyond max_range_m {hi} "
                                      "m")
            if bottom < math.ceil(lo * 1000.0) - 1:
                raise BusPayloadError(f"{what}: depth value {bottom} mm below min_range_m "
                                      f"{lo} m")
    else:
        if height != 1:
            raise BusPayloadError(f"{what}: height must be 1 for a point cloud (width = N), "
                                  f"got {height}")
        expected = width * 12
        if len(body) < expected:
            raise BusPayloadError(f"{what}: truncated: {len(body)} bytes of points after the "
                                  f"header, N = {width} x 12 = {expected} expected")
        if len(body) != expected:
            raise BusPayloadError(f"{what}: size mismatch: {len(body)} bytes of points after "
                                  f"the header, N = {width} x 12 = {expected} expected")
        points = np.frombuffer(body, dtype="<f4").reshape(width, 3).astype(np.float32)
        if not np.all(np.isfinite(points)):
            raise BusPayloadError(f"{what}: points contain non-finite values")
    return SensorFrame(
        kind=kind_name, frame=_FRAME_NAMES[frame_code], time_usec=int(time_usec),
        width=int(width), height=int(height),
        p_world_camera=np.array(p_wc), q_world_optical=np.array(q_wo),
        fx=fx, fy=fy, cx=cx, cy=cy, min_range_m=lo, max_range_m=hi,
        p_world_body=np.array(p_wb), q_world_body=np.array(q_wb),
        depth_mm=depth_mm, points=points)
