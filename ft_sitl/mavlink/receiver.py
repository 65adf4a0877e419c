"""Incoming messages that are one call into the vehicle: SET_MODE, TIMESYNC,
FOLLOW_TARGET and MANUAL_CONTROL. None of them keeps protocol state of its own."""

from __future__ import annotations

import math

import numpy as np
from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.mavlink.outgoing import Outgoing
from ft_sitl.mavlink.vehicle import Vehicle

#: FOLLOW_TARGET fixes used: within this distance of home, altitudes (AMSL) in this range
#: and speeds up to this (others: ignored, or the altitude / velocity taken as unknown)
FOLLOW_MAX_RANGE_M, FOLLOW_ALT_RANGE_M, FOLLOW_MAX_SPEED_M_S = 100_000.0, (-500.0, 10_000.0), 100.0


class Receiver:
    """One vehicle's stateless inputs."""

    def __init__(self, vehicle: Vehicle):
        self.v = vehicle

    def on_set_mode(self, m, link, peer, wall_us):
        if m.target_system != self.v.sysid:
            return []
        main = (m.custom_mode >> 16) & 0xFF
        sub = (m.custom_mode >> 24) & 0xFF
        self.v.cmd.set_mode(main, sub)
        return []

    def on_timesync(self, m, link, peer, wall_us):
        if m.tc1 != 0:
            return []
        # tc1 = 0 would read as a request: at simulated time 0 answer 1 ns
        return [Outgoing(mav.MAVLink_timesync_message(max(1, self.v.fleet.time_us * 1000), m.ts1),
                         link, peer)]

    def on_follow_target(self, m, link, peer, wall_us):
        """FOLLOW_TARGET (a follow-me client's position fix): lat/lon degE7, alt AMSL,
        vel NED. Used as PX4's mavlink receiver does, in any mode (the estimate is for
        AUTO.FOLLOW_TARGET); a fix without a usable position is ignored, an absurd
        altitude or velocity is taken as unknown. A velocity counts when est_capabilities
        says so (bit 1) or any of it is non-zero: MAVSDK sends zeros with only the
        position bit set."""
        lat, lon = m.lat * 1e-7, m.lon * 1e-7
        if (m.lat == 0 and m.lon == 0) or not (abs(lat) <= 90.0 and abs(lon) <= 180.0):
            return []
        pos = self.v.geo.to_local(lat, lon, self.v.geo.alt_m)
        if not np.all(np.isfinite(pos)) or np.hypot(*(pos[:2] - self.v.cmd.home[:2])) \
                > FOLLOW_MAX_RANGE_M:
            return []
        alt = float(m.alt)
        pos[2] = alt - self.v.geo.alt_m if math.isfinite(alt) and \
            FOLLOW_ALT_RANGE_M[0] <= alt <= FOLLOW_ALT_RANGE_M[1] else math.nan
        vel = [float(v) for v in m.vel]
        use_vel = all(math.isfinite(v) and abs(v) <= FOLLOW_MAX_SPEED_M_S for v in vel) \
            and (m.est_capabilities & 2 or any(v != 0.0 for v in vel))
        self.v.cmd.follow_target_measurement(
            self.v.fleet.time_us, pos, frames.ned_to_enu(np.array(vel)) if use_vel else None)
        return []

    def on_manual_control(self, m, link, peer, wall_us):
        """MANUAL_CONTROL as PX4's mavlink receiver reads it: x pitch, y roll, r yaw in
        -1000..1000, z throttle in 0..1000, for target 0 or this system; values beyond
        are clamped (the fields are int16, never NaN)."""
        if m.target not in (0, self.v.sysid):
            return []
        self.v.fleet.manual_control(self.v.index, m.x / 1000.0, m.y / 1000.0, m.z / 1000.0,
                                  m.r / 1000.0)
        return []
