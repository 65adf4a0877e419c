"""Helpers for driving the SITL with the real MAVSDK 4.x native binding (asyncio API)."""

import asyncio

from mavsdk import ComponentType
from mavsdk.asyncio import Configuration, Mavsdk, MavsdkConnectionError

#: every client connect() made, for destroy_clients() after each test
_CLIENTS: list[Mavsdk] = []


def destroy_clients() -> None:
    """Destroy the clients connect() made that their test left alive (a test that failed
    before its own ``m.destroy()``). Otherwise the garbage collector destroys them later,
    in whatever the process is doing then, and the native library can abort the process
    there (seen once in CI: an xdist worker killed in another test's numba compilation)."""
    while _CLIENTS:
        _CLIENTS.pop().destroy()  # (idempotent: a destroyed client is left as it is)


async def connect(port: int = 14540):
    m = Mavsdk(Configuration.create_with_component_type(ComponentType.GROUND_STATION))
    _CLIENTS.append(m)
    # a client destroyed by the previous test may hold the port for a moment: retry
    for attempt in range(50):
        try:
            await m.add_any_connection(f"udpin://0.0.0.0:{port}")
            break
        except MavsdkConnectionError:
            if attempt == 49:
                raise
            await asyncio.sleep(0.2)
    drone = await m.first_autopilot(timeout_s=20.0)
    assert drone is not None, "no autopilot discovered"
    return m, drone


async def first(gen, pred=lambda v: True, timeout=20.0):
    async def scan():
        async for v in gen:
            if pred(v):
                return v
    return await asyncio.wait_for(scan(), timeout)
