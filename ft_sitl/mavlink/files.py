"""The read-only files a vehicle serves to ground stations: MAVLink FTP (``ftp.py``) and
the log protocol (``logs.py``) read the same tree.

PX4 SITL serves its working directory (``rootfs``) over FTP and keeps its flight logs in
``log/<date>/<time>.ulg`` there. ft-sitl writes no ULog; what it serves is::

    /log/YYYY-MM-DD/HH_MM_SS.tlog   the server's telemetry log (only with --tlog), named
                                    by the UTC time the server started, read where it is
    /ft-sitl/params.txt             the vehicle's parameters, one per line in
                                    QGroundControl's parameter-file format

Every file is opened as a snapshot: its size is fixed when it is opened (a telemetry log
keeps growing; re-open it to see more), as PX4's FTP fixes the size at open.

Paths are absolute (``/log``; a missing leading ``/`` is tolerated); ``.`` and empty
components are ignored. A ``..`` component is refused (:class:`PathForbidden`) rather than
resolved: nothing is above the root. Nothing can be written.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from pymavlink.dialects.v20 import common as mav


class PathError(Exception):
    """A path that names nothing servable."""


class PathNotFound(PathError):
    """No such file or directory."""


class PathForbidden(PathError):
    """A ``..`` component: refused, not resolved."""


class NotADirectory(PathError):
    """A directory operation on a file."""


class IsADirectory(PathError):
    """A file operation on a directory."""


class OpenFile:
    """A file opened for reading: ``size`` is fixed at open, ``read`` never goes past it.

    ``read`` raises OSError when the host file behind it fails (removed, unreadable)."""

    def __init__(self, size: int, read: Callable[[int, int], bytes],
                 close: Callable[[], None] = lambda: None):
        self.size = size
        self._read = read
        self._close = close

    def read(self, offset: int, n: int) -> bytes:
        if offset >= self.size or n <= 0:
            return b""
        return self._read(offset, min(n, self.size - offset))

    def close(self) -> None:
        self._close()


@dataclass(frozen=True)
class GeneratedFile:
    """A file whose bytes are made when it is opened (a snapshot of live state)."""

    make: Callable[[], bytes]

    def open(self) -> OpenFile:
        data = self.make()
        return OpenFile(len(data), lambda offset, n: data[offset:offset + n])

    def size(self) -> int:
        return len(self.make())


@dataclass(frozen=True)
class HostFile:
    """A file on the host, read where it is; ``flush`` first makes pending writes of the
    process that writes it visible (the server's telemetry log is buffered)."""

    path: Path
    flush: Callable[[], None] = lambda: None

    def open(self) -> OpenFile:
        self.flush()
        fh = open(self.path, "rb")  # noqa: SIM115 - closed by OpenFile.close
        size = os.fstat(fh.fileno()).st_size

        def read(offset: int, n: int) -> bytes:
            fh.seek(offset)
            return fh.read(n)

        return OpenFile(size, read, fh.close)

    def size(self) -> int:
        self.flush()
        return os.stat(self.path).st_size


@dataclass
class Directory:
    """A directory: names to files or directories, listed in name order."""

    entries: dict[str, Directory | GeneratedFile | HostFile] = field(default_factory=dict)

    def listing(self) -> list[tuple[str, Directory | GeneratedFile | HostFile]]:
        return sorted(self.entries.items())


@dataclass(frozen=True)
class LogFile:
    """A flight log as the log protocol lists it: its directory and name under /log, the
    UTC time it was started (seconds since the epoch) and the file."""

    day: str
    name: str
    time_utc: int
    file: HostFile


def telemetry_log(path: Path, flush: Callable[[], None],
                  started: float | None = None) -> LogFile:
    """The server's telemetry log as PX4 names a log: ``YYYY-MM-DD/HH_MM_SS``, by the UTC
    time the server started, with the ``.tlog`` extension it really has."""
    t = time.time() if started is None else started
    utc = time.gmtime(t)
    return LogFile(time.strftime("%Y-%m-%d", utc), time.strftime("%H_%M_%S.tlog", utc),
                   int(t), HostFile(Path(path), flush))


def params_file(sysid: int, compid: int, values: list[tuple[str, float, int]]) -> bytes:
    """Parameters as QGroundControl writes a parameter file (and loads one): a comment
    header, then ``sysid compid NAME VALUE TYPE`` tab-separated; ``values`` is (name,
    value, MAV_PARAM_TYPE) in order."""
    lines = [f"# Onboard parameters for Vehicle {sysid} (ft-sitl)\n",
             "#\n# Vehicle-Id Component-Id Name Value Type\n"]
    for name, value, ptype in values:
        text = str(int(value)) if ptype == mav.MAV_PARAM_TYPE_INT32 else repr(float(value))
        lines.append(f"{sysid}\t{compid}\t{name}\t{text}\t{ptype}\n")
    return "".join(lines).encode("ascii")


def vehicle_tree(params_text: Callable[[], bytes], logs: list[LogFile]) -> Directory:
    """The tree one vehicle serves (see the module docstring)."""
    log_dir = Directory()
    for log in logs:
        log_dir.entries.setdefault(log.day, Directory()).entries[log.name] = log.file
    return Directory({"log": log_dir,
                      "ft-sitl": Directory({"params.txt": GeneratedFile(params_text)})})


def lookup(root: Directory, path: str) -> Directory | GeneratedFile | HostFile:
    """The node at ``path``; PathError when there is none or the path is refused."""
    node: Directory | GeneratedFile | HostFile = root
    for part in path.split("/"):
        if part in ("", "."):
            continue
        if part == "..":
            raise PathForbidden(path)
        if not isinstance(node, Directory):
            raise NotADirectory(path)
        if part not in node.entries:
            raise PathNotFound(path)
        node = node.entries[part]
    return node
