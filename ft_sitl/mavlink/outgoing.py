"""What every piece of a vehicle's MAVLink side hands back to send, and who it speaks as.

The pieces (streams, commands, mission, parameters, ...) never touch a socket: each returns
:class:`Outgoing` values and the server sends them. This module is the one they all import,
so none of them has to import :mod:`ft_sitl.mavlink.agent`, which imports them.
"""

from __future__ import annotations

from dataclasses import dataclass

from pymavlink.dialects.v20 import common as mav

#: the component every vehicle answers as (PX4's autopilot component)
COMPID = mav.MAV_COMP_ID_AUTOPILOT1


@dataclass
class Outgoing:
    """A message to send: on a link index (None: every link) to a peer (None: all peers)."""

    msg: mav.MAVLink_message
    link: int | None = None
    peer: tuple | None = None
