"""The UDP ports of a SITL instance and who holds one that is taken.

Instance i is PX4 SITL instance i: the vehicle listens on 14580+i (API) and 18570+i (GCS)
and sends to 127.0.0.1:14540+i, where a MAVSDK or pymavlink client listens. A port another
program holds is named with that program (its pid and command line, read from Linux's
/proc) so the error says what to stop, not only "Address already in use".
"""

from __future__ import annotations

import errno
import os
import socket
from pathlib import Path

from ft_sitl.mavlink.server import API_LISTEN_BASE, API_REMOTE_BASE, GCS_LISTEN_BASE

PROC = Path("/proc")
#: the most of a holder's command line an error shows
CMDLINE_SHOWN = 120


def instance_ports(i: int) -> dict[str, int]:
    """Instance i's ports by role: ``client`` (the API link sends there), ``api_listen``,
    ``gcs_listen``."""
    return {"client": API_REMOTE_BASE + i, "api_listen": API_LISTEN_BASE + i,
            "gcs_listen": GCS_LISTEN_BASE + i}


ROLES = {"client": "the MAVSDK/pymavlink client port", "api_listen": "the API listen port",
         "gcs_listen": "the GCS listen port"}


def udp_port_free(host: str, port: int) -> bool:
    """Whether a UDP socket can bind ``host:port`` now (it is closed again at once)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_DGRAM) as s:
        try:
            s.bind((host, port))
        except OSError as exc:
            if exc.errno in (errno.EADDRINUSE, errno.EACCES):
                return False
            raise
    return True


#: the /proc/net tables searched for a port's sockets: UDP (the PX4 face) and TCP (the
#: ArduCopter face's serial ports); a number is rarely held in both by different programs
TABLES = ("udp", "udp6", "tcp", "tcp6")


def _socket_inodes(port: int, proc: Path) -> set[str]:
    """The inodes of the UDP and TCP sockets on local ``port`` (any address)."""
    inodes = set()
    for table in TABLES:
        try:
            lines = (proc / "net" / table).read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            f = line.split()
            # sl local_address rem_address st tx:rx tr:when retrnsmt uid timeout inode
            if len(f) > 9 and int(f[1].rsplit(":", 1)[1], 16) == port:
                inodes.add(f[9])
    return inodes


def port_holders(port: int, proc: Path = PROC) -> list[str] | None:
    """The processes holding ``port`` (UDP or TCP), as ``pid N (command line)``: [] when the
    socket's owner is not visible to this user, None where there is no /proc (not Linux)."""
    if not (proc / "net" / "udp").exists():
        return None
    inodes = _socket_inodes(port, proc)
    if not inodes:
        return []
    wanted = {f"socket:[{i}]" for i in inodes}
    found = []
    for pid_dir in proc.iterdir():
        if not pid_dir.name.isdigit():
            continue
        try:
            fds = list((pid_dir / "fd").iterdir())
        except OSError:  # another user's process, or it ended
            continue
        for fd in fds:
            try:
                if os.readlink(fd) in wanted:
                    cmd = " ".join((pid_dir / "cmdline").read_bytes().decode(
                        errors="replace").replace("\0", " ").split())
                    if len(cmd) > CMDLINE_SHOWN:
                        cmd = cmd[:CMDLINE_SHOWN - 3] + "..."
                    found.append(f"pid {pid_dir.name} ({cmd})")
                    break
            except OSError:
                continue
    return found


def describe_holder(port: int) -> str:
    """Who holds ``port`` (UDP or TCP), for an error message."""
    holders = port_holders(port)
    if holders is None:
        return "held by another program (this system does not say which)"
    if not holders:
        return "held by a process this user cannot see (another user's, or one that just ended)"
    return "held by " + ", ".join(holders)


def taken_ports(i: int, bind: str, client: bool) -> list[tuple[str, int]]:
    """Instance i's ports that cannot be bound now: its listen ports on ``bind`` and, with
    ``client``, the client port on every address (a client listening there, a PX4 SITL)."""
    ports = instance_ports(i)
    taken = [(role, ports[role]) for role in ("api_listen", "gcs_listen")
             if not udp_port_free(bind, ports[role])]
    if client and not udp_port_free("0.0.0.0", ports["client"]):
        taken.append(("client", ports["client"]))
    return taken


def taken_message(i: int, taken: list[tuple[str, int]]) -> str:
    """One line naming instance i's taken ports and who holds each."""
    return "; ".join(f"UDP port {port} ({ROLES[role]} of instance {i}) is "
                     f"{describe_holder(port)}" for role, port in taken)
