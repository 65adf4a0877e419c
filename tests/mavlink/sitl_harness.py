"""Run a real SitlServer (real UDP sockets) in a background thread for the tests."""

import asyncio
import threading
from contextlib import contextmanager

from ft_sitl import frames
from ft_sitl.mavlink.instances import InstanceLock, instances_held
from ft_sitl.mavlink.server import SitlServer
from ft_sitl.physics.catalog import get_platform
from ft_sitl.sim.fleet import Fleet

PLATFORM = "0.98kg-EGO Planner DIY"


@contextmanager
def running_sitl(instances: int = 1, *args, **kwargs):
    """A SitlServer on instance numbers ``base_instance ..`` (default 0), holding them
    (ft_sitl.mavlink.instances) so that no trial over MAVLink on this machine binds the
    same ports meanwhile; it waits for one that holds them to finish."""
    with instances_held(kwargs.get("base_instance", 0), instances, wait_s=300.0):
        with _running_sitl(instances, *args, **kwargs) as server:
            yield server


@contextmanager
def _running_sitl(instances: int = 1, speed_factor: float = 1.0, params=None, scenario=None,
                  estimator=None, platform: str = PLATFORM, server_class=SitlServer,
                  **kwargs):
    p = get_platform(platform)
    if scenario is None:
        spawn, yaw = [[0.0, 2.0 * i, 0.0] for i in range(instances)], None
    else:  # the takeoff point, further vehicles 2 m east
        spawn = [scenario.takeoff + [2.0 * i, 0.0, 0.0] for i in range(instances)]
        yaw = [scenario.start_yaw] * instances
    fleet = Fleet([p] * instances, params=params, spawn=spawn, spawn_yaw=yaw,
                  scenario=scenario)
    for i in range(instances):  # (None: the truth, as without)
        fleet.sim.set_estimator(i, estimator, seed=i)
    server = server_class(fleet, frames.GeoReference(*frames.PX4_SITL_HOME),
                          speed_factor=speed_factor, **kwargs)
    loop = asyncio.new_event_loop()
    started = threading.Event()
    serving = threading.Event()
    errors = []

    def first_chunk():  # the first step is where numba compiles (seconds on a cold cache)
        server.on_chunk = None
        serving.set()

    server.on_chunk = first_chunk

    def runner():
        asyncio.set_event_loop(loop)
        try:
            loop.run_until_complete(server.start())
            started.set()
            loop.run_until_complete(server.run())
        except Exception as exc:  # noqa: BLE001 - reported to the test below
            errors.append(exc)
            started.set()
            serving.set()
        finally:
            server.close()
            loop.close()

    thread = threading.Thread(target=runner, daemon=True)
    thread.start()
    assert started.wait(10), "server did not start"
    assert not errors, errors
    # yield a server that simulates, so the tests' timeouts do not include the compilation
    assert serving.wait(180), "server did not simulate its first step"
    assert not errors, errors
    try:
        yield server
    finally:
        loop.call_soon_threadsafe(server.stop)
        thread.join(10)
        assert not thread.is_alive(), "server thread did not stop"
        assert not errors, errors


@contextmanager
def free_sitl(instances: int = 1, *args, **kwargs):
    """A SitlServer as :func:`running_sitl` on an instance number no other process of this
    machine holds (ft_sitl.mavlink.instances.InstanceLock): for tests that may run beside
    other SITLs. ``server.base_instance`` says which."""
    if instances != 1:
        raise ValueError("free_sitl serves one vehicle")
    with InstanceLock() as inst, _running_sitl(1, *args, base_instance=inst, **kwargs) as s:
        yield s
