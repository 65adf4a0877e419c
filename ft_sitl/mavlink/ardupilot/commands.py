"""The commands ArduCopter answers differently from PX4: arming (its force value, its
"PreArm:" and "Arm:" texts, FAILED), DO_SET_MODE with ArduCopter's mode numbers,
NAV_TAKEOFF in GUIDED (param7 above home), NAV_LAND / NAV_RETURN_TO_LAUNCH / MISSION_START
as mode changes, DO_CHANGE_SPEED, DO_REPOSITION into GUIDED, and GUIDED's heading
(CONDITION_YAW, DO_SET_ROI: :mod:`.guided`) (ArduCopter/GCS_Mavlink.cpp). The rest is the
PX4 face's table."""

from __future__ import annotations

import math

from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import Result
from ft_sitl.autopilot.params import ParamError
from ft_sitl.mavlink.ardupilot import guided, modes
from ft_sitl.mavlink.ardupilot.prearm import refusals
from ft_sitl.mavlink.commands import HANDLERS, CommandArgs, Commands

#: ArduPilot's param2 values that force arming (AP_Arming) and disarming in flight
FORCE_ARM, FORCE_DISARM = 2989, 21196


class ArduCopterCommands(Commands):
    """The commands one vehicle answers, ArduCopter's way."""

    def _arm_disarm(self, a: CommandArgs):
        c, p = self.v.cmd, a.p
        if not math.isfinite(p[0]):
            return Result.FAILED, []
        if p[0] < 0.5:
            force = math.isfinite(p[1]) and round(p[1]) == FORCE_DISARM
            result = c.disarm(force)
            return (Result.ACCEPTED if result == Result.ACCEPTED else Result.FAILED), []
        if c.armed:
            return Result.ACCEPTED, []
        force = math.isfinite(p[1]) and round(p[1]) == FORCE_ARM
        if not force:  # ArduCopter's checks (.prearm), each failure's text
            texts = refusals(self.v)
            for text in texts:
                c.text(cm.Severity.CRITICAL, text)
            if texts:
                return Result.FAILED, []
        c.arm(force=True)  # (checked above, ArduCopter's way)
        return Result.ACCEPTED, []

    def _set_mode(self, a: CommandArgs):
        p = a.p
        if not (math.isfinite(p[0]) and math.isfinite(p[1])):
            return Result.FAILED, []
        if not int(p[0]) & apm.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return Result.UNSUPPORTED, []
        return self.v.modes.set(int(p[1])), []

    def _takeoff(self, a: CommandArgs):
        """MAV_CMD_NAV_TAKEOFF: in GUIDED, armed and landed, climb to param7 metres above
        home (Mode::do_user_takeoff); FAILED otherwise."""
        c, alt = self.v.cmd, a.p[6]
        if not self.v.modes.in_guided or not c.armed or \
                c.landed_state != cm.LandedState.ON_GROUND or not math.isfinite(alt) or \
                c.home[2] + alt <= c.position_now()[2]:
            return Result.FAILED, []
        c.takeoff(c.home[2] + alt)
        return Result.ACCEPTED, []

    def _land(self, a: CommandArgs):
        return self.v.modes.set(modes.LAND), []

    def _return_to_launch(self, a: CommandArgs):
        return self.v.modes.set(modes.RTL), []

    def _fence_enable(self, a: CommandArgs):
        """MAV_CMD_DO_FENCE_ENABLE: param1 1 on, 0 off (FENCE_ENABLE, written through to
        the geofence); 2 (the floor only) is not modelled: UNSUPPORTED."""
        p = a.p[0]
        if not math.isfinite(p) or round(p) not in (0, 1):
            return Result.UNSUPPORTED, []
        try:
            self.v.ap_params.set("FENCE_ENABLE", round(p))
        except ParamError:
            return Result.FAILED, []
        self.v.fleet.refresh_params()
        return Result.ACCEPTED, []

    def _change_speed(self, a: CommandArgs):
        """MAV_CMD_DO_CHANGE_SPEED: param2 > 0 m/s sets the horizontal speed of GUIDED's
        destinations and AUTO's legs (param1 0 air or 1 ground speed alike, as Copter
        reads them); FAILED otherwise. param1 2/3 (climb/descent speed) are not modelled:
        UNSUPPORTED."""
        kind, speed = a.p[0], a.p[1]
        if not (math.isfinite(speed) and speed > 0):
            return Result.FAILED, []
        if math.isfinite(kind) and kind > 1.9:
            return Result.UNSUPPORTED, []
        return self.v.cmd.change_speed(speed), []

    def _reposition(self, a: CommandArgs):
        """MAV_CMD_DO_REPOSITION as Copter takes it (GCS_Mavlink.cpp,
        handle_command_int_do_reposition; COMMAND_INT only, as MAVSDK's goto_location
        sends it): a GUIDED destination at x/y and z in the command's frame (NaN z: the
        altitude now); outside GUIDED only with param2's CHANGE_MODE bit, which switches to
        GUIDED, else DENIED; no position DENIED. Speed (param1) and yaw (param4) are not
        used, as in Copter."""
        p = a.p
        if not a.is_int:
            return Result.UNSUPPORTED, []
        change = math.isfinite(p[1]) and \
            int(p[1]) & apm.MAV_DO_REPOSITION_FLAGS_CHANGE_MODE
        lat, lon = a.lat_lon()
        if (not self.v.modes.in_guided and not change) or (lat == 0 and lon == 0):
            return Result.DENIED, []
        target = self.v.geo.to_local(lat, lon, self.v.geo.alt_m)
        target[2] = self.v.alt_to_local(p[6], a.frame) if math.isfinite(p[6]) else math.nan
        if not self.v.modes.in_guided and self.v.modes.set(modes.GUIDED) != Result.ACCEPTED:
            return Result.FAILED, []
        ok = guided.guided_destination(self.v, target)
        return (Result.ACCEPTED if ok else Result.FAILED), []

    def _condition_yaw(self, a: CommandArgs):
        p = a.p
        return guided.condition_yaw(self.v, p[0], p[2], p[3]), []

    def _set_roi(self, a: CommandArgs):
        """DO_SET_ROI / DO_SET_ROI_LOCATION: param5..7 the point (COMMAND_LONG's altitude
        above home, as ArduPilot converts it); all three 0 clears it."""
        lat, lon = a.lat_lon()
        if lat == 0 and lon == 0 and a.p[6] == 0:
            return guided.set_roi(self.v, None), []
        if not (math.isfinite(lat) and math.isfinite(lon)):
            return Result.FAILED, []
        return guided.set_roi(self.v, self.v.geo.to_local(lat, lon, self.v.geo.alt_m)), []

    def _mission_start(self, a: CommandArgs):
        c, p = self.v.cmd, a.p
        if not c.mission:
            return Result.FAILED, []
        if math.isfinite(p[0]) and p[0] >= 1:  # (ArduPilot's numbering: home is item 0)
            c.set_mission_current(int(p[0]) - 1)
        return self.v.modes.set(modes.AUTO), []


ArduCopterCommands.handlers = {
    **HANDLERS,
    apm.MAV_CMD_COMPONENT_ARM_DISARM: ArduCopterCommands._arm_disarm,
    apm.MAV_CMD_DO_SET_MODE: ArduCopterCommands._set_mode,
    apm.MAV_CMD_NAV_TAKEOFF: ArduCopterCommands._takeoff,
    apm.MAV_CMD_NAV_LAND: ArduCopterCommands._land,
    apm.MAV_CMD_NAV_RETURN_TO_LAUNCH: ArduCopterCommands._return_to_launch,
    apm.MAV_CMD_MISSION_START: ArduCopterCommands._mission_start,
    apm.MAV_CMD_DO_FENCE_ENABLE: ArduCopterCommands._fence_enable,
    apm.MAV_CMD_DO_CHANGE_SPEED: ArduCopterCommands._change_speed,
    apm.MAV_CMD_DO_REPOSITION: ArduCopterCommands._reposition,
    apm.MAV_CMD_CONDITION_YAW: ArduCopterCommands._condition_yaw,
    apm.MAV_CMD_DO_SET_ROI: ArduCopterCommands._set_roi,
    apm.MAV_CMD_DO_SET_ROI_LOCATION: ArduCopterCommands._set_roi,
}
