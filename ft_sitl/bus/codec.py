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
    movers     ``{"v", "t", "time_usec", "movers": [{"name", "shape", "p_world_m",
               "heading_rad", "v_world_m_s", sizes ...}, ...]}``: the moving obstacles of
               the vehicle's world (scenarios.movers), centre and velocity in world ENU.
    config     ``{["v",] "telemetry_rate_hz", "depth", "points"}`` (any non-empty subset).

Each JSON payload is declared once as a ``msgspec.Struct`` (``TelemetryPayload``,
``EventHeader`` and the known events' ``*Fields``, ``StatusPayload``, ``MoversPayload``
and its ``MoverState``, ``ConfigPayload``):
field, type, range (``msgspec.Meta``) and a one-line description. Decoding is
``msgspec.json`` against that declaration, and the values given to ``Telemetry``, ``Event``
and ``validate_config`` are checked against the same declaration with ``msgspec.convert``;
what a type cannot say (``t`` against ``time_usec``, a unit quaternion, the schema
version, event field names) is checked in ``__post_init__`` or next to the conversion.
msgspec's own message (e.g. ``Expected `float` <= 1.0 - at `$.motors[1]```) follows the
payload's name in ``BusPayloadError``.

``t`` is simulated time in seconds and always equals ``time_usec / 1e6`` (decoders check it).

Binary sensor frames (little-endian): a fixed ``HEADER_SIZE`` = 192 byte header (magic
``b"FTSF"``, version, kind, frame, size, time, camera pose, intrinsics, range, vehicle pose;
the byte table is in docs/mqtt.md and in ``_HEADER`` below) followed by either the depth
image as ``height x width`` uint16 millimetres, row-major, 0 = no return, or ``N x 3``
float32 points, row-major (x, y, z).
"""

from __future__ import annotations

import enum
import math
import numbers
import re
import struct
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Annotated, Any

import msgspec
import numpy as np
from msgspec import UNSET, Meta, Struct, UnsetType

from ft_sitl.bus.topics import check_vehicle
from ft_sitl.mover_kinds import MAX_MOVERS, SIZE_FIELDS
from ft_sitl.mover_kinds import SHAPES as MOVER_SHAPES
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
    "CollisionFields",
    "ConfigPayload",
    "Event",
    "EventHeader",
    "EventType",
    "FrameKind",
    "FrameName",
    "ModeFields",
    "MoverState",
    "MoverStates",
    "MoversPayload",
    "NoFields",
    "OfflineReason",
    "SensorFrame",
    "Status",
    "StatusPayload",
    "StatusValue",
    "Telemetry",
    "TelemetryPayload",
    "TrialEndFields",
    "decode_config",
    "decode_event",
    "decode_frame",
    "decode_movers",
    "decode_status",
    "decode_telemetry",
    "encode_config",
    "encode_depth",
    "encode_event",
    "encode_movers",
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
#: Longest string value in an event.
MAX_EVENT_STRING = 1024
#: Most fields (besides v, type, t, time_usec) in one event.
MAX_EVENT_FIELDS = 32
#: Most numbers in an event field's array.
MAX_EVENT_ARRAY = 64
#: Largest allowed difference between ``t`` and ``time_usec / 1e6`` (s).
_T_TOL_S = 1e-6
#: Tolerance on a quaternion's norm in JSON telemetry (values are rounded to 1e-9).
_Q_NORM_TOL_JSON = 1e-3
#: Tolerance on a quaternion's norm in a binary header (float64, normalised on encode).
_Q_NORM_TOL_BIN = 1e-6
#: Decimal places kept in JSON telemetry: 1 um, 1 um/s, 1e-9, 1 urad/s, 1e-4.
_DECIMALS = {"p_world_m": 6, "v_world_m_s": 6, "q_world_body": 9, "w_body_rad_s": 6,
             "motors": 4, "wind_world_m_s": 6}


class BusPayloadError(ValueError):
    """A payload (or the values to encode into one) is malformed; the message says how."""


# --- enumerations ---------------------------------------------------------------------------
class EventType(enum.StrEnum):
    """The event types this library knows (``EVENT_TYPES`` gives their required fields).
    Other types matching ``[a-z][a-z0-9_]*`` are allowed and stay plain strings."""

    ARMED = "armed"
    DISARMED = "disarmed"
    MODE = "mode"
    COLLISION = "collision"
    MOVER_COLLISION = "mover_collision"
    TRIAL_START = "trial_start"
    TRIAL_END = "trial_end"
    GEOFENCE = "geofence"


class StatusValue(enum.StrEnum):
    """``"status"`` of a status payload."""

    ONLINE = "online"
    OFFLINE = "offline"


class OfflineReason(enum.StrEnum):
    """The reasons the publisher gives when a vehicle goes offline (the payload's
    ``"reason"`` is any non-empty string; these are the ones this library writes)."""

    CLOSED = "closed"
    CONNECTION_LOST = "connection lost"


class FrameKind(enum.StrEnum):
    """``SensorFrame.kind``: what a binary frame carries."""

    DEPTH = "depth"
    POINTS = "points"


class FrameName(enum.StrEnum):
    """``SensorFrame.frame``: the coordinate frame of a binary frame's data."""

    OPTICAL = "optical"
    WORLD = "world"
    BODY = "body"


# --- JSON field types -----------------------------------------------------------------------
SchemaVersion = Annotated[int, Meta(description="schema version, must be SCHEMA_VERSION")]
Seconds = Annotated[float, Meta(description="simulated time, s; equals time_usec / 1e6")]
TimeUsec = Annotated[int, Meta(ge=0, le=MAX_TIME_USEC, description="simulated time, µs")]
Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
MotorOutput = Annotated[float, Meta(ge=0.0, le=1.0, description="motor output, 0..1")]
NonEmptyStr = Annotated[str, Meta(min_length=1)]
EventName = Annotated[str, Meta(pattern=r"^[a-z][a-z0-9_]{0,63}$",
                                description="[a-z][a-z0-9_]*, at most 64 characters")]
#: The value of an event's own field.
EventValue = (Annotated[str, Meta(max_length=MAX_EVENT_STRING)] | int | float | bool | None
              | Annotated[list[float], Meta(max_length=MAX_EVENT_ARRAY)])

_EVENT_FIELDS = dict[str, EventValue]
_NAME_RE = re.compile(r"[a-z][a-z0-9_]{0,63}")


def _check_version(v: int, what: str) -> None:
    if v != SCHEMA_VERSION:
        raise ValueError(f"{what}: unsupported schema version v={v} (this library reads "
                         f"v={SCHEMA_VERSION})")


def _check_t(t: float, time_usec: int, what: str) -> None:
    if abs(t - time_usec * 1e-6) > _T_TOL_S:
        raise ValueError(f"{what}: t = {t} s disagrees with time_usec = {time_usec} "
                         "(t must be time_usec / 1e6 to within 1 us)")


_PATH_RE = re.compile(r" - at `\$((?:\.\w+|\[\d+\])*)`$")
_STEP_RE = re.compile(r"\.(\w+)|\[(\d+)\]")


def _error(what: str, exc: Exception, value=None) -> BusPayloadError:
    """A BusPayloadError from msgspec's (or a __post_init__'s) error, prefixed with what.
    ``value``, the input as Python objects, lets it add the offending value msgspec's
    message leaves out (``Expected `float` <= 1.0 - at `$.motors[1]`, got 2.0``)."""
    msg = str(exc)
    m = _PATH_RE.search(msg)
    if m and value is not None and ", got" not in msg and not msg.startswith("Invalid"):
        try:
            for key, index in _STEP_RE.findall(m.group(1)):
                value = value[key] if key else value[int(index)]
            shown = repr(value)
            msg += f", got {shown if len(shown) <= 80 else shown[:76] + ' ...'}"
        except (KeyError, IndexError, TypeError):
            pass
    return BusPayloadError(msg if msg.startswith(f"{what}: ") else f"{what}: {msg}")


def _malformed(payload, what: str, exc: Exception) -> BusPayloadError:
    """Say why a payload msgspec could not parse is not JSON (the error path only)."""
    if not isinstance(payload, str):
        try:
            payload = bytes(payload).decode("utf-8")
        except UnicodeDecodeError as err:
            return BusPayloadError(f"{what}: payload is not UTF-8 ({err.reason} at byte "
                                   f"{err.start})")
    for constant in ("NaN", "Infinity", "-Infinity"):
        if re.search(rf"[\[:,]\s*{constant}\s*[\],}}]", payload):
            return BusPayloadError(f"{what}: JSON constant {constant} is not allowed (numbers "
                                   f"must be finite)")
    return BusPayloadError(f"{what}: payload is not valid JSON ({exc})")


def _check_payload(payload, what: str) -> None:
    """Reject what is not bytes/str or is larger than MAX_JSON_BYTES before parsing it."""
    if isinstance(payload, bytes | bytearray | memoryview | str):
        n = memoryview(payload).nbytes if not isinstance(payload, str) else len(payload)
        if n > MAX_JSON_BYTES:
            unit = "characters" if isinstance(payload, str) else "bytes"
            raise BusPayloadError(f"{what}: payload is {n} {unit}, more than the "
                                  f"{MAX_JSON_BYTES} allowed for JSON")
        return
    raise BusPayloadError(f"{what}: payload must be bytes or str, got "
                          f"{type(payload).__name__}")


def _decode(decoder: msgspec.json.Decoder, payload, what: str):
    _check_payload(payload, what)
    try:
        return decoder.decode(payload)
    except msgspec.ValidationError as exc:
        try:
            obj = msgspec.json.decode(payload)
        except (msgspec.MsgspecError, RecursionError, UnicodeDecodeError):  # no value to show
            obj = None
        raise _error(what, exc, obj) from None
    except (msgspec.DecodeError, UnicodeDecodeError) as exc:  # msgspec raises the latter for
        raise _malformed(payload, what, exc) from None      # bad UTF-8 inside a string
    except RecursionError:
        raise BusPayloadError(f"{what}: payload is nested too deeply to decode") from None


def _convert(value, type_, what: str):
    try:
        return msgspec.convert(value, type_)
    except (msgspec.MsgspecError, RecursionError) as exc:
        raise _error(what, exc, value) from None


def _plain(value, what: str, name: str):
    """numpy arrays (one-dimensional) and scalars as Python lists and scalars."""
    if isinstance(value, np.ndarray):
        if value.ndim != 1:
            raise BusPayloadError(f"{what}: {name} must be one-dimensional, got shape "
                                  f"{value.shape}")
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, list | tuple):
        return [x.item() if isinstance(x, np.generic) else x for x in value]
    return value


def _check_finite(values, what: str, name: str) -> None:
    """NaN and infinity cannot come out of JSON, but can be handed to an encoder."""
    for i, x in enumerate(values):
        if not math.isfinite(x):
            raise BusPayloadError(f"{what}: {name}[{i}] must be finite, got {x!r}")


def _finite(value, what: str, name: str) -> float:
    """A finite real number (int or float, not bool; numpy scalars accepted)."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Real):
        raise BusPayloadError(f"{what}: {name} must be a number, got "
                              f"{type(value).__name__} {value!r}")
    f = float(value)
    if not math.isfinite(f):
        raise BusPayloadError(f"{what}: {name} must be finite, got {value!r}")
    return f


def _time_usec(value, what: str) -> int:
    if isinstance(value, bool | np.bool_) or not isinstance(value, numbers.Integral):
        raise BusPayloadError(f"{what}: time_usec must be an integer (microseconds), got "
                              f"{type(value).__name__} {value!r}")
    t = int(value)
    if not 0 <= t <= MAX_TIME_USEC:
        raise BusPayloadError(f"{what}: time_usec must be in [0, 2**63 - 1], got {t}")
    return t


def _round(values: tuple[float, ...], decimals: int) -> tuple[float, ...]:
    return tuple(round(x, decimals) + 0.0 for x in values)  # + 0.0 turns -0.0 into 0.0


_ENCODER = msgspec.json.Encoder()


# --- telemetry ------------------------------------------------------------------------------
#: the wind of calm air (msgspec omits a default by identity: encode passes this object)
CALM = (0.0, 0.0, 0.0)


class TelemetryPayload(Struct, frozen=True, forbid_unknown_fields=True, omit_defaults=True):
    """The telemetry JSON object; every field but the wind is required (the wind is left
    out in calm air, so calm telemetry is what it was before it existed), unknown fields
    are rejected."""

    v: SchemaVersion
    t: Seconds
    time_usec: TimeUsec
    #: vehicle position, world ENU, m
    p_world_m: Vec3
    #: velocity, world ENU, m/s
    v_world_m_s: Vec3
    #: attitude (w, x, y, z) rotating body FLU into world ENU; unit norm within 1e-3
    q_world_body: Quat
    #: body rates, FLU, rad/s
    w_body_rad_s: Vec3
    #: 1 to 16 motor outputs in [0, 1], PX4 motor order
    motors: Annotated[tuple[MotorOutput, ...], Meta(min_length=1, max_length=MAX_MOTORS)]
    #: the air's velocity at the vehicle (wind), world ENU, m/s; optional, calm when absent
    wind_world_m_s: Vec3 = CALM

    def __post_init__(self):
        what = "telemetry"
        _check_version(self.v, what)
        _check_t(self.t, self.time_usec, what)
        norm = math.sqrt(sum(c * c for c in self.q_world_body))
        if abs(norm - 1.0) > _Q_NORM_TOL_JSON:
            raise ValueError(f"{what}: q_world_body must be a unit quaternion (w, x, y, z) "
                             f"with norm 1 +- {_Q_NORM_TOL_JSON}, got norm {norm:.6g}")


_TELEMETRY_DECODER = msgspec.json.Decoder(TelemetryPayload)
_VECTORS = ("p_world_m", "v_world_m_s", "q_world_body", "w_body_rad_s", "motors",
            "wind_world_m_s")


@dataclass(frozen=True)
class Telemetry:
    """One telemetry sample, validated on construction against ``TelemetryPayload``
    (BusPayloadError naming the field).

    ``p_world_m`` position and ``v_world_m_s`` velocity in world ENU; ``q_world_body`` the
    attitude quaternion (w, x, y, z) rotating body FLU vectors into world ENU (unit norm
    within 1e-3); ``w_body_rad_s`` body rates (FLU); ``motors`` 1 to 16 motor outputs in
    [0, 1], PX4 motor order; ``wind_world_m_s`` the air's velocity at the vehicle (world
    ENU; calm by default). Sequences are stored as tuples of floats.
    """

    time_usec: int
    p_world_m: tuple[float, float, float]
    v_world_m_s: tuple[float, float, float]
    q_world_body: tuple[float, float, float, float]
    w_body_rad_s: tuple[float, float, float]
    motors: tuple[float, ...]
    wind_world_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        what = "telemetry"
        obj = {name: _plain(getattr(self, name), what, name) for name in _VECTORS}
        time_usec = _plain(self.time_usec, what, "time_usec")
        # t as the payload would carry it; when time_usec is not an int, convert names it
        t = time_usec * 1e-6 if type(time_usec) is int else 0.0
        checked = _convert({"v": SCHEMA_VERSION, "t": t, "time_usec": time_usec, **obj},
                           TelemetryPayload, what)
        for name in _VECTORS:
            values = getattr(checked, name)
            _check_finite(values, what, name)
            object.__setattr__(self, name, values)
        object.__setattr__(self, "time_usec", checked.time_usec)

    @classmethod
    def _from_payload(cls, p: TelemetryPayload) -> Telemetry:
        """A Telemetry from a decoded (hence validated) payload, without checking again."""
        self = object.__new__(cls)
        for name in ("time_usec", *_VECTORS):
            object.__setattr__(self, name, getattr(p, name))
        return self

    @property
    def t(self) -> float:
        """Simulated time in seconds."""
        return self.time_usec * 1e-6


def encode_telemetry(sample: Telemetry) -> bytes:
    """Compact JSON of a Telemetry sample (values rounded: 1 um, 1 um/s, 1e-9, 1e-4)."""
    if not isinstance(sample, Telemetry):
        raise BusPayloadError(f"telemetry: expected a Telemetry, got {type(sample).__name__}")
    values = [_round(getattr(sample, name), decimals) for name, decimals in _DECIMALS.items()]
    if values[-1] == CALM:  # (the wind, last: left out in calm air)
        values[-1] = CALM
    return _ENCODER.encode(TelemetryPayload(SCHEMA_VERSION, sample.t, sample.time_usec,
                                            *values))


def decode_telemetry(payload) -> Telemetry:
    """Telemetry from a JSON payload; BusPayloadError naming what was wrong."""
    return Telemetry._from_payload(_decode(_TELEMETRY_DECODER, payload, "telemetry"))


# --- events ---------------------------------------------------------------------------------
class EventHeader(Struct, frozen=True):
    """The fields every event carries; the event's own fields follow at the top level."""

    v: SchemaVersion
    #: event type: an ``EventType`` or another name
    type: EventName
    t: Seconds
    time_usec: TimeUsec

    def __post_init__(self):
        _check_version(self.v, "event")
        _check_t(self.t, self.time_usec, "event")


_EVENT_RESERVED = tuple(EventHeader.__struct_fields__)


class NoFields(Struct, frozen=True):
    """An event type that requires no fields (it may carry any)."""


class ModeFields(Struct, frozen=True):
    """``mode``: the flight mode changed."""

    #: PX4 mode name, e.g. "OFFBOARD"
    mode: NonEmptyStr


class CollisionFields(Struct, frozen=True):
    """``collision``: the vehicle hit an obstacle; ``mover_collision``: a moving obstacle
    (scenarios.movers; ``object`` is its name, ``speed_m_s`` the speed relative to it)."""

    #: obstacle piece name (a mover's name)
    object: NonEmptyStr
    #: impact speed, m/s
    speed_m_s: Annotated[float, Meta(ge=0.0, description="impact speed, m/s")]


class GeofenceFields(Struct, frozen=True):
    """``geofence``: the vehicle breached its geofence."""

    #: e.g. "outside the fence", "more than 50 m from home"
    reason: NonEmptyStr
    #: what the flight controller did (GF_ACTION): none, warning, hold, return,
    #: terminate, land
    action: NonEmptyStr


class TrialEndFields(Struct, frozen=True):
    """``trial_end``: a trial ended."""

    #: e.g. "success", "collision", "timeout"
    outcome: NonEmptyStr


#: Known event types and the fields they require (a Struct each; extra fields are allowed).
#: Other types (names matching ``[a-z][a-z0-9_]*``) carry whatever fields they like; every
#: field value must be an ``EventValue``: a string, a finite number, a boolean, null, or an
#: array of finite numbers.
EVENT_TYPES: dict[EventType, type[Struct]] = {
    EventType.ARMED: NoFields,
    EventType.DISARMED: NoFields,
    EventType.MODE: ModeFields,
    EventType.COLLISION: CollisionFields,
    EventType.MOVER_COLLISION: CollisionFields,
    EventType.TRIAL_START: NoFields,
    EventType.TRIAL_END: TrialEndFields,
    EventType.GEOFENCE: GeofenceFields,
}


def _event_type(value) -> EventType | str:
    if not isinstance(value, str) or not _NAME_RE.fullmatch(value):
        raise BusPayloadError(f"event: type must match [a-z][a-z0-9_]* (at most 64 "
                              f"characters), got {value!r}")
    try:
        return EventType(value)
    except ValueError:  # another type: allowed
        return value


@dataclass(frozen=True)
class Event:
    """A discrete event at simulated time ``time_usec``: ``type`` plus its ``fields``.

    Validated on construction: ``type`` matches ``[a-z][a-z0-9_]*`` (at most 64
    characters) and becomes an ``EventType`` when it is one; known types (``EVENT_TYPES``)
    must carry their required fields, e.g.
    ``Event(EventType.COLLISION, 12_000_000, {"object": "tree_3", "speed_m_s": 2.1})``.
    """

    type: EventType | str
    time_usec: int
    fields: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self):
        object.__setattr__(self, "type", _event_type(self.type))
        what = f"event {str(self.type)!r}"
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
            if isinstance(value, np.ndarray):
                value = value.ravel()
            clean[name] = _plain(value, what, name)
        try:  # one conversion of all fields; on failure, one per field to name the field
            clean = msgspec.convert(clean, _EVENT_FIELDS)
        except (msgspec.MsgspecError, RecursionError):
            for name, value in clean.items():
                _convert(value, EventValue, f"{what}: field {name!r}")
            raise  # not reached: some field failed above
        for name, value in clean.items():
            if isinstance(value, float):
                _check_finite((value,), what, f"field {name!r}")
            elif isinstance(value, list):
                _check_finite(value, what, f"field {name!r}")
        required = EVENT_TYPES.get(self.type)
        if required is not None:
            _convert(clean, required, what)
        object.__setattr__(self, "fields", clean)

    @classmethod
    def _from_payload(cls, header: EventHeader, fields: dict[str, Any]) -> Event:
        """An Event from a decoded header and field values already of ``EventValue`` type
        (decoded as such): checks the names and the required fields, not the values."""
        self = object.__new__(cls)
        object.__setattr__(self, "type", _event_type(header.type))
        object.__setattr__(self, "time_usec", header.time_usec)
        what = f"event {str(self.type)!r}"
        if len(fields) > MAX_EVENT_FIELDS:
            raise BusPayloadError(f"{what}: {len(fields)} fields, more than "
                                  f"{MAX_EVENT_FIELDS}")
        for name in fields:
            if not _NAME_RE.fullmatch(name):
                raise BusPayloadError(f"{what}: field name {name!r} must match "
                                      "[a-z][a-z0-9_]*")
        required = EVENT_TYPES.get(self.type)
        if required is not None:
            _convert(fields, required, what)
        object.__setattr__(self, "fields", fields)
        return self

    @property
    def t(self) -> float:
        """Simulated time in seconds."""
        return self.time_usec * 1e-6


_EVENT_DECODER = msgspec.json.Decoder(dict[str, Any])
#: Decodes an event whose every value is an EventValue (the header's are too); a decoder
#: caches its type, msgspec.convert would rebuild it on every call.
_EVENT_VALUES_DECODER = msgspec.json.Decoder(_EVENT_FIELDS)


def encode_event(event: Event) -> bytes:
    """Compact JSON of an Event."""
    if not isinstance(event, Event):
        raise BusPayloadError(f"event: expected an Event, got {type(event).__name__}")
    return _ENCODER.encode({"v": SCHEMA_VERSION, "type": str(event.type), "t": event.t,
                            "time_usec": event.time_usec, **event.fields})


def decode_event(payload) -> Event:
    """An Event from a JSON payload; BusPayloadError naming what was wrong."""
    what = "event"
    _check_payload(payload, what)
    try:
        obj = _EVENT_VALUES_DECODER.decode(payload)
    except (msgspec.MsgspecError, RecursionError, UnicodeDecodeError):
        # the slow path, to name what is wrong: Event() checks each value by name
        obj = _decode(_EVENT_DECODER, payload, what)
        header = _convert(obj, EventHeader, what)
        fields = {k: v for k, v in obj.items() if k not in _EVENT_RESERVED}
        return Event(type=header.type, time_usec=header.time_usec, fields=fields)
    header = _convert(obj, EventHeader, what)
    return Event._from_payload(header, {k: v for k, v in obj.items()
                                        if k not in _EVENT_RESERVED})


# --- status ---------------------------------------------------------------------------------
class StatusPayload(Struct, frozen=True, forbid_unknown_fields=True, omit_defaults=True):
    """The status JSON object (retained on the vehicle's status topic)."""

    v: SchemaVersion
    #: the vehicle's instance name, [A-Za-z0-9_-]{1,64}
    vehicle: str
    status: StatusValue
    #: why the vehicle is offline (``OfflineReason``); absent when online
    reason: Annotated[str, Meta(min_length=1, max_length=200)] | None = None

    def __post_init__(self):
        _check_version(self.v, "status")
        check_vehicle(self.vehicle)  # ValueError naming the rule


_STATUS_DECODER = msgspec.json.Decoder(StatusPayload)


@dataclass(frozen=True)
class Status:
    """A vehicle's bus status (retained on its status topic).

    ``online`` True while the simulator's publisher is connected. When it goes away the
    status becomes offline with ``reason`` ``OfflineReason.CLOSED`` (clean shutdown) or
    ``OfflineReason.CONNECTION_LOST`` (the broker published the publisher's last will).
    """

    vehicle: str
    online: bool
    reason: str | None = None

    def __post_init__(self):
        if not isinstance(self.online, bool):
            raise BusPayloadError(f"status: online must be a boolean, got {self.online!r}")
        self._payload()

    def _payload(self) -> StatusPayload:
        state = StatusValue.ONLINE if self.online else StatusValue.OFFLINE
        return _convert({"v": SCHEMA_VERSION, "vehicle": self.vehicle, "status": state,
                         "reason": self.reason}, StatusPayload, "status")


def encode_status(status: Status) -> bytes:
    """Compact JSON of a Status (``"reason"`` only when there is one)."""
    return _ENCODER.encode(status._payload())


def decode_status(payload) -> Status:
    """A Status from a JSON payload; BusPayloadError naming what was wrong."""
    p = _decode(_STATUS_DECODER, payload, "status")
    return Status(vehicle=p.vehicle, online=p.status is StatusValue.ONLINE, reason=p.reason)


# --- movers ---------------------------------------------------------------------------------
# MAX_MOVERS (ft_sitl.mover_kinds): the most movers in one payload, as in one field.
#: The size fields each shape carries (m): as ``scenarios.movers.Movers.describe``.
#: Decimal places kept in a movers payload: 0.1 mm, 0.1 mm/s, 1 urad, 0.1 mm.
_MOVER_DECIMALS = {"p_world_m": 4, "v_world_m_s": 4, "heading_rad": 6, "size": 4}
MoverShape = Annotated[str, Meta(pattern=f"^({'|'.join(MOVER_SHAPES)})$",
                                 description=" | ".join(MOVER_SHAPES))]
Size = Annotated[float, Meta(gt=0.0, le=1000.0, description="m")]
Heading = Annotated[float, Meta(ge=-3.141593, le=3.141593,
                                description="rad, ENU: 0 east, pi/2 north")]


class MoverState(Struct, frozen=True, forbid_unknown_fields=True, omit_defaults=True):
    """One moving obstacle at one instant. ``shape`` is person (a standing cylinder: radius,
    height), box (length along its heading, width, height) or sphere (radius); exactly its
    sizes are present."""

    #: its name in the scenario, e.g. "person 2"; collisions name it so
    name: Annotated[str, Meta(min_length=1, max_length=64)]
    shape: MoverShape
    #: the shape's centre, world ENU, m (a person's or a box's at half its height)
    p_world_m: Vec3
    #: its direction of travel, ENU, rad in [-pi, pi] (0 east, pi/2 north)
    heading_rad: Heading
    #: velocity, world ENU, m/s (zero before its field starts moving)
    v_world_m_s: Vec3
    radius_m: Size | UnsetType = UNSET
    height_m: Size | UnsetType = UNSET
    length_m: Size | UnsetType = UNSET
    width_m: Size | UnsetType = UNSET

    def __post_init__(self):
        what = f"movers: {self.name!r}"
        sizes = SIZE_FIELDS[self.shape]
        for key in ("radius_m", "height_m", "length_m", "width_m"):
            given = getattr(self, key) is not UNSET
            if given != (key in sizes):
                raise ValueError(f"{what}: a {self.shape} has {', '.join(sizes)}; "
                                 f"{key} is {'not allowed' if given else 'missing'}")


class MoversPayload(Struct, frozen=True, forbid_unknown_fields=True):
    """The movers JSON object: every mover of the vehicle's world at ``time_usec``."""

    v: SchemaVersion
    t: Seconds
    time_usec: TimeUsec
    movers: Annotated[tuple[MoverState, ...], Meta(max_length=MAX_MOVERS)]

    def __post_init__(self):
        _check_version(self.v, "movers")
        _check_t(self.t, self.time_usec, "movers")
        names = [m.name for m in self.movers]
        if len(set(names)) != len(names):
            dup = next(n for n in names if names.count(n) > 1)
            raise ValueError(f"movers: name {dup!r} is given twice")


_MOVERS_DECODER = msgspec.json.Decoder(MoversPayload)


@dataclass(frozen=True)
class MoverStates:
    """The moving obstacles of a vehicle's world at simulated time ``time_usec``: a tuple
    of :class:`MoverState` (given as MoverStates or mappings of their fields), validated on
    construction against ``MoversPayload`` (BusPayloadError naming the mover and the
    field). ``by_name`` looks one up."""

    time_usec: int
    movers: tuple = ()

    def __post_init__(self):
        what = "movers"
        time_usec = _plain(self.time_usec, what, "time_usec")
        items = []
        for m in self.movers:
            if isinstance(m, MoverState):
                m = msgspec.structs.asdict(m)
            elif not isinstance(m, Mapping):
                raise BusPayloadError(f"{what}: each mover must be a MoverState or a mapping, "
                                      f"got {type(m).__name__}")
            items.append({k: _plain(v, what, str(k)) for k, v in m.items() if v is not UNSET})
        t = time_usec * 1e-6 if type(time_usec) is int else 0.0
        checked = _convert({"v": SCHEMA_VERSION, "t": t, "time_usec": time_usec,
                            "movers": items}, MoversPayload, what)
        for j, m in enumerate(checked.movers):  # (NaN fails the ranges, not a bare float)
            _check_finite(m.p_world_m, what, f"movers[{j}].p_world_m")
            _check_finite(m.v_world_m_s, what, f"movers[{j}].v_world_m_s")
        object.__setattr__(self, "time_usec", checked.time_usec)
        object.__setattr__(self, "movers", checked.movers)

    @classmethod
    def _from_payload(cls, p: MoversPayload) -> MoverStates:
        self = object.__new__(cls)
        object.__setattr__(self, "time_usec", p.time_usec)
        object.__setattr__(self, "movers", p.movers)
        return self

    @property
    def t(self) -> float:
        """Simulated time in seconds."""
        return self.time_usec * 1e-6

    def by_name(self, name: str) -> MoverState:
        for m in self.movers:
            if m.name == name:
                return m
        raise KeyError(f"no mover named {name!r} (movers: "
                       f"{', '.join(m.name for m in self.movers) or 'none'})")


def encode_movers(states: MoverStates) -> bytes:
    """Compact JSON of the movers (values rounded: 0.1 mm, 0.1 mm/s, 1 urad, sizes 0.1
    mm)."""
    if not isinstance(states, MoverStates):
        raise BusPayloadError(f"movers: expected a MoverStates, got {type(states).__name__}")
    dec = _MOVER_DECIMALS
    movers = []
    for m in states.movers:
        sizes = {k: round(getattr(m, k), dec["size"]) for k in SIZE_FIELDS[m.shape]}
        movers.append(msgspec.structs.replace(
            m, p_world_m=_round(m.p_world_m, dec["p_world_m"]),
            v_world_m_s=_round(m.v_world_m_s, dec["v_world_m_s"]),
            heading_rad=round(m.heading_rad, dec["heading_rad"]) + 0.0, **sizes))
    return _ENCODER.encode(MoversPayload(SCHEMA_VERSION, states.t, states.time_usec,
                                         tuple(movers)))


def decode_movers(payload) -> MoverStates:
    """MoverStates from a JSON payload; BusPayloadError naming what was wrong."""
    return MoverStates._from_payload(_decode(_MOVERS_DECODER, payload, "movers"))


# --- config ---------------------------------------------------------------------------------
class ConfigPayload(Struct, frozen=True, forbid_unknown_fields=True, omit_defaults=True):
    """A config request (clients -> simulator): any non-empty subset of the settings."""

    v: SchemaVersion | UnsetType = UNSET
    telemetry_rate_hz: Annotated[float, Meta(
        ge=0.0, le=1000.0,
        description="telemetry rate in simulated Hz; 0 stops telemetry")] | UnsetType = UNSET
    depth: Annotated[bool, Meta(description="publish depth frames")] | UnsetType = UNSET
    points: Annotated[bool, Meta(description="publish point clouds")] | UnsetType = UNSET

    def __post_init__(self):
        if self.v is not UNSET:
            _check_version(self.v, "config")


def _config_fields() -> dict[str, tuple[str, float | None, float | None, str]]:
    out = {}
    for f in msgspec.inspect.type_info(ConfigPayload).fields:
        if f.name == "v":
            continue
        meta = f.type  # msgspec.inspect leaves UnsetType out: Metadata(type=..., ...)
        kind = "bool" if isinstance(meta.type, msgspec.inspect.BoolType) else "number"
        lo, hi = (meta.type.ge, meta.type.le) if kind == "number" else (None, None)
        out[f.name] = (kind, lo, hi, meta.extra_json_schema["description"])
    return out


#: Settings a client may request on the config topic: name -> (kind, low, high, meaning),
#: read off ``ConfigPayload``.
CONFIG_FIELDS: dict[str, tuple[str, float | None, float | None, str]] = _config_fields()
_CONFIG_DECODER = msgspec.json.Decoder(ConfigPayload)


def _settings(p: ConfigPayload, what: str) -> dict[str, Any]:
    out = {name: getattr(p, name) for name in CONFIG_FIELDS if getattr(p, name) is not UNSET}
    if not out:
        raise BusPayloadError(f"{what}: names no setting (known: {', '.join(CONFIG_FIELDS)})")
    if "telemetry_rate_hz" in out:
        out["telemetry_rate_hz"] = float(out["telemetry_rate_hz"])
    return out


def validate_config(config: Mapping[str, Any], what: str = "config") -> dict[str, Any]:
    """A checked copy of a config request (without ``"v"``); BusPayloadError naming the
    setting and its allowed values. At least one setting is required; unknown ones are
    rejected; ``"v"``, if present, must be 1."""
    if not isinstance(config, Mapping):
        raise BusPayloadError(f"{what}: must be a JSON object / mapping, got "
                              f"{type(config).__name__}")
    plain = {k: _plain(v, what, str(k)) for k, v in config.items()}
    return _settings(_convert(plain, ConfigPayload, what), what)


def encode_config(config: Mapping[str, Any]) -> bytes:
    """Compact JSON of a validated config request (with ``"v": 1``)."""
    return _ENCODER.encode({"v": SCHEMA_VERSION, **validate_config(config)})


def decode_config(payload) -> dict[str, Any]:
    """The validated settings of a config payload (``"v"`` optional, dropped)."""
    return _settings(_decode(_CONFIG_DECODER, payload, "config"), "config")


# --- binary sensor frames -------------------------------------------------------------------
#: First four bytes of every binary frame.
FRAME_MAGIC = b"FTSF"
#: Layout version of the binary frames.
FRAME_VERSION = 1
#: kind byte
KIND_DEPTH, KIND_POINTS = 1, 2
_KIND_NAMES = {KIND_DEPTH: FrameKind.DEPTH, KIND_POINTS: FrameKind.POINTS}
#: frame byte: the depth image is in the camera's optical frame; points are in world ENU or
#: body FLU coordinates
FRAME_OPTICAL, FRAME_WORLD, FRAME_BODY = 0, 1, 2
_FRAME_NAMES = {FRAME_OPTICAL: FrameName.OPTICAL, FRAME_WORLD: FrameName.WORLD,
                FRAME_BODY: FrameName.BODY}
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

    kind: FrameKind
    frame: FrameName
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
        # the camera module loads trimesh and numba: only a subscriber rebuilding camera
        # frames pays for them, not every user of the codec
        from ft_sitl.scenarios.camera import DepthFrame

        if self.kind != FrameKind.DEPTH:
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
    if frame_id == FrameName.WORLD:
        pts, code = frame.points_world, FRAME_WORLD
    elif frame_id == FrameName.BODY:
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
