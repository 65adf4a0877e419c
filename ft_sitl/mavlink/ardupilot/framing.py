"""MAVLink frames cut out of a byte stream (a TCP connection carries no packet
boundaries): each connection has its own :class:`FrameSplitter`, so clients sharing a
serial port never interleave half frames in one parser. A candidate frame whose header
carries an unknown incompatibility flag (as ArduPilot's parser refuses it) or whose
checksum fails (a start byte inside garbage, a corrupt byte) gives up only its start byte,
and the search goes on from the next byte: a real frame right behind garbage is found."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as apm

_V1, _V2 = 0xFE, 0xFD
_STARTS = (_V1, _V2)
#: the bytes around the payload: v1 header 6 + crc 2; v2 header 10 + crc 2 (+13 signed)
_V1_EXTRA, _V2_EXTRA, _SIGNATURE = 8, 12, 13
#: the only MAVLink 2 incompatibility flag (signed); a header with another is no frame
_IFLAG_SIGNED = 0x01
#: bytes kept at most while waiting for the rest of a frame
MAX_BUFFER = 1 << 16


def _checksum_ok(frame: bytes, v1: bool) -> bool:
    """Whether a whole frame's CRC (over header and payload, with its message's CRC_EXTRA)
    holds; a message id this dialect does not know passes (the parser judges it)."""
    msg_id = frame[5] if v1 else frame[7] | frame[8] << 8 | frame[9] << 16
    cls = apm.mavlink_map.get(msg_id)
    if cls is None:
        return True
    end = (6 if v1 else 10) + frame[1]
    crc = apm.x25crc(frame[1:end])
    crc.accumulate(bytes((cls.crc_extra,)))
    return crc.crc == frame[end] | frame[end + 1] << 8


def _frame_at(buf: bytearray, i: int) -> int | None:
    """The size of the frame starting at ``buf[i]`` (a start byte): 0 if it is none (an
    unknown incompatibility flag, a failed checksum), None if its bytes are not all in."""
    if len(buf) - i < 3:
        return None
    v1 = buf[i] == _V1
    if not v1 and buf[i + 2] & ~_IFLAG_SIGNED:  # (a flag no one defines: no frame)
        return 0
    size = buf[i + 1] + (_V1_EXTRA if v1 else
                         _V2_EXTRA + (_SIGNATURE if buf[i + 2] & _IFLAG_SIGNED else 0))
    if len(buf) - i < size:
        return None
    return size if _checksum_ok(bytes(buf[i:i + size]), v1) else 0


class FrameSplitter:
    """Whole MAVLink v1/v2 frames from the chunks of one stream: garbage before a start
    byte is dropped, and so is the start byte of a candidate that is no frame; while a
    candidate waits for its bytes, a whole valid frame after its start shows it was
    garbage (a start byte and a length within junk), and the search moves on to it."""

    def __init__(self):
        self._buf = bytearray()
        #: candidates dropped as no frame since :meth:`pop_rejected` last counted them
        self._rejected = 0

    def pop_rejected(self) -> int:
        """How many candidates were dropped as no frame since the last call."""
        n, self._rejected = self._rejected, 0
        return n

    def feed(self, data: bytes) -> list[bytes]:
        buf = self._buf
        buf.extend(data)
        out = []
        while buf:
            start = next((k for k, b in enumerate(buf) if b in _STARTS), None)
            if start is None:
                buf.clear()
                break
            del buf[:start]
            size = _frame_at(buf, 0)
            if size is None:
                later = next((k for k in range(1, len(buf)) if buf[k] in _STARTS
                              and _frame_at(buf, k)), None)
                if later is None:
                    break  # (wait for the rest)
                del buf[:later]
                self._rejected += 1
                continue
            if size == 0:
                del buf[:1]  # (not a frame: look again from the next byte)
                self._rejected += 1
                continue
            out.append(bytes(buf[:size]))
            del buf[:size]
        if len(buf) > MAX_BUFFER:
            buf.clear()
        return out
