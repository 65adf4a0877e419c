"""EmbeddedBroker: an in-process MQTT broker (amqtt) for machines without one.

When the user names no broker, the simulator can start this one so that ``ft-sitl sitl``
works on a fresh machine::

    broker = EmbeddedBroker()          # free localhost port; or port=1883
    broker.start()                     # blocks until it listens (or raises RuntimeError)
    publisher = BusPublisher(broker.url, "0")
    ...
    broker.stop()

The broker runs in its own daemon thread with its own asyncio event loop, so it does not
interfere with the caller's loop (if any). It listens on TCP only (no TLS, no WebSockets),
accepts anonymous clients, keeps retained messages and publishes last wills; it keeps no
state across restarts. It is meant for one machine (default host 127.0.0.1); for anything
bigger, run mosquitto and pass its URL.
"""

from __future__ import annotations

import asyncio
import errno
import logging
import socket
import threading

__all__ = ["EmbeddedBroker"]

log = logging.getLogger("ft_sitl.bus")

#: How many free ports are tried when one picked by the OS is taken before amqtt binds it.
_PORT_ATTEMPTS = 5


def _free_port(host: str) -> int:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def _in_use(exc: BaseException) -> bool:
    while exc is not None:
        if isinstance(exc, OSError) and exc.errno == errno.EADDRINUSE:
            return True
        exc = exc.__cause__
    return False


class EmbeddedBroker:
    """An amqtt MQTT broker on ``host``:``port`` (``port`` None: a free port) in a thread.

    ``start()`` and ``stop()`` are idempotent; the object is also a context manager.
    """

    def __init__(self, host: str = "127.0.0.1", port: int | None = None):
        if not isinstance(host, str) or not host:
            raise ValueError(f"host must be a non-empty string, got {host!r}")
        if port is not None and (isinstance(port, bool) or not isinstance(port, int)
                                 or not 1 <= port <= 65535):
            raise ValueError(f"port must be an integer in [1, 65535] or None (a free port), "
                             f"got {port!r}")
        self.host = host
        self._requested_port = port
        self._port: int | None = None
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stop: asyncio.Event | None = None
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self._want_stop = False
        self._lock = threading.Lock()

    # -- properties ----------------------------------------------------------------------------
    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive() and self._port is not None

    @property
    def port(self) -> int:
        """The port it listens on (after ``start()``)."""
        if self._port is None:
            raise RuntimeError("EmbeddedBroker is not running: call start() first")
        return self._port

    @property
    def url(self) -> str:
        """``mqtt://host:port`` for ``BusPublisher`` / ``BusClient``."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"mqtt://{host}:{self.port}"

    # -- life cycle ----------------------------------------------------------------------------
    def start(self, timeout: float = 20.0) -> EmbeddedBroker:
        """Start the broker and wait until it listens; RuntimeError if it cannot (port in
        use, ...) or does not come up within ``timeout`` seconds."""
        with self._lock:
            if self.running:
                return self
            self._ready.clear()
            self._error = None
            self._want_stop = False
            self._thread = threading.Thread(target=self._run, name="ft-sitl-mqtt-broker",
                                            daemon=True)
            self._thread.start()
        if not self._ready.wait(timeout):
            self.stop()
            raise RuntimeError(f"the embedded MQTT broker did not start within {timeout} s")
        if self._error is not None:
            self._thread.join(timeout)
            err, self._error = self._error, None
            where = f"{self.host}:{self._requested_port or 'a free port'}"
            cause = err.__cause__ if err.__cause__ is not None else err
            raise RuntimeError(f"could not start the embedded MQTT broker on {where}: "
                               f"{cause}") from err
        log.info("embedded MQTT broker listening on %s", self.url)
        return self

    def stop(self, timeout: float = 20.0) -> None:
        """Stop the broker (disconnecting its clients) and join its thread."""
        with self._lock:
            thread, loop, stop = self._thread, self._loop, self._stop
            if thread is None:
                return
            self._want_stop = True
            if loop is not None and stop is not None and not loop.is_closed():
                try:
                    loop.call_soon_threadsafe(stop.set)
                except RuntimeError:  # the loop closed in between
                    pass
            thread.join(timeout)
            if thread.is_alive():
                raise RuntimeError(f"the embedded MQTT broker did not stop within {timeout} s")
            self._thread = self._loop = self._stop = None
            self._port = None

    def __enter__(self) -> EmbeddedBroker:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # -- the broker thread ---------------------------------------------------------------------
    def _run(self) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        try:
            loop.run_until_complete(self._serve())
        except BaseException as exc:  # noqa: BLE001 - reported to start() through _error
            if not self._ready.is_set():
                self._error = exc
                self._ready.set()
            else:
                log.error("embedded MQTT broker failed: %r", exc)
        finally:
            try:
                loop.run_until_complete(loop.shutdown_asyncgens())
            finally:
                loop.close()

    async def _serve(self) -> None:
        # the embedded MQTT broker: loaded only when it is started
        from amqtt.broker import Broker
        from amqtt.errors import BrokerError

        self._stop = asyncio.Event()
        broker = None
        for attempt in range(_PORT_ATTEMPTS):
            port = self._requested_port or _free_port(self.host)
            bind = f"[{self.host}]:{port}" if ":" in self.host else f"{self.host}:{port}"
            config = {
                "listeners": {"default": {"type": "tcp", "bind": bind}},
                "plugins": {"amqtt.plugins.authentication.AnonymousAuthPlugin":
                            {"allow_anonymous": True}},
            }
            candidate = Broker(config)
            try:
                await candidate.start()
            except BrokerError as exc:
                if self._requested_port is None and _in_use(exc) \
                        and attempt + 1 < _PORT_ATTEMPTS:
                    continue  # another process took the free port first: pick another
                self._error = exc
                self._ready.set()
                return
            broker = candidate
            break
        self._port = port
        self._ready.set()
        try:
            if not self._want_stop:  # stop() may have run before self._stop existed
                await self._stop.wait()
        finally:
            await broker.shutdown()
