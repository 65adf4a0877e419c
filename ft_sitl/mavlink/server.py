"""The SITL server: N vehicles on UDP with PX4 SITL's port conventions.

Vehicle i (sysid i+1, compid 1) has two links, as PX4 SITL instance i does:

* API/offboard link ("onboard" stream rates): listens on 14580+i, sends to
  127.0.0.1:14540+i -- where MAVSDK's ``udpin://0.0.0.0:14540`` listens;
* GCS link ("normal" rates): listens on 18570+i, sends to 127.0.0.1:14550 -- QGC,
  MAVProxy.

The vehicle sends first (heartbeats to the default remote), then also answers every peer
that has talked to it in the last 10 s. The physics runs in lockstep; the server paces
it against the wall clock at a speed factor and measures the factor it achieves.

Pacing (``pace``): ``"wall"`` runs the simulated clock at the speed factor whatever the
clients do; ``"client"`` also never lets it run more than ``pace_span_s`` simulated seconds
past the simulated instant at which the last MAVLink message from a client arrived, so a
starved client sees a slower world, not a different one (the speed factor stays the
ceiling). What that guarantees and what it cannot: docs/mavlink.md, "Pacing".
"""

from __future__ import annotations

import asyncio
import hashlib
import math
import select
import socket
import struct
import time
from dataclasses import dataclass, field
from pathlib import Path

from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.mavlink import files
from ft_sitl.mavlink.agent import VehicleAgent
from ft_sitl.mavlink.outgoing import Outgoing
from ft_sitl.sim.fleet import Fleet

API_LISTEN_BASE = 14580
API_REMOTE_BASE = 14540
GCS_LISTEN_BASE = 18570
GCS_REMOTE_PORT = 14550
PEER_TIMEOUT_S = 10.0
CHUNK_US = 4000  # simulated time advanced between telemetry/IO service
#: the most the server catches up after falling behind its pace, in wall seconds' worth
#: of simulated time (speed factor x this): a longer stall (the process suspended, a
#: blocking call, a cold numba cache at start) is not made up in a burst of simulation
#: and telemetry; the simulated clock falls behind the wall clock instead, as PX4 SITL's
#: lockstep clock stands still while the simulator does
MAX_CATCH_UP_S = 0.2
#: the pacing modes (SitlServer ``pace``): the wall clock alone, or the clients' messages too
PACES = ("wall", "client")
#: the span a client-paced server may run ahead of its client's last message (simulated
#: seconds): default and range (one PX4 offboard setpoint period of 20 Hz is 0.05 s; the
#: least is one chunk of simulated time, the most the clock ever advances at once)
PACE_SPAN_DEFAULT_S = 0.05
PACE_SPAN_RANGE_S = (0.004, 60.0)
#: wall seconds between the heartbeats a held or slow simulated clock is topped up with
#: (MAVSDK declares a vehicle lost after 3 s of wall time without one)
HEARTBEAT_TOP_UP_S = 1.0


def check_pacing(speed_factor: float, pace: str, pace_span_s: float | None) -> float | None:
    """The pacing options checked (ValueError naming the option and its allowed range):
    the span client pacing runs with (None for wall pacing)."""
    if isinstance(speed_factor, bool) or not isinstance(speed_factor, (int, float)) or not (
            math.isfinite(speed_factor) and 0.01 <= speed_factor <= 1000):
        extra = " (client pacing keeps the speed factor as its ceiling)" \
            if pace == "client" else ""
        raise ValueError(f"--speed-factor: {speed_factor!r} must be within [0.01, 1000]"
                         f"{extra}")
    if pace not in PACES:
        raise ValueError(f"--pace: {pace!r} must be one of {', '.join(PACES)}")
    lo, hi = PACE_SPAN_RANGE_S
    if pace == "wall":
        if pace_span_s is not None:
            raise ValueError(f"--pace-span: {pace_span_s!r} is only for --pace client "
                             "(wall pacing has no span)")
        return None
    span = PACE_SPAN_DEFAULT_S if pace_span_s is None else pace_span_s
    if isinstance(span, bool) or not isinstance(span, (int, float)) or not (
            math.isfinite(span) and lo <= span <= hi):
        raise ValueError(f"--pace-span: {span!r} must be within [{lo:g}, {hi:g}] simulated "
                         "seconds")
    return float(span)


def signing_secret(key: str) -> bytes:
    """A 32-byte MAVLink 2 signing secret from a passphrase (SHA-256, as MAVProxy does)."""
    return hashlib.sha256(key.encode("utf-8")).digest()


class Tlog:
    """A MAVLink telemetry log: each packet prefixed by a big-endian uint64 of wall us."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self._fh = open(path, "ab")  # noqa: SIM115 - closed in close()

    def write(self, data: bytes) -> None:
        self._fh.write(struct.pack(">Q", int(time.time() * 1e6)) + data)

    def flush(self) -> None:
        """Make what was written visible to readers of the file (log download, FTP)."""
        if not self._fh.closed:
            self._fh.flush()

    def close(self) -> None:
        self._fh.close()


@dataclass
class Link:
    vehicle: int
    index: int  # 0 API (onboard), 1 GCS (normal)
    listen: tuple[str, int]
    default_remote: tuple[str, int]
    sysid: int
    secret: bytes | None = None
    peers: dict = field(default_factory=dict)
    transport: asyncio.DatagramTransport | None = None
    rx_packets: int = 0
    rx_errors: int = 0

    def __post_init__(self):
        self.parser = mav.MAVLink(None, 0, 0)
        self.parser.robust_parsing = True
        self.encoder = mav.MAVLink(None, self.sysid, mav.MAV_COMP_ID_AUTOPILOT1)
        if self.secret is not None:
            for m in (self.parser, self.encoder):
                m.signing.secret_key = self.secret
                m.signing.link_id = self.index
                m.signing.timestamp = int((time.time() - 1420070400) * 1e5)
                m.signing.allow_unsigned_callback = lambda _mav, _msgid: False
            self.encoder.signing.sign_outgoing = True

    def destinations(self, now: float) -> list[tuple]:
        alive = [a for a, t in self.peers.items() if now - t <= PEER_TIMEOUT_S]
        for a in list(self.peers):
            if a not in alive:
                del self.peers[a]
        return list(dict.fromkeys([self.default_remote, *alive]))

    def encode(self, msg) -> bytes:
        buf = msg.pack(self.encoder)
        self.encoder.seq = (self.encoder.seq + 1) % 256
        return buf


class _Protocol(asyncio.DatagramProtocol):
    def __init__(self, server: SitlServer, link: Link):
        self.server = server
        self.link = link

    def datagram_received(self, data: bytes, addr) -> None:
        self.server.on_datagram(self.link, data, addr)

    def error_received(self, exc) -> None:  # ICMP port unreachable etc.: peer not there yet
        pass


class _SocketTransport:
    """A link's UDP socket served without an event loop (SitlServer.open / pump)."""

    def __init__(self, sock: socket.socket):
        self.sock = sock

    def sendto(self, data: bytes, addr) -> None:
        try:
            self.sock.sendto(data, addr)
        except OSError:  # a peer not there yet (ICMP), a full buffer: as a lost datagram
            pass

    def close(self) -> None:
        self.sock.close()


class SitlServer:
    def __init__(self, fleet: Fleet, geo: frames.GeoReference, *, bind: str = "127.0.0.1",
                 remote_host: str = "127.0.0.1", speed_factor: float = 1.0,
                 tlog: Path | None = None, signing_key: str | None = None,
                 base_instance: int = 0, pace: str = "wall", pace_span_s: float | None = None,
                 gcs_link: bool = True):
        #: the simulated seconds a client-paced server may run past its client's last
        #: message (None: paced by the wall clock alone)
        self.pace_span_s = check_pacing(speed_factor, pace, pace_span_s)
        self.pace = pace
        #: whether each vehicle's ground-station link (link 1: 18570+i, to 14550) is served;
        #: a trial's vehicle serves its client's link alone, so no ground station on the
        #: machine (one at 14550 hears every instance) can command it mid-trial
        self.gcs_link = gcs_link
        self.fleet = fleet
        self.base_instance = base_instance
        self.geo = geo
        self.bind = bind
        self.speed_factor = speed_factor
        self.secret = signing_secret(signing_key) if signing_key else None
        self.tlog = Tlog(tlog) if tlog else None
        #: the logs every vehicle serves (log download, FTP /log): the telemetry log
        logs = [files.telemetry_log(self.tlog.path, self.tlog.flush)] if self.tlog else []
        self.links: list[Link] = []
        self.agents: list[VehicleAgent] = []
        for i in range(fleet.n):
            links, agent = self._vehicle(i, base_instance + i, bind, remote_host, logs)
            self.links.extend(links)
            self.agents.append(agent)
        self._stop = asyncio.Event()
        self.achieved_speed_factor = 0.0
        #: wall seconds of pace not made up after stalls (MAX_CATCH_UP_S), including the
        #: time client pacing held the clock
        self.behind_s = 0.0
        self.bad_packets = 0
        #: called after every chunk of simulated time (a trial's judge, the MQTT bus)
        self.on_chunk = None
        #: called with (vehicle index, message) for every message from a client, before
        #: the vehicle handles it (a lockstep trial reads its tick acknowledgements here)
        self.on_message = None
        self._last_hb_wall = [0.0] * fleet.n
        #: simulated time (us) at which the last message from a client arrived (client
        #: pacing holds the clock within pace_span_s of it)
        self.client_sim_us = fleet.time_us
        #: wall seconds the simulated clock stood waiting for a client (client pacing)
        self.held_s = 0.0

    def _vehicle(self, i: int, k: int, bind: str, remote_host: str, logs: list) -> tuple:
        """Vehicle i's two links and its agent as instance k: PX4 SITL's UDP ports and the
        PX4 face (another personality overrides it: ft_sitl.mavlink.ardupilot.server)."""
        links = [
            Link(i, 0, (bind, API_LISTEN_BASE + k), (remote_host, API_REMOTE_BASE + k),
                 i + 1, self.secret),
            Link(i, 1, (bind, GCS_LISTEN_BASE + k), (remote_host, GCS_REMOTE_PORT),
                 i + 1, self.secret),
        ]
        return links, VehicleAgent(self.fleet, i, self.geo, 2, ["onboard", "normal"], logs)

    def urls(self) -> list[dict]:
        out = []
        for i in range(self.fleet.n):
            api, gcs = self.links[2 * i], self.links[2 * i + 1]
            out.append({
                "sysid": i + 1,
                "mavsdk": f"udpin://0.0.0.0:{api.default_remote[1]}",
                "pymavlink": f"udpin:0.0.0.0:{api.default_remote[1]}",
                "api_listen": f"{api.listen[0]}:{api.listen[1]}",
                "gcs": f"udpin:0.0.0.0:{gcs.default_remote[1]} (or udpout:{gcs.listen[0]}:"
                       f"{gcs.listen[1]})",
            })
        return out

    # --- I/O -------------------------------------------------------------------------
    def on_datagram(self, link: Link, data: bytes, addr) -> None:
        now = time.monotonic()
        if self.tlog:
            self.tlog.write(data)
        try:
            msgs = link.parser.parse_buffer(data) or []
        except Exception:  # noqa: BLE001 - pymavlink raises on some corrupt input
            self.bad_packets += 1
            link.parser = _fresh_parser(link)
            return
        agent = self.agents[link.vehicle]
        wall_us = int(now * 1e6)
        for m in msgs:
            if m.get_type() == "BAD_DATA":
                self.bad_packets += 1
                continue
            if m.get_srcSystem() == agent.sysid and m.get_srcComponent() == 1:
                continue  # our own echo
            link.peers[addr] = now
            link.rx_packets += 1
            self.client_sim_us = self.fleet.time_us
            if self.on_message is not None:
                self.on_message(link.vehicle, m)
            try:
                replies = agent.handle(m, link.index, addr, wall_us)
            except Exception as exc:  # noqa: BLE001 - a bad message must never stop the vehicle
                self.bad_packets += 1
                agent.cmd.text(4, f"Dropped {m.get_type()}: {type(exc).__name__}"[:50])
                continue
            self.send_all(link.vehicle, replies)

    def send_all(self, vehicle: int, outs: list[Outgoing]) -> None:
        if not outs:
            return
        now = time.monotonic()
        for out in outs:
            links = [self.links[2 * vehicle + out.link]] if out.link is not None \
                else self.links[2 * vehicle: 2 * vehicle + 2]
            for link in links:
                if link.transport is None:
                    continue
                data = link.encode(out.msg)
                dests = [out.peer] if out.peer is not None else link.destinations(now)
                for dest in dests:
                    link.transport.sendto(data, dest)
                if self.tlog:
                    self.tlog.write(data)

    # --- running ---------------------------------------------------------------------
    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        for link in self._served():
            transport, _ = await loop.create_datagram_endpoint(
                lambda link=link: _Protocol(self, link), local_addr=link.listen)
            link.transport = transport

    def _served(self) -> list[Link]:
        return [link for link in self.links if self.gcs_link or link.index != 1]

    def open(self) -> None:
        """Bind the links without an event loop, for a driver that steps the fleet itself
        and serves the links between its steps (:meth:`service`, :meth:`pump`): the
        lockstep wire trials (ft_sitl.transport.lockstep). OSError if a port is taken."""
        for link in self._served():
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                sock.setblocking(False)
                sock.bind(link.listen)
            except OSError:
                sock.close()
                self.close()
                raise
            link.transport = _SocketTransport(sock)

    def on_received(self, link: Link, data: bytes, addr) -> None:
        """What :meth:`pump` read from ``link``'s socket: one datagram (a face whose
        transport carries a stream of frames cuts it first)."""
        self.on_datagram(link, data, addr)

    def pump(self, timeout_s: float) -> None:
        """Handle every datagram that has arrived on the links (after :meth:`open`), waiting
        up to ``timeout_s`` wall seconds for the first; then the vehicles' wall-clock
        duties."""
        socks = {link.transport.sock: link for link in self.links
                 if link.transport is not None}
        ready, _, _ = select.select(list(socks), [], [], timeout_s)
        for sock in ready:
            while True:
                try:
                    data, addr = sock.recvfrom(65535)
                except (BlockingIOError, InterruptedError):
                    break
                except OSError:  # ICMP port unreachable of an earlier send: no datagram
                    continue
                self.on_received(socks[sock], data, addr)
        wall_us = int(time.monotonic() * 1e6)
        for a in self.agents:
            self.send_all(a.i, a.poll(wall_us))
            if time.monotonic() - self._last_hb_wall[a.i] >= HEARTBEAT_TOP_UP_S:
                self._last_hb_wall[a.i] = time.monotonic()
                self.send_all(a.i, [Outgoing(a.heartbeat())])

    def stop(self) -> None:
        self._stop.set()

    def close(self) -> None:
        for link in self.links:
            if link.transport is not None:
                link.transport.close()
                link.transport = None
        if self.tlog:
            self.tlog.close()
            self.tlog = None

    def service(self) -> None:
        """Send what is due after a chunk of simulated time."""
        for a in self.agents:
            outs = a.events()
            for li in range(2):
                outs.extend(a.due_telemetry(li))
            self.send_all(a.i, outs)

    async def run(self, duration_s: float | None = None) -> None:
        """Serve until stop() (or duration_s of wall time). Call start() first."""
        if self.links[0].transport is None:
            await self.start()
        wall0 = time.monotonic()
        sim0 = self.fleet.time_us
        pace_sim0 = sim0  # simulated time due at wall0, moved back after each stall
        max_behind_us = MAX_CATCH_UP_S * self.speed_factor * 1e6
        span_us = None if self.pace_span_s is None else round(self.pace_span_s * 1e6)
        self.service()
        prev = wall0
        try:
            while not self._stop.is_set():
                now = time.monotonic()
                waited, prev = now - prev, now
                if duration_s is not None and now - wall0 >= duration_s:
                    break
                target = pace_sim0 + (now - wall0) * self.speed_factor * 1e6
                if target - self.fleet.time_us > max_behind_us:  # a stall: not made up
                    dropped_us = target - self.fleet.time_us - max_behind_us
                    pace_sim0 -= dropped_us
                    target -= dropped_us
                    self.behind_s += dropped_us / 1e6 / self.speed_factor
                if span_us is not None and target > self.client_sim_us + span_us:
                    # client pacing: not past the span after the client's last message
                    target = self.client_sim_us + span_us
                    if self.fleet.time_us + CHUNK_US > target:
                        self.held_s += waited
                busy_until = now + 0.02
                while self.fleet.time_us + CHUNK_US <= target and time.monotonic() < busy_until \
                        and not self._stop.is_set():
                    self.fleet.run_us(CHUNK_US)
                    self.service()
                    if self.on_chunk is not None:
                        self.on_chunk()
                wall_us = int(time.monotonic() * 1e6)
                for a in self.agents:
                    self.send_all(a.i, a.poll(wall_us))
                    # below real time (or held by client pacing) the 1 Hz simulated-time
                    # heartbeat would come less than once a wall second: top it up so
                    # clients stay connected
                    if (self.speed_factor < 1.0 or span_us is not None) and \
                            time.monotonic() - self._last_hb_wall[a.i] >= HEARTBEAT_TOP_UP_S:
                        self._last_hb_wall[a.i] = time.monotonic()
                        self.send_all(a.i, [Outgoing(a.heartbeat())])
                elapsed = time.monotonic() - wall0
                if elapsed > 0:
                    self.achieved_speed_factor = (self.fleet.time_us - sim0) / 1e6 / elapsed
                await asyncio.sleep(0.001)
        finally:
            pass


def _fresh_parser(link: Link) -> mav.MAVLink:
    """A parser in place of one corrupt input broke: the link's dialect, its signing."""
    old = link.parser.signing
    p = type(link.parser)(None, 0, 0)
    p.robust_parsing = True
    if link.secret is not None:
        p.signing.secret_key = link.secret
        p.signing.link_id = old.link_id
        p.signing.allow_unsigned_callback = old.allow_unsigned_callback or \
            (lambda _mav, _msgid: False)
    return p
