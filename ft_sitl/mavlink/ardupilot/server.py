"""ArduPilot SITL's connection conventions over the same server loop as the PX4 face
(:class:`~ft_sitl.mavlink.server.SitlServer`): vehicle i as instance k = first + i (``-I``)
listens on TCP 5760+10k (SERIAL0), 5762+10k (SERIAL1) and 5763+10k (SERIAL2) for any
number of clients, and sends to the ``--out`` UDP targets (as MAVProxy's ``--out``
forwards), answering what they send. Link 0 is SERIAL0 with the UDP targets (SR0_*
rates), link 1 SERIAL1 and SERIAL2 (SR1_*). The ardupilotmega dialect both ways."""

from __future__ import annotations

import asyncio
import socket
from dataclasses import dataclass

from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.mavlink.ardupilot.agent import ArduCopterAgent
from ft_sitl.mavlink.ardupilot.framing import FrameSplitter
from ft_sitl.mavlink.ardupilot.signing import VehicleSigning, accept_unsigned
from ft_sitl.mavlink.server import Link, SitlServer

#: SERIAL0's TCP port of instance 0, and the step between instances (ArduPilot SITL)
TCP_BASE, INSTANCE_STEP = 5760, 10
#: the further serial ports' offsets from SERIAL0 (SERIAL1, SERIAL2)
SERIAL_OFFSETS = (0, 2, 3)
#: a client's unsent bytes beyond which its messages are dropped (a stalled reader)
MAX_PENDING = 1 << 20


def tcp_ports(k: int) -> list[int]:
    """Instance k's TCP ports: SERIAL0, SERIAL1, SERIAL2."""
    return [TCP_BASE + INSTANCE_STEP * k + d for d in SERIAL_OFFSETS]


def tcp_port_free(host: str, port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, port))
        except OSError:
            return False
    return True


def serial_ports_free(k: int, host: str = "127.0.0.1") -> bool:
    """Whether instance k's three TCP serial ports (:func:`tcp_ports`) are free on
    ``host``: the test an instance number must pass to be taken for an ArduCopter face."""
    return all(tcp_port_free(host, p) for p in tcp_ports(k))


def parse_out(text: str) -> tuple[str, int]:
    """An ``--out`` target: udp:HOST:PORT, udpout:HOST:PORT or HOST:PORT (ValueError)."""
    body = text.split(":", 1)[1] if text.split(":", 1)[0] in ("udp", "udpout") else text
    host, _, port = body.rpartition(":")
    if not host or not port.isdigit() or not 1 <= int(port) <= 65535:
        raise ValueError(f"--out: {text!r} must be udp:HOST:PORT (port 1..65535)")
    return host, int(port)


@dataclass
class SerialLink(Link):
    """A link over TCP ports (and UDP targets): the ardupilotmega dialect; what is not a
    reply goes to every connected client and target."""

    def __post_init__(self):
        super().__post_init__()
        secret = self.secret
        self.parser = apm.MAVLink(None, 0, 0)
        self.parser.robust_parsing = True
        self.encoder = apm.MAVLink(None, self.sysid, apm.MAV_COMP_ID_AUTOPILOT1)
        if secret is not None:
            for m in (self.parser, self.encoder):
                m.signing.secret_key = secret
                m.signing.link_id = self.index
                m.signing.allow_unsigned_callback = accept_unsigned
            self.encoder.signing.sign_outgoing = True

    def destinations(self, now: float) -> list:
        return [None]


class _Ports:
    """A link's transport: its TCP servers' connections and its UDP targets."""

    def __init__(self, targets: list[tuple[str, int]]):
        self.targets = targets
        self.writers: dict[tuple, asyncio.StreamWriter] = {}
        self.servers: list[asyncio.AbstractServer] = []
        self.udp: asyncio.DatagramTransport | None = None

    def sendto(self, data: bytes, dest) -> None:
        if dest is None:
            for w in list(self.writers.values()):
                self._write(w, data)
            if self.udp is not None:
                for t in self.targets:
                    self.udp.sendto(data, t)
        elif dest in self.writers:
            self._write(self.writers[dest], data)
        elif self.udp is not None:
            self.udp.sendto(data, dest)

    @staticmethod
    def _write(w: asyncio.StreamWriter, data: bytes) -> None:
        if w.is_closing() or w.transport.get_write_buffer_size() > MAX_PENDING:
            return  # as a lost datagram
        w.write(data)

    def close(self) -> None:
        for w in self.writers.values():
            w.close()
        for s in self.servers:
            s.close()
        if self.udp is not None:
            self.udp.close()


class _Udp(asyncio.DatagramProtocol):
    def __init__(self, server: ArduPilotServer, link: Link):
        self.server, self.link = server, link

    def datagram_received(self, data: bytes, addr) -> None:
        frames = FrameSplitter()
        for frame in frames.feed(data):
            self.server.on_datagram(self.link, frame, addr)
        self.server.bad_packets += frames.pop_rejected()

    def error_received(self, exc) -> None:  # a target not listening yet
        pass


class ArduPilotServer(SitlServer):
    """N vehicles as ArduCopter SITL instances ``base_instance ..``; ``outs``: UDP targets
    every vehicle also sends to (``--out``)."""

    def __init__(self, *args, outs: list[tuple[str, int]] | None = None, **kwargs):
        self.outs = list(outs or [])
        super().__init__(*args, **kwargs)

    def _vehicle(self, i, k, bind, remote_host, logs):
        links = [SerialLink(i, 0, (bind, tcp_ports(k)[0]), None, i + 1, self.secret),
                 SerialLink(i, 1, (bind, tcp_ports(k)[1]), None, i + 1, self.secret)]
        agent = ArduCopterAgent(self.fleet, i, self.geo, 2, ["serial0", "serial1"], logs)
        agent.signing = VehicleSigning(links, agent.cmd)
        return links, agent

    def urls(self) -> list[dict]:
        out = []
        for i in range(self.fleet.n):
            s0, s1, s2 = tcp_ports(self.base_instance + i)
            host = self.bind
            out.append({"sysid": i + 1, "autopilot": "ardupilot",
                        "pymavlink": f"tcp:{host}:{s0}", "mavproxy": f"--master=tcp:{host}:{s0}",
                        "serial": [f"tcp:{host}:{p}" for p in (s0, s1, s2)],
                        "out": [f"udp:{h}:{p}" for h, p in self.outs]})
        return out

    async def start(self) -> None:
        loop = asyncio.get_running_loop()
        try:
            for link in self.links:
                ports = _Ports(self.outs if link.index == 0 else [])
                link.transport = ports
                k = self.base_instance + link.vehicle
                for port in (tcp_ports(k)[:1] if link.index == 0 else tcp_ports(k)[1:]):
                    ports.servers.append(await asyncio.start_server(
                        lambda r, w, link=link: self._serve(link, r, w), link.listen[0], port))
                if link.index == 0 and self.outs:
                    ports.udp, _ = await loop.create_datagram_endpoint(
                        lambda link=link: _Udp(self, link), local_addr=(self.bind, 0))
        except OSError:
            self.close()
            raise

    async def _serve(self, link: Link, reader: asyncio.StreamReader,
                     writer: asyncio.StreamWriter) -> None:
        peer = ("tcp", *writer.get_extra_info("peername")[:2])
        ports: _Ports = link.transport
        ports.writers[peer] = writer
        frames = FrameSplitter()
        try:
            while True:
                data = await reader.read(65536)
                if not data:
                    break
                for frame in frames.feed(data):
                    self.on_datagram(link, frame, peer)
                self.bad_packets += frames.pop_rejected()  # (corrupt or garbage)
        except (ConnectionError, OSError):
            pass
        finally:
            ports.writers.pop(peer, None)
            writer.close()

    def open(self) -> None:
        raise NotImplementedError("the ArduCopter face serves under an event loop only "
                                  "(lockstep wire trials use the PX4 face)")
