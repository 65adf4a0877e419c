"""The bus's MQTT topic tree: building and parsing topic names, in one place.

Every topic is ``ft-sitl/v1/<vehicle>/<kind>``:

============  ==========================================  =======================
kind          payload (see ``codec``)                      direction
============  ==========================================  =======================
telemetry     JSON ``Telemetry``                           simulator -> clients
events        JSON ``Event``                               simulator -> clients
depth         binary depth frame (``SensorFrame``)         simulator -> clients
points        binary point cloud (``SensorFrame``)         simulator -> clients
movers        JSON ``MoverStates`` (moving obstacles)      simulator -> clients
status        JSON ``Status``, retained, last will         simulator -> clients
config        JSON config request                          clients -> simulator
tick          binary lockstep tick (``tick.Tick``)         simulator -> clients
============  ==========================================  =======================

``v1`` is the topic-tree version (``TREE_VERSION``). It changes only when the tree itself
changes (a topic renamed or removed, a payload's meaning changed incompatibly); payload
schemas carry their own ``"v"`` field. ``<vehicle>`` is the vehicle's instance name, a
string such as ``"0"``: 1 to 64 characters from ``[A-Za-z0-9_-]`` (so it can never contain
MQTT's ``/``, ``+`` or ``#``).
"""

from __future__ import annotations

import re

__all__ = [
    "KINDS",
    "PREFIX",
    "PUBLISHED_KINDS",
    "TREE_VERSION",
    "check_vehicle",
    "parse_topic",
    "topic",
    "topic_filter",
]

#: First level of every topic.
PREFIX = "ft-sitl"
#: Second level: the topic-tree version.
TREE_VERSION = "v1"
#: Every kind of topic under a vehicle.
KINDS = ("telemetry", "events", "depth", "points", "movers", "status", "config", "tick")
#: The kinds the simulator publishes (``config`` is the one it subscribes to).
PUBLISHED_KINDS = ("telemetry", "events", "depth", "points", "movers", "status", "tick")

_VEHICLE_RE = re.compile(r"[A-Za-z0-9_-]{1,64}")


def check_vehicle(vehicle: str) -> str:
    """Return ``vehicle`` if it is a valid vehicle name, else raise ValueError naming why."""
    if not isinstance(vehicle, str):
        raise ValueError(f"vehicle must be a string such as '0', got {type(vehicle).__name__} "
                         f"{vehicle!r}")
    if not _VEHICLE_RE.fullmatch(vehicle):
        raise ValueError(f"vehicle must be 1 to 64 characters from [A-Za-z0-9_-], got "
                         f"{vehicle!r}")
    return vehicle


def _check_kind(kind: str) -> str:
    if kind not in KINDS:
        raise ValueError(f"topic kind must be one of {', '.join(KINDS)}, got {kind!r}")
    return kind


def topic(vehicle: str, kind: str) -> str:
    """The topic of ``kind`` for ``vehicle``: ``topic("0", "telemetry")`` is
    ``"ft-sitl/v1/0/telemetry"``."""
    return f"{PREFIX}/{TREE_VERSION}/{check_vehicle(vehicle)}/{_check_kind(kind)}"


def topic_filter(vehicle: str | None = None, kind: str | None = None) -> str:
    """A subscription filter: ``None`` for either part is the MQTT single-level wildcard.

    ``topic_filter()`` is ``"ft-sitl/v1/+/+"`` (everything of every vehicle),
    ``topic_filter(kind="status")`` the status of every vehicle.
    """
    v = "+" if vehicle is None else check_vehicle(vehicle)
    k = "+" if kind is None else _check_kind(kind)
    return f"{PREFIX}/{TREE_VERSION}/{v}/{k}"


def parse_topic(name: str) -> tuple[str, str]:
    """``(vehicle, kind)`` of a bus topic; ValueError naming the problem for any other topic
    (other prefix, other tree version, bad vehicle name, unknown kind, wrong depth)."""
    if not isinstance(name, str):
        raise ValueError(f"topic must be a string, got {type(name).__name__}")
    parts = name.split("/")
    if len(parts) != 4:
        raise ValueError(f"topic {name!r} is not of the form "
                         f"{PREFIX}/{TREE_VERSION}/<vehicle>/<kind>")
    prefix, version, vehicle, kind = parts
    if prefix != PREFIX:
        raise ValueError(f"topic {name!r} does not start with {PREFIX}/")
    if version != TREE_VERSION:
        raise ValueError(f"topic {name!r} has tree version {version!r}, this library speaks "
                         f"{TREE_VERSION!r}")
    try:
        check_vehicle(vehicle)
        _check_kind(kind)
    except ValueError as exc:
        raise ValueError(f"topic {name!r}: {exc}") from None
    return vehicle, kind
