"""BusClient: the clients' side of the bus (asyncio, over aiomqtt).

    async with BusClient("mqtt://localhost:1883", "0",
                         kinds=("telemetry", "events", "depth")) as bus:
        await bus.request_config(depth=True, telemetry_rate_hz=50)
        async for msg in bus:
            if msg.kind == "telemetry":
                print(msg.data.t, msg.data.p_world_m)
            elif msg.kind == "depth":
                frame = msg.data.to_depth_frame()    # scenarios.camera.DepthFrame

``vehicle`` None subscribes to every vehicle (``msg.vehicle`` says which). Messages are
decoded according to their topic: ``Telemetry``, ``Event``, ``SensorFrame`` (depth and
points), ``MoverStates`` (movers: the moving obstacles of the vehicle's world) and
``Status``. ``kinds=("movers",)`` follows the moving obstacles::

    async with BusClient(url, "0", kinds=("movers",)) as bus:
        async for msg in bus:
            for m in msg.data.movers:
                print(msg.data.t, m.name, m.shape, m.p_world_m, m.v_world_m_s)
 A malformed message is logged (logger ``ft_sitl.bus``), counted in
``rejected`` and skipped; it never ends the iteration. Losing the connection does
(aiomqtt.MqttError): the client does not reconnect by itself; enter a new one.
"""

from __future__ import annotations

import contextlib
import logging
import secrets
from collections.abc import AsyncIterator, Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from ft_sitl.bus import codec
from ft_sitl.bus.codec import (
    BusPayloadError,
    Event,
    MoverStates,
    SensorFrame,
    Status,
    Telemetry,
)
from ft_sitl.bus.options import SOCKET_OPTIONS, BrokerOptions, TlsOptions, parse_broker_url
from ft_sitl.bus.publisher import QOS, close_socket, mqtt_log
from ft_sitl.bus.tick import decode_tick
from ft_sitl.bus.topics import PUBLISHED_KINDS, check_vehicle, parse_topic, topic, topic_filter

__all__ = ["DEFAULT_KINDS", "BusClient", "BusMessage", "subscribe"]

log = logging.getLogger("ft_sitl.bus")

#: What a client subscribes to unless told otherwise (frames are large: ask for them).
DEFAULT_KINDS = ("telemetry", "events", "status")

_DECODERS = {
    "telemetry": codec.decode_telemetry,
    "events": codec.decode_event,
    "depth": lambda payload: codec.decode_frame(payload, expect_kind="depth"),
    "points": lambda payload: codec.decode_frame(payload, expect_kind="points"),
    "movers": codec.decode_movers,
    "status": codec.decode_status,
    "tick": decode_tick,
}


@dataclass(frozen=True)
class BusMessage:
    """A decoded message: which vehicle, which kind, the payload object, whether the
    broker delivered it as a retained message (status, typically), and its topic."""

    vehicle: str
    kind: str
    data: Telemetry | Event | SensorFrame | MoverStates | Status
    retained: bool
    topic: str


class BusClient:
    """Subscribe to one vehicle's (or, ``vehicle`` None, every vehicle's) ``kinds`` and send
    config requests. An async context manager and an async iterator of ``BusMessage``.

    ``kinds``: any of telemetry, events, depth, points, movers, status. ``queue_size``: incoming
    messages buffered before aiomqtt discards new ones (with a warning).
    """

    def __init__(self, url: str | BrokerOptions, vehicle: str | None = "0", *,
                 kinds: Iterable[str] = DEFAULT_KINDS, tls: TlsOptions | None = None,
                 client_id: str | None = None, queue_size: int = 256,
                 timeout_s: float = 10.0):
        if isinstance(url, BrokerOptions):
            if tls is not None:
                raise ValueError("pass TLS options inside the BrokerOptions, not as tls=")
            self.options = url
        else:
            self.options = parse_broker_url(url, tls)
        self.vehicle = None if vehicle is None else check_vehicle(vehicle)
        kinds = tuple(kinds) if not isinstance(kinds, str) else (kinds,)
        if not kinds:
            raise ValueError("kinds must name at least one of " + ", ".join(PUBLISHED_KINDS))
        for kind in kinds:
            if kind not in PUBLISHED_KINDS:
                raise ValueError(f"kind {kind!r} cannot be subscribed to; choose from "
                                 f"{', '.join(PUBLISHED_KINDS)}")
        self.kinds = kinds
        if isinstance(queue_size, bool) or not isinstance(queue_size, int) or queue_size < 1:
            raise ValueError(f"queue_size must be a positive integer, got {queue_size!r}")
        if isinstance(timeout_s, bool) or not isinstance(timeout_s, int | float) \
                or not timeout_s > 0:
            raise ValueError(f"timeout_s must be a positive number, got {timeout_s!r}")
        self.client_id = client_id or f"ft-sitl-client-{secrets.token_hex(4)}"
        self._queue_size = queue_size
        self._timeout_s = float(timeout_s)
        self._client = None
        #: malformed messages skipped so far
        self.rejected = 0

    async def __aenter__(self) -> BusClient:
        # the MQTT client: loaded only when the bus is used
        import aiomqtt

        o = self.options
        client = aiomqtt.Client(
            o.host, o.port, username=o.username, password=o.password,
            identifier=self.client_id, timeout=self._timeout_s,
            tls_context=o.tls.ssl_context() if o.tls is not None else None,
            tls_insecure=True if o.tls is not None and o.tls.insecure else None,
            max_queued_incoming_messages=self._queue_size, logger=mqtt_log,
            socket_options=SOCKET_OPTIONS)
        try:
            await client.__aenter__()
        except BaseException:
            close_socket(client)
            raise
        try:
            for kind in self.kinds:
                await client.subscribe(topic_filter(self.vehicle, kind), qos=QOS[kind])
        except BaseException:
            await client.__aexit__(None, None, None)
            raise
        self._client = client
        return self

    async def __aexit__(self, *exc) -> None:
        client, self._client = self._client, None
        if client is not None:
            await client.__aexit__(*exc)

    def _connected_client(self):
        if self._client is None:
            raise RuntimeError("BusClient is not connected: use 'async with BusClient(...)'")
        return self._client

    async def __aiter__(self) -> AsyncIterator[BusMessage]:
        while True:
            yield await self.receive()

    async def receive(self) -> BusMessage:
        """The next valid message (malformed ones are skipped); aiomqtt.MqttError if the
        connection is lost. Wrap it in ``asyncio.timeout`` to bound the wait."""
        messages = self._connected_client().messages
        while True:
            message = await anext(messages)
            decoded = self._decode(str(message.topic), message.payload, bool(message.retain))
            if decoded is not None:
                return decoded

    def _decode(self, topic_name: str, payload, retained: bool) -> BusMessage | None:
        try:
            vehicle, kind = parse_topic(topic_name)
            if kind not in self.kinds or (self.vehicle is not None and vehicle != self.vehicle):
                # not subscribed to: amqtt 0.12 sends a new client the retained messages of
                # every client's subscriptions
                log.debug("ignored message on %s (not subscribed)", topic_name)
                return None
            decoder = _DECODERS.get(kind)
            if decoder is None:
                raise BusPayloadError(f"no decoder for topic kind {kind!r}")
            data = decoder(payload if payload is not None else b"")
        except (BusPayloadError, ValueError) as exc:
            self.rejected += 1
            log.warning("skipped malformed message on %s: %s", topic_name, exc)
            return None
        return BusMessage(vehicle=vehicle, kind=kind, data=data, retained=retained,
                          topic=topic_name)

    async def request_config(self, vehicle: str | None = None, *, retain: bool = False,
                             **settings: Any) -> None:
        """Publish a config request (QoS 1) to ``vehicle`` (default: the client's vehicle),
        e.g. ``request_config(depth=True, telemetry_rate_hz=20)``. Settings are validated
        first (BusPayloadError). ``retain`` True leaves it on the broker for a simulator
        that connects later."""
        await self.send_config(settings, vehicle, retain=retain)

    async def send_config(self, config: Mapping[str, Any], vehicle: str | None = None, *,
                          retain: bool = False) -> None:
        """Like ``request_config`` with the settings as a mapping."""
        target = vehicle if vehicle is not None else self.vehicle
        if target is None:
            raise ValueError("this client follows every vehicle: name the vehicle to configure")
        await self._connected_client().publish(topic(target, "config"),
                                               codec.encode_config(config),
                                               qos=QOS["config"], retain=retain)

    async def publish_raw(self, kind: str, payload: bytes, vehicle: str | None = None, *,
                          qos: int = 1, retain: bool = False) -> None:
        """Publish raw bytes on a bus topic (for tools and tests: no validation of the
        payload)."""
        target = vehicle if vehicle is not None else self.vehicle
        if target is None:
            raise ValueError("name the vehicle to publish to")
        await self._connected_client().publish(topic(target, kind), payload, qos=qos,
                                               retain=retain)


@contextlib.asynccontextmanager
async def subscribe(url: str | BrokerOptions, vehicle: str | None = "0", *,
                    kinds: Iterable[str] = DEFAULT_KINDS, tls: TlsOptions | None = None,
                    **options: Any) -> AsyncIterator[BusClient]:
    """``async with subscribe(url, "0", kinds=("telemetry",)) as bus: async for msg in
    bus: ...``; the same as ``async with BusClient(...)``."""
    async with BusClient(url, vehicle, kinds=kinds, tls=tls, **options) as client:
        yield client
