"""The simulator's side of flying over the wire, between the missions layer and the CLI.

- :mod:`ft_sitl.transport.mavlink_trial`: one trial of the protocol with the vehicle served
  over MAVLink and the navigator in another process (``ft-sitl navigate`` or a user's
  program), judged by the same referee as in-process, free-running against the wall clock;
- :mod:`ft_sitl.transport.lockstep`: the same in lockstep: the in-process driver holds its
  clock at every navigator call until the client's answer has arrived;
- :mod:`ft_sitl.transport.wire_trial`: what both set up around a trial (plan, vehicle,
  referee, instance number, the navigator process);
- :mod:`ft_sitl.transport.faces`: which autopilot's MAVLink face serves the vehicle (PX4's
  or ArduCopter's, ``--autopilot``);
- :mod:`ft_sitl.transport.sitl_bus`: a served vehicle's telemetry, events and depth frames
  on the MQTT bus.

The navigator's side (MAVSDK clients, setpoint conversion) is :mod:`ft_sitl.wire`; the
campaign runner (:mod:`ft_sitl.missions.campaign`) flies trials over MAVLink through the
:class:`~ft_sitl.missions.campaign.Transport` this package makes.
"""

from __future__ import annotations

import functools

from ft_sitl.mavlink.autopilots import DEFAULT_AUTOPILOT
from ft_sitl.missions.campaign import CampaignError, Transport
from ft_sitl.missions.campaign_file import COMMAND
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.transport.faces import check_autopilot
from ft_sitl.transport.lockstep import run_trial_lockstep
from ft_sitl.transport.mavlink_trial import fly_over_mavlink, worker_bus


def fly_wire(spec: TrialSpec, speed_factor: float, mqtt: str | None, *,
             lockstep: bool = True, autopilot: str = DEFAULT_AUTOPILOT) -> dict:
    """One campaign trial over MAVLink, its row, served by ``autopilot``'s face: in
    lockstep (a registered navigator, ``lockstep``), else free-running at ``speed_factor``
    (a ``command`` navigator always)."""
    if lockstep and spec.algorithm != COMMAND:
        return run_trial_lockstep(spec, autopilot=autopilot, **worker_bus(mqtt)).row
    return fly_over_mavlink(spec, speed_factor, mqtt, autopilot=autopilot)


def transport(kind: str = "inprocess", speed_factor: float = 2.0,
              mqtt: str | None = None, *, lockstep: bool = True,
              autopilot: str = DEFAULT_AUTOPILOT) -> Transport:
    """A campaign's transport that can fly trials over MAVLink (``kind`` "mavlink", and a
    ``command`` algorithm in any campaign), in lockstep (default) or free-running, served
    by ``autopilot``'s face (:mod:`ft_sitl.transport.faces`); CampaignError for a bad
    kind, speed factor or autopilot."""
    try:
        check_autopilot(autopilot)
    except ValueError as exc:
        raise CampaignError(str(exc)) from None
    return Transport(kind, speed_factor, mqtt,
                     wire=functools.partial(fly_wire, lockstep=lockstep, autopilot=autopilot),
                     lockstep=lockstep, autopilot=autopilot)
