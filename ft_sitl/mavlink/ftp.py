"""MAVLink FTP (``FILE_TRANSFER_PROTOCOL``, 110): a read-only server of the vehicle's files.

The protocol is the MAVLink FTP specification as PX4 implements it
(``src/modules/mavlink/mavlink_ftp.cpp``): a 12-byte header (``seq_number`` u16,
``session``, ``opcode``, ``size``, ``req_opcode``, ``burst_complete``, padding, ``offset``
u32) and up to 239 data bytes; each request is answered ACK (128) or NAK (129) with
``seq_number`` + 1 and ``req_opcode`` set to the request's opcode; a NAK carries an error
code (and an errno after ``FailErrno``). As PX4, a link has one session at a time, closed
after 10 s without activity, and a request repeated with the same sequence number (its
answer was lost) gets the same answer again. The session's id is the one the client sent
with ``OpenFileRO`` (MAVSDK sends 0, the only id PX4 has; MAVProxy picks its own, as
ArduPilot lets it, and routes the answers by it).

Served (the tree is :mod:`ft_sitl.mavlink.files`): ``TerminateSession``, ``ResetSessions``,
``ListDirectory``, ``OpenFileRO``, ``ReadFile``, ``BurstReadFile``, ``CalcFileCRC32``.
Refused: every write (``CreateFile``, ``WriteFile``, ``RemoveFile``, ``CreateDirectory``,
``RemoveDirectory``, ``OpenFileWO``, ``TruncateFile``, ``Rename``) with ``FileProtected``,
other opcodes with ``UnknownCommand`` (so MAVSDK's ``ListDirectoryWithTime``, 16, falls
back to ``ListDirectory``). Bad input is answered, never raised: ``InvalidDataSize``,
``InvalidSession``, ``EOF``, ``FileNotFound``, ``FailErrno`` (``EACCES`` for ``..``,
``ENAMETOOLONG``, ``EISDIR``, ``ENOTDIR``, a host read error's errno).
"""

from __future__ import annotations

import errno
import struct
import zlib
from dataclasses import dataclass
from enum import IntEnum

from pymavlink.dialects.v20 import common as mav

from ft_sitl.mavlink import files

#: seq_number, session, opcode, size, req_opcode, burst_complete, padding, offset
HEADER = struct.Struct("<HBBBBBBI")
PAYLOAD_LEN = 251  # FILE_TRANSFER_PROTOCOL.payload
MAX_DATA = PAYLOAD_LEN - HEADER.size  # 239
#: an open session without a request (or burst packet) for this long is closed (PX4: 10 s)
SESSION_IDLE_US = 10_000_000
#: a burst ends (burst_complete) after this many bytes and the client asks for the next
#: one (PX4 sends bursts of about 35 kB)
BURST_MAX_BYTES = 35_000
#: burst packets sent per pass of the server loop, so a client's receive buffer keeps up
BURST_PACKETS_PER_POLL = 20


class Op(IntEnum):
    NONE = 0
    TERMINATE_SESSION = 1
    RESET_SESSIONS = 2
    LIST_DIRECTORY = 3
    OPEN_FILE_RO = 4
    READ_FILE = 5
    CREATE_FILE = 6
    WRITE_FILE = 7
    REMOVE_FILE = 8
    CREATE_DIRECTORY = 9
    REMOVE_DIRECTORY = 10
    OPEN_FILE_WO = 11
    TRUNCATE_FILE = 12
    RENAME = 13
    CALC_FILE_CRC32 = 14
    BURST_READ_FILE = 15
    ACK = 128
    NAK = 129


class Err(IntEnum):
    NONE = 0
    FAIL = 1
    FAIL_ERRNO = 2
    INVALID_DATA_SIZE = 3
    INVALID_SESSION = 4
    NO_SESSIONS_AVAILABLE = 5
    EOF = 6
    UNKNOWN_COMMAND = 7
    FILE_EXISTS = 8
    FILE_PROTECTED = 9
    FILE_NOT_FOUND = 10


#: the opcodes that would change the file system: all refused (FileProtected)
WRITES = frozenset({Op.CREATE_FILE, Op.WRITE_FILE, Op.REMOVE_FILE, Op.CREATE_DIRECTORY,
                    Op.REMOVE_DIRECTORY, Op.OPEN_FILE_WO, Op.TRUNCATE_FILE, Op.RENAME})


@dataclass(frozen=True)
class Header:
    seq: int
    session: int
    opcode: int
    size: int
    req_opcode: int
    burst_complete: int
    offset: int


class Nak(Exception):
    """A request refused with an FTP error code (and an errno after FAIL_ERRNO)."""

    def __init__(self, err: Err, errno_: int = 0):
        super().__init__(err.name)
        self.err = err
        self.errno = errno_


def mavlink_crc32(data: bytes, crc: int = 0) -> int:
    """The CRC32 of MAVLink FTP's CalcFileCRC32 (PX4's ``crc32part``, MAVSDK's ``Crc32``):
    the ISO 3309 polynomial, but starting at 0 and without the final XOR; ``crc`` continues
    a previous value."""
    return zlib.crc32(data, crc ^ 0xFFFFFFFF) ^ 0xFFFFFFFF


def pack(h: Header, data: bytes = b"") -> list[int]:
    """A FILE_TRANSFER_PROTOCOL payload (251 bytes) from a header and its data."""
    raw = HEADER.pack(h.seq, h.session, h.opcode, len(data), h.req_opcode, h.burst_complete,
                      0, h.offset) + data
    return list(raw.ljust(PAYLOAD_LEN, b"\0"))


def unpack(payload) -> tuple[Header, bytes]:
    """Header and data (``size`` bytes, at most what the payload holds) of a payload."""
    raw = bytes(payload).ljust(PAYLOAD_LEN, b"\0")
    seq, session, opcode, size, req_opcode, burst, _pad, offset = HEADER.unpack_from(raw)
    return (Header(seq, session, opcode, size, req_opcode, burst, offset),
            raw[HEADER.size:HEADER.size + min(size, MAX_DATA)])


def _path(data: bytes) -> str:
    """The path a request carries: its data up to the first NUL. A path that fills the
    whole data field leaves no room for the NUL PX4 needs: ENAMETOOLONG (PX4 would cut it
    silently)."""
    raw = data.split(b"\0", 1)[0]
    if len(raw) >= MAX_DATA:
        raise Nak(Err.FAIL_ERRNO, errno.ENAMETOOLONG)
    return raw.decode("utf-8", "surrogateescape")


def _path_nak(exc: files.PathError) -> Nak:
    if isinstance(exc, files.PathForbidden):
        return Nak(Err.FAIL_ERRNO, errno.EACCES)
    return Nak(Err.FILE_NOT_FOUND)


class FtpServer:
    """One link's FTP server (PX4 runs one per MAVLink instance): one session at a time."""

    def __init__(self, root: files.Directory):
        self.root = root
        self._file: files.OpenFile | None = None
        self._session = 0  # the open session's id: the client's, from its OpenFileRO
        self._last_use_us = 0
        #: (request header and data, reply payload) of the last answered request
        self._last: tuple[tuple, list[int]] | None = None
        # a burst in progress: next offset, next seq_number, bytes sent, the client's ids
        self._burst: dict | None = None

    @property
    def bursting(self) -> bool:
        return self._burst is not None

    def handle(self, m, wall_us: int) -> list:
        """Answer one FILE_TRANSFER_PROTOCOL request (a burst's packets come from
        :meth:`stream`)."""
        h, data = unpack(m.payload)
        self._expire(wall_us)
        self._last_use_us = wall_us
        key = (h, data)
        if self._last is not None and self._last[0] == key:
            return [self._message(self._last[1], m.get_srcSystem(), m.get_srcComponent())]
        try:
            if h.size > MAX_DATA:
                raise Nak(Err.INVALID_DATA_SIZE)
            reply = self._work(h, data, m.get_srcSystem(), m.get_srcComponent())
        except Nak as nak:
            reply = self._nak(h, nak)
        except OSError as exc:  # the host file behind a served file failed
            reply = self._nak(h, _os_nak(exc))
        if reply is None:  # a burst started: its packets are the answer
            self._last = None
            return []
        self._last = (key, reply)
        return [self._message(reply, m.get_srcSystem(), m.get_srcComponent())]

    def stream(self, wall_us: int) -> list:
        """The next packets of a burst in progress (none when there is none)."""
        out = []
        while self._burst is not None and len(out) < BURST_PACKETS_PER_POLL:
            payload, more = self._burst_packet()
            out.append(self._message(payload, *self._burst["to"]))
            if not more:
                self._burst = None
        if out:
            self._last_use_us = wall_us
        return out

    def _burst_packet(self) -> tuple[list[int], bool]:
        """One burst packet and whether more follow: data from the burst's offset, ending
        the burst (burst_complete) after BURST_MAX_BYTES; past the end of the file a NAK
        EOF, which ends the transfer (PX4's stream)."""
        b, f = self._burst, self._file
        h = Header(b["seq"], self._session, Op.ACK, 0, Op.BURST_READ_FILE, 0, b["offset"])
        b["seq"] = (b["seq"] + 1) & 0xFFFF
        try:
            if f is None or b["offset"] >= f.size:
                raise Nak(Err.EOF)
            data = f.read(b["offset"], MAX_DATA)
            if not data:  # the host file shrank under the snapshot
                raise Nak(Err.EOF)
        except Nak as nak:
            return self._nak(h, nak, keep_opcode=True), False
        except OSError as exc:
            return self._nak(h, _os_nak(exc), keep_opcode=True), False
        b["offset"] += len(data)
        b["sent"] += len(data)
        complete = b["sent"] >= BURST_MAX_BYTES and b["offset"] < f.size
        return pack(Header(h.seq, h.session, Op.ACK, 0, Op.BURST_READ_FILE, int(complete),
                           h.offset), data), not complete

    # --- the requests ---------------------------------------------------------------
    def _work(self, h: Header, data: bytes, sysid: int, compid: int) -> list[int] | None:
        op = h.opcode
        if op == Op.NONE:
            return self._ack(h)
        if op == Op.TERMINATE_SESSION:
            self._check_session(h)
            self._close()
            return self._ack(h)
        if op == Op.RESET_SESSIONS:
            self._close()
            return self._ack(h)
        if op == Op.LIST_DIRECTORY:
            return self._ack(h, self._list(_path(data), h.offset))
        if op == Op.OPEN_FILE_RO:
            if self._file is not None:
                raise Nak(Err.NO_SESSIONS_AVAILABLE)
            self._file = self._node_file(_path(data)).open()
            self._session = h.session
            return self._ack(h, struct.pack("<I", min(self._file.size, 0xFFFFFFFF)))
        if op == Op.READ_FILE:
            self._check_session(h)
            if h.offset >= self._file.size:
                raise Nak(Err.EOF)
            return self._ack(h, self._file.read(h.offset, min(h.size, MAX_DATA)))
        if op == Op.BURST_READ_FILE:
            self._check_session(h)
            self._burst = {"offset": h.offset, "seq": (h.seq + 1) & 0xFFFF, "sent": 0,
                           "to": (sysid, compid)}
            return None
        if op == Op.CALC_FILE_CRC32:
            return self._ack(h, struct.pack("<I", self._crc32(_path(data))))
        if op in WRITES:
            raise Nak(Err.FILE_PROTECTED)
        raise Nak(Err.UNKNOWN_COMMAND)

    def _list(self, path: str, first: int) -> bytes:
        """Entries from index ``first`` that fit in one answer: ``D<name>`` for a directory,
        ``F<name>\\t<size>`` for a file, each NUL-terminated. Past the end: EOF (an empty
        directory at index 0 answers no entries, as PX4)."""
        try:
            node = files.lookup(self.root, path)
        except files.PathError as exc:
            raise _path_nak(exc) from None
        if not isinstance(node, files.Directory):
            raise Nak(Err.FILE_NOT_FOUND)  # PX4: opendir fails
        entries = node.listing()
        if first >= len(entries) and first > 0:
            raise Nak(Err.EOF)
        out = b""
        for name, child in entries[first:]:
            if isinstance(child, files.Directory):
                text = b"D" + name.encode()
            else:
                try:
                    size = child.size()
                except OSError:  # PX4 lists a file it cannot stat with size 0
                    size = 0
                text = b"F" + name.encode() + b"\t" + str(size).encode()
            if len(out) + len(text) + 1 > MAX_DATA:
                break
            out += text + b"\0"
        return out

    def _crc32(self, path: str) -> int:
        f = self._node_file(path).open()
        try:
            crc, offset = 0, 0
            while offset < f.size:
                chunk = f.read(offset, 1 << 16)
                if not chunk:
                    break
                crc = mavlink_crc32(chunk, crc)
                offset += len(chunk)
            return crc
        finally:
            f.close()

    # --- helpers ----------------------------------------------------------------------
    def _node_file(self, path: str):
        try:
            node = files.lookup(self.root, path)
        except files.PathError as exc:
            raise _path_nak(exc) from None
        if isinstance(node, files.Directory):
            raise Nak(Err.FAIL_ERRNO, errno.EISDIR)
        return node

    def _check_session(self, h: Header) -> None:
        if self._file is None or h.session != self._session:
            raise Nak(Err.INVALID_SESSION)

    def _close(self) -> None:
        if self._file is not None:
            self._file.close()
        self._file = None
        self._burst = None

    def _expire(self, wall_us: int) -> None:
        if self._file is not None and wall_us - self._last_use_us > SESSION_IDLE_US:
            self._close()  # the client went away mid-transfer (PX4 does the same)
            self._last = None

    @staticmethod
    def _ack(h: Header, data: bytes = b"") -> list[int]:
        return pack(Header((h.seq + 1) & 0xFFFF, h.session, Op.ACK, 0, h.opcode, 0, h.offset),
                    data)

    @staticmethod
    def _nak(h: Header, nak: Nak, keep_opcode: bool = False) -> list[int]:
        """A NAK answering ``h`` (for a burst packet, ``h`` is already the reply's header)."""
        data = bytes([nak.err, nak.errno]) if nak.err == Err.FAIL_ERRNO else bytes([nak.err])
        if keep_opcode:
            return pack(Header(h.seq, h.session, Op.NAK, 0, h.req_opcode, 0, h.offset), data)
        return pack(Header((h.seq + 1) & 0xFFFF, h.session, Op.NAK, 0, h.opcode, 0, h.offset),
                    data)

    @staticmethod
    def _message(payload: list[int], sysid: int, compid: int):
        return mav.MAVLink_file_transfer_protocol_message(0, sysid, compid, payload)


def _os_nak(exc: OSError) -> Nak:
    if exc.errno == errno.ENOENT:
        return Nak(Err.FILE_NOT_FOUND)  # (PX4 turns ENOENT into FileNotFound too)
    return Nak(Err.FAIL_ERRNO, (exc.errno or errno.EIO) & 0xFF)
