"""MAVLink 2 signing as ArduPilot sets it up (libraries/GCS_MAVLink/GCS_Signing.cpp): a
ground station sends SETUP_SIGNING with a 32-byte secret key and an initial timestamp;
from then on the vehicle signs what it sends and drops every unsigned or wrongly signed
message on all its links but RADIO_STATUS and RADIO (a radio's own reports), until a
SETUP_SIGNING (itself signed) with an all-zero key and timestamp turns signing off. It is
refused while armed ("ERROR: Won't setup signing when armed"). ArduPilot keeps the key in
its storage across reboots; ft-sitl keeps it for the life of the server."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.autopilot import commander as cm

#: what ArduPilot accepts unsigned while signing is on (accept_unsigned_callback)
ACCEPT_UNSIGNED = frozenset((apm.MAVLINK_MSG_ID_RADIO_STATUS, apm.MAVLINK_MSG_ID_RADIO))


def accept_unsigned(_mav, msg_id: int) -> bool:
    return msg_id in ACCEPT_UNSIGNED


def use_key(link, secret: bytes | None, timestamp: int) -> None:
    """Sign (and demand signatures) on one link with ``secret`` (None: signing off). The
    link's parser and encoder are pymavlink MAVLink objects; ``link.secret`` is what a
    parser made afresh after corrupt input takes."""
    link.secret = secret
    for m in (link.parser, link.encoder):
        m.signing.secret_key = secret
        m.signing.link_id = link.index
        m.signing.timestamp = max(int(timestamp), 1)
        m.signing.allow_unsigned_callback = accept_unsigned if secret is not None else None
    link.encoder.signing.sign_outgoing = secret is not None


class VehicleSigning:
    """One vehicle's signing over all its links (``links``: the server's Links of it)."""

    def __init__(self, links: list, cmd: cm.Commander):
        self.links = links
        self.cmd = cmd

    @property
    def active(self) -> bool:
        return any(link.secret is not None for link in self.links)

    def setup(self, m) -> list:
        """SETUP_SIGNING: the key for every link at once, or off with an all-zero key and
        timestamp; nothing while armed. No answer, as ArduPilot gives none."""
        if self.cmd.armed:
            self.cmd.text(cm.Severity.WARNING, "ERROR: Won't setup signing when armed")
            return []
        key = bytes(m.secret_key)
        off = m.initial_timestamp == 0 and not any(key)
        for link in self.links:
            use_key(link, None if off else key, m.initial_timestamp)
        return []
