"""Telemetry as ArduPilot streams it: per serial port, stream groups at the SRn_* rates
(all 0 by default on ArduCopter: nothing but HEARTBEAT until a client asks), set by
REQUEST_DATA_STREAM (MAVProxy, DroneKit) or PARAM_SET, with SET_MESSAGE_INTERVAL
overriding one message's rate (GCS_Common.cpp)."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.autopilot.commander import Result
from ft_sitl.mavlink.ardupilot.params import STREAM_GROUPS, STREAM_PORTS
from ft_sitl.mavlink.streams import MAX_STREAM_HZ, Streams
from ft_sitl.mavlink.telemetry import Telemetry

_M = apm
#: the messages of each stream group this face produces (GCS_Common.cpp's
#: STREAM_*_msgs, those ft-sitl has a value for)
GROUP_MESSAGES = {
    "RAW_SENS": (),
    "EXT_STAT": (_M.MAVLINK_MSG_ID_SYS_STATUS, _M.MAVLINK_MSG_ID_MISSION_CURRENT,
                 _M.MAVLINK_MSG_ID_GPS_RAW_INT, _M.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT,
                 _M.MAVLINK_MSG_ID_FENCE_STATUS),
    "RC_CHAN": (_M.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW, _M.MAVLINK_MSG_ID_RC_CHANNELS),
    "RAW_CTRL": (),
    "POSITION": (_M.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, _M.MAVLINK_MSG_ID_LOCAL_POSITION_NED),
    "EXTRA1": (_M.MAVLINK_MSG_ID_ATTITUDE, _M.MAVLINK_MSG_ID_AHRS2),
    "EXTRA2": (_M.MAVLINK_MSG_ID_VFR_HUD,),
    "EXTRA3": (_M.MAVLINK_MSG_ID_BATTERY_STATUS, _M.MAVLINK_MSG_ID_EKF_STATUS_REPORT),
    "PARAMS": (),
    "ADSB": (_M.MAVLINK_MSG_ID_ADSB_VEHICLE,),
}
#: REQUEST_DATA_STREAM's stream ids (MAV_DATA_STREAM) -> the group they set
DATA_STREAMS = {
    _M.MAV_DATA_STREAM_RAW_SENSORS: "RAW_SENS", _M.MAV_DATA_STREAM_EXTENDED_STATUS: "EXT_STAT",
    _M.MAV_DATA_STREAM_RC_CHANNELS: "RC_CHAN", _M.MAV_DATA_STREAM_RAW_CONTROLLER: "RAW_CTRL",
    _M.MAV_DATA_STREAM_POSITION: "POSITION", _M.MAV_DATA_STREAM_EXTRA1: "EXTRA1",
    _M.MAV_DATA_STREAM_EXTRA2: "EXTRA2", _M.MAV_DATA_STREAM_EXTRA3: "EXTRA3",
}
#: MAV_DATA_STREAM_ALL sets every group before PARAMS (ArduPilot leaves PARAMS and ADSB)
ALL_GROUPS = STREAM_GROUPS[:STREAM_GROUPS.index("PARAMS")]
#: the most REQUEST_DATA_STREAM sets (SRn_*'s range)
MAX_GROUP_HZ = 50


class ArduCopterStreams(Streams):
    """The streams of one vehicle's links; link n reads SRn_* (n < STREAM_PORTS)."""

    def __init__(self, telemetry: Telemetry, link_modes: list[str]):
        self.telemetry = telemetry
        self.ap = telemetry.v.ap_params
        n = len(link_modes)
        #: SET_MESSAGE_INTERVAL's rates per link, over the groups' (Hz; 0 stops)
        self.overrides: list[dict[int, float]] = [{} for _ in range(n)]
        self.rates = [{} for _ in range(n)]
        self.next_due = [{} for _ in range(n)]
        self._seen = -1
        self._refresh()

    def _port(self, link: int) -> int:
        return min(link, STREAM_PORTS - 1)

    def _refresh(self) -> None:
        """Each link's rates from SRn_* and its overrides (after any parameter change)."""
        self._seen = self.ap.version
        for link, rates in enumerate(self.rates):
            new = {_M.MAVLINK_MSG_ID_HEARTBEAT: 1.0}
            for g in STREAM_GROUPS:
                hz = float(self.ap[f"SR{self._port(link)}_{g}"])
                for msg_id in GROUP_MESSAGES[g]:
                    new[msg_id] = max(new.get(msg_id, 0.0), hz)
            new.update(self.overrides[link])
            rates.clear()
            rates.update(new)
            for msg_id in new:
                self.next_due[link].setdefault(msg_id, 0)

    def due_telemetry(self, link: int):
        if self._seen != self.ap.version:
            self._refresh()
        return super().due_telemetry(link)

    def request_data_stream(self, stream_id: int, rate_hz: int, start: int, link: int) -> None:
        """REQUEST_DATA_STREAM on this link, as ArduPilot reads it: start_stop 1 sets the
        group(s) to the rate, 0 stops them, anything else is ignored; the SRn_*
        parameters change with it."""
        if start not in (0, 1):
            return
        hz = min(int(rate_hz), MAX_GROUP_HZ) if start == 1 else 0
        if stream_id == _M.MAV_DATA_STREAM_ALL:
            groups = ALL_GROUPS
        elif stream_id in DATA_STREAMS:
            groups = (DATA_STREAMS[stream_id],)
        else:
            return
        for g in groups:
            self.ap.set(f"SR{self._port(link)}_{g}", hz)

    def set_message_interval(self, msg_id: float, interval_us: float, link: int) -> Result:
        """As the PX4 face checks it; the rate is kept over the groups' (0: back to the
        group's rate)."""
        result = super().set_message_interval(msg_id, interval_us, link)
        if result != Result.ACCEPTED:
            return result
        msg_id = int(round(msg_id))
        if interval_us == 0:
            self.overrides[link].pop(msg_id, None)
        else:
            self.overrides[link][msg_id] = 0.0 if interval_us < 0 else \
                min(1e6 / interval_us, MAX_STREAM_HZ)
        self._refresh()
        return result
