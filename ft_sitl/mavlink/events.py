"""Messages sent when something happens rather than at a rate: the commander's status
texts, mission items reached, changes of mission progress, and an orbit's status.

The commander only appends to its logs (``statustexts``, ``reached``); :class:`Events`
remembers how far it has sent each, so every entry goes out once, on every link.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mav

from ft_sitl.autopilot import commander as cm
from ft_sitl.mavlink.outgoing import Outgoing
from ft_sitl.mavlink.telemetry import Telemetry

#: ORBIT_EXECUTION_STATUS while orbiting, every (simulated) 0.5 s
ORBIT_STATUS_PERIOD_US = 500_000


class Events:
    """What one vehicle has to report since the last call of :meth:`events`."""

    def __init__(self, telemetry: Telemetry):
        self.telemetry = telemetry
        self.v = telemetry.v
        self._texts_sent = 0
        self._text_id = 0
        self._reached_sent = 0
        self._orbit_due_us = 0
        self._last_mission_current: tuple | None = None

    def texts(self) -> list[Outgoing]:
        """STATUSTEXTs for the commander's new texts (long ones in MAVLink 2 chunks)."""
        out = []
        t = list(self.v.cmd.statustexts)
        for severity, text in t[self._texts_sent:] if len(t) >= self._texts_sent else t:
            raw = text.encode("ascii", "replace")
            if len(raw) <= 50:
                out.append(Outgoing(mav.MAVLink_statustext_message(severity, raw)))
                continue
            # MAVLink 2 chunking: one id, chunk_seq 0.., a chunk shorter than 50 ends it
            self._text_id = self._text_id % 65535 + 1
            chunks = [raw[k:k + 50] for k in range(0, len(raw), 50)]
            if len(chunks[-1]) == 50:
                chunks.append(b"")
            for seq, chunk in enumerate(chunks):
                out.append(Outgoing(mav.MAVLink_statustext_message(
                    severity, chunk, self._text_id, seq)))
        self._texts_sent = len(t)
        if self.v.cmd.statustexts.maxlen and len(t) == self.v.cmd.statustexts.maxlen:
            self.v.cmd.statustexts.clear()
            self._texts_sent = 0
        return out

    def events(self) -> list[Outgoing]:
        """Status texts, reached items and mission progress changes since the last call."""
        out = self.texts()
        reached = list(self.v.cmd.reached)
        for seq in reached[self._reached_sent:]:
            out.append(Outgoing(self.telemetry.item_reached(seq)))
        self._reached_sent = len(reached)
        mc = self.telemetry.mission_current()
        key = (mc.seq, mc.total, mc.mission_state, mc.mission_mode)
        if key != self._last_mission_current:
            self._last_mission_current = key
            out.append(Outgoing(mc))
        c = self.v.cmd
        now = self.v.fleet.time_us
        if (c.main_mode, c.sub_mode) == (cm.MAIN_POSCTL, cm.SUB_POSCTL_ORBIT) and \
                now >= self._orbit_due_us and c.orbit_state is not None:
            self._orbit_due_us = now + ORBIT_STATUS_PERIOD_US
            center, radius, _, _, _ = c.orbit_state
            lat, lon, alt = self.v.geo.to_global(center)
            out.append(Outgoing(mav.MAVLink_orbit_execution_status_message(
                now, radius, mav.MAV_FRAME_GLOBAL_INT, int(round(lat * 1e7)),
                int(round(lon * 1e7)), alt)))
        return out
