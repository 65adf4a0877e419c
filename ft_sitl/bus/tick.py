"""The lockstep tick on the bus: what a navigator is given at one of its ticks, exactly.

In a lockstep wire trial (docs/wire.md, "Lockstep") the simulator publishes, at every
instant the in-process driver would call its navigator, one tick message (topic kind
``tick``, QoS 1) and holds its clock until the client acknowledges it over MAVLink. The
message carries the observation bit for bit: named float and integer scalars in a JSON
header and named arrays as their raw little-endian bytes, so nothing is rounded on the way
(depth frames included, unlike the ``depth`` topic's millimetres).

Layout: ``b"FTTK"``, uint32 header length, the JSON header ``{"v": 1, "seq", "phase",
"time_usec", "scalars": {name: number}, "arrays": [[name, dtype, shape], ...]}``, then the
arrays' bytes in the header's order. ``phase`` is ``observe`` (a frame during the
approach: ``Navigator.observe``) or ``step`` (a navigation tick: ``Navigator.step``).
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass, field

import numpy as np

TICK_MAGIC = b"FTTK"
TICK_VERSION = 1
PHASES = ("observe", "step")
_LEN = struct.Struct("<I")
#: the array types a tick may carry (what observations and depth frames hold)
_DTYPES = ("<f8", "<f4", "<i4", "<i8", "|b1")


class TickError(ValueError):
    """A malformed tick message; the message says what is wrong."""


@dataclass(frozen=True)
class Tick:
    """One lockstep tick: its number ``seq`` (from 1), ``phase`` (PHASES), the simulated
    time ``time_usec`` of the vehicle's clock, and the observation's fields."""

    seq: int
    phase: str
    time_usec: int
    scalars: dict = field(default_factory=dict)
    arrays: dict = field(default_factory=dict)


def encode_tick(tick: Tick) -> bytes:
    if tick.phase not in PHASES:
        raise TickError(f"tick: phase must be one of {', '.join(PHASES)}, got {tick.phase!r}")
    arrays, blobs = [], []
    for name, a in tick.arrays.items():
        a = np.asarray(a)
        dt = a.dtype.newbyteorder("<") if a.dtype.byteorder == ">" else a.dtype
        if dt.str not in _DTYPES:
            raise TickError(f"tick: array {name!r} has type {a.dtype}, not one of "
                            f"{', '.join(_DTYPES)}")
        arrays.append([name, dt.str, list(a.shape)])
        blobs.append(np.ascontiguousarray(a, dtype=dt).tobytes())
    scalars = {}
    for k, v in tick.scalars.items():
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer,
                                                                  np.floating)):
            raise TickError(f"tick: scalar {k!r} must be a number, got {v!r}")
        scalars[k] = int(v) if isinstance(v, (int, np.integer)) else float(v)
    head = json.dumps({"v": TICK_VERSION, "seq": int(tick.seq), "phase": tick.phase,
                       "time_usec": int(tick.time_usec), "scalars": scalars,
                       "arrays": arrays}).encode()
    return TICK_MAGIC + _LEN.pack(len(head)) + head + b"".join(blobs)


def decode_tick(payload) -> Tick:
    buf = bytes(payload)
    if buf[:4] != TICK_MAGIC or len(buf) < 8:
        raise TickError("tick: not a tick message (magic FTTK)")
    (n,) = _LEN.unpack_from(buf, 4)
    try:
        head = json.loads(buf[8:8 + n])
    except (ValueError, UnicodeDecodeError) as exc:
        raise TickError(f"tick: bad header ({exc})") from None
    if head.get("v") != TICK_VERSION:
        raise TickError(f"tick: version {head.get('v')!r}, this reader knows {TICK_VERSION}")
    pos = 8 + n
    arrays = {}
    for name, dt, shape in head["arrays"]:
        if dt not in _DTYPES:
            raise TickError(f"tick: array {name!r} has type {dt!r}")
        dtype = np.dtype(dt)
        size = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        if pos + size > len(buf):
            raise TickError(f"tick: truncated at array {name!r}")
        arrays[name] = np.frombuffer(buf, dtype=dtype, count=size // dtype.itemsize,
                                     offset=pos).reshape(shape).copy()
        pos += size
    if pos != len(buf):
        raise TickError(f"tick: {len(buf) - pos} bytes after the last array")
    if head.get("phase") not in PHASES:
        raise TickError(f"tick: phase {head.get('phase')!r}")
    return Tick(int(head["seq"]), head["phase"], int(head["time_usec"]),
                dict(head["scalars"]), arrays)
