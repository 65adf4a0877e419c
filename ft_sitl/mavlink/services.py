"""The byte-stream services of a vehicle: its shell (SERIAL_CONTROL), MAVLink FTP and
log download, one server of each protocol per link, as PX4 keeps one per mavlink
instance, so transfers on two links never mix. The protocols themselves live in
:mod:`ft_sitl.mavlink.shell`, :mod:`ft_sitl.mavlink.ftp` and :mod:`ft_sitl.mavlink.logs`;
this module routes their messages and remembers which peer each link's transfer is for.
"""

from __future__ import annotations

from collections.abc import Callable

from pymavlink.dialects.v20 import common as mav

from ft_sitl.mavlink import files
from ft_sitl.mavlink.ftp import FtpServer
from ft_sitl.mavlink.logs import LogServer
from ft_sitl.mavlink.outgoing import Outgoing
from ft_sitl.mavlink.shell import Shell

#: SERIAL_CONTROL's data field: the most bytes one message carries
SERIAL_CHUNK = 70


class Services:
    """Shell, FTP and logs of one vehicle with ``n_links`` links. ``shell`` is the
    vehicle's shell; ``params_file`` makes the parameter file FTP serves; ``warn``
    reports a log server's trouble as a STATUSTEXT."""

    def __init__(self, shell: Shell, n_links: int, params_file: Callable[[], bytes],
                 logs: list[files.LogFile], warn: Callable[[str], None]):
        self.shell = shell
        tree = files.vehicle_tree(params_file, list(logs))
        self._ftp = [FtpServer(tree) for _ in range(n_links)]
        self._logs = [LogServer(list(logs), warn) for _ in range(n_links)]
        self._ftp_peer: dict[int, tuple] = {}
        self._log_peer: dict[int, tuple] = {}

    def on_serial_control(self, m, link, peer, wall_us):
        """SERIAL_CONTROL to the shell device: run its lines, answer with their output in
        SERIAL_CONTROL replies of at most 70 bytes (mavlink/shell.py)."""
        if m.device != mav.SERIAL_CONTROL_DEV_SHELL:
            return []
        n = max(0, min(int(m.count), SERIAL_CHUNK))
        text = self.shell.feed(bytes(m.data[:n]))
        raw = text.encode("ascii", "replace")
        out = []
        for k in range(0, len(raw), SERIAL_CHUNK):
            chunk = raw[k:k + SERIAL_CHUNK]
            out.append(Outgoing(mav.MAVLink_serial_control_message(
                mav.SERIAL_CONTROL_DEV_SHELL, mav.SERIAL_CONTROL_FLAG_REPLY, 0, 0, len(chunk),
                list(chunk) + [0] * (SERIAL_CHUNK - len(chunk))), link, peer))
        return out

    def on_file_transfer_protocol(self, m, link, peer, wall_us):
        self._ftp_peer[link] = peer
        return [Outgoing(r, link, peer) for r in self._ftp[link].handle(m, wall_us)]

    def on_log(self, m, link, peer, wall_us):
        self._log_peer[link] = peer
        return [Outgoing(r, link, peer) for r in self._logs[link].handle(m)]

    def poll(self, wall_us: int) -> list[Outgoing]:
        """FTP bursts and log data on, to the peer that asked on each link."""
        out = []
        for link, ftp in enumerate(self._ftp):
            if ftp.bursting:
                out += [Outgoing(r, link, self._ftp_peer[link]) for r in ftp.stream(wall_us)]
        for link, logs in enumerate(self._logs):
            if logs.sending:
                out += [Outgoing(r, link, self._log_peer[link]) for r in logs.stream()]
        return out
