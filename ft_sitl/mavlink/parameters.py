"""The parameter protocol: PARAM_REQUEST_LIST, PARAM_REQUEST_READ, PARAM_SET.

Integer parameters travel bytewise (their int32 bits in PARAM_VALUE's float, as
MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE advertises), so a client reads back exactly
the integer it set. The list goes out in chunks from :meth:`Parameters.poll`, not as one
burst, so a slow client's socket buffer is not overrun.
"""

from __future__ import annotations

import struct

from pymavlink.dialects.v20 import common as mav

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.params import PARAMS, ParamError
from ft_sitl.mavlink import files
from ft_sitl.mavlink.outgoing import COMPID, Outgoing
from ft_sitl.mavlink.vehicle import Vehicle

#: PARAM_VALUEs sent per poll while streaming the list: a burst of all ~480 small datagrams
#: could overrun a client's socket buffer; chunks of this size cannot
PARAM_STREAM_CHUNK = 40
#: each parameter's PARAM_VALUE index (PARAMS order)
PARAM_INDEX = {name: k for k, name in enumerate(PARAMS)}
#: the PARAM_SET types whose float carries an integer's bits
_INT_TYPES = (mav.MAV_PARAM_TYPE_INT32, mav.MAV_PARAM_TYPE_UINT32, mav.MAV_PARAM_TYPE_INT8,
              mav.MAV_PARAM_TYPE_UINT8, mav.MAV_PARAM_TYPE_INT16, mav.MAV_PARAM_TYPE_UINT16)


def _param_type(name: str) -> int:
    return mav.MAV_PARAM_TYPE_INT32 if PARAMS[name].is_int else mav.MAV_PARAM_TYPE_REAL32


def _param_wire(name: str, value: float) -> float:
    """The float field of PARAM_VALUE: ints are sent bytewise (int32 bits in the float)."""
    if PARAMS[name].is_int:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def _param_from_wire(name: str, value: float, ptype: int) -> float:
    if PARAMS[name].is_int and ptype in _INT_TYPES:
        return float(struct.unpack("<i", struct.pack("<f", value))[0])
    return float(value)


def param_name(raw) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", "replace")
    return raw.split("\x00", 1)[0]


class Parameters:
    """One vehicle's parameters on the wire (the fleet's ParamSet of it), as PX4 answers.

    A face with other parameters (the ArduCopter face) subclasses it with the differences
    as hooks: :meth:`store` (the ParamSet it serves, whose ``table`` gives names and
    indices), :meth:`value` (PARAM_VALUE's type and encoding), :meth:`decode` (PARAM_SET's
    value, None: ignored without an answer), :meth:`unknown` and :meth:`refused` (what a
    bad set is told)."""

    def __init__(self, vehicle: Vehicle):
        self.v = vehicle
        self.names = list(self.store.table)
        self.index = {n: k for k, n in enumerate(self.names)}
        # PARAM_REQUEST_LIST answers in progress: (link, peer) -> next index to send
        self._streams: dict[tuple, int] = {}

    @property
    def store(self):
        """The ParamSet served: the flight controller's PX4-named parameters."""
        return self.v.params

    def value(self, name: str) -> mav.MAVLink_param_value_message:
        return mav.MAVLink_param_value_message(
            name.encode("ascii"), _param_wire(name, self.v.params[name]), _param_type(name),
            len(PARAMS), PARAM_INDEX[name])

    def decode(self, name: str, m) -> float | None:
        """PARAM_SET's value for a known ``name`` (integers bytewise)."""
        return _param_from_wire(name, m.param_value, m.param_type)

    def unknown(self, name: str) -> None:
        """A PARAM_SET of a name not served: PX4 says so and does not answer."""
        self.v.cmd.text(cm.Severity.WARNING, f"Param {name[:16]} unknown: not set")

    def refused(self, name: str, exc: ParamError) -> None:
        """A PARAM_SET the declaration refuses (its value is echoed unchanged after)."""
        self.v.cmd.text(cm.Severity.WARNING, str(exc)[:50])

    def on_request_list(self, m, link, peer, wall_us):
        # all of them, index 0..count-1, to the asker: the first chunk now, the rest from
        # poll() (a new request from the same peer starts over)
        self._streams[(link, peer)] = 0
        return self.poll()

    def poll(self) -> list[Outgoing]:
        """The next chunk of every list being streamed."""
        out = []
        for key, start in list(self._streams.items()):
            stop = min(start + PARAM_STREAM_CHUNK, len(self.names))
            out.extend(Outgoing(self.value(n), *key) for n in self.names[start:stop])
            if stop >= len(self.names):
                del self._streams[key]
            else:
                self._streams[key] = stop
        return out

    def on_request_read(self, m, link, peer, wall_us):
        if m.param_index >= 0:
            if m.param_index >= len(self.names):
                return []
            name = self.names[m.param_index]
        else:
            name = param_name(m.param_id)
            if name not in self.index:
                return []
        return [Outgoing(self.value(name), link, peer)]

    def on_set(self, m, link, peer, wall_us):
        name = param_name(m.param_id)
        if name not in self.index:
            self.unknown(name)
            return []
        value = self.decode(name, m)
        if value is None:
            return []
        try:
            self.set(name, value)
        except ParamError as exc:
            self.refused(name, exc)
        return [Outgoing(self.value(name))]

    def set(self, name: str, value) -> None:
        """Set one parameter (PARAM_SET, the shell); ParamError refuses it as a whole,
        nothing half-applied."""
        store = self.store
        old = store[name]
        try:
            store.set(name, value)
            if store.spec(name).honoured:  # a stored parameter changes nothing to rebuild
                self.v.fleet.refresh_params()
        except ParamError:
            store.set(name, old)
            self.v.fleet.refresh_params()
            raise

    def file(self) -> bytes:
        """The parameter file FTP serves (QGroundControl's format)."""
        return files.params_file(self.v.sysid, COMPID, [
            (n, self.v.params[n], _param_type(n)) for n in self.names])
