"""HEARTBEAT and AUTOPILOT_VERSION as ArduCopter fills them; every other message is the
PX4 face's (:class:`~ft_sitl.mavlink.telemetry.Telemetry`): the same state, the same
encoding."""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.mavlink.ardupilot.modes import GUIDED_FLAG_MODES
from ft_sitl.mavlink.telemetry import Telemetry

#: what ArduPilot advertises (GCS_MAVLINK::capabilities): parameters C-cast, not bytewise
CAPABILITIES = (
    apm.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
    | apm.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
    | apm.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    | apm.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
    | apm.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
    | apm.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
    | apm.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_GLOBAL_INT
    | apm.MAV_PROTOCOL_CAPABILITY_SET_ATTITUDE_TARGET
    | apm.MAV_PROTOCOL_CAPABILITY_FLIGHT_TERMINATION
    | apm.MAV_PROTOCOL_CAPABILITY_MAVLINK2
)
#: the ArduCopter release this face answers as (flight_sw_version 4.5.7, official)
VERSION = (4, 5, 7)
#: EKF_STATUS_REPORT's flags of a healthy EKF3 with GPS: attitude, horizontal and vertical
#: velocity, relative and absolute horizontal position, absolute vertical position, and
#: the predicted horizontal positions (EKF_STATUS_FLAGS); DroneKit's is_armable reads
#: EKF_PRED_POS_HORIZ_ABS
EKF_HEALTHY = (apm.EKF_ATTITUDE | apm.EKF_VELOCITY_HORIZ | apm.EKF_VELOCITY_VERT
               | apm.EKF_POS_HORIZ_REL | apm.EKF_POS_HORIZ_ABS | apm.EKF_POS_VERT_ABS
               | apm.EKF_PRED_POS_HORIZ_REL | apm.EKF_PRED_POS_HORIZ_ABS)
#: the innovation test ratios reported (0: perfect, 1: at the rejection gate): the
#: estimator stage models no filter, so a small constant
EKF_TEST_RATIO = 0.01


class ArduCopterTelemetry(Telemetry):
    """One vehicle's telemetry with ArduCopter's identity."""

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
        if msg_id == apm.MAVLINK_MSG_ID_EKF_STATUS_REPORT:
            return self.ekf_status_report()
        return super().build(msg_id)

    def ekf_status_report(self) -> apm.MAVLink_ekf_status_report_message:
        """EKF_STATUS_REPORT as a healthy EKF3 sends it (AP_NavEKF3's send_status_report)."""
        r = EKF_TEST_RATIO
        return apm.MAVLink_ekf_status_report_message(EKF_HEALTHY, r, r, r, r, 0.0, 0.0)

    def item_reached(self, seq: int) -> apm.MAVLink_mission_item_reached_message:
        return apm.MAVLink_mission_item_reached_message(seq + 1)  # (home is item 0)

    def mission_current(self) -> apm.MAVLink_mission_current_message:
        """MISSION_CURRENT in ArduPilot's numbering: home is item 0, so the commander's
        item k is k + 1 and the total counts home."""
        mc = super().mission_current()
        n = len(self.v.cmd.mission)
        return apm.MAVLink_mission_current_message(mc.seq + 1 if n else 0, n + 1 if n else 0,
                                                   mc.mission_state, mc.mission_mode)
