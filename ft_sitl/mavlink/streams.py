"""Which telemetry goes out on which link, and when: PX4's per-link stream rates.

Each link starts with its mode's rates (``onboard`` for an API, ``normal`` for a ground
station, PX4's two SITL link modes) and a client changes them per link with
MAV_CMD_SET_MESSAGE_INTERVAL. Streams are scheduled by simulated time, so a run faster or
slower than real time sends the same messages per simulated second.
"""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import common as mav

from ft_sitl.autopilot.commander import Result
from ft_sitl.mavlink.outgoing import Outgoing
from ft_sitl.mavlink.telemetry import Telemetry
from ft_sitl.mavlink.traffic import TRAFFIC_HZ, traffic_reports

# PX4 stream rates (Hz) per link mode; SET_MESSAGE_INTERVAL overrides per link.
ONBOARD_RATES = {
    mav.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    mav.MAVLINK_MSG_ID_ATTITUDE: 100.0,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 50.0,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 30.0,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 50.0,
    mav.MAVLINK_MSG_ID_ODOMETRY: 30.0,
    mav.MAVLINK_MSG_ID_HIGHRES_IMU: 50.0,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 5.0,
    mav.MAVLINK_MSG_ID_SYS_STATUS: 5.0,
    mav.MAVLINK_MSG_ID_VFR_HUD: 10.0,
    mav.MAVLINK_MSG_ID_ALTITUDE: 10.0,
    mav.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: 5.0,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
    mav.MAVLINK_MSG_ID_ADSB_VEHICLE: TRAFFIC_HZ,
}
NORMAL_RATES = {
    mav.MAVLINK_MSG_ID_HEARTBEAT: 1.0,
    mav.MAVLINK_MSG_ID_ATTITUDE: 20.0,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: 10.0,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 1.0,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 5.0,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: 1.0,
    mav.MAVLINK_MSG_ID_SYS_STATUS: 1.0,
    mav.MAVLINK_MSG_ID_VFR_HUD: 4.0,
    mav.MAVLINK_MSG_ID_ALTITUDE: 1.0,
    mav.MAVLINK_MSG_ID_HOME_POSITION: 0.5,
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: 0.5,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: 1.0,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: 1.0,
    mav.MAVLINK_MSG_ID_ADSB_VEHICLE: TRAFFIC_HZ,
}

MAX_STREAM_HZ = 500.0  # SET_MESSAGE_INTERVAL: the fastest a message is streamed


class Streams:
    """The telemetry schedule of one vehicle's links (``link_modes``: "onboard" or
    "normal" per link)."""

    def __init__(self, telemetry: Telemetry, link_modes: list[str]):
        self.telemetry = telemetry
        self.rates: list[dict[int, float]] = [
            dict(ONBOARD_RATES if m == "onboard" else NORMAL_RATES) for m in link_modes
        ]
        self.next_due: list[dict[int, int]] = [dict.fromkeys(r, 0) for r in self.rates]

    def due_telemetry(self, link: int) -> list[Outgoing]:
        """Messages whose interval has elapsed on this link, by simulated time."""
        out = []
        t = self.telemetry
        now = t.v.fleet.time_us
        due = self.next_due[link]
        for msg_id, hz in self.rates[link].items():
            if hz <= 0 or now < due[msg_id]:
                continue
            period = int(1e6 / hz)
            due[msg_id] = max(due[msg_id] + period, now)
            if msg_id == mav.MAVLINK_MSG_ID_ADSB_VEHICLE:
                out.extend(Outgoing(m, link) for m in traffic_reports(t.v.fleet, t.v.geo))
                continue
            m = t.build(msg_id)
            if m is not None:
                out.append(Outgoing(m, link))
        return out

    def set_message_interval(self, msg_id: float, interval_us: float, link: int) -> Result:
        """MAV_CMD_SET_MESSAGE_INTERVAL on this link: interval > 0 sets 1e6 / interval Hz (at
        most MAX_STREAM_HZ), 0 the link's default rate, a negative one (-1) stops the
        message. FAILED, as PX4's ``set_message_interval``: the heartbeat (its rate is not
        a client's to change: one client must not make the vehicle look dead to the others)
        and a message we cannot produce. DENIED: a non-finite message id or interval (PX4
        reads a NaN interval as 0 and +-inf as "stop")."""
        if not math.isfinite(msg_id):
            return Result.DENIED
        msg_id = int(round(msg_id))  # PX4: (int)(param1 + 0.5f)
        if not math.isfinite(interval_us):
            return Result.DENIED
        if msg_id == mav.MAVLINK_MSG_ID_HEARTBEAT:
            return Result.FAILED
        streamable = msg_id == mav.MAVLINK_MSG_ID_ADSB_VEHICLE or \
            self.build_probe(msg_id) is not None  # (traffic: one message per mover)
        if not streamable:
            return Result.FAILED
        if interval_us == 0:
            hz = (ONBOARD_RATES if link == 0 else NORMAL_RATES).get(msg_id, 0.0)
        elif interval_us < 0:
            hz = 0.0
        else:
            hz = min(1e6 / interval_us, MAX_STREAM_HZ)
        self.rates[link][msg_id] = hz
        self.next_due[link].setdefault(msg_id, 0)
        return Result.ACCEPTED

    def build_probe(self, msg_id: int):
        """The message ``msg_id`` now, or None when we cannot build it."""
        try:
            return self.telemetry.build(msg_id)
        except Exception:  # noqa: BLE001 - a message we cannot build is unsupported
            return None
