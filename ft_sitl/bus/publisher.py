"""BusPublisher: the simulator's side of the bus, one per vehicle.

    publisher = BusPublisher("mqtt://localhost:1883", "0", on_config=requests.put)
    publisher.start()                          # returns at once; connects in the background
    gate = RateGate(20.0)
    ...                                        # in the simulation loop:
    if gate.take(t_us):
        publisher.publish_telemetry(Telemetry(t_us, p, v, q, w, motors))
    publisher.publish_event("collision", t_us, object="tree_3", speed_m_s=2.1)
    publisher.publish_depth(frame, camera.config)
    publisher.publish_movers(MoverStates(t_us, movers))   # a world with moving obstacles
    ...
    publisher.close()

The MQTT client (aiomqtt) runs in a daemon thread with its own asyncio event loop. The
``publish_*`` methods encode the payload in the caller's thread (raising BusPayloadError
for invalid values, a caller bug) and then only append it to a bounded per-kind queue: they
never wait for the network. A message is dropped, and counted in ``stats().dropped``, when

* the publisher is not connected (broker absent, restarting, connection lost),
* its kind's queue is full (the broker or the network is slower than the producer),
* the connection is lost while it is queued, or its publish fails or times out.

The sender serves the queues in priority order events > telemetry > movers > depth >
points. It
reconnects by itself with exponential backoff (``reconnect_min_s`` doubling to
``reconnect_max_s``, +-20 % jitter) whether the broker is absent at start, killed, or
restarted.

On every connection it publishes ``{"status": "online"}`` retained on the vehicle's status
topic, having registered ``{"status": "offline", "reason": "connection lost"}`` as its last
will (published by the broker if the connection dies); ``close()`` publishes ``"offline"``
with reason ``"closed"``. It subscribes to the vehicle's config topic; each valid config
request is handed to ``on_config`` (called on the bus thread: keep it short and
thread-safe, e.g. put it on a ``queue.SimpleQueue`` the simulation drains between steps).
Malformed requests are logged (logger ``ft_sitl.bus``, with the reason) and counted, never
raised into the simulator; so is an exception from ``on_config``.
"""

from __future__ import annotations

import asyncio
import collections
import logging
import random
import secrets
import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from ft_sitl.bus import codec
from ft_sitl.bus.codec import (
    BusPayloadError,
    Event,
    MoverStates,
    OfflineReason,
    Status,
    Telemetry,
)
from ft_sitl.bus.options import SOCKET_OPTIONS, BrokerOptions, TlsOptions, parse_broker_url
from ft_sitl.bus.tick import encode_tick
from ft_sitl.bus.topics import check_vehicle, topic

if TYPE_CHECKING:
    from ft_sitl.scenarios.camera import CameraConfig, DepthFrame

__all__ = ["DATA_KINDS", "QOS", "BusPublisher", "BusStats"]

log = logging.getLogger("ft_sitl.bus")
#: aiomqtt / paho-mqtt messages (connection errors, at ERROR) go here
mqtt_log = logging.getLogger("ft_sitl.bus.mqtt")

#: The kinds a publisher sends, in the sender's priority order.
DATA_KINDS = ("events", "telemetry", "movers", "depth", "points", "tick")
#: QoS per topic kind: telemetry, movers and frames are streams (a lost sample is replaced
#: by the next), events are rare and matter (at least once); status and config use QoS 1.
QOS = {"telemetry": 0, "events": 1, "movers": 0, "depth": 0, "points": 0, "status": 1,
       "config": 1, "tick": 1}


@dataclass(frozen=True)
class BusStats:
    """A snapshot of a publisher's counters (``BusPublisher.stats()``).

    ``sent`` / ``dropped`` / ``queued``: per kind (events, telemetry, movers, depth,
    points).
    ``connects``: successful connections; ``reconnects``: those after the first;
    ``connect_failures``: failed attempts; ``config_accepted`` / ``config_rejected``: config
    requests handed to the callback / rejected as malformed; ``callback_errors``: exceptions
    raised by ``on_config``; ``last_error``: the latest connection or publish error.
    """

    connected: bool
    sent: dict[str, int]
    dropped: dict[str, int]
    queued: dict[str, int]
    connects: int
    reconnects: int
    connect_failures: int
    config_accepted: int
    config_rejected: int
    callback_errors: int
    last_error: str | None


def _positive(name: str, value, integer: bool = False) -> None:
    kind = int if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kind) or not value > 0:
        raise ValueError(f"{name} must be a positive {'integer' if integer else 'number'}, "
                         f"got {value!r}")


class BusPublisher:
    """Publish one vehicle's telemetry, events, depth frames and point clouds over MQTT.

    ``url``: ``mqtt://[user[:password]@]host[:port]`` or ``mqtts://...`` (or a
    ``BrokerOptions``); ``tls``: TLS options for ``mqtts://``. ``vehicle``: the instance
    name in the topics (e.g. "0"). ``queue_size``: per-kind queue length for events,
    telemetry and movers; ``frame_queue_size``: for depth and points (large, and stale
    quickly).
    ``on_config(dict)``: receives validated config requests. Nothing happens until
    ``start()``; the constructor only validates.
    """

    def __init__(self, url: str | BrokerOptions, vehicle: str, *,
                 tls: TlsOptions | None = None,
                 queue_size: int = 64,
                 frame_queue_size: int = 2,
                 on_config: Callable[[dict[str, Any]], None] | None = None,
                 keepalive_s: int = 10,
                 reconnect_min_s: float = 0.1,
                 reconnect_max_s: float = 2.0,
                 timeout_s: float = 5.0,
                 close_timeout_s: float = 3.0,
                 client_id: str | None = None):
        if isinstance(url, BrokerOptions):
            if tls is not None:
                raise ValueError("pass TLS options inside the BrokerOptions, not as tls=")
            self.options = url
        else:
            self.options = parse_broker_url(url, tls)
        self.vehicle = check_vehicle(vehicle)
        _positive("queue_size", queue_size, integer=True)
        _positive("frame_queue_size", frame_queue_size, integer=True)
        _positive("keepalive_s", keepalive_s, integer=True)
        for name, value in (("reconnect_min_s", reconnect_min_s),
                            ("reconnect_max_s", reconnect_max_s), ("timeout_s", timeout_s),
                            ("close_timeout_s", close_timeout_s)):
            _positive(name, value)
        if reconnect_max_s < reconnect_min_s:
            raise ValueError(f"reconnect_max_s ({reconnect_max_s}) must be >= reconnect_min_s "
                             f"({reconnect_min_s})")
        if on_config is not None and not callable(on_config):
            raise ValueError(f"on_config must be callable, got {type(on_config).__name__}")
        if client_id is not None and (not isinstance(client_id, str) or not client_id):
            raise ValueError(f"client_id must be a non-empty string, got {client_id!r}")
        self.client_id = client_id or f"ft-sitl-{vehicle}-{secrets.token_hex(4)}"
        self.topics = {kind: topic(vehicle, kind) for kind in (*DATA_KINDS, "status",
                                                               "config")}
        self._capacity = {"events": queue_size, "telemetry": queue_size,
                          "movers": queue_size, "depth": frame_queue_size,
                          "points": frame_queue_size, "tick": queue_size}
        self._on_config = on_config
        self._keepalive_s = keepalive_s
        self._reconnect_min_s = float(reconnect_min_s)
        self._reconnect_max_s = float(reconnect_max_s)
        self._timeout_s = float(timeout_s)
        self._close_timeout_s = float(close_timeout_s)
        self._online = codec.encode_status(Status(vehicle, True))
        self._will = codec.encode_status(Status(vehicle, False, OfflineReason.CONNECTION_LOST))
        self._closed_status = codec.encode_status(Status(vehicle, False, OfflineReason.CLOSED))

        # shared with the bus thread, under _lock
        self._lock = threading.Lock()
        self._queues: dict[str, collections.deque] = {k: collections.deque()
                                                      for k in DATA_KINDS}
        self._sent = dict.fromkeys(DATA_KINDS, 0)
        self._dropped = dict.fromkeys(DATA_KINDS, 0)
        self._connected = False
        self._connects = 0
        self._connect_failures = 0
        self._config_accepted = 0
        self._config_rejected = 0
        self._callback_errors = 0
        self._last_error: str | None = None
        self._sleeping = False  # the sender waits for _wake
        self._state = "new"     # new -> running -> closing -> closed
        self._connected_evt = threading.Event()

        # owned by the bus thread
        self._thread: threading.Thread | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._wake: asyncio.Event | None = None
        self._closing: asyncio.Event | None = None
        self._main_task: asyncio.Task | None = None
        self._session_up = False
        self._rng = random.Random()

    # -- public API (any thread) -----------------------------------------------------------------
    @property
    def url(self) -> str:
        """The broker URL without the password."""
        return self.options.url

    def start(self) -> BusPublisher:
        """Start the bus thread; returns at once (the connection is made in the background).
        Calling it again is a no-op; after ``close()`` it raises RuntimeError."""
        with self._lock:
            if self._state == "running":
                return self
            if self._state != "new":
                raise RuntimeError("BusPublisher was closed; create a new one")
            self._state = "running"
            ready = threading.Event()
            self._thread = threading.Thread(target=self._run, args=(ready,), daemon=True,
                                            name=f"ft-sitl-bus-{self.vehicle}")
            self._thread.start()
        ready.wait()  # the loop exists: close() can reach it
        return self

    def close(self) -> None:
        """Flush what is queued (for at most ``close_timeout_s``), publish the "closed"
        offline status, disconnect and stop the thread. Safe to call twice and before
        ``start()``; publishing afterwards counts drops."""
        with self._lock:
            if self._state in ("new", "closed"):
                self._state = "closed"
                return
            first = self._state == "running"
            self._state = "closing"
            thread, loop = self._thread, self._loop
        if first and loop is not None:
            try:
                loop.call_soon_threadsafe(self._begin_close)
            except RuntimeError:  # loop already closed (the thread died)
                pass
        if thread is not None and thread is not threading.current_thread():
            thread.join(self._close_timeout_s + self._timeout_s + 2.0)
            if thread.is_alive():
                log.error("bus thread for vehicle %s did not stop within %.1f s", self.vehicle,
                          self._close_timeout_s + self._timeout_s + 2.0)
        with self._lock:
            self._state = "closed"

    def __enter__(self) -> BusPublisher:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    @property
    def connected(self) -> bool:
        return self._connected

    def wait_connected(self, timeout: float) -> bool:
        """Block up to ``timeout`` seconds until connected; True if connected. (The
        ``publish_*`` methods never block; this is for start-up and tests.)"""
        return self._connected_evt.wait(timeout)

    def stats(self) -> BusStats:
        """A consistent snapshot of the counters."""
        with self._lock:
            return BusStats(
                connected=self._connected, sent=dict(self._sent), dropped=dict(self._dropped),
                queued={k: len(q) for k, q in self._queues.items()},
                connects=self._connects, reconnects=max(0, self._connects - 1),
                connect_failures=self._connect_failures,
                config_accepted=self._config_accepted, config_rejected=self._config_rejected,
                callback_errors=self._callback_errors, last_error=self._last_error)

    def publish_telemetry(self, sample: Telemetry) -> bool:
        """Queue a telemetry sample (QoS 0). True if queued, False if dropped."""
        if not isinstance(sample, Telemetry):
            raise BusPayloadError(f"publish_telemetry needs a Telemetry, got "
                                  f"{type(sample).__name__}")
        if not self._accepting("telemetry"):
            return False
        return self._offer("telemetry", codec.encode_telemetry(sample))

    def publish_movers(self, states: MoverStates) -> bool:
        """Queue the state of the world's moving obstacles (QoS 0). True if queued, False
        if dropped."""
        if not isinstance(states, MoverStates):
            raise BusPayloadError(f"publish_movers needs a MoverStates, got "
                                  f"{type(states).__name__}")
        if not self._accepting("movers"):
            return False
        return self._offer("movers", codec.encode_movers(states))

    def publish_event(self, event_type: str, time_usec: int, /, **fields) -> bool:
        """Queue an event (QoS 1), e.g. ``publish_event("trial_end", t_us,
        outcome="success")``. True if queued, False if dropped. BusPayloadError if the event
        is invalid (see ``codec.Event``)."""
        payload = codec.encode_event(Event(event_type, time_usec, fields))
        return self._offer("events", payload)

    def publish_depth(self, frame: DepthFrame, config: CameraConfig) -> bool:
        """Queue a depth frame taken with camera ``config`` (QoS 0). True if queued. The
        frame is encoded only if it can be queued."""
        if not self._accepting("depth"):
            return False
        return self._offer("depth", codec.encode_depth(frame, config))

    def publish_points(self, frame: DepthFrame, config: CameraConfig,
                       frame_id: str = "world") -> bool:
        """Queue a frame's point cloud, ``frame_id`` "world" (ENU) or "body" (FLU), QoS 0.
        True if queued."""
        if not self._accepting("points"):
            return False
        return self._offer("points", codec.encode_points(frame, config, frame_id))

    def publish_tick(self, tick) -> bool:
        """Queue a lockstep tick (``bus.tick.Tick``, QoS 1). True if queued."""
        return self._offer("tick", encode_tick(tick))

    # -- queueing ----------------------------------------------------------------------------
    def _check_started(self) -> None:
        if self._state == "new":
            raise RuntimeError("BusPublisher.start() has not been called")

    def _accepting(self, kind: str) -> bool:
        """Whether a message of ``kind`` would be queued now; counts the drop if not (so a
        large frame is not encoded just to be dropped)."""
        self._check_started()
        with self._lock:
            if self._state == "running" and self._connected \
                    and len(self._queues[kind]) < self._capacity[kind]:
                return True
            self._dropped[kind] += 1
            return False

    def _offer(self, kind: str, payload: bytes) -> bool:
        self._check_started()
        with self._lock:
            q = self._queues[kind]
            if self._state != "running" or not self._connected \
                    or len(q) >= self._capacity[kind]:
                self._dropped[kind] += 1
                return False
            q.append(payload)
            wake = self._sleeping
            self._sleeping = False
        if wake:
            try:
                self._loop.call_soon_threadsafe(self._wake.set)
            except RuntimeError:  # the loop is closed: the message stays queued, unsent
                pass
        return True

    def _pop(self) -> tuple[str, bytes] | None:
        """Next message in priority order, or None (and the sender is marked sleeping)."""
        with self._lock:
            for kind in DATA_KINDS:
                q = self._queues[kind]
                if q:
                    return kind, q.popleft()
            self._sleeping = True
            self._wake.clear()
            return None

    def _drop_queued(self) -> None:
        with self._lock:
            for kind, q in self._queues.items():
                self._dropped[kind] += len(q)
                q.clear()

    def _set_connected(self, value: bool) -> None:
        with self._lock:
            self._connected = value
            if value:
                self._connects += 1
        if value:
            self._connected_evt.set()
        else:
            self._connected_evt.clear()
            self._drop_queued()

    # -- the bus thread ------------------------------------------------------------------------
    def _run(self, ready: threading.Event) -> None:
        loop = asyncio.new_event_loop()
        self._loop = loop
        self._wake = asyncio.Event()
        self._closing = asyncio.Event()
        self._main_task = loop.create_task(self._main())
        ready.set()
        try:
            loop.run_until_complete(self._main_task)
        except asyncio.CancelledError:  # cut short by close_timeout_s
            log.warning("closing the bus connection to %s took more than %.1f s: abandoned",
                        self.url, self._close_timeout_s)
        except Exception as exc:  # noqa: BLE001 - the bus must never take the simulator down
            log.exception("bus thread for vehicle %s failed", self.vehicle)
            with self._lock:
                self._last_error = f"bus thread failed: {exc!r}"
        finally:
            self._set_connected(False)
            with self._lock:
                self._state = "closed" if self._state != "running" else "closing"
            try:
                pending = asyncio.all_tasks(loop)
                for task in pending:
                    task.cancel()
                if pending:
                    loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
                loop.run_until_complete(loop.shutdown_asyncgens())
            finally:
                loop.close()

    def _begin_close(self) -> None:
        """On the loop: start closing, and cut it short after close_timeout_s."""
        self._closing.set()
        self._wake.set()
        main = self._main_task
        self._loop.call_later(self._close_timeout_s, lambda: main.done() or main.cancel())

    async def _main(self) -> None:
        delay = self._reconnect_min_s
        failures_in_row = 0
        while not self._closing.is_set():
            self._session_up = False
            session = asyncio.create_task(self._session())
            closing = asyncio.create_task(self._closing.wait())
            await asyncio.wait({session, closing}, return_when=asyncio.FIRST_COMPLETED)
            if not session.done() and not self._connected:
                session.cancel()  # closing while connecting: do not wait for the connect
            try:
                await session
                return  # a session returns normally only after a clean close
            except asyncio.CancelledError:
                if self._closing.is_set():
                    return
                raise
            except Exception as exc:  # noqa: BLE001 - any failure means: reconnect later
                was_connected = self._session_up
                self._set_connected(False)
                msg = _describe(exc)
                with self._lock:
                    self._last_error = msg
                    if not was_connected:
                        self._connect_failures += 1
                if self._closing.is_set():
                    log.info("MQTT connection to %s ended while closing (%s)", self.url, msg)
                    return
                if was_connected:
                    log.warning("MQTT connection to %s lost (%s); reconnecting", self.url, msg)
                    failures_in_row = 0
                    delay = self._reconnect_min_s
                else:
                    failures_in_row += 1
                    level = logging.WARNING if failures_in_row == 1 else logging.DEBUG
                    log.log(level, "cannot connect to MQTT broker %s (%s); retrying with "
                            "backoff up to %.1f s", self.url, msg, self._reconnect_max_s)
            finally:
                closing.cancel()
            if self._closing.is_set():
                return
            wait = delay * self._rng.uniform(0.8, 1.2)
            delay = min(delay * 2.0, self._reconnect_max_s)
            try:
                await asyncio.wait_for(self._closing.wait(), wait)
            except TimeoutError:
                pass

    async def _session(self) -> None:
        """One connection: raises on any failure (``_session_up`` tells whether the
        connection was established), returns only after a clean close."""
        # the MQTT client: loaded only when the bus is used
        import aiomqtt

        o = self.options
        client = aiomqtt.Client(
            o.host, o.port, username=o.username, password=o.password,
            identifier=self.client_id, keepalive=self._keepalive_s, timeout=self._timeout_s,
            will=aiomqtt.Will(self.topics["status"], self._will, qos=QOS["status"],
                              retain=True),
            tls_context=o.tls.ssl_context() if o.tls is not None else None,
            tls_insecure=True if o.tls is not None and o.tls.insecure else None,
            max_queued_incoming_messages=64, logger=mqtt_log,
            socket_options=SOCKET_OPTIONS)
        try:
            await self._connected_session(client)
        finally:
            close_socket(client)

    async def _connected_session(self, client) -> None:
        async with client:
            await client.publish(self.topics["status"], self._online, qos=QOS["status"],
                                 retain=True)
            await client.subscribe(self.topics["config"], qos=QOS["config"])
            self._set_connected(True)
            self._session_up = True
            with self._lock:
                n = self._connects
            log.info("connected to MQTT broker %s as %s (connection %d)", self.url,
                     self.client_id, n)
            receiver = asyncio.create_task(self._receive(client))
            sender = asyncio.create_task(self._send(client))
            try:
                done, _ = await asyncio.wait({receiver, sender},
                                             return_when=asyncio.FIRST_COMPLETED)
                if sender in done and sender.exception() is None:
                    # closing, queue drained: say goodbye while still connected
                    self._set_connected(False)
                    await client.publish(self.topics["status"], self._closed_status,
                                         qos=QOS["status"], retain=True)
                    log.info("closed MQTT connection to %s", self.url)
                    return
                for task in done:
                    task.result()  # raises the failure
                raise ConnectionError("receive loop ended")
            finally:
                receiver.cancel()
                sender.cancel()
                await asyncio.gather(receiver, sender, return_exceptions=True)

    async def _send(self, client) -> None:
        """Publish queued messages until closing and drained; raise on a failed publish."""
        while True:
            item = self._pop()
            if item is None:
                if self._closing.is_set():
                    return
                await self._wake.wait()
                continue
            kind, payload = item
            try:
                await client.publish(self.topics[kind], payload, qos=QOS[kind],
                                     timeout=self._timeout_s)
            except Exception:
                with self._lock:
                    self._dropped[kind] += 1
                raise
            with self._lock:
                self._sent[kind] += 1

    async def _receive(self, client) -> None:
        """Hand config requests to the callback until the connection ends (then raise)."""
        async for message in client.messages:
            self._handle_config(str(message.topic), message.payload)
        raise ConnectionError("message stream ended")

    def _handle_config(self, topic_name: str, payload) -> None:
        if topic_name != self.topics["config"]:
            # not subscribed to: amqtt 0.12 sends a new client the retained messages of
            # every client's subscriptions
            log.debug("ignored message on %s (not subscribed)", topic_name)
            return
        try:
            config = codec.decode_config(payload if payload is not None else b"")
        except BusPayloadError as exc:
            with self._lock:
                self._config_rejected += 1
            log.warning("rejected config request on %s: %s", topic_name, exc)
            return
        with self._lock:
            self._config_accepted += 1
        if self._on_config is None:
            log.info("config request on %s (no on_config callback): %s", topic_name, config)
            return
        try:
            self._on_config(config)
        except Exception:  # noqa: BLE001 - a callback bug must not kill the bus
            with self._lock:
                self._callback_errors += 1
            log.exception("on_config callback raised for %s", config)


def close_socket(client) -> None:
    """Close the socket an aiomqtt client left open, if any.

    After a connection attempt that timed out waiting for CONNACK, or a disconnect that
    timed out, aiomqtt keeps paho-mqtt's socket open. A stalled broker would later process
    that connection: its CONNECT would take over the client id of a newer connection. This
    closes it now, through paho-mqtt's own close (which also unregisters it from the event
    loop). That method is private, so a failure is logged, not raised.
    """
    paho = getattr(client, "_client", None)
    try:
        if paho is not None and paho.socket() is not None:
            paho._sock_close()
    except Exception as exc:  # noqa: BLE001 - best effort; the socket is collected later
        log.debug("could not close an abandoned MQTT socket: %r", exc)


def _describe(exc: BaseException) -> str:
    text = str(exc) or type(exc).__name__
    cause = exc.__cause__ or exc.__context__
    if cause is not None and str(cause) and str(cause) not in text:
        text = f"{text}: {cause}"
    return f"{type(exc).__name__}: {text}"
