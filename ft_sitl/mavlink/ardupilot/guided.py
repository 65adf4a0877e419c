"""GUIDED's targets as ArduCopter reads them (ArduCopter/GCS_Mavlink.cpp and
mode_guided.cpp): SET_POSITION_TARGET_LOCAL_NED and _GLOBAL_INT only in GUIDED, and not
on the ground (take off first); any ignore bit of a group ignores the whole group; a
position alone is a destination (flown at WPNAV_SPEED and held), velocity or acceleration
(with or without position) a target that times out after GUID_TIMEOUT, and a combination
ArduCopter has no controller for stops the vehicle. In the body frames the position is an
offset from where the vehicle is, rotated by its heading. Also SET_MODE with ArduCopter's
numbers."""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl import frames
from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import Result
from ft_sitl.mavlink.offboard import Offboard
from ft_sitl.mavlink.receiver import Receiver

_POS, _VEL, _ACC = 0b111, 0b111000, 0b111000000
_YAW = 1 << 10
_LOCAL = (apm.MAV_FRAME_LOCAL_NED, apm.MAV_FRAME_LOCAL_OFFSET_NED, apm.MAV_FRAME_BODY_NED,
          apm.MAV_FRAME_BODY_OFFSET_NED)
_BODY = (apm.MAV_FRAME_BODY_NED, apm.MAV_FRAME_BODY_OFFSET_NED)
_GLOBAL = (apm.MAV_FRAME_GLOBAL_INT, apm.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
           apm.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, apm.MAV_FRAME_GLOBAL,
           apm.MAV_FRAME_GLOBAL_RELATIVE_ALT, apm.MAV_FRAME_GLOBAL_TERRAIN_ALT)


def _whole_groups(mask: int) -> int:
    """ArduPilot's reading: a group with any ignore bit set is ignored as a whole."""
    for group in (_POS, _VEL, _ACC):
        if mask & group:
            mask |= group
    return mask


class GuidedTargets(Offboard):
    """One vehicle's GUIDED targets."""

    def _usable(self) -> bool:
        c = self.v.cmd
        return self.v.modes.in_guided and c.armed and \
            c.landed_state != cm.LandedState.ON_GROUND

    def _stop(self) -> list:
        """A combination ArduCopter has no controller for: stop where it is."""
        self.v.cmd.set_mode(cm.MAIN_AUTO, cm.SUB_LOITER)
        self.v.cmd.auto.hold_here()
        return []

    def _goto(self, target_enu: np.ndarray, mask: int, yaw_ned: float) -> list:
        yaw = math.nan if mask & _YAW or not math.isfinite(yaw_ned) else \
            frames.yaw_ned_to_enu(yaw_ned)
        if not np.all(np.isfinite(target_enu)):
            return self._reject("position is not finite")
        self.v.cmd.reposition(target_enu, yaw)
        return []

    def _offboard(self) -> None:
        """Fly the setpoint just given as the commander's offboard stream."""
        c = self.v.cmd
        if c.main_mode != cm.MAIN_OFFBOARD:
            c.set_mode(cm.MAIN_OFFBOARD)

    def on_local_ned(self, m, link, peer, wall_us):
        if not self._usable():
            return []
        if m.coordinate_frame not in _LOCAL:
            return self._reject(f"frame {m.coordinate_frame} not supported")
        mask = _whole_groups(m.type_mask)
        pos, vel, acc = (not mask & _POS, not mask & _VEL, not mask & _ACC)
        if pos and not vel and not acc:
            p = np.array([m.x, m.y, m.z], dtype=float)
            s = self.v.fleet.state(self.v.index)
            if m.coordinate_frame in _BODY:
                yaw = frames.yaw_enu_to_ned(s.yaw)
                c, sn = math.cos(yaw), math.sin(yaw)
                p = np.array([c * p[0] - sn * p[1], sn * p[0] + c * p[1], p[2]])
            base = self.v.origin if m.coordinate_frame == apm.MAV_FRAME_LOCAL_NED \
                else s.position
            return self._goto(frames.ned_to_enu(p) + base, mask, m.yaw)
        if (pos and acc and not vel) or not (pos or vel or acc):
            return self._stop()
        m.type_mask = mask
        out = super().on_local_ned(m, link, peer, wall_us)
        self._offboard()
        return out

    def on_global_int(self, m, link, peer, wall_us):
        if not self._usable():
            return []
        if m.coordinate_frame not in _GLOBAL:
            return self._reject(f"frame {m.coordinate_frame} not supported")
        mask = _whole_groups(m.type_mask)
        pos, vel, acc = (not mask & _POS, not mask & _VEL, not mask & _ACC)
        if pos and not vel and not acc:
            if not math.isfinite(m.alt):
                return self._reject("altitude is not finite")
            p = self.v.geo.to_local(m.lat_int * 1e-7, m.lon_int * 1e-7, self.v.geo.alt_m)
            frame = m.coordinate_frame
            if frame in (apm.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, apm.MAV_FRAME_GLOBAL_TERRAIN_ALT):
                frame = apm.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT  # flat ground: above home
            p[2] = self.v.alt_to_local(m.alt, frame)
            return self._goto(p, mask, m.yaw)
        if (pos and acc and not vel) or not (pos or vel or acc):
            return self._stop()
        m.type_mask = mask
        out = super().on_global_int(m, link, peer, wall_us)
        self._offboard()
        return out


class ArduCopterReceiver(Receiver):
    """SET_MODE with ArduCopter's mode number in custom_mode."""

    def on_set_mode(self, m, link, peer, wall_us):
        if m.target_system != self.v.sysid or \
                not m.base_mode & apm.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return []
        self.v.modes.set(int(m.custom_mode))
        return []



def _holding(c: cm.Commander) -> bool:
    """The commander flies GUIDED's hold or destination (not a take-off or setpoints)."""
    return (c.main_mode, c.sub_mode) == (cm.MAIN_AUTO, cm.SUB_LOITER) and \
        c.auto.nav.target is not None


def _turn(v, yaw_enu: float) -> None:
    """Hold or fly GUIDED's destination facing ``yaw_enu`` (ArduCopter's auto_yaw in a
    fixed heading); nothing outside GUIDED's hold and destinations."""
    c = v.cmd
    if v.modes.in_guided and _holding(c):
        c.auto.nav.yaw = math.atan2(math.sin(yaw_enu), math.cos(yaw_enu))


def condition_yaw(v, heading_deg: float, direction: float, relative: float) -> Result:
    """MAV_CMD_CONDITION_YAW as Copter takes it (GCS_Mavlink.cpp, AutoYaw::set_fixed_yaw):
    param1 0..360 degrees, param4 0 (from north) or 1 (an offset from the heading held,
    clockwise unless param3 is negative); anything else FAILED. It turns GUIDED's hold
    or destination; a later GUIDED target without a yaw ends it (ModeGuided::set_yaw_state),
    as in ArduCopter."""
    if not (math.isfinite(heading_deg) and 0.0 <= heading_deg <= 360.0) or \
            relative not in (0.0, 1.0):
        return Result.FAILED
    c = v.cmd
    if relative:
        held = c.auto.nav.yaw if _holding(c) and math.isfinite(c.auto.nav.yaw) \
            else c.yaw_now()
        sign = -1.0 if math.isfinite(direction) and direction < 0 else 1.0
        yaw = held - sign * math.radians(heading_deg)  # (ENU yaw grows anticlockwise)
    else:
        yaw = frames.yaw_ned_to_enu(math.radians(heading_deg))
    _turn(v, yaw)
    return Result.ACCEPTED


def set_roi(v, roi_enu: np.ndarray | None) -> Result:
    """MAV_CMD_DO_SET_ROI / DO_SET_ROI_LOCATION (GCS_MAVLINK_Copter::
    handle_command_do_set_roi): GUIDED's hold faces the point (horizontally); None (a ROI of
    0, 0, 0) returns to the default heading, which a hold keeps as it is."""
    if roi_enu is None:
        return Result.ACCEPTED
    if not np.all(np.isfinite(roi_enu[:2])):
        return Result.FAILED
    c = v.cmd
    where = c.auto.nav.target if _holding(c) else c.position_now()
    d = np.asarray(roi_enu, dtype=float)[:2] - where[:2]
    if float(np.hypot(*d)) > 0.1:  # (right above it: any heading faces it)
        _turn(v, math.atan2(d[1], d[0]))
    return Result.ACCEPTED


def guided_destination(v, target_enu: np.ndarray) -> bool:
    """ArduCopter's guided request (a MISSION_ITEM with current 2, as DroneKit's simple_goto
    and MAVProxy's 'guided' send it; GCS_MAVLINK::handle_guided_request): in GUIDED, fly to
    the point and hold there (NaN altitude: the altitude now); False outside GUIDED or when
    the vehicle cannot go (not flying)."""
    if not v.modes.in_guided or not np.all(np.isfinite(target_enu[:2])):
        return False
    return v.cmd.reposition(np.asarray(target_enu, dtype=float)) == Result.ACCEPTED


def guided_altitude(v, alt_local: float) -> bool:
    """ArduCopter's change-altitude request (a MISSION_ITEM with current 3): in GUIDED,
    the destination or hold keeps its position and heading and takes this altitude (local
    z)."""
    c = v.cmd
    if not v.modes.in_guided or not math.isfinite(alt_local):
        return False
    target = c.auto.nav.target.copy() if _holding(c) else c.position_now()
    target[2] = alt_local
    return c.reposition(target, c.auto.nav.yaw if _holding(c) else math.nan) == \
        Result.ACCEPTED
