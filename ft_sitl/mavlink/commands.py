"""COMMAND_LONG and COMMAND_INT: one handler per MAV_CMD, found in a table.

Both messages carry the same seven parameters; COMMAND_INT's x and y are degE7 integers
where COMMAND_LONG's param5 and param6 are degrees, which :class:`CommandArgs` hides, so a
handler reads a latitude and longitude the same way from either. Every handler returns
(Result, extra messages); the ACK is made here. A command not in the table is
UNSUPPORTED, as PX4 answers it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import Result
from ft_sitl.autopilot.setpoints import SetpointError
from ft_sitl.mavlink.outgoing import Outgoing
from ft_sitl.mavlink.streams import Streams
from ft_sitl.mavlink.telemetry import Telemetry

#: MAV_CMD_COMPONENT_ARM_DISARM's param2 that forces arming or disarming
FORCE_MAGIC = 21196


@dataclass(frozen=True)
class CommandArgs:
    """One command's parameters (``p``: param1..param7, COMMAND_INT's x, y, z in the last
    three), how it came (``is_int``, the frame) and where to answer."""

    p: list
    is_int: bool
    frame: int
    link: int
    peer: tuple | None

    def lat_lon(self) -> tuple[float, float]:
        """param5 and param6 as degrees (COMMAND_INT carries them as degE7)."""
        if self.is_int:
            return self.p[4] * 1e-7, self.p[5] * 1e-7
        return self.p[4], self.p[5]


class Commands:
    """The commands one vehicle answers (:attr:`handlers`, by MAV_CMD)."""

    #: the handler of each MAV_CMD (the table below; a personality's subclass extends it)
    handlers: dict = {}

    def __init__(self, telemetry: Telemetry, streams: Streams):
        self.telemetry = telemetry
        self.streams = streams
        self.v = telemetry.v

    def on_command(self, m, link, peer, wall_us):
        """COMMAND_LONG or COMMAND_INT: run it, answer COMMAND_ACK (and what it returns)."""
        is_int = m.get_type() == "COMMAND_INT"
        p = [m.param1, m.param2, m.param3, m.param4]
        if is_int:
            p += [m.x, m.y, m.z]
        else:
            p += [m.param5, m.param6, m.param7]
        args = CommandArgs(p, is_int, getattr(m, "frame", 0), link, peer)
        handler = self.handlers.get(m.command)
        try:
            result, extra = handler(self, args) if handler is not None else \
                (Result.UNSUPPORTED, [])
        except (ValueError, SetpointError) as exc:
            self.v.cmd.text(cm.Severity.CRITICAL, f"Command {m.command} rejected: {exc}")
            result, extra = Result.DENIED, []
        ack = mav.MAVLink_command_ack_message(m.command, int(result), 0, 0, m.get_srcSystem(),
                                              m.get_srcComponent())
        return [Outgoing(ack, link, peer), *extra]

    # --- arming and flight modes -------------------------------------------------------
    def _arm_disarm(self, a: CommandArgs):
        p = a.p
        force = abs(p[1] - FORCE_MAGIC) < 0.5
        if not math.isfinite(p[0]):
            return Result.DENIED, []
        return (self.v.cmd.arm(force) if p[0] > 0.5 else self.v.cmd.disarm(force)), []

    def _takeoff(self, a: CommandArgs):
        alt = a.p[6]  # AMSL; lat/lon (p[4], p[5]) and yaw (p[3]) are not used
        local = None if not math.isfinite(alt) else alt - self.v.geo.alt_m
        return self.v.cmd.nav_takeoff(local), []

    def _land(self, a: CommandArgs):
        return self.v.cmd.land(), []

    def _return_to_launch(self, a: CommandArgs):
        return self.v.cmd.return_to_launch(), []

    def _set_mode(self, a: CommandArgs):
        p = a.p
        if not (math.isfinite(p[1]) and math.isfinite(p[2])):
            return Result.DENIED, []
        if not int(p[0]) & mav.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return Result.UNSUPPORTED, []
        return self.v.cmd.set_mode(int(p[1]), int(p[2])), []

    def _mission_start(self, a: CommandArgs):
        c, p = self.v.cmd, a.p
        if not c.mission:
            return Result.DENIED, []
        if math.isfinite(p[0]) and p[0] >= 0:
            c.set_mission_current(int(p[0]))
        return c.set_mode(cm.MAIN_AUTO, cm.SUB_MISSION), []

    # --- where to fly ------------------------------------------------------------------
    def _reposition(self, a: CommandArgs):
        p = a.p
        lat, lon = a.lat_lon()
        alt = p[6]
        if not (math.isfinite(lat) and math.isfinite(lon)) or (lat == 0 and lon == 0):
            target = np.array([math.nan, math.nan, math.nan])
        else:
            target = self.v.geo.to_local(lat, lon, self.v.geo.alt_m)
            target[2] = math.nan
        if math.isfinite(alt):
            target[2] = self.v.alt_to_local(alt, a.frame)
        yaw = frames.yaw_ned_to_enu(p[3]) if math.isfinite(p[3]) else math.nan
        if math.isfinite(p[0]) and p[0] > 0:
            self.v.cmd.change_speed(p[0])
        return self.v.cmd.reposition(target, yaw), []

    def _change_speed(self, a: CommandArgs):
        return self.v.cmd.change_speed(a.p[1]), []

    def _orbit(self, a: CommandArgs):
        p = a.p
        lat, lon = a.lat_lon()
        center = np.array([math.nan, math.nan, math.nan])
        if math.isfinite(lat) and math.isfinite(lon) and not (lat == 0 and lon == 0):
            center[:2] = self.v.geo.to_local(lat, lon, self.v.geo.alt_m)[:2]
        if math.isfinite(p[6]):  # PX4 reads an orbit's altitude as AMSL in any frame
            center[2] = p[6] - self.v.geo.alt_m
        yaw_mode = int(p[2]) if math.isfinite(p[2]) else 0
        return self.v.cmd.orbit(center, p[0], p[1], yaw_mode), []

    def _set_home(self, a: CommandArgs):
        p = a.p
        if p[0] > 0.5:
            pos = self.v.fleet.state(self.v.index).position
        else:
            lat, lon = a.lat_lon()
            if not all(math.isfinite(v) for v in (lat, lon, p[6])):
                return Result.DENIED, []
            pos = self.v.geo.to_local(lat, lon, p[6])
        self.v.cmd.set_home(pos)
        return Result.ACCEPTED, [Outgoing(self.telemetry.home_position())]

    # --- messages on request ---------------------------------------------------------
    def _set_message_interval(self, a: CommandArgs):
        return self.streams.set_message_interval(a.p[0], a.p[1], a.link), []

    def _request_message(self, a: CommandArgs):
        msg_id = int(a.p[0]) if math.isfinite(a.p[0]) else -1
        m = self.telemetry.build(msg_id) if msg_id != mav.MAVLINK_MSG_ID_PARAM_VALUE else None
        if m is None:  # as PX4: no stream for it, or nothing to send
            return Result.DENIED, []
        return Result.ACCEPTED, [Outgoing(m, a.link, a.peer)]

    def _request_autopilot_capabilities(self, a: CommandArgs):
        return Result.ACCEPTED, [Outgoing(self.telemetry.autopilot_version(), a.link, a.peer)]

    def _get_home_position(self, a: CommandArgs):
        return Result.ACCEPTED, [Outgoing(self.telemetry.home_position(), a.link, a.peer)]

    # --- failures, termination, the ground ----------------------------------------------
    def _inject_failure(self, a: CommandArgs):
        p = a.p
        if not all(math.isfinite(v) for v in p[:3]):
            return Result.DENIED, []
        return self.v.fleet.inject_failure(self.v.index, int(p[0]), int(p[1]), int(p[2])), []

    def _flight_termination(self, a: CommandArgs):
        if a.p[0] > 0.5:
            return self.v.cmd.terminate(), []
        return Result.ACCEPTED, []

    def _calibrate(self, a: CommandArgs):
        """PREFLIGHT_CALIBRATION as PX4 SITL answers it, completed at once: the "[cal]"
        STATUSTEXT protocol (started, progress, done) MAVSDK's Calibration plugin and
        QGroundControl follow. Refused when armed."""
        p = a.p
        kinds = [(0, 1, "gyro"), (1, 1, "mag"), (2, 1, "baro"), (4, 1, "accel"),
                 (4, 2, "level"), (5, 1, "airspeed")]
        chosen = [k for i, v, k in kinds if math.isfinite(p[i]) and round(p[i]) == v]
        if not chosen:  # all zero: nothing to calibrate (PX4: cancels a running one)
            return Result.ACCEPTED, []
        if self.v.cmd.armed:
            self.v.cmd.text(cm.Severity.CRITICAL, "[cal] calibration denied: vehicle armed")
            return Result.TEMPORARILY_REJECTED, []
        kind = chosen[0]
        for text in (f"[cal] calibration started: 2 {kind}", "[cal] progress <50>",
                     "[cal] progress <100>", f"[cal] calibration done: {kind}"):
            self.v.cmd.text(cm.Severity.INFO, text)
        return Result.ACCEPTED, []

    def _reboot(self, a: CommandArgs):
        c = self.v.cmd
        if c.armed:
            return Result.DENIED, []
        if a.p[0] == 1:  # autopilot reboot: clears a flight termination
            if c.crashed:  # and puts a crashed vehicle back on its spawn point
                self.v.fleet.respawn(self.v.index)
            c.terminated = False
            c.text(cm.Severity.INFO, "Rebooting autopilot")
        return Result.ACCEPTED, []


#: the handler of each MAV_CMD a vehicle answers
HANDLERS = {
    mav.MAV_CMD_COMPONENT_ARM_DISARM: Commands._arm_disarm,
    mav.MAV_CMD_NAV_TAKEOFF: Commands._takeoff,
    mav.MAV_CMD_NAV_LAND: Commands._land,
    mav.MAV_CMD_NAV_RETURN_TO_LAUNCH: Commands._return_to_launch,
    mav.MAV_CMD_DO_SET_MODE: Commands._set_mode,
    mav.MAV_CMD_DO_REPOSITION: Commands._reposition,
    mav.MAV_CMD_DO_CHANGE_SPEED: Commands._change_speed,
    mav.MAV_CMD_DO_ORBIT: Commands._orbit,
    mav.MAV_CMD_INJECT_FAILURE: Commands._inject_failure,
    mav.MAV_CMD_MISSION_START: Commands._mission_start,
    mav.MAV_CMD_SET_MESSAGE_INTERVAL: Commands._set_message_interval,
    mav.MAV_CMD_REQUEST_MESSAGE: Commands._request_message,
    mav.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: Commands._request_autopilot_capabilities,
    mav.MAV_CMD_GET_HOME_POSITION: Commands._get_home_position,
    mav.MAV_CMD_DO_SET_HOME: Commands._set_home,
    mav.MAV_CMD_DO_FLIGHTTERMINATION: Commands._flight_termination,
    mav.MAV_CMD_PREFLIGHT_CALIBRATION: Commands._calibrate,
    mav.MAV_CMD_PREFLIGHT_REBOOT_SHUTDOWN: Commands._reboot,
}
Commands.handlers = HANDLERS
