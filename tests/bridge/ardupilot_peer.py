"""ArduPilot's side of the JSON simulator protocol, for the bridge tests.

Written from ArduPilot's sources (libraries/SITL/SIM_JSON.cpp and SIM_JSON.h, upstream
90700977c5), independently of ft_sitl.bridge.ardupilot so that the tests check the bridge
against what ArduPilot does, not against the bridge's own idea of it:

- servo packets packed as ``servo_packet_16`` / ``servo_packet_32`` (little-endian);
- answers read as ``JSON::recv_fdm`` does: newlines become string ends, the text between
  the last two of them is parsed;
- parsed as ``JSON::parse_sensors`` does: ``strstr`` for the section, skip it and one
  character, ``strstr`` for the key, skip it and two characters (the closing quote and the
  colon), then ``atof`` for numbers and ``sscanf("[%f, %f, %f]")`` for vectors (the ``[``
  must come at once; a space in a scanf format matches any amount of white space, none
  included);
- ArduCopter's quad X motor table (AP_MotorsMatrix::setup_quad_matrix), its thrust
  linearisation (Thrust_Linearization::thrust_to_actuator) and PWM output
  (AP_MotorsMulticopter::output_to_pwm), and parameter-file lines
  (AP_Param::parse_param_line).
"""

from __future__ import annotations

import math
import re
import socket
import struct
from dataclasses import dataclass

import numpy as np

MAGIC_16 = 18458
MAGIC_32 = 29569
COPTER_RATE_HZ = 1200  # SIM_RATE_HZ default in SITL builds (SITL.cpp)

# ArduCopter quad X: (angle clockwise from the nose in degrees, yaw factor: +1 CCW, -1 CW)
QUAD_X = ((45.0, 1), (-135.0, 1), (-45.0, -1), (135.0, -1))
QUAD_PLUS = ((90.0, 1), (-90.0, 1), (0.0, -1), (180.0, -1))


def mixer_signs(table) -> list[tuple[float, float, float]]:
    """(roll, pitch, yaw) factors of each motor as AP_MotorsMatrix::add_motor sets them."""
    return [(math.cos(math.radians(a + 90.0)), math.cos(math.radians(a)), float(y))
            for a, y in table]


def servo_packet(frame_count: int, pwm, *, frame_rate: int = COPTER_RATE_HZ,
                 channels: int = 16) -> bytes:
    pwm = [int(x) for x in pwm] + [0] * (channels - len(pwm))
    if channels == 16:
        return struct.pack("<HHI16H", MAGIC_16, frame_rate, frame_count, *pwm)
    if channels == 32:
        return struct.pack("<HHI32H", MAGIC_32, frame_rate, frame_count, *pwm)
    raise ValueError(f"channels: {channels}, ArduPilot sends 16 or 32")


# --- reading the answer as ArduPilot does ------------------------------------------------
_FLOAT = r"[+-]?(?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?"
_NUMBER = re.compile(r"\s*(" + _FLOAT + ")")
_VEC3 = re.compile(rf"\[\s*({_FLOAT}),\s*({_FLOAT}),\s*({_FLOAT})")
_VEC4 = re.compile(rf"\[\s*({_FLOAT}),\s*({_FLOAT}),\s*({_FLOAT}),\s*({_FLOAT})")

# SIM_JSON.h keytable: section, key, type, required
_KEYS = (
    ("", "timestamp", "double", True),
    ("imu", "gyro", "vec3", True),
    ("imu", "accel_body", "vec3", True),
    ("", "position", "vec3", True),
    ("", "attitude", "vec3", False),
    ("", "quaternion", "quat", False),
    ("", "velocity", "vec3", True),
)


class ArduPilotParseError(AssertionError):
    """What ArduPilot would have rejected (or silently misread)."""


@dataclass
class JsonState:
    timestamp: float
    gyro: np.ndarray
    accel_body: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    quaternion: np.ndarray | None
    attitude: np.ndarray | None


def frame_text(datagram: bytes) -> str:
    """The line recv_fdm hands to parse_sensors (it needs a newline before and after)."""
    buf = datagram.replace(b"\n", b"\0")
    p2 = buf.rfind(b"\0")
    if p2 <= 0:
        raise ArduPilotParseError(f"no terminating newline after the object: {datagram!r}")
    p1 = buf.rfind(b"\0", 0, p2)
    if p1 < 0:
        raise ArduPilotParseError(f"no newline before the object: {datagram!r}")
    return buf[p1 + 1:p2].decode("ascii")


def parse_sensors(text: str) -> JsonState:
    found: dict[str, object] = {}
    for section, key, kind, required in _KEYS:
        p = text.find(section)  # strstr(json, "") is json itself
        if p < 0:
            if required:
                raise ArduPilotParseError(f"section {section!r} not found in {text!r}")
            continue
        p += len(section) + 1
        q = text.find(key, p)
        if q < 0:
            if required:
                raise ArduPilotParseError(f"key {section}/{key} not found in {text!r}")
            continue
        p = q + len(key) + 2
        rest = text[p:]
        if kind == "double":
            m = _NUMBER.match(rest)  # atof would read garbage as 0: demand a number
            if not m:
                raise ArduPilotParseError(f"{key}: no number at {rest[:30]!r}")
            found[key] = float(m.group(1))
        else:
            m = (_VEC4 if kind == "quat" else _VEC3).match(rest)
            if not m:
                raise ArduPilotParseError(
                    f"{section}/{key}: sscanf would not read a vector at {rest[:40]!r}")
            found[key] = np.array([float(g) for g in m.groups()])
    if "quaternion" not in found and "attitude" not in found:
        raise ArduPilotParseError("neither attitude nor quaternion")
    return JsonState(found["timestamp"], found["gyro"], found["accel_body"],
                     found["position"], found["velocity"], found.get("quaternion"),
                     found.get("attitude"))


# --- the peer ------------------------------------------------------------------------------
class ArduPilotPeer:
    """A UDP socket on a free port that talks to the bridge as ArduPilot's SITL would."""

    def __init__(self, bridge_address, *, host: str = "127.0.0.1", timeout_s: float = 20.0):
        self.bridge_address = tuple(bridge_address)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((host, 0))
        self.sock.settimeout(timeout_s)  # a guard against a hang, not a timing check

    def send_raw(self, data: bytes) -> None:
        self.sock.sendto(data, self.bridge_address)

    def recv_raw(self) -> bytes:
        try:
            data, addr = self.sock.recvfrom(65536)
        except TimeoutError:
            raise AssertionError("no answer from the bridge") from None
        assert addr == self.bridge_address, f"answer from {addr}, not the bridge"
        return data

    def exchange(self, frame_count: int, pwm, *, frame_rate: int = COPTER_RATE_HZ,
                 channels: int = 16) -> tuple[bytes, JsonState]:
        self.send_raw(servo_packet(frame_count, pwm, frame_rate=frame_rate,
                                   channels=channels))
        raw = self.recv_raw()
        return raw, parse_sensors(frame_text(raw))

    def fly(self, first_count: int, n: int, pwm, **kw) -> tuple[int, JsonState]:
        """n frames with constant PWM from frame_count first_count; (next count, last state)."""
        state = None
        for k in range(n):
            _, state = self.exchange(first_count + k, pwm, **kw)
        return first_count + n, state

    def close(self) -> None:
        self.sock.close()


# --- ArduCopter's parameter file and motor output ----------------------------------------
def read_param_file(text: str) -> dict[str, float]:
    """NAME -> value as AP_Param::parse_param_line reads each line ('#' lines skipped)."""
    out: dict[str, float] = {}
    for line in text.splitlines():
        if not line or line[0] == "#":
            continue
        tokens = [t for t in re.split(r"[, =\t\r\n]", line) if t]
        if len(tokens) < 2:
            raise AssertionError(f"parameter line without a value: {line!r}")
        if len(tokens[0]) > 16:
            raise AssertionError(f"parameter name longer than 16 characters: {line!r}")
        out[tokens[0]] = float(tokens[1])
    return out


def hover_pwm(params: dict[str, float]) -> int:
    """The PWM ArduCopter outputs on every motor at MOT_THST_HOVER (no voltage scaling)."""
    e = params["MOT_THST_EXPO"]
    thrust = params["MOT_THST_HOVER"]
    ratio = ((e - 1.0) + math.sqrt((1.0 - e) ** 2 + 4.0 * e * thrust)) / (2.0 * e)
    s_min, s_max = params["MOT_SPIN_MIN"], params["MOT_SPIN_MAX"]
    actuator = s_min + (s_max - s_min) * ratio
    lo, hi = params["MOT_PWM_MIN"], params["MOT_PWM_MAX"]
    return int(lo + (hi - lo) * actuator)  # rc_write takes an int16_t
