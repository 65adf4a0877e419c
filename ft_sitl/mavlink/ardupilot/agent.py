"""One vehicle's ArduCopter face: the PX4 face's router (:class:`VehicleAgent`) with the
pieces ArduCopter answers differently replaced, and REQUEST_DATA_STREAM."""

from __future__ import annotations

from ft_sitl import frames
from ft_sitl.mavlink.agent import VehicleAgent
from ft_sitl.mavlink.ardupilot.commands import ArduCopterCommands
from ft_sitl.mavlink.ardupilot.guided import ArduCopterReceiver, GuidedTargets
from ft_sitl.mavlink.ardupilot.mission import ArduCopterMission, ArduCopterMissionItems
from ft_sitl.mavlink.ardupilot.modes import FlightModes
from ft_sitl.mavlink.ardupilot.parameters import ArduCopterParameters
from ft_sitl.mavlink.ardupilot.params import ApParamSet
from ft_sitl.mavlink.ardupilot.streams import ArduCopterStreams
from ft_sitl.mavlink.ardupilot.telemetry import ArduCopterTelemetry
from ft_sitl.mavlink.vehicle import Vehicle
from ft_sitl.sim.fleet import Fleet


class ArduCopterVehicle(Vehicle):
    """The vehicle with its ArduCopter mode and parameters (whose defaults it flies)."""

    def __init__(self, fleet: Fleet, index: int, geo: frames.GeoReference):
        super().__init__(fleet, index, geo)
        self.modes = FlightModes(self.cmd)
        self.ap_params = ApParamSet(self.params, self.sysid)
        fleet.refresh_params()


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

    def _dispatch_table(self) -> dict:
        table = super()._dispatch_table()
        table["REQUEST_DATA_STREAM"] = self._on_request_data_stream
        return table

    def _on_request_data_stream(self, m, link, peer, wall_us):
        self.streams.request_data_stream(m.req_stream_id, m.req_message_rate, m.start_stop,
                                         link)
        return []

    @property
    def mode_name(self) -> str:
        """The ArduCopter mode now (its name)."""
        return self.vehicle.modes.name
