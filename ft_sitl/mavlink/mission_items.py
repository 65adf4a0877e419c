"""Mission protocol items to and from the commander's types: MISSION_ITEM_INT as uploaded
becomes MissionItem, Fence or a rally point (local ENU), and a fence the commander got
otherwise becomes the items a download returns.

Kept apart from the transfer protocol (:mod:`ft_sitl.mavlink.mission`) because it is the
part that knows frames and units: degE7, metres * 1e4 in LOCAL_NED, altitude by frame.
"""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.autopilot.commander import MissionItem
from ft_sitl.autopilot.geofence import Fence, FenceError, Polygon, circle, polygon
from ft_sitl.mavlink.vehicle import Vehicle

#: the MAVLink frames whose x, y are latitude and longitude
GLOBAL_FRAMES = (mav.MAV_FRAME_GLOBAL_INT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                 mav.MAV_FRAME_GLOBAL, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT)
#: the frames a mission item may use here (others: MAV_MISSION_UNSUPPORTED_FRAME, as PX4)
SUPPORTED_FRAMES = GLOBAL_FRAMES + (mav.MAV_FRAME_LOCAL_NED, mav.MAV_FRAME_MISSION)
_POLYGON_VERTICES = (mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                     mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION)
_CIRCLES = (mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, mav.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION)


def deg_e7(v: float) -> int:
    """A float coordinate as MISSION_ITEM_INT's int32 (out of range: 0, "not given")."""
    if not math.isfinite(v):
        return 0
    r = round(v * 1e7)
    return r if -2**31 <= r < 2**31 else 0


def _f(v: float) -> float:
    return v if math.isfinite(v) else 0.0


class MissionItems:
    """Item conversions for one vehicle (relative altitudes from its home, LOCAL_NED from
    its local frame's origin)."""

    def __init__(self, vehicle: Vehicle):
        self.v = vehicle

    def position(self, it) -> tuple:
        """An item's position in the local ENU frame (NaN where not given)."""
        nan = math.nan
        if it.frame in GLOBAL_FRAMES:
            lat, lon = it.x * 1e-7, it.y * 1e-7  # MISSION_ITEM_INT: degE7 in any global frame
            if (lat == 0 and lon == 0) or not (math.isfinite(lat) and math.isfinite(lon)):
                xy = (nan, nan)
            else:
                p = self.v.geo.to_local(lat, lon, self.v.geo.alt_m)
                xy = (p[0], p[1])
            z = self.v.alt_to_local(it.z, it.frame) \
                if math.isfinite(it.z) else nan
            return (xy[0], xy[1], z)
        if it.frame == mav.MAV_FRAME_LOCAL_NED:  # MISSION_ITEM_INT: x, y in m * 1e4
            return tuple(frames.ned_to_enu([it.x * 1e-4, it.y * 1e-4, it.z]) + self.v.origin)
        if it.frame == mav.MAV_FRAME_MISSION:
            return (nan, nan, nan)
        raise ValueError(f"item {it.seq}: frame {it.frame} not supported")

    def to_mission_item(self, it) -> MissionItem:
        nan = math.nan
        pos = self.position(it)
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

    def to_fence(self, items: list) -> Fence:
        """Fence items in order: a polygon is param1 consecutive vertices of one kind."""
        fence = Fence()
        k = 0
        while k < len(items):
            it = items[k]
            where = f"item {it.seq}"
            if it.command in _POLYGON_VERTICES:
                n = int(it.param1) if math.isfinite(it.param1) else 0
                group = items[k:k + n]
                if n < 3 or len(group) < n or any(g.command != it.command for g in group):
                    raise FenceError(f"{where}: a polygon of {it.param1:g} vertices needs "
                                     f"that many vertex items in a row")
                xy = [self.position(g)[:2] for g in group]
                fence.areas.append(polygon(xy, it.command ==
                                           mav.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION,
                                           where))
                k += n
                continue
            if it.command in _CIRCLES:
                fence.areas.append(circle(self.position(it)[:2], it.param1,
                                          it.command == mav.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION,
                                          where))
            elif it.command == mav.MAV_CMD_NAV_FENCE_RETURN_POINT:
                p = np.array(self.position(it))
                if not np.all(np.isfinite(p[:2])):
                    raise FenceError(f"{where}: the return point is not a finite position")
                fence.return_point = p
            else:
                raise FenceError(f"{where}: command {it.command} is not a fence item")
            k += 1
        return fence

    def to_rally_point(self, it) -> np.ndarray:
        if it.command != mav.MAV_CMD_NAV_RALLY_POINT:
            raise FenceError(f"item {it.seq}: command {it.command} is not a rally point")
        p = np.array(self.position(it))
        if not np.all(np.isfinite(p[:2])):
            raise FenceError(f"item {it.seq}: the rally point is not a finite position")
        if not math.isfinite(p[2]):
            p[2] = self.v.cmd.home[2]
        return p

    def fence_items(self, fence: Fence) -> list:
        """A fence's areas and return point as PX4 stores them: vertex and circle items in
        MAV_FRAME_GLOBAL, altitude 0."""
        items: list = []

        def add(command: int, xy, param1: float) -> None:
            lat, lon, _ = self.v.geo.to_global((float(xy[0]), float(xy[1]), 0.0))
            items.append(mav.MAVLink_mission_item_int_message(
                0, 0, len(items), mav.MAV_FRAME_GLOBAL, command, 0, 1, float(param1), 0.0,
                0.0, 0.0, deg_e7(lat), deg_e7(lon), 0.0, mav.MAV_MISSION_TYPE_FENCE))

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
