"""One vehicle's MAVLink side: what PX4's mavlink module does, transport-free.

:class:`VehicleAgent` turns incoming MAVLink messages into commander calls and answers,
and produces the telemetry streams at their rates. It never touches a socket: the server
hands it decoded messages with the link they came on and sends what it returns.

It is the entry point and the router; the work is split along PX4's own seams, one
module per protocol, so each can be read (and tested) alone:

- :mod:`~ft_sitl.mavlink.telemetry`: the value of each telemetry message;
- :mod:`~ft_sitl.mavlink.streams`: which of them goes out on which link, when;
- :mod:`~ft_sitl.mavlink.events`: status texts, items reached, mission progress;
- :mod:`~ft_sitl.mavlink.traffic`: the world's movers as ADSB_VEHICLE;
- :mod:`~ft_sitl.mavlink.commands`: COMMAND_LONG / COMMAND_INT, a table of handlers;
- :mod:`~ft_sitl.mavlink.mission` and :mod:`~ft_sitl.mavlink.mission_items`: the
  mission protocol for missions, fences and rally points;
- :mod:`~ft_sitl.mavlink.parameters`: the parameter protocol;
- :mod:`~ft_sitl.mavlink.offboard`: offboard setpoints;
- :mod:`~ft_sitl.mavlink.receiver`: modes, time sync, follow-me, manual control;
- :mod:`~ft_sitl.mavlink.services`: shell, FTP and log download;
- :mod:`~ft_sitl.mavlink.vehicle`: the vehicle they all speak for.

Conversions between the wire's NED/FRD and the simulator's ENU/FLU happen only through
:mod:`ft_sitl.frames`, and the vehicle's state is read only through the fleet's named
accessors (tests/test_layers.py keeps the plant's array layout out of this package).
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.autopilot import commander as cm
from ft_sitl.mavlink import files
from ft_sitl.mavlink.commands import Commands
from ft_sitl.mavlink.events import Events
from ft_sitl.mavlink.mission import MissionProtocol
from ft_sitl.mavlink.mission_items import MissionItems
from ft_sitl.mavlink.offboard import Offboard
from ft_sitl.mavlink.outgoing import COMPID, Outgoing
from ft_sitl.mavlink.parameters import Parameters
from ft_sitl.mavlink.receiver import Receiver
from ft_sitl.mavlink.services import Services
from ft_sitl.mavlink.shell import Shell
from ft_sitl.mavlink.streams import Streams
from ft_sitl.mavlink.telemetry import Telemetry
from ft_sitl.mavlink.traffic import traffic_reports
from ft_sitl.mavlink.vehicle import Vehicle
from ft_sitl.sim.fleet import Fleet

__all__ = ["COMPID", "Outgoing", "VehicleAgent"]

#: what an injected MAVLink signal failure drops (commands still pass, so it can be undone)
SIGNAL_LOSS_DROPS = ("HEARTBEAT", "MANUAL_CONTROL", "SET_POSITION_TARGET_LOCAL_NED",
                     "SET_POSITION_TARGET_GLOBAL_INT", "SET_ATTITUDE_TARGET", "FOLLOW_TARGET")


class VehicleAgent:
    """The MAVLink face of vehicle ``index`` of a :class:`Fleet` (sysid index + 1), with
    ``n_links`` links whose stream rates start as ``link_modes`` says ("onboard" or
    "normal" per link) and ``logs`` to serve for log download and FTP."""

    #: the pieces a personality's agent may replace (the ArduCopter face:
    #: :mod:`ft_sitl.mavlink.ardupilot.agent`); each is built with the same arguments
    vehicle_class = Vehicle
    telemetry_class = Telemetry
    streams_class = Streams
    commands_class = Commands
    parameters_class = Parameters
    offboard_class = Offboard
    receiver_class = Receiver
    mission_class = MissionProtocol
    mission_items_class = MissionItems

    def __init__(self, fleet: Fleet, index: int, geo: frames.GeoReference, n_links: int,
                 link_modes: list[str], logs: list[files.LogFile] | None = None):
        v = self.vehicle_class(fleet, index, geo)
        self.vehicle = v
        self.fleet, self.i, self.sysid, self.geo = fleet, index, v.sysid, geo
        self.cmd: cm.Commander = v.cmd
        self.params, self.origin, self.n_links = v.params, v.origin, n_links
        self.telemetry = self.telemetry_class(v)
        self.streams = self.streams_class(self.telemetry, link_modes)
        self.rates = self.streams.rates
        self.next_due = self.streams.next_due
        self._events = Events(self.telemetry)
        self.commands = self.commands_class(self.telemetry, self.streams)
        self.mission = self.mission_class(self.mission_items_class(v), self.telemetry)
        self.parameters = self.parameters_class(v)
        self.offboard = self.offboard_class(v)
        self.receiver = self.receiver_class(v)
        self.services = Services(Shell(self), n_links, self.parameters.file,
                                 list(logs or []), self._warn)
        self._handlers = self._dispatch_table()

    def _dispatch_table(self) -> dict:
        """The handler of each message type a vehicle reacts to (others are ignored)."""
        c, ms, pr, ob, rx, sv = (self.commands, self.mission, self.parameters, self.offboard,
                                 self.receiver, self.services)
        return {
            "COMMAND_LONG": c.on_command,
            "COMMAND_INT": c.on_command,
            "SET_MODE": rx.on_set_mode,
            "SET_POSITION_TARGET_LOCAL_NED": ob.on_local_ned,
            "SET_POSITION_TARGET_GLOBAL_INT": ob.on_global_int,
            "SET_ATTITUDE_TARGET": ob.on_attitude_target,
            "PARAM_REQUEST_LIST": pr.on_request_list,
            "PARAM_REQUEST_READ": pr.on_request_read,
            "PARAM_SET": pr.on_set,
            "MISSION_COUNT": ms.on_count,
            "MISSION_ITEM_INT": ms.on_item_int,
            "MISSION_ITEM": ms.on_item,
            "MISSION_REQUEST_LIST": ms.on_request_list,
            "MISSION_REQUEST_INT": ms.on_request,
            "MISSION_REQUEST": ms.on_request,
            "MISSION_CLEAR_ALL": ms.on_clear_all,
            "MISSION_SET_CURRENT": ms.on_set_current,
            "MISSION_ACK": ms.on_ack,
            "TIMESYNC": rx.on_timesync,
            "SERIAL_CONTROL": sv.on_serial_control,
            "FOLLOW_TARGET": rx.on_follow_target,
            "MANUAL_CONTROL": rx.on_manual_control,
            "FILE_TRANSFER_PROTOCOL": sv.on_file_transfer_protocol,
            "LOG_REQUEST_LIST": sv.on_log,
            "LOG_REQUEST_DATA": sv.on_log,
            "LOG_REQUEST_END": sv.on_log,
            "LOG_ERASE": sv.on_log,
        }

    @property
    def sim(self):
        return self.fleet.sim

    def _warn(self, text: str) -> None:
        self.cmd.text(cm.Severity.WARNING, text)

    # --- incoming -----------------------------------------------------------------------
    def for_us(self, m) -> bool:
        """Whether ``m`` is addressed to this vehicle's autopilot (or to everyone)."""
        ts = getattr(m, "target_system", None)
        tc = getattr(m, "target_component", None)
        if ts is None:
            return True
        if ts not in (0, self.sysid):
            return False
        return tc is None or tc in (0, COMPID)

    def handle(self, m, link: int, peer, wall_us: int) -> list[Outgoing]:
        """React to one decoded message; returns the replies (none for most streams)."""
        t = m.get_type()
        handler = self._handlers.get(t)
        if handler is None or not self.for_us(m):
            return []
        if t in SIGNAL_LOSS_DROPS and not self.cmd.sensor_ok("mavlink_signal"):
            return []  # an injected MAVLink signal failure
        return handler(m, link, peer, wall_us)

    def poll(self, wall_us: int) -> list[Outgoing]:
        """Wall-clock duties: stream the parameter list, FTP bursts and log data on,
        re-request mission items, give up abandoned uploads."""
        return self.parameters.poll() + self.services.poll(wall_us) + \
            self.mission.poll(wall_us)

    # --- outgoing -----------------------------------------------------------------------
    def due_telemetry(self, link: int) -> list[Outgoing]:
        """Messages whose interval has elapsed on this link, by simulated time."""
        return self.streams.due_telemetry(link)

    def events(self) -> list[Outgoing]:
        """Status texts, reached items and mission progress changes since the last call."""
        return self._events.events()

    def texts(self) -> list[Outgoing]:
        """STATUSTEXTs for the commander's texts since the last call."""
        return self._events.texts()

    def build(self, msg_id: int):
        """The current value of a telemetry message, or None if we do not produce it."""
        return self.telemetry.build(msg_id)

    def build_probe(self, msg_id: int):
        """As :meth:`build`, None also when building it fails."""
        return self.streams.build_probe(msg_id)

    def heartbeat(self) -> mav.MAVLink_heartbeat_message:
        return self.telemetry.heartbeat()

    def autopilot_version(self) -> mav.MAVLink_autopilot_version_message:
        return self.telemetry.autopilot_version()

    def home_position(self) -> mav.MAVLink_home_position_message:
        return self.telemetry.home_position()

    def mission_current(self) -> mav.MAVLink_mission_current_message:
        return self.telemetry.mission_current()

    def traffic(self) -> list:
        """One ADSB_VEHICLE per moving obstacle of the vehicle's world (empty without)."""
        return traffic_reports(self.fleet, self.geo)

    def set_param(self, name: str, value) -> None:
        """Set one parameter (PARAM_SET, the shell); ParamError refuses it as a whole,
        nothing half-applied."""
        self.parameters.set(name, value)
