"""MAVLink frames cut out of a byte stream (a TCP connection carries no packet
boundaries): each connection has its own :class:`FrameSplitter`, so clients sharing a
serial port never interleave half frames in one parser."""

from __future__ import annotations

_V1, _V2 = 0xFE, 0xFD
#: the bytes around the payload: v1 header 6 + crc 2; v2 header 10 + crc 2 (+13 signed)
_V1_EXTRA, _V2_EXTRA, _SIGNATURE = 8, 12, 13
#: bytes kept at most while waiting for the rest of a frame
MAX_BUFFER = 1 << 16


class FrameSplitter:
    """Whole MAVLink v1/v2 frames from the chunks of one stream (garbage before a start
    byte is dropped; the frames' checksums are the parser's business)."""

    def __init__(self):
        self._buf = bytearray()

    def feed(self, data: bytes) -> list[bytes]:
        buf = self._buf
        buf.extend(data)
        out = []
        while buf:
            start = next((k for k, b in enumerate(buf) if b in (_V1, _V2)), None)
            if start is None:
                buf.clear()
                break
            del buf[:start]
            if len(buf) < 3:
                break
            if buf[0] == _V1:
                size = buf[1] + _V1_EXTRA
            else:
                size = buf[1] + _V2_EXTRA + (_SIGNATURE if buf[2] & 1 else 0)
            if len(buf) < size:
                break
            out.append(bytes(buf[:size]))
            del buf[:size]
        if len(buf) > MAX_BUFFER:
            buf.clear()
        return out
