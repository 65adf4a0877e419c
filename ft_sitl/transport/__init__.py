"""The simulator's side of flying over the wire, between the missions layer and the CLI.

- :mod:`ft_sitl.transport.mavlink_trial`: one trial of the protocol with the vehicle served
  over MAVLink and the navigator in another process (``ft-sitl navigate`` or a user's
  program), judged by the same referee as in-process;
- :mod:`ft_sitl.transport.sitl_bus`: a served vehicle's telemetry, events and depth frames
  on the MQTT bus.

The navigator's side (MAVSDK clients, setpoint conversion) is :mod:`ft_sitl.wire`; the
campaign runner (:mod:`ft_sitl.missions.campaign`) flies trials over MAVLink through the
:class:`~ft_sitl.missions.campaign.Transport` this package makes.
"""

from __future__ import annotations

from ft_sitl.missions.campaign import Transport
from ft_sitl.transport.mavlink_trial import fly_over_mavlink


def transport(kind: str = "inprocess", speed_factor: float = 2.0,
              mqtt: str | None = None) -> Transport:
    """A campaign's transport that can fly trials over MAVLink (``kind`` "mavlink", and a
    ``command`` algorithm in any campaign); CampaignError for a bad kind or speed
    factor."""
    return Transport(kind, speed_factor, mqtt, wire=fly_over_mavlink)
