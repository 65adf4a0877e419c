"""ArduCopter's fence (libraries/AC_Fence/AC_Fence.cpp) over the flight controller's
geofence, which keeps the one rule of what breaches (:mod:`ft_sitl.autopilot.geofence`).

FENCE_ENABLE turns the fence on; FENCE_TYPE picks its kinds (bitmask: 1 maximum altitude
FENCE_ALT_MAX, 2 circle FENCE_RADIUS around home, 4 the polygons and circles uploaded
over the mission protocol's FENCE list, 8 minimum altitude); FENCE_ACTION is what a breach
does. The altitude and circle limits reach the controller as GF_MAX_VER_DIST /
GF_MAX_HOR_DIST (:func:`.params.fence_px4`); the uploaded areas reach it only while the
fence is on with kind 4 (ArduPilot keeps them stored either way: a download reads them).

SYS_STATUS's MAV_SYS_STATUS_GEOFENCE bits as AC_Fence sets them (sys_status_present,
_enabled, _failed): present when a kind is configured (the polygon kind only with areas
uploaded), enabled when present, on and not report-only, healthy unless present and
breached. The health bit is set with no fence at all: a ground station (MAVProxy's fence
module) reads a missing health bit as "fence breach". FENCE_STATUS goes out while a fence
is present and FENCE_ENABLE is on.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.autopilot.geofence import Fence

if TYPE_CHECKING:  # the vehicle owns this object; only its type is needed here
    from ft_sitl.mavlink.ardupilot.agent import ArduCopterVehicle

#: FENCE_TYPE's bits (AC_FENCE_TYPE_*)
ALT_MAX, CIRCLE, POLYGON, ALT_MIN = 1, 2, 4, 8
#: FENCE_ACTION's report-only value
REPORT_ONLY = 0


class ArduCopterFence:
    """One vehicle's fence: the areas last uploaded, and what the controller flies."""

    def __init__(self, v: ArduCopterVehicle):
        self.v = v
        #: the polygons and circles of the last FENCE upload (kept whatever FENCE_ENABLE)
        self.uploaded = Fence()
        #: the fence the controller gets while the uploaded areas are off
        self._off = Fence()
        v.ap_params.on_fence = self.apply

    def upload(self, fence: Fence) -> None:
        """A complete FENCE upload (checked by the caller)."""
        self.uploaded = fence
        self.apply()

    @property
    def areas_on(self) -> bool:
        ap = self.v.ap_params
        return bool(ap["FENCE_ENABLE"]) and bool(int(ap["FENCE_TYPE"]) & POLYGON)

    def apply(self) -> None:
        """Give the controller the uploaded areas while the fence is on with kind 4, none
        otherwise (after an upload and every FENCE_* change)."""
        want = self.uploaded if self.areas_on else self._off
        if self.v.cmd.fence is not want:
            self.v.cmd.set_fence(want)

    def owns(self, fence: Fence) -> bool:
        """Whether ``fence`` (the controller's) is one this face gave it."""
        return fence is self.uploaded or fence is self._off

    # --- what the wire reports -------------------------------------------------------------
    @property
    def present(self) -> bool:
        kinds = int(self.v.ap_params["FENCE_TYPE"])
        return bool(kinds & (ALT_MAX | CIRCLE | ALT_MIN)) or \
            (bool(kinds & POLYGON) and not self.uploaded.empty)

    @property
    def enabled(self) -> bool:
        ap = self.v.ap_params
        return self.present and bool(ap["FENCE_ENABLE"]) and \
            int(ap["FENCE_ACTION"]) != REPORT_ONLY

    @property
    def breached(self) -> bool:
        return self.present and self.v.cmd.fence_breached

    def sys_status_bits(self, present: int, enabled: int, health: int) -> tuple[int, int, int]:
        """SYS_STATUS's three sensor words with the geofence bit as ArduPilot sets it."""
        bit = apm.MAV_SYS_STATUS_GEOFENCE
        present, enabled, health = present & ~bit, enabled & ~bit, health & ~bit
        if self.present:
            present |= bit
        if self.enabled:
            enabled |= bit
        if not self.breached:
            health |= bit
        return present, enabled, health

    def status(self) -> apm.MAVLink_fence_status_message | None:
        """FENCE_STATUS (GCS_MAVLINK::send_fence_status) while a fence is present and
        FENCE_ENABLE is on (none with the fence off): breached now, breaches so far, the
        last one's kind and time (ms since boot)."""
        if not self.present or not self.v.ap_params["FENCE_ENABLE"]:
            return None
        events = self.v.cmd.fence_events
        kind, t_ms = apm.FENCE_BREACH_NONE, 0
        if events:
            t_us, reason, _ = events[-1]
            kind = apm.FENCE_BREACH_MAXALT if "above home" in reason else \
                apm.FENCE_BREACH_BOUNDARY
            t_ms = t_us // 1000
        return apm.MAVLink_fence_status_message(
            int(self.breached), min(len(events), 65535), kind, t_ms & 0xFFFFFFFF,
            apm.FENCE_MITIGATE_UNKNOWN)
