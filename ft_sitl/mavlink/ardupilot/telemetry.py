"""HEARTBEAT, AUTOPILOT_VERSION, SYS_STATUS's geofence bits and the messages only
ArduPilot sends (AHRS2, EKF_STATUS_REPORT, NAV_CONTROLLER_OUTPUT, SERVO_OUTPUT_RAW,
RC_CHANNELS, FENCE_STATUS) as ArduCopter fills them; every other message is the PX4 face's
(:class:`~ft_sitl.mavlink.telemetry.Telemetry`): the same state, the same encoding."""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.autopilot import commander as cm
from ft_sitl.mavlink.ardupilot.modes import AUTO, GUIDED, GUIDED_FLAG_MODES, RTL
from ft_sitl.mavlink.ardupilot.rc import RC_CHANNELS
from ft_sitl.mavlink.telemetry import Telemetry
from ft_sitl.physics.quaternion import qto_euler

#: what ArduPilot advertises (GCS_MAVLINK::capabilities, GCS_MAVLINK_Copter's) of what
#: this face does: the mission, fence and rally lists, COMMAND_INT, the setpoint messages.
#: No parameter encoding bit: ArduPilot announces neither C_CAST nor BYTEWISE, though its
#: PARAM_VALUE carries integers C-cast into the float (so does this face, .parameters);
#: ground stations assume that of ArduPilot. Not the compass calibration, FTP or terrain
#: ArduCopter also announces (the face has none of them).
CAPABILITIES = (
    apm.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | apm.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | apm.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | apm.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | apm.MAV_PROTOCOL_CAPABILITY_MISSION_FENCE
    | apm.MAV_PROTOCOL_CAPABILITY_MISSION_RALLY
    | apm.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | apm.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | apm.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | apm.MAV_PROTOCOL_CAPABILITY_FLIGHT_TERMINATION
    | apm.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)
#: the modes whose NAV_CONTROLLER_OUTPUT carries a target
NAV_MODES = (GUIDED, AUTO, RTL)
#: the motors SERVO_OUTPUT_RAW reports (a quadrotor's, on SERVO1..4)
SERVO_MOTORS = 4
#: the ArduCopter release this face answers as (flight_sw_version 4.5.7, official)
VERSION = (4, 5, 7)
#: EKF_STATUS_REPORT's flags of a healthy EKF3 with GPS: attitude, horizontal and vertical
#: velocity, relative and absolute horizontal position, absolute vertical position, and
#: the predicted horizontal positions (EKF_STATUS_FLAGS); DroneKit's is_armable reads
#: EKF_PRED_POS_HORIZ_ABS
EKF_HEALTHY = (apm.EKF_ATTITUDE | apm.EKF_VELOCITY_HORIZ | apm.EKF_VELOCITY_VERT
               | apm.EKF_POS_HORIZ_REL | apm.EKF_POS_HORIZ_ABS | apm.EKF_POS_VERT_ABS
               | apm.EKF_PRED_POS_HORIZ_REL | apm.EKF_PRED_POS_HORIZ_ABS)
#: EKF_STATUS_REPORT's flags without GPS: no horizontal position or velocity, the
#: constant-position mode EKF3 falls back to
EKF_NO_GPS = (apm.EKF_ATTITUDE | apm.EKF_VELOCITY_VERT | apm.EKF_POS_VERT_ABS
              | apm.EKF_CONST_POS_MODE)
#: the innovation test ratios reported (0: perfect, 1: at the rejection gate): the
#: estimator stage models no filter, so a small constant
EKF_TEST_RATIO = 0.01


class ArduCopterTelemetry(Telemetry):
    """One vehicle's telemetry with ArduCopter's identity."""

    def __init__(self, vehicle):
        super().__init__(vehicle)
        #: NAV_CONTROLLER_OUTPUT's leg: (its target, where the vehicle was when it began)
        self._leg: tuple[np.ndarray, np.ndarray] | None = None

    def heartbeat(self) -> apm.MAVLink_heartbeat_message:
        c = self.v.cmd
        mode = self.v.modes.number
        # GCS_MAVLINK_Copter::base_mode: stabilise and manual input always, guided in the
        # navigating modes, armed, custom mode
        base = (apm.MAV_MODE_FLAG_STABILIZE_ENABLED | apm.MAV_MODE_FLAG_MANUAL_INPUT_ENABLED
                | apm.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)
        if mode in GUIDED_FLAG_MODES:
            base |= apm.MAV_MODE_FLAG_GUIDED_ENABLED
        if c.armed:
            base |= apm.MAV_MODE_FLAG_SAFETY_ARMED
        if c.terminated:
            status = apm.MAV_STATE_EMERGENCY
        elif c.armed:
            status = apm.MAV_STATE_ACTIVE
        else:
            status = apm.MAV_STATE_STANDBY
        return apm.MAVLink_heartbeat_message(apm.MAV_TYPE_QUADROTOR,
                                             apm.MAV_AUTOPILOT_ARDUPILOTMEGA, base, mode,
                                             status, 3)

    def autopilot_version(self) -> apm.MAVLink_autopilot_version_message:
        major, minor, patch = VERSION
        return apm.MAVLink_autopilot_version_message(
            CAPABILITIES, (major << 24) | (minor << 16) | (patch << 8) | 255, 0, 0, 0,
            [0] * 8, [0] * 8, [0] * 8, 0, 0, 0x46540000 + self.v.sysid, [0] * 18)

    def build(self, msg_id: int):
        builder = _AP_BUILDERS.get(msg_id)
        if builder is not None:
            return builder(self)
        m = super().build(msg_id)
        if msg_id == apm.MAVLINK_MSG_ID_SYS_STATUS:  # the geofence bits AC_Fence's way
            (m.onboard_control_sensors_present, m.onboard_control_sensors_enabled,
             m.onboard_control_sensors_health) = self.v.fence.sys_status_bits(
                m.onboard_control_sensors_present, m.onboard_control_sensors_enabled,
                m.onboard_control_sensors_health)
        return m

    def ahrs2(self) -> apm.MAVLink_ahrs2_message:
        """AHRS2 (GCS_MAVLINK::send_ahrs2): the secondary estimate's attitude (rad, NED),
        altitude (m AMSL) and position; ft-sitl has one estimate, so it is that one."""
        snap = self.snapshot()
        roll, pitch, yaw = (float(a) for a in qto_euler(snap.q_ned))
        lat, lon, alt = self.v.geo.to_global(snap.state.position)
        return apm.MAVLink_ahrs2_message(roll, pitch, yaw, float(alt), int(round(lat * 1e7)),
                                         int(round(lon * 1e7)))

    def _nav_target(self) -> np.ndarray | None:
        """Where the navigating modes (GUIDED, AUTO, RTL) fly now (local ENU), or None."""
        c = self.v.cmd
        if self.v.modes.number not in NAV_MODES or c.main_mode != cm.MAIN_AUTO or \
                c.auto.nav.target is None:
            return None
        return np.asarray(c.auto.nav.target, dtype=float)

    def nav_controller_output(self) -> apm.MAVLink_nav_controller_output_message:
        """NAV_CONTROLLER_OUTPUT (GCS_MAVLINK_Copter::send_nav_controller_output): the
        attitude flown as nav roll/pitch and nav bearing (deg), and in GUIDED/AUTO/RTL the
        target's bearing (deg), horizontal distance (m), altitude error (target above the
        vehicle, m) and cross-track error (m from the line the leg began on); 0 else."""
        snap = self.snapshot()
        roll, pitch, yaw = (math.degrees(float(a)) for a in qto_euler(snap.q_ned))
        p = snap.state.position
        target = self._nav_target()
        if target is None:
            self._leg = None
            return apm.MAVLink_nav_controller_output_message(
                roll, pitch, int(round(yaw)) % 360, 0, 0, 0.0, 0.0, 0.0)
        if self._leg is None or not np.array_equal(self._leg[0], target):
            self._leg = (target.copy(), np.array(p[:2], dtype=float))  # a new leg begins
        origin = self._leg[1]
        d = target[:2] - p[:2]
        bearing = math.degrees(math.atan2(d[0], d[1])) % 360.0  # (ENU: east over north)
        track = target[:2] - origin
        length = float(np.hypot(*track))
        xtrack = 0.0 if length < 1e-6 else \
            abs(float(track[0] * (p[1] - origin[1]) - track[1] * (p[0] - origin[0]))) / length
        return apm.MAVLink_nav_controller_output_message(
            roll, pitch, int(round(yaw)) % 360, int(round(bearing)) % 360,
            min(int(round(float(np.hypot(*d)))), 65535), float(target[2] - p[2]), 0.0, xtrack)

    def servo_output_raw(self) -> apm.MAVLink_servo_output_raw_message:
        """SERVO_OUTPUT_RAW (GCS_MAVLINK::send_servo_output_raw): motor n (ArduPilot's
        order, the layouts' order) on servo n, SERVOn_MIN at a zero rotor speed command to
        SERVOn_MAX at full; the rest 0."""
        v = self.v
        w = v.fleet.rotor_speed_commands(v.index)
        w_max = v.fleet.sim.platforms[v.index].rotor_speed_max_rad_s
        pwm = [0] * 16
        for k in range(min(len(w), SERVO_MOTORS)):
            lo, hi = v.ap_params[f"SERVO{k + 1}_MIN"], v.ap_params[f"SERVO{k + 1}_MAX"]
            frac = min(max(float(w[k]) / w_max, 0.0), 1.0)
            pwm[k] = int(round(lo + (hi - lo) * frac))
        return apm.MAVLink_servo_output_raw_message(v.fleet.time_us & 0xFFFFFFFF, 0, *pwm)

    def rc_channels(self) -> apm.MAVLink_rc_channels_message:
        """RC_CHANNELS (GCS_MAVLINK::send_rc_channels): the 16 channels the vehicle reads
        now, overrides included (:mod:`.rc`: an override, else the simulated radio's
        value); channels 17 and 18 unused (0); RSSI unknown (255)."""
        pwm = [self.v.rc.pwm(ch) for ch in range(1, RC_CHANNELS + 1)] + [0, 0]
        return apm.MAVLink_rc_channels_message(self._boot_ms() & 0xFFFFFFFF, RC_CHANNELS,
                                               *pwm, 255)

    def fence_status(self) -> apm.MAVLink_fence_status_message | None:
        return self.v.fence.status()

    def ekf_status_report(self) -> apm.MAVLink_ekf_status_report_message:
        """EKF_STATUS_REPORT as EKF3 sends it (AP_NavEKF3's send_status_report): healthy,
        or without GPS (SIM_GPS_DISABLE, an injected GPS failure) attitude, vertical
        velocity and height only, in constant-position mode."""
        r = EKF_TEST_RATIO
        flags = EKF_HEALTHY if self.v.cmd.sensor_ok("gps") else EKF_NO_GPS
        return apm.MAVLink_ekf_status_report_message(flags, r, r, r, r, 0.0, 0.0)

    def item_reached(self, seq: int) -> apm.MAVLink_mission_item_reached_message:
        return apm.MAVLink_mission_item_reached_message(seq + 1)  # (home is item 0)

    def mission_current(self) -> apm.MAVLink_mission_current_message:
        """MISSION_CURRENT in ArduPilot's numbering: home is item 0, so the commander's
        item k is k + 1 and the total counts home."""
        mc = super().mission_current()
        n = len(self.v.cmd.mission)
        return apm.MAVLink_mission_current_message(mc.seq + 1 if n else 0, n + 1 if n else 0,
                                                   mc.mission_state, mc.mission_mode)


#: the messages this face builds itself, by id (the rest are the PX4 face's)
_AP_BUILDERS = {
    apm.MAVLINK_MSG_ID_EKF_STATUS_REPORT: ArduCopterTelemetry.ekf_status_report,
    apm.MAVLINK_MSG_ID_AHRS2: ArduCopterTelemetry.ahrs2,
    apm.MAVLINK_MSG_ID_NAV_CONTROLLER_OUTPUT: ArduCopterTelemetry.nav_controller_output,
    apm.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: ArduCopterTelemetry.servo_output_raw,
    apm.MAVLINK_MSG_ID_FENCE_STATUS: ArduCopterTelemetry.fence_status,
    apm.MAVLINK_MSG_ID_RC_CHANNELS: ArduCopterTelemetry.rc_channels,
}
