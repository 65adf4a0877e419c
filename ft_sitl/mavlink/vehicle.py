"""The vehicle every piece of one agent speaks for: which one of the fleet, where its
world is on the globe, and where its local frame starts.

Each piece (telemetry, commands, mission, ...) holds this one object instead of its own
copies of the fleet, index and commander, and reads the wire's altitudes through it, so
commands, mission items and offboard setpoints agree on what an altitude means.
"""

from __future__ import annotations

import numpy as np
from pymavlink.dialects.v20 import common as mav

from ft_sitl import frames
from ft_sitl.autopilot import commander as cm
from ft_sitl.sim.fleet import Fleet


class Vehicle:
    """Vehicle ``index`` of ``fleet`` (MAVLink system id index + 1) on the wire, its
    local ENU frame placed on the globe by ``geo``."""

    def __init__(self, fleet: Fleet, index: int, geo: frames.GeoReference):
        self.fleet = fleet
        self.index = index
        self.sysid = index + 1
        self.geo = geo
        self.cmd: cm.Commander = fleet.commanders[index]
        self.params = fleet.params[index]
        #: the local frame's origin (ENU): PX4 SITL starts each instance's local frame
        #: where it spawned, so LOCAL_NED positions are relative to it
        self.origin = np.asarray(self.cmd.home, dtype=float).copy()

    def alt_to_local(self, alt: float, frame: int) -> float:
        """A wire altitude as a local ENU z: relative to home in the RELATIVE_ALT frames,
        AMSL in every other one."""
        if frame in (mav.MAV_FRAME_GLOBAL_RELATIVE_ALT, mav.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT):
            return self.cmd.home[2] + alt
        return alt - self.geo.alt_m
