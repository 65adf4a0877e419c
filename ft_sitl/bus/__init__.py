"""ft_sitl.bus: MQTT publishing of telemetry, events and sensor frames (reference:
docs/mqtt.md).

Topic tree ``ft-sitl/v1/<vehicle>/{telemetry,events,depth,points,movers,status,config}``
(``topics``); payloads: compact JSON with ``"v": 1`` and a little-endian binary layout for
depth images and point clouds (``codec``); broker URLs ``mqtt://`` / ``mqtts://``
(``options``); the simulator's non-blocking, self-reconnecting ``BusPublisher``
(``publisher``) and its ``RateGate`` (``ratelimit``); the clients' asyncio ``BusClient``
(``client``); and an in-process amqtt ``EmbeddedBroker`` for machines without a broker
(``broker``).

    from ft_sitl.bus import BusPublisher, EmbeddedBroker, RateGate, Telemetry

aiomqtt and amqtt are imported only when a connection or a broker is started, so the codec
can be used without them.
"""

from ft_sitl.bus.broker import EmbeddedBroker
from ft_sitl.bus.client import DEFAULT_KINDS, BusClient, BusMessage, subscribe
from ft_sitl.bus.codec import (
    CONFIG_FIELDS,
    EVENT_TYPES,
    HEADER_SIZE,
    SCHEMA_VERSION,
    BusPayloadError,
    Event,
    EventType,
    MoverState,
    MoverStates,
    OfflineReason,
    SensorFrame,
    Status,
    StatusValue,
    Telemetry,
    decode_config,
    decode_event,
    decode_frame,
    decode_movers,
    decode_status,
    decode_telemetry,
    encode_config,
    encode_depth,
    encode_event,
    encode_movers,
    encode_points,
    encode_status,
    encode_telemetry,
    validate_config,
)
from ft_sitl.bus.options import BrokerOptions, TlsOptions, parse_broker_url
from ft_sitl.bus.publisher import QOS, BusPublisher, BusStats
from ft_sitl.bus.ratelimit import RateGate
from ft_sitl.bus.topics import KINDS, TREE_VERSION, parse_topic, topic, topic_filter

__all__ = [
    "CONFIG_FIELDS",
    "DEFAULT_KINDS",
    "EVENT_TYPES",
    "HEADER_SIZE",
    "KINDS",
    "QOS",
    "SCHEMA_VERSION",
    "TREE_VERSION",
    "BrokerOptions",
    "BusClient",
    "BusMessage",
    "BusPayloadError",
    "BusPublisher",
    "BusStats",
    "EmbeddedBroker",
    "Event",
    "EventType",
    "MoverState",
    "MoverStates",
    "OfflineReason",
    "RateGate",
    "SensorFrame",
    "Status",
    "StatusValue",
    "Telemetry",
    "TlsOptions",
    "decode_config",
    "decode_event",
    "decode_frame",
    "decode_movers",
    "decode_status",
    "decode_telemetry",
    "encode_config",
    "encode_depth",
    "encode_event",
    "encode_movers",
    "encode_points",
    "encode_status",
    "encode_telemetry",
    "parse_broker_url",
    "parse_topic",
    "subscribe",
    "topic",
    "topic_filter",
    "validate_config",
]
