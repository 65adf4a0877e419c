"""The mission protocol as ArduCopter serves it: item 0 of the mission list is home.

ArduPilot's mission (AP_Mission) keeps home at index 0, written by the vehicle: a
download's item 0 is the home now, and an upload's item 0 is a placeholder the vehicle
does not fly. Items 1..n are the commander's mission 0..n-1, so every sequence number on
the wire (MISSION_CURRENT, MISSION_ITEM_REACHED, MISSION_SET_CURRENT, MISSION_START's
first item, DO_JUMP's target) is the commander's plus one. ArduCopter's commands map onto
the executor's (:mod:`ft_sitl.autopilot.mission`): NAV_LOITER_TIME is a waypoint held
param1 seconds, NAV_SPLINE_WAYPOINT a waypoint flown as ArduCopter's curve through it
(:mod:`ft_sitl.autopilot.spline`, held param1 seconds), NAV_LOITER_TURNS param1
turns round the point at radius param3 (none: CIRCLE_RADIUS's 10 m; negative:
anticlockwise) at CIRCLE_RATE's 20 deg/s, DO_SET_ROI(_LOCATION) the front toward its point
(at latitude and longitude 0: no longer), DO_JUMP jumps param2 times (-1: for ever);
CONDITION_DELAY / CONDITION_DISTANCE / CONDITION_YAW run with the DO items after them
beside the next nav item (:mod:`ft_sitl.autopilot.conditions`).
Fences and rally points are the PX4 face's lists; an uploaded fence is kept and flown as
FENCE_ENABLE/FENCE_TYPE say (:mod:`.fence`), RTL picks among the rally points by RALLY_*
(:mod:`.rally`).
"""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import MissionItem, Result
from ft_sitl.autopilot.conditions import Condition
from ft_sitl.autopilot.mission import (
    CMD_DO_JUMP,
    CMD_NAV_LOITER_TURNS,
    CMD_NAV_WAYPOINT,
    MissionState,
)
from ft_sitl.mavlink.ardupilot import guided
from ft_sitl.mavlink.mission import MissionProtocol
from ft_sitl.mavlink.mission_items import GLOBAL_FRAMES, MissionItems, deg_e7
from ft_sitl.mavlink.outgoing import Outgoing

_MISSION = apm.MAV_MISSION_TYPE_MISSION
#: the commands AP_Mission stores with a location (AP_Mission::stored_in_location); a
#: download gives every other command frame 0 (MAV_FRAME_GLOBAL, the packet's default)
LOCATION_COMMANDS = frozenset((
    apm.MAV_CMD_NAV_WAYPOINT, apm.MAV_CMD_NAV_LOITER_UNLIM, apm.MAV_CMD_NAV_LOITER_TURNS,
    apm.MAV_CMD_NAV_LOITER_TIME, apm.MAV_CMD_NAV_LAND, apm.MAV_CMD_NAV_TAKEOFF,
    apm.MAV_CMD_NAV_CONTINUE_AND_CHANGE_ALT, apm.MAV_CMD_NAV_LOITER_TO_ALT,
    apm.MAV_CMD_NAV_SPLINE_WAYPOINT, apm.MAV_CMD_NAV_GUIDED_ENABLE, apm.MAV_CMD_DO_SET_HOME,
    apm.MAV_CMD_DO_LAND_START, apm.MAV_CMD_DO_GO_AROUND, apm.MAV_CMD_DO_SET_ROI,
    apm.MAV_CMD_NAV_VTOL_TAKEOFF, apm.MAV_CMD_NAV_VTOL_LAND, apm.MAV_CMD_NAV_PAYLOAD_PLACE))
#: the mission states in which a nav command runs (a download marks it current)
_RUNNING = (MissionState.ACTIVE, MissionState.PAUSED)
#: a LOITER_TURNS item's radius when it gives none, and the speed round it: ArduCopter's
#: CIRCLE_RADIUS (1000 cm) and CIRCLE_RATE (20 deg/s) defaults (AC_Circle.cpp)
CIRCLE_RADIUS_M, CIRCLE_RATE_DEG_S = 10.0, 20.0
#: the CONDITION_* items ArduCopter flies in AUTO (ModeAuto::start_command)
_CONDITIONS = (apm.MAV_CMD_CONDITION_DELAY, apm.MAV_CMD_CONDITION_DISTANCE,
               apm.MAV_CMD_CONDITION_YAW)


class ArduCopterMissionItems(MissionItems):
    """Item conversions with ArduCopter's command set and its sequence offset of one."""

    def to_mission_item(self, it) -> MissionItem:
        if it.command == apm.MAV_CMD_NAV_LOITER_TIME:
            hold = it.param1 if math.isfinite(it.param1) else 0.0
            return MissionItem(CMD_NAV_WAYPOINT, self.position(it), hold_s=max(0.0, hold))
        if it.command == apm.MAV_CMD_NAV_SPLINE_WAYPOINT:  # a curve (autopilot.spline)
            hold = it.param1 if math.isfinite(it.param1) else 0.0
            return MissionItem(CMD_NAV_WAYPOINT, self.position(it), hold_s=max(0.0, hold),
                               spline=True)
        if it.command == apm.MAV_CMD_NAV_LOITER_TURNS:  # (AP_Mission, ModeAuto::do_circle)
            r = it.param3 if math.isfinite(it.param3) and it.param3 != 0 else CIRCLE_RADIUS_M
            return MissionItem(CMD_NAV_LOITER_TURNS, self.position(it),
                               turns=max(0.0, _finite(it.param1)), radius_m=r,
                               speed_m_s=math.radians(CIRCLE_RATE_DEG_S) * abs(r))
        if it.command in _CONDITIONS:  # (beside the next nav item, autopilot.conditions)
            return MissionItem(it.command, condition=Condition(
                it.command, _finite(it.param1), rate_deg_s=_finite(it.param2),
                direction=int(_finite(it.param3)), relative=_finite(it.param4) > 0))
        if it.command == CMD_DO_JUMP:
            target = int(it.param1) if math.isfinite(it.param1) else 0
            repeat = int(it.param2) if math.isfinite(it.param2) else 0
            return MissionItem(CMD_DO_JUMP, jump_to=target - 1, repeat=repeat)
        return super().to_mission_item(it)


def _finite(v: float) -> float:
    return v if math.isfinite(v) else 0.0


def _as_float(it):
    """A MISSION_ITEM_INT as the MISSION_ITEM carrying the same item (degrees; metres in
    LOCAL_NED)."""
    if it.frame in GLOBAL_FRAMES:
        x, y = it.x * 1e-7, it.y * 1e-7
    elif it.frame == apm.MAV_FRAME_LOCAL_NED:
        x, y = it.x * 1e-4, it.y * 1e-4
    else:
        x, y = float(it.x), float(it.y)
    return apm.MAVLink_mission_item_message(
        it.target_system, it.target_component, it.seq, it.frame, it.command, it.current,
        it.autocontinue, it.param1, it.param2, it.param3, it.param4, x, y, it.z,
        it.mission_type)


def _as_stored(it):
    """An uploaded item as AP_Mission gives it back: frame 0 for a command it stores
    without a location (RTL, DO_* ...), else as uploaded."""
    if it.command in LOCATION_COMMANDS or it.frame == apm.MAV_FRAME_GLOBAL:
        return it
    return apm.MAVLink_mission_item_int_message(
        it.target_system, it.target_component, it.seq, apm.MAV_FRAME_GLOBAL, it.command,
        it.current, it.autocontinue, it.param1, it.param2, it.param3, it.param4, it.x, it.y,
        it.z, it.mission_type)


class ArduCopterMission(MissionProtocol):
    """One vehicle's mission protocol with home at sequence 0 of the mission list."""

    def _apply_upload(self, mtype: int, items: list) -> None:
        if mtype == apm.MAV_MISSION_TYPE_FENCE:  # kept; flown as FENCE_ENABLE/TYPE say
            self.v.fence.upload(self.items.to_fence(items))
            self._stored[mtype] = list(items)
            return
        if mtype != _MISSION:
            super()._apply_upload(mtype, items)
            return
        # item 0 is home's placeholder: the vehicle flies items 1..n
        self.v.cmd.set_mission([self.items.to_mission_item(it) for it in items[1:]])
        self._stored[mtype] = list(items)

    def _fence_download(self) -> list:
        """The fence items as uploaded, whether the fence is on or not (a fence the
        controller got otherwise, a trial's: made from it, as the PX4 face does)."""
        if self.v.fence.owns(self.v.cmd.fence):
            return self._stored[apm.MAV_MISSION_TYPE_FENCE]
        return super()._fence_download()

    def _download(self, mtype: int) -> list | None:
        """The mission as AP_Mission reads it back: nothing when none is stored (after
        MISSION_CLEAR_ALL too: its count is 0, though item 0, home, can still be read:
        :meth:`on_request`), else home now as item 0 and the items, a command without a
        location in frame 0 (MAV_FRAME_GLOBAL)."""
        if mtype != _MISSION:
            return super()._download(mtype)
        stored = self._stored[mtype]
        if not stored:
            return []
        return [self._home_item()] + [_as_stored(it) for it in stored[1:]]

    def _home_item(self):
        """Item 0: home now, as AP_Mission writes it (absolute altitude, MAV_FRAME_GLOBAL)."""
        lat, lon, alt = self.v.geo.to_global(tuple(float(x) for x in self.v.cmd.home))
        return apm.MAVLink_mission_item_int_message(
            0, 0, 0, apm.MAV_FRAME_GLOBAL, apm.MAV_CMD_NAV_WAYPOINT, 0, 1, 0.0, 0.0, 0.0, 0.0,
            deg_e7(lat), deg_e7(lon), float(alt), _MISSION)

    def load(self, items: list) -> None:
        """Take a whole mission (MISSION_ITEM_INT, item 0 home's placeholder) as an
        upload would (ValueError: refused, nothing changed)."""
        self._apply_upload(_MISSION, list(items))

    def mission_items(self) -> list:
        """The mission as a download returns it (item 0: home now; empty when no mission
        is loaded)."""
        return self._download(_MISSION)

    def _request_item(self, seq: int) -> Outgoing:
        """ArduPilot asks for each uploaded item with MISSION_REQUEST (either item message
        answers it; MissionItemProtocol::queued_request_send): DroneKit answers no other."""
        out = super()._request_item(seq)
        r = out.msg
        return Outgoing(apm.MAVLink_mission_request_message(
            r.target_system, r.target_component, r.seq, r.mission_type), out.link, out.peer)

    def on_request(self, m, link, peer, wall_us):
        """A download's MISSION_REQUEST is answered with MISSION_ITEM (degrees as floats),
        MISSION_REQUEST_INT with MISSION_ITEM_INT, as ArduPilot answers each
        (GCS_MAVLINK::handle_mission_request): DroneKit reads what it asked for."""
        if getattr(m, "mission_type", 0) == _MISSION and m.seq == 0 and \
                not self._stored[_MISSION]:
            # no mission (count 0): home can still be read (MissionItemProtocol_Waypoints
            # get_item "always allow HOME to be read"; DroneKit's download asks for it)
            h = self._home_item()
            out = [Outgoing(apm.MAVLink_mission_item_int_message(
                m.get_srcSystem(), m.get_srcComponent(), 0, h.frame, h.command, 0,
                h.autocontinue, h.param1, h.param2, h.param3, h.param4, h.x, h.y, h.z,
                _MISSION), link, peer)]
        else:
            out = super().on_request(m, link, peer, wall_us)
        if m.get_type() != "MISSION_REQUEST":
            return out
        return [Outgoing(_as_float(o.msg), o.link, o.peer)
                if o.msg.get_type() == "MISSION_ITEM_INT" else o for o in out]

    def on_item(self, m, link, peer, wall_us):
        if m.current not in (2, 3):
            return super().on_item(m, link, peer, wall_us)
        x, y = (deg_e7(m.x), deg_e7(m.y)) if m.frame in GLOBAL_FRAMES else (0, 0)
        return [self._guided_request(apm.MAVLink_mission_item_int_message(
            m.target_system, m.target_component, m.seq, m.frame, m.command, m.current,
            m.autocontinue, m.param1, m.param2, m.param3, m.param4, x, y, m.z), m, link, peer)]

    def on_item_int(self, m, link, peer, wall_us):
        if m.current not in (2, 3):
            return super().on_item_int(m, link, peer, wall_us)
        return [self._guided_request(m, m, link, peer)]

    def _guided_request(self, it, m, link, peer) -> Outgoing:
        """A mission item with current 2 (go there) or 3 (change altitude) is GUIDED's
        request, not an upload (GCS_MAVLINK::handle_mission_item): MISSION_ACK ACCEPTED,
        or ERROR outside GUIDED or when the vehicle cannot go (:mod:`.guided`)."""
        try:
            pos = np.array(self.items.position(it), dtype=float)
        except ValueError:
            ok = False
        else:
            ok = guided.guided_destination(self.v, pos) if it.current == 2 else \
                guided.guided_altitude(self.v, pos[2])
        return Outgoing(apm.MAVLink_mission_ack_message(
            m.get_srcSystem(), m.get_srcComponent(),
            apm.MAV_MISSION_ACCEPTED if ok else apm.MAV_MISSION_ERROR, _MISSION), link, peer)

    def _current_seq(self) -> int:
        """The item a download marks current: the nav command running (AP_Mission's
        current nav index), none before the mission has started."""
        c = self.v.cmd
        return c.mission_seq + 1 if c.mission and c.mission_state in _RUNNING else -1

    def on_set_current(self, m, link, peer, wall_us):
        seq = max(int(m.seq), 1)  # (ArduPilot: home cannot be the current item)
        if self.v.cmd.set_mission_current(seq - 1) != Result.ACCEPTED:
            self.v.cmd.text(cm.Severity.WARNING, f"Mission item {m.seq} does not exist")
        return [Outgoing(self.telemetry.mission_current())]
