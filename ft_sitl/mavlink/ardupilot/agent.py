"""One vehicle's ArduCopter face: the PX4 face's router (:class:`VehicleAgent`) with the
pieces ArduCopter answers differently replaced, and REQUEST_DATA_STREAM."""

from __future__ import annotations

from ft_sitl import frames
from ft_sitl.mavlink.agent import VehicleAgent
from ft_sitl.mavlink.ardupilot.commands import ArduCopterCommands
from ft_sitl.mavlink.ardupilot.copter import CopterLoop
from ft_sitl.mavlink.ardupilot.fence import ArduCopterFence
from ft_sitl.mavlink.ardupilot.guided import ArduCopterReceiver, GuidedTargets
from ft_sitl.mavlink.ardupilot.mission import ArduCopterMission, ArduCopterMissionItems
from ft_sitl.mavlink.ardupilot.modes import FlightModes
from ft_sitl.mavlink.ardupilot.parameters import ArduCopterParameters
from ft_sitl.mavlink.ardupilot.params import ApParamSet
from ft_sitl.mavlink.ardupilot.rally import RallyRule
from ft_sitl.mavlink.ardupilot.streams import ArduCopterStreams
from ft_sitl.mavlink.ardupilot.telemetry import ArduCopterTelemetry
from ft_sitl.mavlink.vehicle import Vehicle
from ft_sitl.sim.fleet import Fleet


class ArduCopterVehicle(Vehicle):
    """The vehicle with its ArduCopter mode and parameters (whose defaults it flies)."""

    def __init__(self, fleet: Fleet, index: int, geo: frames.GeoReference):
        super().__init__(fleet, index, geo)
        self.modes = FlightModes(self.cmd, lambda: fleet.state(index).velocity)
        self.ap_params = ApParamSet(self.params, self.sysid)
        #: the fence's kinds and uploaded areas (.fence); RTL's return point (.rally)
        self.fence = ArduCopterFence(self)
        self.cmd.rally_rule = RallyRule(self.ap_params)
        fleet.refresh_params()
        #: RC input, failsafes and RTL's last legs, run each chunk (.copter)
        self.loop = CopterLoop(self)
        self.rc, self.gcs_fs, self.battery_fs = (self.loop.rc, self.loop.gcs_fs,
                                                 self.loop.battery_fs)


class ArduCopterAgent(VehicleAgent):
    """The MAVLink face of one vehicle as ArduCopter."""

    vehicle_class = ArduCopterVehicle
    telemetry_class = ArduCopterTelemetry
    streams_class = ArduCopterStreams
    commands_class = ArduCopterCommands
    parameters_class = ArduCopterParameters
    offboard_class = GuidedTargets
    receiver_class = ArduCopterReceiver
    mission_class = ArduCopterMission
    mission_items_class = ArduCopterMissionItems
    #: SETUP_SIGNING over the vehicle's links (.signing; the server gives it)
    signing = None

    def _dispatch_table(self) -> dict:
        table = super()._dispatch_table()
        table["REQUEST_DATA_STREAM"] = self._on_request_data_stream
        table["SETUP_SIGNING"] = lambda m, *a: self.signing.setup(m) if self.signing else []
        table["RC_CHANNELS_OVERRIDE"] = self._on_rc_override
        table["HEARTBEAT"] = self._on_heartbeat
        manual = table["MANUAL_CONTROL"]
        table["MANUAL_CONTROL"] = lambda m, *a: self._on_heartbeat(m, *a) + manual(m, *a)
        return table

    def _on_heartbeat(self, m, link, peer, wall_us):
        self.vehicle.gcs_fs.heard(m.get_srcSystem())  # (the GCS failsafe's timer)
        return []

    def _on_rc_override(self, m, link, peer, wall_us):
        self.vehicle.rc.on_override(m)
        return self._on_heartbeat(m, link, peer, wall_us)

    def events(self):
        self.vehicle.loop.tick()  # (once per chunk of simulated time)
        return super().events()

    def _on_request_data_stream(self, m, link, peer, wall_us):
        self.streams.request_data_stream(m.req_stream_id, m.req_message_rate, m.start_stop,
                                         link)
        return []

    @property
    def mode_name(self) -> str:
        """The ArduCopter mode now (its name)."""
        return self.vehicle.modes.name
