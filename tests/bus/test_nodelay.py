"""Every connection of the bus to its broker turns Nagle's algorithm off (TCP_NODELAY):
with it on, a small message written while the one before was unacknowledged waited for the
broker's delayed ACK, and a lockstep tick reached its navigator 40 ms late. Checked on the
sockets themselves, so no assertion depends on how long anything took."""

from __future__ import annotations

import asyncio
import secrets
import socket
from urllib.parse import urlsplit

import psutil
import pytest

from ft_sitl.bus import BusClient, BusPublisher

from .busutil import DEADLINE_S


def nodelay_of_connections_to(port: int) -> list[int]:
    """TCP_NODELAY of every connection this process has open to ``port`` (read through a
    duplicate of each socket's descriptor)."""
    out = []
    for c in psutil.Process().net_connections(kind="tcp"):
        if c.raddr and c.raddr.port == port and c.status == psutil.CONN_ESTABLISHED:
            with socket.fromfd(c.fd, socket.AF_INET, socket.SOCK_STREAM) as s:
                out.append(s.getsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY))
    return out


@pytest.mark.e2e
def test_publisher_and_client_connect_without_nagle(broker_url):
    port = urlsplit(broker_url).port
    vehicle = f"t{secrets.token_hex(4)}"
    before = len(nodelay_of_connections_to(port))
    pub = BusPublisher(broker_url, vehicle).start()
    try:
        assert pub.wait_connected(DEADLINE_S), "the publisher did not connect"

        async def with_client() -> list[int]:
            async with BusClient(broker_url, vehicle, kinds=("tick",)):
                return nodelay_of_connections_to(port)

        flags = asyncio.run(with_client())
    finally:
        pub.close()
    # the session's other tests may hold connections of their own: ours are the new two
    assert len(flags) >= before + 2, flags
    assert all(flags), f"a connection to the broker keeps Nagle's algorithm on: {flags}"
