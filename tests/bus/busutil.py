"""Helpers of the bus tests: deadline polling (never a timed assertion), free ports, and a
telemetry sample."""

from __future__ import annotations

import asyncio
import math
import socket
import time

from ft_sitl.bus import Telemetry

#: Generous deadline for anything that waits on the network (a loaded 2-core machine).
DEADLINE_S = 20.0


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_until(predicate, what: str, timeout: float = DEADLINE_S, interval: float = 0.02):
    """Poll ``predicate`` until it is true; AssertionError naming ``what`` at the deadline."""
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError(f"gave up after {timeout} s waiting for {what}")
        time.sleep(interval)


async def receive_until(client, predicate, what: str, timeout: float = DEADLINE_S):
    """Receive messages from a BusClient until ``predicate(msg)``; returns that message."""
    try:
        async with asyncio.timeout(timeout):
            while True:
                msg = await client.receive()
                if predicate(msg):
                    return msg
    except TimeoutError:
        raise AssertionError(f"gave up after {timeout} s waiting for {what}") from None


def telemetry(i: int) -> Telemetry:
    """Sample i of a simple stream (time_usec 1 s + 50 ms * i)."""
    a = 0.01 * i
    return Telemetry(time_usec=1_000_000 + 50_000 * i, p_world_m=(i, 2.0 * i, 1.5),
                     v_world_m_s=(0.5, -0.25, 0.0), q_world_body=(math.cos(a), 0, 0, math.sin(a)),
                     w_body_rad_s=(0.0, 0.0, 0.2), motors=(0.5, 0.5, 0.5, 0.5))
