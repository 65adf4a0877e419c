"""The MAVLink log protocol (``LOG_REQUEST_LIST`` / ``LOG_ENTRY`` / ``LOG_REQUEST_DATA`` /
``LOG_DATA`` / ``LOG_REQUEST_END`` / ``LOG_ERASE``), as PX4's ``mavlink_log_handler.cpp``
answers MAVSDK's LogFiles plugin and QGroundControl's log download.

The logs are the vehicle's :class:`~ft_sitl.mavlink.files.LogFile` s (the server's
telemetry log with ``--tlog``, otherwise none). As PX4:

* ``LOG_REQUEST_LIST`` (start, end) answers one ``LOG_ENTRY`` per log in the range (ids
  from 0, clamped to the last), each with ``num_logs``, ``last_log_num``, the size at the
  time of the request and the start time; with no logs, one ``LOG_ENTRY`` with
  ``num_logs`` 0, so a client learns at once that there is nothing (MAVSDK: NO_LOGFILES);
* ``LOG_REQUEST_DATA`` (id, ofs, count) streams ``LOG_DATA`` of 90 bytes from ``ofs``,
  up to ``count`` bytes and the size the list reported; at or past the end, one
  ``LOG_DATA`` with ``count`` 0;
* ``LOG_REQUEST_END`` stops a transfer.

Where PX4 differs: it ignores a request for a log that does not exist (the client times
out); here it is answered with an empty ``LOG_DATA`` and a status text. PX4 erases its
logs on ``LOG_ERASE``; here the logs are the user's files and are not touched (a status
text says so).
"""

from __future__ import annotations

from collections.abc import Callable

from pymavlink.dialects.v20 import common as mav

from ft_sitl.mavlink.files import LogFile, OpenFile

#: LOG_DATA.data
DATA_LEN = 90
#: LOG_DATA messages sent per pass of the server loop while streaming
PACKETS_PER_POLL = 40


class LogServer:
    """One link's log handler (PX4 runs one per MAVLink instance)."""

    def __init__(self, logs: list[LogFile], notice: Callable[[str], None]):
        self.logs = list(logs)
        self._notice = notice
        #: the sizes reported by the last LOG_REQUEST_LIST (data is served up to them)
        self._sizes: list[int] | None = None
        # a transfer in progress: log id, its open file, next offset, end offset
        self._send: dict | None = None

    @property
    def sending(self) -> bool:
        return self._send is not None

    def handle(self, m) -> list:
        """Answer one LOG_REQUEST_LIST, LOG_REQUEST_DATA, LOG_REQUEST_END or LOG_ERASE."""
        return {"LOG_REQUEST_LIST": self.on_request_list,
                "LOG_REQUEST_DATA": self.on_request_data,
                "LOG_REQUEST_END": self.on_request_end,
                "LOG_ERASE": self.on_erase}[m.get_type()](m)

    def on_request_list(self, m) -> list:
        sizes = self._list()
        n = len(sizes)
        if n == 0:
            return [mav.MAVLink_log_entry_message(0, 0, 0, 0, 0)]
        first = min(max(m.start, 0), n - 1)
        last = max(min(m.end, n - 1), first)
        return [mav.MAVLink_log_entry_message(i, n, last, self.logs[i].time_utc,
                                              min(sizes[i], 0xFFFFFFFF))
                for i in range(first, last + 1)]

    def on_request_data(self, m) -> list:
        self._stop()
        sizes = self._sizes if self._sizes is not None else self._list()
        if not 0 <= m.id < len(sizes):
            self._notice(f"Log {m.id} does not exist ({len(sizes)} logs)")
            return [_data(m.id, m.ofs, b"")]
        try:
            f = self.logs[m.id].file.open()
        except OSError as exc:
            self._notice(f"Log {m.id} unreadable: {exc.strerror}")
            return [_data(m.id, m.ofs, b"")]
        end = min(sizes[m.id], f.size, m.ofs + max(m.count, 0))
        self._send = {"id": m.id, "file": f, "ofs": m.ofs, "end": end}
        return self.stream()

    def on_request_end(self, m) -> list:
        self._stop()
        return []

    def on_erase(self, m) -> list:
        self._stop()
        self._notice("Log erase refused: the logs are read-only")
        return []

    def stream(self) -> list:
        """The next LOG_DATA of a transfer in progress; the last one is shorter than 90
        bytes or ends the requested range (one with count 0 when nothing is left)."""
        out = []
        s = self._send
        while s is not None and len(out) < PACKETS_PER_POLL:
            n = min(DATA_LEN, s["end"] - s["ofs"])
            try:
                chunk = s["file"].read(s["ofs"], n) if n > 0 else b""
            except OSError as exc:
                self._notice(f"Log {s['id']} unreadable: {exc.strerror}")
                chunk = b""
            out.append(_data(s["id"], s["ofs"], chunk))
            s["ofs"] += len(chunk)
            if len(chunk) < DATA_LEN or s["ofs"] >= s["end"]:
                self._stop()
                s = None
        return out

    def _list(self) -> list[int]:
        sizes = []
        for log in self.logs:
            try:
                sizes.append(log.file.size())
            except OSError:  # (PX4 lists a log it cannot stat with size 0)
                sizes.append(0)
        self._sizes = sizes
        return sizes

    def _stop(self) -> None:
        if self._send is not None:
            f: OpenFile = self._send["file"]
            f.close()
        self._send = None


def _data(log_id: int, ofs: int, chunk: bytes):
    return mav.MAVLink_log_data_message(log_id & 0xFFFF, ofs & 0xFFFFFFFF, len(chunk),
                                        list(chunk.ljust(DATA_LEN, b"\0")))
