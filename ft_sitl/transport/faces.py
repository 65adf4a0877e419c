"""Which autopilot's MAVLink face serves a wire trial (``--autopilot``): PX4's (the default,
:class:`~ft_sitl.mavlink.server.SitlServer`) or ArduCopter's
(:class:`~ft_sitl.mavlink.ardupilot.server.ArduPilotServer`), and where its navigator
client connects.

The face is the protocol only; the vehicle is the trial's. The ArduCopter face writes
ArduCopter's defaults (WPNAV_*, PSC_*, ANGLE_MAX, FENCE_*, ...) into the flight
controller's parameters when it starts, which would fly another tuning than the trial's
spec names (a 30 degree lean limit instead of PX4's 45, other gains): a wire trial puts
the trial's parameters back (:func:`serve`), so the vehicle flies as in-process and only
what crosses the wire changes (docs/wire.md, "Autopilots").

A lockstep trial serves the links between its own physics steps, without an event loop
(:meth:`SitlServer.open`, :meth:`SitlServer.pump`). The ArduCopter face has no such mode
of its own (it serves TCP under asyncio); :class:`LockstepArduPilotServer` serves it as
ArduPilot SITL forwards to a ground station with MAVProxy's ``--out``: SERIAL0's
messages go to the client's UDP port (the instance's client port, as the PX4 face's),
and what the client sends from there is answered on SERIAL0. A free-running trial
(:class:`FreeRunningArduPilotServer`) serves the same UDP link under the event loop,
paced as the PX4 face's (SitlServer ``run``); no TCP port is bound, so a trial holds
only its instance's UDP ports.

Over the ArduCopter face the navigator client asks for its telemetry's rates itself
(ArduPilot streams nothing but HEARTBEAT until asked: :mod:`ft_sitl.wire.navigate`
``ARDUPILOT_RATES_HZ``), as a MAVSDK user on ArduPilot does.
"""

from __future__ import annotations

import asyncio
import socket

from ft_sitl import frames
from ft_sitl.mavlink.ardupilot.framing import FrameSplitter
from ft_sitl.mavlink.ardupilot.server import ArduPilotServer
from ft_sitl.mavlink.autopilots import AUTOPILOTS, DEFAULT_AUTOPILOT, PX4
from ft_sitl.mavlink.server import API_REMOTE_BASE, SitlServer

__all__ = ["AUTOPILOTS", "DEFAULT_AUTOPILOT", "FreeRunningArduPilotServer",
           "LockstepArduPilotServer", "check_autopilot", "client_port", "serve"]


def check_autopilot(name) -> str:
    """``name`` if it is a face (ValueError naming the allowed ones)."""
    if name not in AUTOPILOTS:
        raise ValueError(f"--autopilot: {name!r} is not one of {', '.join(AUTOPILOTS)}")
    return name


class _UdpOut:
    """SERIAL0's transport in lockstep: one UDP socket; a message for every client goes to
    the ``--out`` targets, a reply to the peer that asked."""

    def __init__(self, sock: socket.socket, targets: list[tuple[str, int]]):
        self.sock, self.targets = sock, targets

    def sendto(self, data: bytes, dest) -> None:
        for addr in (self.targets if dest is None else [dest]):
            try:
                self.sock.sendto(data, addr)
            except (BlockingIOError, ConnectionRefusedError):
                pass  # as a lost datagram (the client not listening yet)

    def close(self) -> None:
        self.sock.close()


class LockstepArduPilotServer(ArduPilotServer):
    """The ArduCopter face served without an event loop (module docstring): SERIAL0 on a
    UDP socket sending to ``outs``; SERIAL1 not served."""

    def open(self) -> None:
        for link in self.links:
            if link.index != 0:
                continue
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                sock.setblocking(False)
                sock.bind((self.bind, 0))
            except OSError:
                sock.close()
                self.close()
                raise
            link.transport = _UdpOut(sock, list(self.outs))

    def on_received(self, link, data: bytes, addr) -> None:
        for frame in FrameSplitter().feed(data):  # (a datagram may carry several frames)
            self.on_datagram(link, frame, addr)


class _Datagrams(asyncio.DatagramProtocol):
    """SERIAL0's UDP socket under the event loop: what arrives goes to the server."""

    def __init__(self, server: LockstepArduPilotServer, link):
        self.server, self.link = server, link

    def datagram_received(self, data: bytes, addr) -> None:
        self.server.on_received(self.link, data, addr)

    def error_received(self, exc) -> None:  # the client not listening yet
        pass


class FreeRunningArduPilotServer(LockstepArduPilotServer):
    """The ArduCopter face of a free-running wire trial: SERIAL0 on a UDP socket sending to
    ``outs``, served under the event loop (:meth:`start`, then SitlServer ``run``, paced
    as the PX4 face's); SERIAL1 and the TCP ports not served."""

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        try:
            for link in self.links:
                if link.index != 0:
                    continue
                transport, _ = await loop.create_datagram_endpoint(
                    lambda link=link: _Datagrams(self, link), local_addr=(self.bind, 0))
                link.transport = _UdpOut(transport, list(self.outs))
        except OSError:
            self.close()
            raise


def client_port(instance: int) -> int:
    """The UDP port a navigator client listens on for instance ``instance`` (the one the
    instance lock reserves for it: PX4 SITL's 14540 + i)."""
    return API_REMOTE_BASE + instance


def serve(autopilot: str, fleet, instance: int, *, lockstep: bool,
          speed_factor: float = 1.0,
          pace_span_s: float | None = None) -> tuple[SitlServer, str]:
    """The face ``autopilot`` serving ``fleet`` as ``instance`` (bound: :meth:`open` in
    lockstep; started later under an event loop otherwise), the trial's parameters kept,
    and the MAVSDK URL its client connects with; free-running at ``speed_factor``, with
    ``pace_span_s`` client-paced (SitlServer ``pace="client"``)."""
    geo = frames.GeoReference(*frames.PX4_SITL_HOME)
    port = client_port(instance)
    pacing = {} if lockstep else {"speed_factor": speed_factor,
                                  "pace": "wall" if pace_span_s is None else "client",
                                  "pace_span_s": pace_span_s}
    if check_autopilot(autopilot) == PX4:
        server = SitlServer(fleet, geo, speed_factor=speed_factor, base_instance=instance,
                            pace="wall" if pace_span_s is None else "client",
                            pace_span_s=pace_span_s, gcs_link=False)
    else:
        trial_params = [p.as_dict() for p in fleet.params]
        face = LockstepArduPilotServer if lockstep else FreeRunningArduPilotServer
        server = face(fleet, geo, base_instance=instance, outs=[("127.0.0.1", port)],
                      gcs_link=False, **pacing)
        for params, values in zip(fleet.params, trial_params, strict=True):
            for name, value in values.items():
                if params[name] != value:
                    params.set(name, value)
        fleet.refresh_params()
    if lockstep:
        server.open()
    return server, f"udpin://0.0.0.0:{port}"
