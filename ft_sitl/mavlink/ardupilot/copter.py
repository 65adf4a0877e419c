"""What ArduCopter does every loop beyond the flight controller's own tick, for one
vehicle: its RC input (:mod:`.rc`), its GCS and battery failsafes (:mod:`.failsafe`) and
its RTL's last legs (:mod:`.rtl`), and SITL's SIM_GPS_DISABLE (the flight controller's
GPS failure, as MAV_CMD_INJECT_FAILURE injects it), run once per chunk of simulated time the server
advances (ft_sitl.mavlink.server.CHUNK_US), in ArduCopter's order: read the radio, check
the failsafes, fly the mode."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ft_sitl.mavlink.ardupilot.failsafe import BatteryFailsafe, GcsFailsafe
from ft_sitl.mavlink.ardupilot.rc import RcInput
from ft_sitl.mavlink.ardupilot.rtl import RtlPhases

if TYPE_CHECKING:  # the vehicle owns this object; only its type is needed here
    from ft_sitl.mavlink.ardupilot.agent import ArduCopterVehicle


class CopterLoop:
    """One vehicle's ArduCopter duties; :meth:`tick` runs them."""

    def __init__(self, v: ArduCopterVehicle):
        self.rc = RcInput(v)
        self.gcs_fs = GcsFailsafe(v)
        self.battery_fs = BatteryFailsafe(v)
        self.rtl = RtlPhases(v)
        self.v = v
        self._gps_disabled = 0

    def _sim_gps(self) -> None:
        off = int(self.v.ap_params["SIM_GPS_DISABLE"])
        if off != self._gps_disabled:
            self._gps_disabled = off
            self.v.cmd.record_failure("gps", "off" if off else "ok", 0)

    def tick(self) -> None:
        self._sim_gps()
        self.rc.tick()
        self.gcs_fs.tick()
        self.battery_fs.tick()
        self.rtl.tick()
