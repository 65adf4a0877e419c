"""One vehicle's MAVLink side: what PX4's mavlink module does, transport-free.

:class:`VehicleAgent` turns incoming MAVLink messages into commander calls and answers
(COMMAND_ACK, PARAM_VALUE, mission protocol), and produces the telemetry streams at
their rates. It never touches a socket: the server hands it decoded messages with the
link they came on and sends what it returns. Conversions between the wire's NED/FRD and
the simulator's ENU/FLU happen only through :mod:`ft_sitl.frames`.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field

import numpy as np
from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import MissionItem, Result
from ft_sitl.autopilot.geofence import Fence, FenceError, Polygon, circle, fits, polygon
from ft_sitl.autopilot.params import PARAMS, ParamError
from ft_sitl.autopilot.setpoints import Setpoint, SetpointError
from ft_sitl.mavlink import files
from ft_sitl.mavlink.ftp import FtpServer
from ft_sitl.mavlink.logs import LogServer
from ft_sitl.mavlink.shell import Shell
from ft_sitl.physics import dynamics as d
from ft_sitl.physics.quaternion import qrotate_inv, qto_euler
from ft_sitl.sim.fleet import Fleet

COMPID = mav.MAV_COMP_ID_AUTOPILOT1
#: ORBIT_EXECUTION_STATUS while orbiting, every (simulated) 0.5 s
ORBIT_STATUS_PERIOD_US = 500_000
#: FOLLOW_TARGET fixes used: within this distance of home, altitudes (AMSL) in this range
#: and speeds up to this (others: ignored, or the altitude / velocity taken as unknown)
FOLLOW_MAX_RANGE_M, FOLLOW_ALT_RANGE_M, FOLLOW_MAX_SPEED_M_S = 100_000.0, (-500.0, 10_000.0), 100.0
#: the mission protocol's item lists a vehicle keeps (PX4's three)
MISSION_TYPES = (mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_FENCE,
                 mav.MAV_MISSION_TYPE_RALLY)
GLOBAL_FRAMES = (mav.MAV_FRAME_GLOBAL_INT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                 mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT)
#: the frames a mission item may use here (others: MAV_MISSION_UNSUPPORTED_FRAME, as PX4)
SUPPORTED_FRAMES = GLOBAL_FRAMES + (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_MISSION)
FORCE_MAGIC = 21196

CAPABILITIES = (
    mav.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | mav.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | mav.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | mav.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
    | mav.MAV_PROTOCOL_CAPABILITY_FTP
    | mav.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | mav.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | mav.MAV_PROTOCOL_CAPABILITY_FLIGHT_TERMINATION
    | mav.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)

#: ADSB_VEHICLE, one per moving obstacle of the world (scenarios.movers), Hz: an ADS-B Out
#: transmitter's airborne position rate (two squitters a second). PX4 forwards each traffic
#: report its receiver gets, on every link ("unlimited" ADSB_VEHICLE stream); we play the
#: receiver, hearing every mover at this rate. Nothing is sent in a world without movers.
TRAFFIC_HZ = 2.0
#: the ICAO address of mover j is this + j + 1 (an arbitrary block: ADSB_FLAGS_SIMULATED
#: marks them as not real aircraft)
TRAFFIC_ICAO_BASE = 0xFE0000
#: the ADS-B emitter category of each mover shape (mover_kinds.SHAPES): a person has
#: none of its own (POINT_OBSTACLE), a box is a cart or a car (SERVICE_SURFACE), a sphere a
#: balloon or another drone (UAV)
TRAFFIC_EMITTER = {"person": mav.ADSB_EMITTER_TYPE_POINT_OBSTACLE,
                   "box": mav.ADSB_EMITTER_TYPE_SERVICE_SURFACE,
                   "sphere": mav.ADSB_EMITTER_TYPE_UAV}
TRAFFIC_FLAGS = (mav.ADSB_FLAGS_VALID_COORDS | mav.ADSB_FLAGS_VALID_ALTITUDE
                 | mav.ADSB_FLAGS_VALID_HEADING | mav.ADSB_FLAGS_VALID_VELOCITY
                 | mav.ADSB_FLAGS_VALID_CALLSIGN | mav.ADSB_FLAGS_SIMULATED)

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

#: the SYS_STATUS health bit of each sensor failure injection can turn off
SENSOR_BITS = {"gyro": mav.MAV_SYS_STATUS_SENSOR_3D_GYRO,
               "accel": mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
               "mag": mav.MAV_SYS_STATUS_SENSOR_3D_MAG,
               "baro": mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE,
               "gps": mav.MAV_SYS_STATUS_SENSOR_GPS}
#: what an injected MAVLink signal failure drops (commands still pass, so it can be undone)
SIGNAL_LOSS_DROPS = ("HEARTBEAT", "MANUAL_CONTROL", "SET_POSITION_TARGET_LOCAL_NED",
                     "SET_POSITION_TARGET_GLOBAL_INT", "SET_ATTITUDE_TARGET", "FOLLOW_TARGET")

SENSORS = (
    mav.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | mav.MAV_SYS_STATUS_SENSOR_3D_MAG
    | mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | mav.MAV_SYS_STATUS_SENSOR_GPS
    | mav.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | mav.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | mav.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | mav.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | mav.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | mav.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | mav.MAV_SYS_STATUS_PREARM_CHECK
)

MAX_STREAM_HZ = 500.0  # SET_MESSAGE_INTERVAL: the fastest a message is streamed

MISSION_TIMEOUT_US = 1_500_000  # wall time between re-requests during a transfer
MISSION_RETRIES = 5
#: PARAM_VALUEs sent per poll while streaming the list: a burst of all ~480 small datagrams
#: could overrun a client's socket buffer; chunks of this size cannot
PARAM_STREAM_CHUNK = 40
#: each parameter's PARAM_VALUE index (PARAMS order)
PARAM_INDEX = {name: k for k, name in enumerate(PARAMS)}
PARAM_NAMES = list(PARAMS)


@dataclass
class Outgoing:
    """A message to send: on a link index (None: every link) to a peer (None: all peers)."""

    msg: mav.MAVLink_message
    link: int | None = None
    peer: tuple | None = None


@dataclass
class _Snapshot:
    time_us: int
    state: object
    x: np.ndarray
    q_ned: np.ndarray
    w_frd: np.ndarray
    p_ned: np.ndarray
    v_ned: np.ndarray


@dataclass
class _Transfer:
    """An upload in progress (client -> vehicle)."""

    count: int
    link: int
    peer: tuple
    items: list = field(default_factory=list)
    last_request_wall_us: int = 0
    retries: int = 0
    mission_type: int = 0


def _param_type(name: str) -> int:
    return mav.MAV_PARAM_TYPE_INT32 if PARAMS[name].is_int else mav.MAV_PARAM_TYPE_REAL32


def _param_wire(name: str, value: float) -> float:
    """The float field of PARAM_VALUE: ints are sent bytewise (int32 bits in the float)."""
    if PARAMS[name].is_int:
        return struct.unpack("<f", struct.pack("<i", int(value)))[0]
    return float(value)


def _param_from_wire(name: str, value: float, ptype: int) -> float:
    if PARAMS[name].is_int and ptype in (mav.MAV_PARAM_TYPE_INT32, mav.MAV_PARAM_TYPE_UINT32,
                                         mav.MAV_PARAM_TYPE_INT8, mav.MAV_PARAM_TYPE_UINT8,
                                         mav.MAV_PARAM_TYPE_INT16, mav.MAV_PARAM_TYPE_UINT16):
        return float(struct.unpack("<i", struct.pack("<f", value))[0])
    return float(value)


class VehicleAgent:
    """The MAVLink face of vehicle ``index`` of a :class:`Fleet` (sysid index + 1)."""

    def __init__(self, fleet: Fleet, index: int, geo: frames.GeoReference, n_links: int,
                 link_modes: list[str], logs: list[files.LogFile] | None = None):
        self.fleet = fleet
        self.i = index
        self.sysid = index + 1
        self.geo = geo
        self.cmd: cm.Commander = fleet.commanders[index]
        self.params = fleet.params[index]
        self.rates: list[dict[int, float]] = [
            dict(ONBOARD_RATES if m == "onboard" else NORMAL_RATES) for m in link_modes
        ]
        self.next_due: list[dict[int, int]] = [dict.fromkeys(r, 0) for r in self.rates]
        self.n_links = n_links
        self._texts_sent = 0
        self._text_id = 0
        self._reached_sent = 0
        self._orbit_due_us = 0
        self._shell = Shell(self)
        self._upload: _Transfer | None = None
        self._download_items: list = []
        #: MISSION_ITEM_INT messages as uploaded, per mission type (mission, fence, rally)
        self._stored: dict[int, list] = {t: [] for t in MISSION_TYPES}
        #: the commander's fence as the last fence upload set it, and the items made for a
        #: fence it got otherwise (a trial's), with that fence (see _fence_download)
        self._fence_uploaded: Fence | None = None
        self._fence_made: tuple[Fence, list] | None = None
        self._last_mission_current: tuple | None = None
        self._snap: _Snapshot | None = None
        # PARAM_REQUEST_LIST answers in progress: (link, peer) -> next index to send
        self._param_streams: dict[tuple, int] = {}
        # PX4 SITL: each instance's local frame starts where it spawned
        self.origin = np.asarray(self.cmd.home, dtype=float).copy()
        # MAVLink FTP and the log protocol, one server of each per link (as PX4), and the
        # peer a burst or a log transfer of each link goes to
        tree = files.vehicle_tree(self._params_file, list(logs or []))
        self._ftp = [FtpServer(tree) for _ in range(n_links)]
        self._logs = [LogServer(list(logs or []), self._warn) for _ in range(n_links)]
        self._ftp_peer: dict[int, tuple] = {}
        self._log_peer: dict[int, tuple] = {}

    # --- helpers --------------------------------------------------------------------
    @property
    def sim(self):
        return self.fleet.sim

    def _boot_ms(self) -> int:
        return self.fleet.time_us // 1000

    def _state(self):
        return self.fleet.state(self.i)

    def _ack(self, command: int, result: int, m, link: int, peer) -> Outgoing:
        return Outgoing(mav.MAVLink_command_ack_message(
            command, int(result), 0, 0, m.get_srcSystem(), m.get_srcComponent()), link, peer)

    def texts(self) -> list[Outgoing]:
        out = []
        t = list(self.cmd.statustexts)
        for severity, text in t[self._texts_sent:] if len(t) >= self._texts_sent else t:
            raw = text.encode("ascii", "replace")
            if len(raw) <= 50:
                out.append(Outgoing(mav.MAVLink_statustext_message(severity, raw)))
                continue
            # MAVLink 2 chunking: one id, chunk_seq 0.., a chunk shorter than 50 ends it
            self._text_id = self._text_id % 65535 + 1
            chunks = [raw[k:k + 50] for k in range(0, len(raw), 50)]
            if len(chunks[-1]) == 50:
                chunks.append(b"")
            for seq, chunk in enumerate(chunks):
                out.append(Outgoing(mav.MAVLink_statustext_message(
                    severity, chunk, self._text_id, seq)))
        self._texts_sent = len(t)
        if self.cmd.statustexts.maxlen and len(t) == self.cmd.statustexts.maxlen:
            self.cmd.statustexts.clear()
            self._texts_sent = 0
        return out

    # --- telemetry --------------------------------------------------------------------
    def heartbeat(self) -> mav.MAVLink_heartbeat_message:
        c = self.cmd
        base = mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if c.armed:
            base |= mav.MAV_MODE_FLAG_SAFETY_ARMED
        if c.main_mode in (cm.MAIN_AUTO, cm.MAIN_OFFBOARD):
            base |= (mav.MAV_MODE_FLAG_AUTO_ENABLED | mav.MAV_MODE_FLAG_GUIDED_ENABLED
                     | mav.MAV_MODE_FLAG_STABILIZE_ENABLED)
        else:
            base |= mav.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
            if c.main_mode != cm.MAIN_MANUAL and c.main_mode != cm.MAIN_ACRO:
                base |= mav.MAV_MODE_FLAG_STABILIZE_ENABLED
            if c.main_mode == cm.MAIN_POSCTL:
                base |= mav.MAV_MODE_FLAG_GUIDED_ENABLED
        if c.terminated:
            status = mav.MAV_STATE_FLIGHT_TERMINATION
        elif c.armed:
            status = mav.MAV_STATE_ACTIVE
        else:
            status = mav.MAV_STATE_STANDBY
        custom = (c.main_mode << 16) | (c.sub_mode << 24)
        return mav.MAVLink_heartbeat_message(mav.MAV_TYPE_QUADROTOR, mav.MAV_AUTOPILOT_PX4,
                                             base, custom, status, 3)

    def autopilot_version(self) -> mav.MAVLink_autopilot_version_message:
        # flight_sw_version 1.15.0 release (major<<24 | minor<<16 | patch<<8 | 255)
        return mav.MAVLink_autopilot_version_message(
            CAPABILITIES, (1 << 24) | (15 << 16) | (0 << 8) | 255, 0, 0, 0,
            [0] * 8, [0] * 8, [0] * 8, 0, 0, 0x46540000 + self.sysid, [0] * 18)

    def home_position(self) -> mav.MAVLink_home_position_message:
        h = self.cmd.home
        lat, lon, alt = self.geo.to_global(h)
        ned = frames.enu_to_ned(h - self.origin)
        return mav.MAVLink_home_position_message(
            int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)),
            float(ned[0]), float(ned[1]), float(ned[2]), [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
            self.fleet.time_us)

    def build(self, msg_id: int):
        """The current value of a telemetry message, or None if we do not produce it."""
        if msg_id == mav.MAVLINK_MSG_ID_HEARTBEAT:
            return self.heartbeat()
        snap = self._snapshot()
        s, x, q_ned, w_frd, p_ned, v_ned = (snap.state, snap.x, snap.q_ned, snap.w_frd,
                                            snap.p_ned, snap.v_ned)
        t_ms = self._boot_ms()
        t_us = self.fleet.time_us
        if msg_id == mav.MAVLINK_MSG_ID_ATTITUDE:
            rpy = qto_euler(q_ned)
            return mav.MAVLink_attitude_message(t_ms, *(float(v) for v in rpy),
                                                *(float(v) for v in w_frd))
        if msg_id == mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION:
            return mav.MAVLink_attitude_quaternion_message(
                t_ms, *(float(v) for v in q_ned), *(float(v) for v in w_frd), [0.0] * 4)
        if msg_id == mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED:
            return mav.MAVLink_local_position_ned_message(
                t_ms, *(float(v) for v in p_ned), *(float(v) for v in v_ned))
        if msg_id == mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT:
            lat, lon, alt = self.geo.to_global(s.position)
            rel = s.position[2] - self.cmd.home[2]
            hdg = math.degrees(frames.yaw_enu_to_ned(s.yaw)) % 360.0
            return mav.MAVLink_global_position_int_message(
                t_ms, int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)),
                int(round(rel * 1000)), *(int(round(v * 100)) for v in v_ned),
                int(round(hdg * 100)) % 36000)
        if msg_id == mav.MAVLINK_MSG_ID_ODOMETRY:
            v_body = frames.flu_to_frd(_rotate_inv(x[d.X_QUAT:d.X_QUAT + 4], s.velocity))
            return mav.MAVLink_odometry_message(
                t_us, mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_BODY_FRD,
                *(float(v) for v in p_ned), [float(v) for v in q_ned],
                *(float(v) for v in v_body), *(float(v) for v in w_frd),
                [math.nan] * 21, [math.nan] * 21, 0, mav.MAV_ESTIMATOR_TYPE_NAIVE, 100)
        if msg_id == mav.MAVLINK_MSG_ID_HIGHRES_IMU:
            f_frd = frames.flu_to_frd(
                self.sim.plant.status[self.i, d.S_SPECIFIC_FORCE:d.S_SPECIFIC_FORCE + 3])
            alt = self.geo.alt_m + s.position[2]
            pressure = 1013.25 * (1 - 2.25577e-5 * alt) ** 5.25588
            return mav.MAVLink_highres_imu_message(
                t_us, *(float(v) for v in f_frd), *(float(v) for v in w_frd),
                0.21, 0.0, 0.43, pressure, 0.0, float(alt), 20.0, 0x1FFF, 0)
        if msg_id == mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE:
            return mav.MAVLink_extended_sys_state_message(
                mav.MAV_VTOL_STATE_UNDEFINED, int(self.cmd.landed_state))
        if msg_id == mav.MAVLINK_MSG_ID_SYS_STATUS:
            bat = self.cmd.battery
            power = self._shaft_power()
            current = bat.current_a(power)
            present = SENSORS
            if self.cmd.geofence_active:  # PX4: the geofence bit while a fence is set
                present |= mav.MAV_SYS_STATUS_GEOFENCE
            health = present
            if self.cmd.terminated or self.cmd.battery.remaining < self.params["BAT_CRIT_THR"]:
                health &= ~mav.MAV_SYS_STATUS_PREARM_CHECK
            if self.cmd.fence_breached:
                health &= ~mav.MAV_SYS_STATUS_GEOFENCE
            for unit, bit in SENSOR_BITS.items():  # injected sensor failures
                if not self.cmd.sensor_ok(unit):
                    health &= ~bit
            return mav.MAVLink_sys_status_message(
                present, present, health, 200, int(bat.voltage(current) * 1000),
                int(current * 100), int(round(bat.remaining * 100)), 0, 0, 0, 0, 0, 0)
        if msg_id == mav.MAVLINK_MSG_ID_VFR_HUD:
            speed = float(np.linalg.norm(s.velocity[:2]))
            hdg = int(math.degrees(frames.yaw_enu_to_ned(s.yaw)) % 360.0)
            thr = float(self.fleet.sim.w_cmd[self.i].mean() /
                        self.fleet.sim.platforms[self.i].rotor_speed_max_rad_s) ** 2
            return mav.MAVLink_vfr_hud_message(speed, speed, hdg, int(thr * 100),
                                               float(self.geo.alt_m + s.position[2]),
                                               float(s.velocity[2]))
        if msg_id == mav.MAVLINK_MSG_ID_ALTITUDE:
            amsl = float(self.geo.alt_m + s.position[2])
            rel = float(s.position[2] - self.cmd.home[2])
            return mav.MAVLink_altitude_message(t_us, amsl, amsl, rel, float(-p_ned[2]),
                                                float(s.position[2] - self.cmd.home[2]),
                                                float(s.position[2]))
        if msg_id == mav.MAVLINK_MSG_ID_HOME_POSITION:
            return self.home_position()
        if msg_id == mav.MAVLINK_MSG_ID_BATTERY_STATUS:
            bat = self.cmd.battery
            current = bat.current_a(self._shaft_power())
            volts, volts_ext = _cell_voltages_mv(bat.voltage(current) / bat.cells, bat.cells)
            return mav.MAVLink_battery_status_message(
                0, mav.MAV_BATTERY_FUNCTION_ALL, mav.MAV_BATTERY_TYPE_LIPO, 2500, volts,
                int(current * 100), int(bat.used_j / 3.6 / max(bat.voltage(), 1.0)), -1,
                int(round(bat.remaining * 100)), voltages_ext=volts_ext)
        if msg_id == mav.MAVLINK_MSG_ID_GPS_RAW_INT:
            if not self.cmd.sensor_ok("gps"):  # an injected GPS failure: no fix
                return mav.MAVLink_gps_raw_int_message(
                    t_us, mav.GPS_FIX_TYPE_NO_FIX, 0, 0, 0, 65535, 65535, 65535, 65535, 0)
            lat, lon, alt = self.geo.to_global(s.position)
            return mav.MAVLink_gps_raw_int_message(
                t_us, mav.GPS_FIX_TYPE_3D_FIX, int(round(lat * 1e7)), int(round(lon * 1e7)),
                int(round(alt * 1000)), 80, 120, int(np.linalg.norm(s.velocity[:2]) * 100),
                65535, 12)
        if msg_id == mav.MAVLINK_MSG_ID_MISSION_CURRENT:
            return self.mission_current()
        if msg_id == mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return self.autopilot_version()
        return None

    def _snapshot(self) -> _Snapshot:
        """The vehicle's state in wire frames, computed once per simulated instant."""
        snap = self._snap
        if snap is None or snap.time_us != self.fleet.time_us:
            s = self._state()
            x = self.sim.estimated(self.i).copy()  # PX4 reports its estimate
            snap = _Snapshot(
                time_us=self.fleet.time_us, state=s, x=x,
                q_ned=frames.q_enu_flu_to_ned_frd(x[d.X_QUAT:d.X_QUAT + 4]),
                w_frd=frames.flu_to_frd(x[d.X_OMEGA:d.X_OMEGA + 3]),
                p_ned=frames.enu_to_ned(s.position - self.origin),
                v_ned=frames.enu_to_ned(s.velocity))
            self._snap = snap
        return snap

    def _shaft_power(self) -> float:
        p = self.sim.platforms[self.i]
        w = self.sim.x[self.i, d.X_ROTOR:]
        return float(np.sum(p.torque_thrust_ratio_m * p.thrust_coefficient * w**3))

    def mission_current(self) -> mav.MAVLink_mission_current_message:
        c = self.cmd
        n = len(c.mission)
        state = c.mission_state
        if state == cm.MissionState.ACTIVE and not (c.main_mode == cm.MAIN_AUTO
                                                    and c.sub_mode == cm.SUB_MISSION):
            state = cm.MissionState.PAUSED
        mode = 1 if c.main_mode == cm.MAIN_AUTO and c.sub_mode == cm.SUB_MISSION else 0
        return mav.MAVLink_mission_current_message(min(c.mission_seq, max(n - 1, 0)) if n else 0,
                                                   n, state, mode)

    def due_telemetry(self, link: int) -> list[Outgoing]:
        """Messages whose interval has elapsed on this link, by simulated time."""
        out = []
        now = self.fleet.time_us
        due = self.next_due[link]
        for msg_id, hz in self.rates[link].items():
            if hz <= 0 or now < due[msg_id]:
                continue
            period = int(1e6 / hz)
            due[msg_id] = max(due[msg_id] + period, now)
            if msg_id == mav.MAVLINK_MSG_ID_ADSB_VEHICLE:
                out.extend(Outgoing(m, link) for m in self.traffic())
                continue
            m = self.build(msg_id)
            if m is not None:
                out.append(Outgoing(m, link))
        return out

    def traffic(self) -> list:
        """One ADSB_VEHICLE per moving obstacle of the vehicle's world (the collision
        guard's movers, where they are now), as a traffic receiver reports them: position
        (degE7) and altitude AMSL (mm) of the shape's centre, course over ground (cdeg from
        north) and horizontal speed (cm/s), the mover's name as the callsign ("PERSON2"),
        an emitter type by shape (TRAFFIC_EMITTER), flagged simulated. Empty without
        movers."""
        guard = self.fleet.guard
        movers = guard.movers if guard is not None else None
        if movers is None:
            return []
        t_us = self.fleet.time_us
        poses, vel = movers.poses(t_us), movers.velocities(t_us)
        out = []
        for j, info in enumerate(movers.describe()):
            lat, lon, alt = self.geo.to_global(poses[j, :3])
            course = math.degrees(frames.yaw_enu_to_ned(float(poses[j, 3]))) % 360.0
            speed = math.hypot(vel[j, 0], vel[j, 1])
            callsign = info["name"].replace(" ", "").upper()[:8].encode("ascii")
            out.append(mav.MAVLink_adsb_vehicle_message(
                TRAFFIC_ICAO_BASE + j + 1, int(round(lat * 1e7)), int(round(lon * 1e7)),
                mav.ADSB_ALTITUDE_TYPE_GEOMETRIC, int(round(alt * 1000)),
                int(round(course * 100)) % 36000, min(int(round(speed * 100)), 65535), 0,
                callsign, TRAFFIC_EMITTER[info["shape"]], 0, TRAFFIC_FLAGS, 0))
        return out

    def events(self) -> list[Outgoing]:
        """Status texts, reached items and mission progress changes since the last call."""
        out = self.texts()
        reached = list(self.cmd.reached)
        for seq in reached[self._reached_sent:]:
            out.append(Outgoing(mav.MAVLink_mission_item_reached_message(seq)))
        self._reached_sent = len(reached)
        mc = self.mission_current()
        key = (mc.seq, mc.total, mc.mission_state, mc.mission_mode)
        if key != self._last_mission_current:
            self._last_mission_current = key
            out.append(Outgoing(mc))
        c = self.cmd
        if (c.main_mode, c.sub_mode) == (cm.MAIN_POSCTL, cm.SUB_POSCTL_ORBIT) and \
                self.fleet.time_us >= self._orbit_due_us and c.orbit_state is not None:
            self._orbit_due_us = self.fleet.time_us + ORBIT_STATUS_PERIOD_US
            center, radius, _, _, _ = c.orbit_state
            lat, lon, alt = self.geo.to_global(center)
            out.append(Outgoing(mav.MAVLink_orbit_execution_status_message(
                self.fleet.time_us, radius, mav.MAV_FRAME_GLOBAL_INT, int(round(lat * 1e7)),
                int(round(lon * 1e7)), alt)))
        return out

    # --- incoming -------------------------------------------------------------------
    def for_us(self, m) -> bool:
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
        handler = _HANDLERS.get(t)
        if handler is None or not self.for_us(m):
            return []
        if t in SIGNAL_LOSS_DROPS and not self.cmd.sensor_ok("mavlink_signal"):
            return []  # an injected MAVLink signal failure
        return handler(self, m, link, peer, wall_us)

    # commands --------------------------------------------------------------------------
    def _on_command(self, m, link, peer, wall_us):
        is_int = m.get_type() == "COMMAND_INT"
        p = [m.param1, m.param2, m.param3, m.param4]
        if is_int:
            p += [m.x, m.y, m.z]
        else:
            p += [m.param5, m.param6, m.param7]
        try:
            result, extra = self._command(m.command, p, is_int, getattr(m, "frame", 0), link,
                                          peer)
        except (ValueError, SetpointError) as exc:
            self.cmd.text(cm.Severity.CRITICAL, f"Command {m.command} rejected: {exc}")
            result, extra = Result.DENIED, []
        return [self._ack(m.command, result, m, link, peer), *extra]

    def _command(self, command: int, p, is_int: bool, frame: int, link, peer):
        c = self.cmd
        if command == mav.MAV_CMD_COMPONENT_ARM_DISARM:
            force = abs(p[1] - FORCE_MAGIC) < 0.5
            if not math.isfinite(p[0]):
                return Result.DENIED, []
            return (c.arm(force) if p[0] > 0.5 else c.disarm(force)), []
        if command == mav.MAV_CMD_NAV_TAKEOFF:
            alt = p[6]  # AMSL; lat/lon (p[4], p[5]) and yaw (p[3]) are not used
            local = None if not math.isfinite(alt) else alt - self.geo.alt_m
            return c.nav_takeoff(local), []
        if command == mav.MAV_CMD_NAV_LAND:
            return c.land(), []
        if command == mav.MAV_CMD_NAV_RETURN_TO_LAUNCH:
            return c.return_to_launch(), []
        if command == mav.MAV_CMD_DO_SET_MODE:
            if not (math.isfinite(p[1]) and math.isfinite(p[2])):
                return Result.DENIED, []
            if not int(p[0]) & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
                return Result.UNSUPPORTED, []
            return c.set_mode(int(p[1]), int(p[2])), []
        if command == mav.MAV_CMD_DO_REPOSITION:
            if is_int:
                lat, lon = p[4] * 1e-7, p[5] * 1e-7
            else:
                lat, lon = p[4], p[5]
            alt = p[6]
            if not (math.isfinite(lat) and math.isfinite(lon)) or (lat == 0 and lon == 0):
                target = np.array([math.nan, math.nan, math.nan])
            else:
                target = self.geo.to_local(lat, lon, self.geo.alt_m)
                target[2] = math.nan
            if math.isfinite(alt):
                target[2] = self._alt_to_local(alt, frame)
            yaw = frames.yaw_ned_to_enu(p[3]) if math.isfinite(p[3]) else math.nan
            if math.isfinite(p[0]) and p[0] > 0:
                c.change_speed(p[0])
            return c.reposition(target, yaw), []
        if command == mav.MAV_CMD_DO_CHANGE_SPEED:
            return c.change_speed(p[1]), []
        if command == mav.MAV_CMD_DO_ORBIT:
            if is_int:
                lat, lon = p[4] * 1e-7, p[5] * 1e-7
            else:
                lat, lon = p[4], p[5]
            center = np.array([math.nan, math.nan, math.nan])
            if math.isfinite(lat) and math.isfinite(lon) and not (lat == 0 and lon == 0):
                center[:2] = self.geo.to_local(lat, lon, self.geo.alt_m)[:2]
            if math.isfinite(p[6]):  # PX4 reads an orbit's altitude as AMSL in any frame
                center[2] = p[6] - self.geo.alt_m
            yaw_mode = int(p[2]) if math.isfinite(p[2]) else 0
            return c.orbit(center, p[0], p[1], yaw_mode), []
        if command == mav.MAV_CMD_INJECT_FAILURE:
            if not all(math.isfinite(v) for v in p[:3]):
                return Result.DENIED, []
            return self.fleet.inject_failure(self.i, int(p[0]), int(p[1]), int(p[2])), []
        if command == mav.MAV_CMD_MISSION_START:
            if not c.mission:
                return Result.DENIED, []
            if math.isfinite(p[0]) and p[0] >= 0:
                c.set_mission_current(int(p[0]))
            return c.set_mode(cm.MAIN_AUTO, cm.SUB_MISSION), []
        if command == mav.MAV_CMD_SET_MESSAGE_INTERVAL:
            return self._set_message_interval(p[0], p[1], link), []
        if command == mav.MAV_CMD_REQUEST_MESSAGE:
            msg_id = int(p[0]) if math.isfinite(p[0]) else -1
            m = self.build(msg_id) if msg_id != mav.MAVLINK_MSG_ID_PARAM_VALUE else None
            if m is None:  # as PX4: no stream for it, or nothing to send
                return Result.DENIED, []
            return Result.ACCEPTED, [Outgoing(m, link, peer)]
        if command == mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES:
            return Result.ACCEPTED, [Outgoing(self.autopilot_version(), link, peer)]
        if command == mav.MAV_CMD_GET_HOME_POSITION:
            return Result.ACCEPTED, [Outgoing(self.home_position(), link, peer)]
        if command == mav.MAV_CMD_DO_SET_HOME:
            if p[0] > 0.5:
                pos = self._state().position
            else:
                if is_int:
                    lat, lon = p[4] * 1e-7, p[5] * 1e-7
                else:
                    lat, lon = p[4], p[5]
                if not all(math.isfinite(v) for v in (lat, lon, p[6])):
                    return Result.DENIED, []
                pos = self.geo.to_local(lat, lon, p[6])
            c.set_home(pos)
            return Result.ACCEPTED, [Outgoing(self.home_position())]
        if command == mav.MAV_CMD_DO_FLIGHTTERMINATION:
            if p[0] > 0.5:
                return c.terminate(), []
            return Result.ACCEPTED, []
        if command == mav.MAV_CMD_PREFLIGHT_CALIBRATION:
            return self._calibrate(p), []
        if command == mav.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN:
            if c.armed:
                return Result.DENIED, []
            if p[0] == 1:  # autopilot reboot: clears a flight termination
                if c.crashed:  # and puts a crashed vehicle back on its spawn point
                    self.fleet.respawn(self.i)
                c.terminated = False
                c.text(cm.Severity.INFO, "Rebooting autopilot")
            return Result.ACCEPTED, []
        return Result.UNSUPPORTED, []

    def _calibrate(self, p) -> Result:
        """PREFLIGHT_CALIBRATION as PX4 SITL answers it, completed at once: the "[cal]"
        STATUSTEXT protocol (started, progress, done) MAVSDK's Calibration plugin and
        QGroundControl follow. Refused when armed."""
        kinds = [(0, 1, "gyro"), (1, 1, "mag"), (2, 1, "baro"), (4, 1, "accel"),
                 (4, 2, "level"), (5, 1, "airspeed")]
        chosen = [k for i, v, k in kinds if math.isfinite(p[i]) and round(p[i]) == v]
        if not chosen:  # all zero: nothing to calibrate (PX4: cancels a running one)
            return Result.ACCEPTED
        if self.cmd.armed:
            self.cmd.text(cm.Severity.CRITICAL, "[cal] calibration denied: vehicle armed")
            return Result.TEMPORARILY_REJECTED
        kind = chosen[0]
        for text in (f"[cal] calibration started: 2 {kind}", "[cal] progress <50>",
                     "[cal] progress <100>", f"[cal] calibration done: {kind}"):
            self.cmd.text(cm.Severity.INFO, text)
        return Result.ACCEPTED

    def _set_message_interval(self, msg_id: float, interval_us: float, link: int) -> Result:
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
        try:
            return self.build(msg_id)
        except Exception:  # noqa: BLE001 - a message we cannot build is unsupported
            return None

    def _alt_to_local(self, alt: float, frame: int) -> float:
        if frame in (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
            return self.cmd.home[2] + alt
        return alt - self.geo.alt_m

    def _on_set_mode(self, m, link, peer, wall_us):
        if m.target_system != self.sysid:
            return []
        main = (m.custom_mode >> 16) & 0xFF
        sub = (m.custom_mode >> 24) & 0xFF
        self.cmd.set_mode(main, sub)
        return []

    # follow target ------------------------------------------------------------------
    def _on_follow_target(self, m, link, peer, wall_us):
        """FOLLOW_TARGET (a follow-me client's position fix): lat/lon degE7, alt AMSL,
        vel NED. Used as PX4's mavlink receiver does, in any mode (the estimate is for
        AUTO.FOLLOW_TARGET); a fix without a usable position is ignored, an absurd
        altitude or velocity is taken as unknown. A velocity counts when est_capabilities
        says so (bit 1) or any of it is non-zero: MAVSDK sends zeros with only the
        position bit set."""
        lat, lon = m.lat * 1e-7, m.lon * 1e-7
        if (m.lat == 0 and m.lon == 0) or not (abs(lat) <= 90.0 and abs(lon) <= 180.0):
            return []
        pos = self.geo.to_local(lat, lon, self.geo.alt_m)
        if not np.all(np.isfinite(pos)) or np.hypot(*(pos[:2] - self.cmd.home[:2])) \
                > FOLLOW_MAX_RANGE_M:
            return []
        alt = float(m.alt)
        pos[2] = alt - self.geo.alt_m if math.isfinite(alt) and \
            FOLLOW_ALT_RANGE_M[0] <= alt <= FOLLOW_ALT_RANGE_M[1] else math.nan
        vel = [float(v) for v in m.vel]
        use_vel = all(math.isfinite(v) and abs(v) <= FOLLOW_MAX_SPEED_M_S for v in vel) \
            and (m.est_capabilities & 2 or any(v != 0.0 for v in vel))
        self.cmd.follow_target_measurement(
            self.fleet.time_us, pos, frames.ned_to_enu(np.array(vel)) if use_vel else None)
        return []

    # manual control ------------------------------------------------------------------
    def _on_manual_control(self, m, link, peer, wall_us):
        """MANUAL_CONTROL as PX4's mavlink receiver reads it: x pitch, y roll, r yaw in
        -1000..1000, z throttle in 0..1000, for target 0 or this system; values beyond
        are clamped (the fields are int16, never NaN)."""
        if m.target not in (0, self.sysid):
            return []
        self.fleet.manual_control(self.i, m.x / 1000.0, m.y / 1000.0, m.z / 1000.0,
                                  m.r / 1000.0)
        return []

    # offboard -----------------------------------------------------------------------
    def _offboard(self, sp: Setpoint) -> None:
        self.fleet.offboard_setpoint(self.i, sp)

    def _reject_setpoint(self, why: str) -> list:
        self.cmd.text(cm.Severity.WARNING, f"Offboard setpoint rejected: {why}"[:50])
        return []

    def _on_local_ned(self, m, link, peer, wall_us):
        mask = m.type_mask
        frame = m.coordinate_frame
        if frame not in (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_BODY_NED,
                         mav.MAV_FRAME_LOCAL_OFFSET_NED, mav.MAV_FRAME_BODY_OFFSET_NED):
            return self._reject_setpoint(f"frame {frame} not supported")
        pos = None if mask & 0b111 == 0b111 else [m.x, m.y, m.z]
        vel = None if mask & 0b111000 == 0b111000 else [m.vx, m.vy, m.vz]
        acc = None if mask & 0b111000000 == 0b111000000 else [m.afx, m.afy, m.afz]
        s = self._state()
        try:
            pos, vel, acc = (None if v is None else _no_inf3(v, name)
                             for v, name in ((pos, "position"), (vel, "velocity"),
                                             (acc, "acceleration")))
        except SetpointError as exc:
            return self._reject_setpoint(str(exc))
        body = frame in (mav.MAV_FRAME_BODY_NED, mav.MAV_FRAME_BODY_OFFSET_NED)
        offset = frame in (mav.MAV_FRAME_LOCAL_OFFSET_NED, mav.MAV_FRAME_BODY_OFFSET_NED)
        yaw_ned = frames.yaw_enu_to_ned(s.yaw)

        def to_enu(v, is_position):
            if v is None:
                return None
            v = np.asarray(v, dtype=float)
            # body frames turn vectors with the heading (x forward, y right); a BODY_NED
            # position is still a local position (MAVLink), only offsets are relative
            if body and not (is_position and not offset):
                c, sn = math.cos(yaw_ned), math.sin(yaw_ned)
                v = np.array([c * v[0] - sn * v[1], sn * v[0] + c * v[1], v[2]])
            out = frames.ned_to_enu(v)
            if is_position:
                return out + (s.position if offset else self.origin)
            return out

        yaw = None if mask & (1 << 10) else m.yaw
        yaw_rate = None if mask & (1 << 11) else m.yaw_rate
        if yaw is not None and math.isnan(yaw):
            yaw = None  # PX4: a NaN yaw is not controlled (heading held)
        if yaw is not None and not math.isfinite(yaw):
            return self._reject_setpoint("yaw is not finite")
        if yaw_rate is not None and not math.isfinite(yaw_rate):
            return self._reject_setpoint("yaw rate is not finite")
        if pos is None and vel is None and acc is None:
            return self._reject_setpoint("type_mask ignores position, velocity and accel")
        try:
            sp = Setpoint.trajectory(
                to_enu(pos, True), to_enu(vel, False), to_enu(acc, False),
                yaw=None if yaw is None else frames.yaw_ned_to_enu(yaw),
                yaw_rate=None if yaw_rate is None else -yaw_rate)
        except SetpointError as exc:
            return self._reject_setpoint(str(exc))
        self._offboard(sp)
        return []

    def _on_global_int(self, m, link, peer, wall_us):
        mask = m.type_mask
        s = self._state()
        pos = None
        if mask & 0b111 != 0b111:
            lat, lon = m.lat_int * 1e-7, m.lon_int * 1e-7
            if not math.isfinite(m.alt):
                return self._reject_setpoint("altitude is not finite")
            p = self.geo.to_local(lat, lon, self.geo.alt_m)
            p[2] = self._alt_to_local(m.alt, m.coordinate_frame)
            pos = p
        try:
            vel = None if mask & 0b111000 == 0b111000 else frames.ned_to_enu(
                _finite3([m.vx, m.vy, m.vz], "velocity"))
            acc = None if mask & 0b111000000 == 0b111000000 else frames.ned_to_enu(
                _finite3([m.afx, m.afy, m.afz], "acceleration"))
            yaw = None if mask & (1 << 10) else frames.yaw_ned_to_enu(m.yaw)
            yaw_rate = None if mask & (1 << 11) else -m.yaw_rate
            if pos is None and vel is None and acc is None:
                return self._reject_setpoint("type_mask ignores everything")
            sp = Setpoint.trajectory(pos, vel, acc, yaw=yaw, yaw_rate=yaw_rate)
        except SetpointError as exc:
            return self._reject_setpoint(str(exc))
        del s
        self._offboard(sp)
        return []

    def _on_attitude_target(self, m, link, peer, wall_us):
        mask = m.type_mask
        thrust = m.thrust
        if mask & (1 << 6) or not math.isfinite(thrust) or not 0.0 <= thrust <= 1.0:
            return self._reject_setpoint("thrust must be within 0..1")
        try:
            if mask & (1 << 7):  # attitude ignored: body rates
                rates = _finite3([m.body_roll_rate, m.body_pitch_rate, m.body_yaw_rate], "rates")
                sp = Setpoint.body_rates(frames.frd_to_flu(rates), thrust)
            else:
                q = np.asarray(m.q, dtype=float)
                if not np.isfinite(q).all() or abs(np.linalg.norm(q) - 1.0) > 1e-2:
                    return self._reject_setpoint("attitude quaternion is not a unit quaternion")
                q_enu = frames.q_ned_frd_to_enu_flu(q / np.linalg.norm(q))
                sp = Setpoint.attitude(q_enu, thrust)
        except SetpointError as exc:
            return self._reject_setpoint(str(exc))
        self._offboard(sp)
        return []

    # parameters ---------------------------------------------------------------------
    def _param_value(self, name: str) -> mav.MAVLink_param_value_message:
        return mav.MAVLink_param_value_message(
            name.encode("ascii"), _param_wire(name, self.params[name]), _param_type(name),
            len(PARAMS), PARAM_INDEX[name])

    def _on_param_request_list(self, m, link, peer, wall_us):
        # all of them, index 0..count-1, to the asker: the first chunk now, the rest from
        # poll() (a new request from the same peer starts over)
        self._param_streams[(link, peer)] = 0
        return self._stream_params()

    def _stream_params(self) -> list[Outgoing]:
        out = []
        for key, start in list(self._param_streams.items()):
            stop = min(start + PARAM_STREAM_CHUNK, len(PARAM_NAMES))
            out.extend(Outgoing(self._param_value(n), *key) for n in PARAM_NAMES[start:stop])
            if stop >= len(PARAM_NAMES):
                del self._param_streams[key]
            else:
                self._param_streams[key] = stop
        return out

    def _param_name(self, raw) -> str:
        if isinstance(raw, bytes):
            raw = raw.decode("ascii", "replace")
        return raw.split("\x00", 1)[0]

    def _on_param_request_read(self, m, link, peer, wall_us):
        if m.param_index >= 0:
            if m.param_index >= len(PARAM_NAMES):
                return []
            name = PARAM_NAMES[m.param_index]
        else:
            name = self._param_name(m.param_id)
            if name not in PARAMS:
                return []
        return [Outgoing(self._param_value(name), link, peer)]

    def _on_param_set(self, m, link, peer, wall_us):
        name = self._param_name(m.param_id)
        if name not in PARAMS:
            self.cmd.text(cm.Severity.WARNING, f"Param {name[:16]} unknown: not set")
            return []
        value = _param_from_wire(name, m.param_value, m.param_type)
        try:
            self.set_param(name, value)
        except ParamError as exc:
            self.cmd.text(cm.Severity.WARNING, str(exc)[:50])
        return [Outgoing(self._param_value(name))]

    def set_param(self, name: str, value) -> None:
        """Set one parameter (PARAM_SET, the shell); ParamError refuses it as a whole,
        nothing half-applied."""
        old = self.params[name]
        try:
            self.params.set(name, value)
            if PARAMS[name].honoured:  # a stored parameter changes nothing to rebuild
                self.fleet.refresh_params()
        except ParamError:
            self.params.set(name, old)
            self.fleet.refresh_params()
            raise

    # the shell ------------------------------------------------------------------------
    def _on_serial_control(self, m, link, peer, wall_us):
        """SERIAL_CONTROL to the shell device: run its lines, answer with their output in
        SERIAL_CONTROL replies of at most 70 bytes (mavlink/shell.py)."""
        if m.device != mav.SERIAL_CONTROL_DEV_SHELL:
            return []
        n = max(0, min(int(m.count), 70))
        text = self._shell.feed(bytes(m.data[:n]))
        raw = text.encode("ascii", "replace")
        out = []
        for k in range(0, len(raw), 70):
            chunk = raw[k:k + 70]
            out.append(Outgoing(mav.MAVLink_serial_control_message(
                mav.SERIAL_CONTROL_DEV_SHELL, mav.SERIAL_CONTROL_FLAG_REPLY, 0, 0, len(chunk),
                list(chunk) + [0] * (70 - len(chunk))), link, peer))
        return out

    # missions, fences, rally points ----------------------------------------------------
    def _mission_ack(self, m, result: int, link, peer, mission_type=0) -> Outgoing:
        return Outgoing(mav.MAVLink_mission_ack_message(
            m.get_srcSystem(), m.get_srcComponent(), result, mission_type), link, peer)

    def _on_mission_count(self, m, link, peer, wall_us):
        mtype = getattr(m, "mission_type", 0)
        if mtype not in MISSION_TYPES:
            return [self._mission_ack(m, mav.MAV_MISSION_UNSUPPORTED, link, peer, mtype)]
        # (PX4 accepts a new mission while flying one; it restarts from item 0)
        if m.count == 0:
            self._apply_upload(mtype, [])
            return [self._mission_ack(m, mav.MAV_MISSION_ACCEPTED, link, peer, mtype)]
        full = m.count > 10000 if mtype == mav.MAV_MISSION_TYPE_MISSION else not fits(m.count)
        if full:
            return [self._mission_ack(m, mav.MAV_MISSION_NO_SPACE, link, peer, mtype)]
        self._upload = _Transfer(m.count, link, peer, last_request_wall_us=wall_us,
                                 mission_type=mtype)
        self._upload_src = (m.get_srcSystem(), m.get_srcComponent())
        return [self._request_item(0)]

    def _request_item(self, seq: int) -> Outgoing:
        up = self._upload
        sysid, compid = self._upload_src
        return Outgoing(mav.MAVLink_mission_request_int_message(sysid, compid, seq,
                                                                up.mission_type),
                        up.link, up.peer)

    def _on_mission_item(self, m, link, peer, wall_us):
        """Plain MISSION_ITEM (float x/y: degrees in the global frames, metres in the
        local ones), as MISSION_FLOAT is advertised: kept as its MISSION_ITEM_INT form."""
        if self._upload is None:
            return []
        if m.frame in GLOBAL_FRAMES:
            x, y = _deg_e7(m.x), _deg_e7(m.y)
        elif m.frame == mav.MAV_FRAME_LOCAL_NED:
            x, y = _deg_e7(m.x * 1e-3), _deg_e7(m.y * 1e-3)  # (m * 1e4, as _INT carries)
        else:
            x, y = _deg_e7(m.x * 1e-7), _deg_e7(m.y * 1e-7)
        as_int = mav.MAVLink_mission_item_int_message(
            m.target_system, m.target_component, m.seq, m.frame, m.command, m.current,
            m.autocontinue, m.param1, m.param2, m.param3, m.param4, x, y, m.z,
            getattr(m, "mission_type", 0))
        as_int._header = m._header
        return self._on_mission_item_int(as_int, link, peer, wall_us)

    def _on_mission_item_int(self, m, link, peer, wall_us):
        up = self._upload
        if up is None:
            return []
        mtype = up.mission_type
        expected = len(up.items)
        if m.seq != expected:
            return [self._request_item(expected)]  # out of order: ask again for ours
        if m.frame not in SUPPORTED_FRAMES:  # PX4 answers this item at once
            self._upload = None
            self.cmd.text(cm.Severity.CRITICAL,
                          f"Mission rejected: item {m.seq}: frame {m.frame} unsupported"[:50])
            return [self._mission_ack(m, mav.MAV_MISSION_UNSUPPORTED_FRAME, link, peer, mtype)]
        up.items.append(m)
        up.last_request_wall_us = wall_us
        up.retries = 0
        if len(up.items) < up.count:
            return [self._request_item(len(up.items))]
        self._upload = None
        try:
            self._apply_upload(mtype, up.items)
        except (ValueError, FenceError) as exc:
            what = {mav.MAV_MISSION_TYPE_FENCE: "Fence",
                    mav.MAV_MISSION_TYPE_RALLY: "Rally points"}.get(mtype, "Mission")
            self.cmd.text(cm.Severity.CRITICAL, f"{what} rejected: {exc}"[:50])
            return [self._mission_ack(m, mav.MAV_MISSION_INVALID, link, peer, mtype)]
        return [self._mission_ack(m, mav.MAV_MISSION_ACCEPTED, link, peer, mtype)]

    def _apply_upload(self, mtype: int, items: list) -> None:
        """Hand a complete upload of one type to the commander (ValueError / FenceError:
        refused as a whole, nothing changed)."""
        if mtype == mav.MAV_MISSION_TYPE_MISSION:
            self.cmd.set_mission([self._to_mission_item(it) for it in items])
        elif mtype == mav.MAV_MISSION_TYPE_FENCE:
            self.cmd.set_fence(self._to_fence(items))
            self._fence_uploaded = self.cmd.fence
        else:
            self.cmd.set_rally([self._to_rally_point(it) for it in items])
        self._stored[mtype] = list(items)

    def _item_position(self, it) -> tuple:
        """An item's position in the local ENU frame (NaN where not given)."""
        nan = math.nan
        if it.frame in GLOBAL_FRAMES:
            lat, lon = it.x * 1e-7, it.y * 1e-7  # MISSION_ITEM_INT: degE7 in any global frame
            if (lat == 0 and lon == 0) or not (math.isfinite(lat) and math.isfinite(lon)):
                xy = (nan, nan)
            else:
                p = self.geo.to_local(lat, lon, self.geo.alt_m)
                xy = (p[0], p[1])
            z = self._alt_to_local(it.z, it.frame) if math.isfinite(it.z) else nan
            return (xy[0], xy[1], z)
        if it.frame == mav.MAV_FRAME_LOCAL_NED:  # MISSION_ITEM_INT: x, y in m * 1e4
            return tuple(frames.ned_to_enu([it.x * 1e-4, it.y * 1e-4, it.z]) + self.origin)
        if it.frame == mav.MAV_FRAME_MISSION:
            return (nan, nan, nan)
        raise ValueError(f"item {it.seq}: frame {it.frame} not supported")

    def _to_mission_item(self, it) -> MissionItem:
        nan = math.nan
        pos = self._item_position(it)
        if it.command == mav.MAV_CMD_NAV_WAYPOINT:
            yaw = frames.yaw_ned_to_enu(math.radians(it.param4)) if math.isfinite(it.param4) \
                else nan
            return MissionItem(it.command, pos, hold_s=max(0.0, _f(it.param1)),
                               acceptance_radius_m=max(0.0, _f(it.param2)), yaw_rad=yaw,
                               autocontinue=bool(it.autocontinue))
        if it.command == mav.MAV_CMD_NAV_DELAY:
            return MissionItem(it.command, pos, hold_s=_f(it.param1))
        if it.command == mav.MAV_CMD_DO_CHANGE_SPEED:
            return MissionItem(it.command, speed_m_s=it.param2)
        return MissionItem(it.command, pos)

    def _to_fence(self, items: list) -> Fence:
        """Fence items in order: a polygon is param1 consecutive vertices of one kind."""
        fence = Fence()
        k = 0
        while k < len(items):
            it = items[k]
            where = f"item {it.seq}"
            if it.command in (mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                              mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION):
                n = int(it.param1) if math.isfinite(it.param1) else 0
                group = items[k:k + n]
                if n < 3 or len(group) < n or any(g.command != it.command for g in group):
                    raise FenceError(f"{where}: a polygon of {it.param1:g} vertices needs "
                                     f"that many vertex items in a row")
                xy = [self._item_position(g)[:2] for g in group]
                fence.areas.append(polygon(xy, it.command ==
                                           mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                                           where))
                k += n
                continue
            if it.command in (mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
                              mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION):
                fence.areas.append(circle(self._item_position(it)[:2], it.param1,
                                          it.command == mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
                                          where))
            elif it.command == mav.MAV_CMD_NAV_FENCE_RETURN_POINT:
                p = np.array(self._item_position(it))
                if not np.all(np.isfinite(p[:2])):
                    raise FenceError(f"{where}: the return point is not a finite position")
                fence.return_point = p
            else:
                raise FenceError(f"{where}: command {it.command} is not a fence item")
            k += 1
        return fence

    def _to_rally_point(self, it) -> np.ndarray:
        if it.command != mav.MAV_CMD_NAV_RALLY_POINT:
            raise FenceError(f"item {it.seq}: command {it.command} is not a rally point")
        p = np.array(self._item_position(it))
        if not np.all(np.isfinite(p[:2])):
            raise FenceError(f"item {it.seq}: the rally point is not a finite position")
        if not math.isfinite(p[2]):
            p[2] = self.cmd.home[2]
        return p

    def _download(self, mtype: int) -> list | None:
        """The items a download of ``mtype`` returns (None: not a type we keep)."""
        if mtype == mav.MAV_MISSION_TYPE_FENCE:
            return self._fence_download()
        return self._stored.get(mtype)

    def _fence_download(self) -> list:
        """The fence items: as uploaded; for a fence the commander got otherwise (a
        trial's ``fence``, set before the first step, as PX4 loads a fence file at boot
        into the store a download reads), its areas and return point as PX4 stores them
        (vertex and circle items in MAV_FRAME_GLOBAL, altitude 0), made once per fence."""
        fence = self.cmd.fence
        if fence is self._fence_uploaded:
            return self._stored[mav.MAV_MISSION_TYPE_FENCE]
        if self._fence_made is None or self._fence_made[0] is not fence:
            self._fence_made = (fence, self._fence_items(fence))
        return self._fence_made[1]

    def _fence_items(self, fence: Fence) -> list:
        items: list = []

        def add(command: int, xy, param1: float) -> None:
            lat, lon, _ = self.geo.to_global((float(xy[0]), float(xy[1]), 0.0))
            items.append(mav.MAVLink_mission_item_int_message(
                0, 0, len(items), mav.MAV_FRAME_GLOBAL, command, 0, 1, float(param1), 0.0,
                0.0, 0.0, _deg_e7(lat), _deg_e7(lon), 0.0, mav.MAV_MISSION_TYPE_FENCE))

        for a in fence.areas:
            if isinstance(a, Polygon):
                command = mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION if a.inclusion else \
                    mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION
                for v in a.vertices:
                    add(command, v, len(a.vertices))
            else:
                add(mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION if a.inclusion else
                    mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, a.center, a.radius_m)
        if fence.return_point is not None:
            add(mav.MAV_CMD_NAV_FENCE_RETURN_POINT, fence.return_point[:2], 0.0)
        return items

    def _on_mission_request_list(self, m, link, peer, wall_us):
        mtype = getattr(m, "mission_type", 0)
        count = len(self._download(mtype) or [])
        return [Outgoing(mav.MAVLink_mission_count_message(
            m.get_srcSystem(), m.get_srcComponent(), count, mtype), link, peer)]

    def _on_mission_request(self, m, link, peer, wall_us):
        mtype = getattr(m, "mission_type", 0)
        stored = self._download(mtype)
        if stored is None:
            return []
        if not 0 <= m.seq < len(stored):
            return [self._mission_ack(m, mav.MAV_MISSION_INVALID_SEQUENCE, link, peer, mtype)]
        it = stored[m.seq]
        current = 1 if mtype == mav.MAV_MISSION_TYPE_MISSION and it.seq == self.cmd.mission_seq \
            else 0
        return [Outgoing(mav.MAVLink_mission_item_int_message(
            m.get_srcSystem(), m.get_srcComponent(), it.seq, it.frame, it.command,
            current, it.autocontinue, it.param1, it.param2,
            it.param3, it.param4, it.x, it.y, it.z, mtype), link, peer)]

    def _on_mission_clear_all(self, m, link, peer, wall_us):
        mtype = getattr(m, "mission_type", 0)
        cleared = MISSION_TYPES if mtype == mav.MAV_MISSION_TYPE_ALL else \
            (mtype,) if mtype in MISSION_TYPES else ()
        for t in cleared:
            self._apply_upload(t, [])
        if cleared:
            self._upload = None
        return [self._mission_ack(m, mav.MAV_MISSION_ACCEPTED, link, peer, mtype)]

    def _on_mission_set_current(self, m, link, peer, wall_us):
        if self.cmd.set_mission_current(m.seq) != Result.ACCEPTED:
            self.cmd.text(cm.Severity.WARNING, f"Mission item {m.seq} does not exist")
        return [Outgoing(self.mission_current())]

    def _on_mission_ack(self, m, link, peer, wall_us):
        return []

    def poll(self, wall_us: int) -> list[Outgoing]:
        """Wall-clock duties: stream the parameter list, FTP bursts and log data on,
        re-request mission items, give up abandoned uploads."""
        out = self._stream_params() if self._param_streams else []
        for link, ftp in enumerate(self._ftp):
            if ftp.bursting:
                out += [Outgoing(r, link, self._ftp_peer[link]) for r in ftp.stream(wall_us)]
        for link, logs in enumerate(self._logs):
            if logs.sending:
                out += [Outgoing(r, link, self._log_peer[link]) for r in logs.stream()]
        return out + self._poll_upload(wall_us)

    def _poll_upload(self, wall_us: int) -> list[Outgoing]:
        up = self._upload
        if up is None or wall_us - up.last_request_wall_us < MISSION_TIMEOUT_US:
            return []
        up.retries += 1
        up.last_request_wall_us = wall_us
        if up.retries > MISSION_RETRIES:
            self._upload = None
            self.cmd.text(cm.Severity.WARNING, "Mission upload timed out")
            sysid, compid = self._upload_src
            return [Outgoing(mav.MAVLink_mission_ack_message(
                sysid, compid, mav.MAV_MISSION_OPERATION_CANCELLED, up.mission_type), up.link,
                up.peer)]
        return [self._request_item(len(up.items))]

    # files and logs (mavlink/ftp.py, mavlink/logs.py) ---------------------------------
    def _on_file_transfer_protocol(self, m, link, peer, wall_us):
        self._ftp_peer[link] = peer
        return [Outgoing(r, link, peer) for r in self._ftp[link].handle(m, wall_us)]

    def _on_log(self, m, link, peer, wall_us):
        self._log_peer[link] = peer
        return [Outgoing(r, link, peer) for r in self._logs[link].handle(m)]

    def _params_file(self) -> bytes:
        return files.params_file(self.sysid, COMPID, [
            (n, self.params[n], _param_type(n)) for n in PARAM_NAMES])

    def _warn(self, text: str) -> None:
        self.cmd.text(cm.Severity.WARNING, text)

    def _on_timesync(self, m, link, peer, wall_us):
        if m.tc1 != 0:
            return []
        # tc1 = 0 would read as a request: at simulated time 0 answer 1 ns
        return [Outgoing(mav.MAVLink_timesync_message(max(1, self.fleet.time_us * 1000), m.ts1),
                         link, peer)]


def _deg_e7(v: float) -> int:
    """A float coordinate as MISSION_ITEM_INT's int32 (out of range: 0, "not given")."""
    if not math.isfinite(v):
        return 0
    r = round(v * 1e7)
    return r if -2**31 <= r < 2**31 else 0


def _cell_voltages_mv(cell_v: float, cells: int) -> tuple[list[int], list[int]]:
    """BATTERY_STATUS ``voltages`` (cells 1-10) and ``voltages_ext`` (cells 11-14, a
    MAVLink 2 extension) in mV, as the message definition and PX4's BATTERY_STATUS stream
    fill them: an absent cell is UINT16_MAX in ``voltages`` but 0 ("not supported", so
    the extension can be truncated) in ``voltages_ext``, where a measured 0 is sent as 1.
    Cells past the 14th are not reported."""
    mv = min(max(int(cell_v * 1000), 0), 65534)
    volts = [mv if k < cells else 65535 for k in range(10)]
    ext = [max(mv, 1) if k < cells else 0 for k in range(10, 14)]
    return volts, ext


def _f(v: float) -> float:
    return v if math.isfinite(v) else 0.0


def _no_inf3(v, name: str) -> list[float]:
    """A local-NED vector where NaN components stay NaN: PX4 controls such an axis at the
    next level (position NaN -> velocity), as in its trajectory_setpoint; the setpoint is
    refused later if an axis ends up controlled at no level. Infinities are refused."""
    if any(math.isinf(x) for x in v):
        raise SetpointError(f"{name} has infinite components")
    return [float(x) for x in v]


def _finite3(v, name: str) -> list[float]:
    if not all(math.isfinite(x) for x in v):
        raise SetpointError(f"{name} has non-finite components")
    return [float(x) for x in v]


def _rotate_inv(q, v):
    return qrotate_inv(np.asarray(q, dtype=float), np.asarray(v, dtype=float))


_HANDLERS = {
    "COMMAND_LONG": VehicleAgent._on_command,
    "COMMAND_INT": VehicleAgent._on_command,
    "SET_MODE": VehicleAgent._on_set_mode,
    "SET_POSITION_TARGET_LOCAL_NED": VehicleAgent._on_local_ned,
    "SET_POSITION_TARGET_GLOBAL_INT": VehicleAgent._on_global_int,
    "SET_ATTITUDE_TARGET": VehicleAgent._on_attitude_target,
    "PARAM_REQUEST_LIST": VehicleAgent._on_param_request_list,
    "PARAM_REQUEST_READ": VehicleAgent._on_param_request_read,
    "PARAM_SET": VehicleAgent._on_param_set,
    "MISSION_COUNT": VehicleAgent._on_mission_count,
    "MISSION_ITEM_INT": VehicleAgent._on_mission_item_int,
    "MISSION_ITEM": VehicleAgent._on_mission_item,
    "MISSION_REQUEST_LIST": VehicleAgent._on_mission_request_list,
    "MISSION_REQUEST_INT": VehicleAgent._on_mission_request,
    "MISSION_REQUEST": VehicleAgent._on_mission_request,
    "MISSION_CLEAR_ALL": VehicleAgent._on_mission_clear_all,
    "MISSION_SET_CURRENT": VehicleAgent._on_mission_set_current,
    "MISSION_ACK": VehicleAgent._on_mission_ack,
    "TIMESYNC": VehicleAgent._on_timesync,
    "SERIAL_CONTROL": VehicleAgent._on_serial_control,
    "FOLLOW_TARGET": VehicleAgent._on_follow_target,
    "MANUAL_CONTROL": VehicleAgent._on_manual_control,
    "FILE_TRANSFER_PROTOCOL": VehicleAgent._on_file_transfer_protocol,
    "LOG_REQUEST_LIST": VehicleAgent._on_log,
    "LOG_REQUEST_DATA": VehicleAgent._on_log,
    "LOG_REQUEST_END": VehicleAgent._on_log,
    "LOG_ERASE": VehicleAgent._on_log,
}
