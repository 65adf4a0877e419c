"""One vehicle's telemetry messages: the current value of each message PX4 streams.

:class:`Telemetry` builds a message from the vehicle's state on demand; when and on which
link it goes out is :mod:`ft_sitl.mavlink.streams`' business, and a client may also ask
for one (MAV_CMD_REQUEST_MESSAGE). The state is read through the fleet's named accessors
and turned into the wire's NED/FRD once per simulated instant (:class:`Snapshot`): a burst
of streams due together reads one consistent state and pays the conversions once.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.autopilot import commander as cm
from ft_sitl.mavlink.vehicle import Vehicle
from ft_sitl.physics.quaternion import qrotate_inv, qto_euler

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

#: the SYS_STATUS health bit of each sensor failure injection can turn off
SENSOR_BITS = {"gyro": mav.MAV_SYS_STATUS_SENSOR_3D_GYRO,
               "accel": mav.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
               "mag": mav.MAV_SYS_STATUS_SENSOR_3D_MAG,
               "baro": mav.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE,
               "gps": mav.MAV_SYS_STATUS_SENSOR_GPS}

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


@dataclass
class Snapshot:
    """The vehicle's estimated state at one simulated instant, in the wire's frames where
    a message needs them (the local NED position is relative to the spawn point)."""

    time_us: int
    state: object  # the fleet's VehicleState
    q_enu_flu: np.ndarray
    q_ned: np.ndarray
    w_frd: np.ndarray
    p_ned: np.ndarray
    v_ned: np.ndarray


class Telemetry:
    """The telemetry messages of one vehicle."""

    def __init__(self, vehicle: Vehicle):
        self.v = vehicle
        self._snap: Snapshot | None = None

    def build(self, msg_id: int):
        """The current value of a telemetry message, or None if we do not produce it."""
        if msg_id == mav.MAVLINK_MSG_ID_HEARTBEAT:
            return self.heartbeat()
        snap = self.snapshot()
        builder = _BUILDERS.get(msg_id)
        return None if builder is None else builder(self, snap)

    def snapshot(self) -> Snapshot:
        """The vehicle's state in wire frames, computed once per simulated instant."""
        snap = self._snap
        if snap is None or snap.time_us != self.v.fleet.time_us:
            s = self.v.fleet.state(self.v.index)
            q = self.v.fleet.attitude(self.v.index)  # PX4 reports its estimate
            snap = Snapshot(
                time_us=self.v.fleet.time_us, state=s, q_enu_flu=q,
                q_ned=frames.q_enu_flu_to_ned_frd(q),
                w_frd=frames.flu_to_frd(self.v.fleet.body_rates(self.v.index)),
                p_ned=frames.enu_to_ned(s.position - self.v.origin),
                v_ned=frames.enu_to_ned(s.velocity))
            self._snap = snap
        return snap

    def _boot_ms(self) -> int:
        return self.v.fleet.time_us // 1000

    # --- messages a client may also ask for alone -------------------------------------
    def heartbeat(self) -> mav.MAVLink_heartbeat_message:
        c = self.v.cmd
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
            [0] * 8, [0] * 8, [0] * 8, 0, 0, 0x46540000 + self.v.sysid, [0] * 18)

    def home_position(self) -> mav.MAVLink_home_position_message:
        h = self.v.cmd.home
        lat, lon, alt = self.v.geo.to_global(h)
        ned = frames.enu_to_ned(h - self.v.origin)
        return mav.MAVLink_home_position_message(
            int(round(lat * 1e7)), int(round(lon * 1e7)), int(round(alt * 1000)),
            float(ned[0]), float(ned[1]), float(ned[2]), [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0,
            self.v.fleet.time_us)

    def item_reached(self, seq: int) -> mav.MAVLink_mission_item_reached_message:
        """MISSION_ITEM_REACHED for the commander's mission item ``seq``."""
        return mav.MAVLink_mission_item_reached_message(seq)

    def mission_current(self) -> mav.MAVLink_mission_current_message:
        c = self.v.cmd
        n = len(c.mission)
        state = c.mission_state
        if state == cm.MissionState.ACTIVE and not (c.main_mode == cm.MAIN_AUTO
                                                    and c.sub_mode == cm.SUB_MISSION):
            state = cm.MissionState.PAUSED
        mode = 1 if c.main_mode == cm.MAIN_AUTO and c.sub_mode == cm.SUB_MISSION else 0
        return mav.MAVLink_mission_current_message(min(c.mission_seq, max(n - 1, 0)) if n else 0,
                                                   n, state, mode)

    # --- the streamed state -----------------------------------------------------------
    def _attitude(self, snap: Snapshot):
        rpy = qto_euler(snap.q_ned)
        return mav.MAVLink_attitude_message(self._boot_ms(), *(float(v) for v in rpy),
                                            *(float(v) for v in snap.w_frd))

    def _attitude_quaternion(self, snap: Snapshot):
        return mav.MAVLink_attitude_quaternion_message(
            self._boot_ms(), *(float(v) for v in snap.q_ned), *(float(v) for v in snap.w_frd),
            [0.0] * 4)

    def _local_position_ned(self, snap: Snapshot):
        return mav.MAVLink_local_position_ned_message(
            self._boot_ms(), *(float(v) for v in snap.p_ned), *(float(v) for v in snap.v_ned))

    def _global_position_int(self, snap: Snapshot):
        s = snap.state
        lat, lon, alt = self.v.geo.to_global(s.position)
        rel = s.position[2] - self.v.cmd.home[2]
        hdg = math.degrees(frames.yaw_enu_to_ned(s.yaw)) % 360.0
        return mav.MAVLink_global_position_int_message(
            self._boot_ms(), int(round(lat * 1e7)), int(round(lon * 1e7)),
            int(round(alt * 1000)), int(round(rel * 1000)),
            *(int(round(v * 100)) for v in snap.v_ned), int(round(hdg * 100)) % 36000)

    def _odometry(self, snap: Snapshot):
        v_body = frames.flu_to_frd(qrotate_inv(np.asarray(snap.q_enu_flu, dtype=float),
                                               np.asarray(snap.state.velocity, dtype=float)))
        return mav.MAVLink_odometry_message(
            self.v.fleet.time_us, mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_BODY_FRD,
            *(float(v) for v in snap.p_ned), [float(v) for v in snap.q_ned],
            *(float(v) for v in v_body), *(float(v) for v in snap.w_frd),
            [math.nan] * 21, [math.nan] * 21, 0, mav.MAV_ESTIMATOR_TYPE_NAIVE, 100)

    def _highres_imu(self, snap: Snapshot):
        f_frd = frames.flu_to_frd(self.v.fleet.specific_force(self.v.index))
        alt = self.v.geo.alt_m + snap.state.position[2]
        pressure = 1013.25 * (1 - 2.25577e-5 * alt) ** 5.25588
        return mav.MAVLink_highres_imu_message(
            self.v.fleet.time_us, *(float(v) for v in f_frd), *(float(v) for v in snap.w_frd),
            0.21, 0.0, 0.43, pressure, 0.0, float(alt), 20.0, 0x1FFF, 0)

    def _extended_sys_state(self, snap: Snapshot):
        return mav.MAVLink_extended_sys_state_message(
            mav.MAV_VTOL_STATE_UNDEFINED, int(self.v.cmd.landed_state))

    def _sys_status(self, snap: Snapshot):
        bat = self.v.cmd.battery
        power = self._shaft_power()
        current = bat.current_a(power)
        present = SENSORS
        if self.v.cmd.geofence_active:  # PX4: the geofence bit while a fence is set
            present |= mav.MAV_SYS_STATUS_GEOFENCE
        health = present
        if self.v.cmd.terminated or self.v.cmd.battery.remaining < self.v.params["BAT_CRIT_THR"]:
            health &= ~mav.MAV_SYS_STATUS_PREARM_CHECK
        if self.v.cmd.fence_breached:
            health &= ~mav.MAV_SYS_STATUS_GEOFENCE
        for unit, bit in SENSOR_BITS.items():  # injected sensor failures
            if not self.v.cmd.sensor_ok(unit):
                health &= ~bit
        return mav.MAVLink_sys_status_message(
            present, present, health, 200, int(bat.voltage(current) * 1000),
            int(current * 100), int(round(bat.remaining * 100)), 0, 0, 0, 0, 0, 0)

    def _vfr_hud(self, snap: Snapshot):
        s = snap.state
        speed = float(np.linalg.norm(s.velocity[:2]))
        hdg = int(math.degrees(frames.yaw_enu_to_ned(s.yaw)) % 360.0)
        thr = float(self.v.fleet.rotor_speed_commands(self.v.index).mean() /
                    self.v.fleet.sim.platforms[self.v.index].rotor_speed_max_rad_s) ** 2
        return mav.MAVLink_vfr_hud_message(speed, speed, hdg, int(thr * 100),
                                           float(self.v.geo.alt_m + s.position[2]),
                                           float(s.velocity[2]))

    def _altitude(self, snap: Snapshot):
        s = snap.state
        amsl = float(self.v.geo.alt_m + s.position[2])
        rel = float(s.position[2] - self.v.cmd.home[2])
        return mav.MAVLink_altitude_message(self.v.fleet.time_us, amsl, amsl, rel,
                                            float(-snap.p_ned[2]),
                                            float(s.position[2] - self.v.cmd.home[2]),
                                            float(s.position[2]))

    def _battery_status(self, snap: Snapshot):
        bat = self.v.cmd.battery
        current = bat.current_a(self._shaft_power())
        volts, volts_ext = _cell_voltages_mv(bat.voltage(current) / bat.cells, bat.cells)
        return mav.MAVLink_battery_status_message(
            0, mav.MAV_BATTERY_FUNCTION_ALL, mav.MAV_BATTERY_TYPE_LIPO, 2500, volts,
            int(current * 100), int(bat.used_j / 3.6 / max(bat.voltage(), 1.0)), -1,
            int(round(bat.remaining * 100)), voltages_ext=volts_ext)

    def _gps_raw_int(self, snap: Snapshot):
        t_us = self.v.fleet.time_us
        if not self.v.cmd.sensor_ok("gps"):  # an injected GPS failure: no fix
            return mav.MAVLink_gps_raw_int_message(
                t_us, mav.GPS_FIX_TYPE_NO_FIX, 0, 0, 0, 65535, 65535, 65535, 65535, 0)
        s = snap.state
        lat, lon, alt = self.v.geo.to_global(s.position)
        return mav.MAVLink_gps_raw_int_message(
            t_us, mav.GPS_FIX_TYPE_3D_FIX, int(round(lat * 1e7)), int(round(lon * 1e7)),
            int(round(alt * 1000)), 80, 120, int(np.linalg.norm(s.velocity[:2]) * 100),
            65535, 12)

    def _shaft_power(self) -> float:
        """The rotors' mechanical power (W), what the battery model draws its current for."""
        p = self.v.fleet.sim.platforms[self.v.index]
        w = self.v.fleet.rotor_speeds(self.v.index)
        return float(np.sum(p.torque_thrust_ratio_m * p.thrust_coefficient * w**3))


#: the builder of each message id build() produces besides HEARTBEAT
_BUILDERS = {
    mav.MAVLINK_MSG_ID_ATTITUDE: Telemetry._attitude,
    mav.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: Telemetry._attitude_quaternion,
    mav.MAVLINK_MSG_ID_LOCAL_POSITION_NED: Telemetry._local_position_ned,
    mav.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: Telemetry._global_position_int,
    mav.MAVLINK_MSG_ID_ODOMETRY: Telemetry._odometry,
    mav.MAVLINK_MSG_ID_HIGHRES_IMU: Telemetry._highres_imu,
    mav.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: Telemetry._extended_sys_state,
    mav.MAVLINK_MSG_ID_SYS_STATUS: Telemetry._sys_status,
    mav.MAVLINK_MSG_ID_VFR_HUD: Telemetry._vfr_hud,
    mav.MAVLINK_MSG_ID_ALTITUDE: Telemetry._altitude,
    mav.MAVLINK_MSG_ID_HOME_POSITION: lambda t, snap: t.home_position(),
    mav.MAVLINK_MSG_ID_BATTERY_STATUS: Telemetry._battery_status,
    mav.MAVLINK_MSG_ID_GPS_RAW_INT: Telemetry._gps_raw_int,
    mav.MAVLINK_MSG_ID_MISSION_CURRENT: lambda t, snap: t.mission_current(),
    mav.MAVLINK_MSG_ID_AUTOPILOT_VERSION: lambda t, snap: t.autopilot_version(),
}


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
