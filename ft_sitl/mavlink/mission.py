"""The mission protocol for PX4's three item lists (mission, fence, rally points).

An upload is a transfer the vehicle drives: it requests item by item, re-requests after
MISSION_TIMEOUT_US of wall time without an answer, and gives up after MISSION_RETRIES. A
complete upload goes to the commander as a whole or is refused as a whole. Downloads
return the items as uploaded, so a client reads back exactly what it sent.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pymavlink.dialects.v20 import common as mav

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import Result
from ft_sitl.autopilot.geofence import Fence, FenceError, fits
from ft_sitl.mavlink.mission_items import GLOBAL_FRAMES, SUPPORTED_FRAMES, MissionItems, deg_e7
from ft_sitl.mavlink.outgoing import Outgoing
from ft_sitl.mavlink.telemetry import Telemetry

#: the mission protocol's item lists a vehicle keeps (PX4's three)
MISSION_TYPES = (mav.MAV_MISSION_TYPE_MISSION, mav.MAV_MISSION_TYPE_FENCE,
                 mav.MAV_MISSION_TYPE_RALLY)
MISSION_TIMEOUT_US = 1_500_000  # wall time between re-requests during a transfer
MISSION_RETRIES = 5


@dataclass
class _Transfer:
    """An upload in progress (client -> vehicle)."""

    count: int
    link: int
    peer: tuple
    items: list = field(default_factory=list)
    last_request_wall_us: int = 0
    retries: int = 0
    mission_type: int = 0


def _ack(m, result: int, link, peer, mission_type=0) -> Outgoing:
    return Outgoing(mav.MAVLink_mission_ack_message(
        m.get_srcSystem(), m.get_srcComponent(), result, mission_type), link, peer)


class MissionProtocol:
    """One vehicle's side of the mission protocol (MISSION_* messages)."""

    def __init__(self, items: MissionItems, telemetry: Telemetry):
        self.items = items
        self.telemetry = telemetry
        self.v = items.v
        self._upload: _Transfer | None = None
        self._upload_src: tuple = (0, 0)  # (sysid, compid) of the uploading client
        #: MISSION_ITEM_INT messages as uploaded, per mission type (mission, fence, rally)
        self._stored: dict[int, list] = {t: [] for t in MISSION_TYPES}
        #: the commander's fence as the last fence upload set it, and the items made for a
        #: fence it got otherwise (a trial's), with that fence (see _fence_download)
        self._fence_uploaded: Fence | None = None
        self._fence_made: tuple[Fence, list] | None = None

    # --- uploads ------------------------------------------------------------------------
    def on_count(self, m, link, peer, wall_us):
        mtype = getattr(m, "mission_type", 0)
        if mtype not in MISSION_TYPES:
            return [_ack(m, mav.MAV_MISSION_UNSUPPORTED, link, peer, mtype)]
        # (PX4 accepts a new mission while flying one; it restarts from item 0)
        if m.count == 0:
            self._apply_upload(mtype, [])
            return [_ack(m, mav.MAV_MISSION_ACCEPTED, link, peer, mtype)]
        full = m.count > 10000 if mtype == mav.MAV_MISSION_TYPE_MISSION else not fits(m.count)
        if full:
            return [_ack(m, mav.MAV_MISSION_NO_SPACE, link, peer, mtype)]
        self._upload = _Transfer(m.count, link, peer, last_request_wall_us=wall_us,
                                 mission_type=mtype)
        self._upload_src = (m.get_srcSystem(), m.get_srcComponent())
        return [self._request_item(0)]

    def _request_item(self, seq: int) -> Outgoing:
        up = self._upload
        sysid, compid = self._upload_src
        return Outgoing(mav.MAVLink_mission_request_int_message(sysid, compid, seq,
                                                                up.mission_type),
                        up.link, up.peer)

    def on_item(self, m, link, peer, wall_us):
        """Plain MISSION_ITEM (float x/y: degrees in the global frames, metres in the
        local ones), as MISSION_FLOAT is advertised: kept as its MISSION_ITEM_INT form."""
        if self._upload is None:
            return []
        if m.frame in GLOBAL_FRAMES:
            x, y = deg_e7(m.x), deg_e7(m.y)
        elif m.frame == mav.MAV_FRAME_LOCAL_NED:
            x, y = deg_e7(m.x * 1e-3), deg_e7(m.y * 1e-3)  # (m * 1e4, as _INT carries)
        else:
            x, y = deg_e7(m.x * 1e-7), deg_e7(m.y * 1e-7)
        as_int = mav.MAVLink_mission_item_int_message(
            m.target_system, m.target_component, m.seq, m.frame, m.command, m.current,
            m.autocontinue, m.param1, m.param2, m.param3, m.param4, x, y, m.z,
            getattr(m, "mission_type", 0))
        as_int._header = m._header
        return self.on_item_int(as_int, link, peer, wall_us)

    def on_item_int(self, m, link, peer, wall_us):
        up = self._upload
        if up is None:
            return []
        mtype = up.mission_type
        expected = len(up.items)
        if m.seq != expected:
            return [self._request_item(expected)]  # out of order: ask again for ours
        if m.frame not in SUPPORTED_FRAMES:  # PX4 answers this item at once
            self._upload = None
            self.v.cmd.text(cm.Severity.CRITICAL,
                          f"Mission rejected: item {m.seq}: frame {m.frame} unsupported"[:50])
            return [_ack(m, mav.MAV_MISSION_UNSUPPORTED_FRAME, link, peer, mtype)]
        up.items.append(m)
        up.last_request_wall_us = wall_us
        up.retries = 0
        if len(up.items) < up.count:
            return [self._request_item(len(up.items))]
        self._upload = None
        try:
            self._apply_upload(mtype, up.items)
        except (ValueError, FenceError) as exc:
            what = {mav.MAV_MISSION_TYPE_FENCE: "Fence",
                    mav.MAV_MISSION_TYPE_RALLY: "Rally points"}.get(mtype, "Mission")
            self.v.cmd.text(cm.Severity.CRITICAL, f"{what} rejected: {exc}"[:50])
            return [_ack(m, mav.MAV_MISSION_INVALID, link, peer, mtype)]
        return [_ack(m, mav.MAV_MISSION_ACCEPTED, link, peer, mtype)]

    def _apply_upload(self, mtype: int, items: list) -> None:
        """Hand a complete upload of one type to the commander (ValueError / FenceError:
        refused as a whole, nothing changed)."""
        if mtype == mav.MAV_MISSION_TYPE_MISSION:
            self.v.cmd.set_mission([self.items.to_mission_item(it) for it in items])
        elif mtype == mav.MAV_MISSION_TYPE_FENCE:
            self.v.cmd.set_fence(self.items.to_fence(items))
            self._fence_uploaded = self.v.cmd.fence
        else:
            self.v.cmd.set_rally([self.items.to_rally_point(it) for it in items])
        self._stored[mtype] = list(items)

    def poll(self, wall_us: int) -> list[Outgoing]:
        """Re-request the awaited item of a stalled upload; give it up after the retries."""
        up = self._upload
        if up is None or wall_us - up.last_request_wall_us < MISSION_TIMEOUT_US:
            return []
        up.retries += 1
        up.last_request_wall_us = wall_us
        if up.retries > MISSION_RETRIES:
            self._upload = None
            self.v.cmd.text(cm.Severity.WARNING, "Mission upload timed out")
            sysid, compid = self._upload_src
            return [Outgoing(mav.MAVLink_mission_ack_message(
                sysid, compid, mav.MAV_MISSION_OPERATION_CANCELLED, up.mission_type), up.link,
                up.peer)]
        return [self._request_item(len(up.items))]

    # --- downloads ----------------------------------------------------------------------
    def _download(self, mtype: int) -> list | None:
        """The items a download of ``mtype`` returns (None: not a type we keep)."""
        if mtype == mav.MAV_MISSION_TYPE_FENCE:
            return self._fence_download()
        return self._stored.get(mtype)

    def _fence_download(self) -> list:
        """The fence items: as uploaded; for a fence the commander got otherwise (a
        trial's ``fence``, set before the first step, as PX4 loads a fence file at boot
        into the store a download reads), made from it once per fence."""
        fence = self.v.cmd.fence
        if fence is self._fence_uploaded:
            return self._stored[mav.MAV_MISSION_TYPE_FENCE]
        if self._fence_made is None or self._fence_made[0] is not fence:
            self._fence_made = (fence, self.items.fence_items(fence))
        return self._fence_made[1]

    def _current_seq(self) -> int:
        """The sequence number on the wire of the mission item in progress."""
        return self.v.cmd.mission_seq

    def on_request_list(self, m, link, peer, wall_us):
        mtype = getattr(m, "mission_type", 0)
        count = len(self._download(mtype) or [])
        return [Outgoing(mav.MAVLink_mission_count_message(
            m.get_srcSystem(), m.get_srcComponent(), count, mtype), link, peer)]

    def on_request(self, m, link, peer, wall_us):
        mtype = getattr(m, "mission_type", 0)
        stored = self._download(mtype)
        if stored is None:
            return []
        if not 0 <= m.seq < len(stored):
            return [_ack(m, mav.MAV_MISSION_INVALID_SEQUENCE, link, peer, mtype)]
        it = stored[m.seq]
        current = 1 if mtype == mav.MAV_MISSION_TYPE_MISSION and it.seq == self._current_seq() \
            else 0
        return [Outgoing(mav.MAVLink_mission_item_int_message(
            m.get_srcSystem(), m.get_srcComponent(), it.seq, it.frame, it.command,
            current, it.autocontinue, it.param1, it.param2,
            it.param3, it.param4, it.x, it.y, it.z, mtype), link, peer)]

    # --- the rest -----------------------------------------------------------------------
    def on_clear_all(self, m, link, peer, wall_us):
        mtype = getattr(m, "mission_type", 0)
        cleared = MISSION_TYPES if mtype == mav.MAV_MISSION_TYPE_ALL else \
            (mtype,) if mtype in MISSION_TYPES else ()
        for t in cleared:
            self._apply_upload(t, [])
        if cleared:
            self._upload = None
        return [_ack(m, mav.MAV_MISSION_ACCEPTED, link, peer, mtype)]

    def on_set_current(self, m, link, peer, wall_us):
        if self.v.cmd.set_mission_current(m.seq) != Result.ACCEPTED:
            self.v.cmd.text(cm.Severity.WARNING, f"Mission item {m.seq} does not exist")
        return [Outgoing(self.telemetry.mission_current())]

    def on_ack(self, m, link, peer, wall_us):
        return []
