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
