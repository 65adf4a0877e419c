"""A failed test's flight from its telemetry log: each vehicle's LOCAL_POSITION_NED as a top
view (east, north) and height over time, drawn to a PNG, and one summary line per vehicle.

Positions are each vehicle's own local frame (PX4's: metres from where it spawned), as its
clients see them. Drawn with matplotlib's object API on the Agg canvas, never pyplot, so
the user's pyplot state and backend are left alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from pymavlink import mavutil

#: MAV_COMP_ID_AUTOPILOT1: the vehicles' component (clients' own messages are skipped)
AUTOPILOT = 1
DPI = 100


@dataclass
class Track:
    """One vehicle's local positions: time (s since boot), north, east, height (m)."""

    sysid: int
    t_s: list[float] = field(default_factory=list)
    north: list[float] = field(default_factory=list)
    east: list[float] = field(default_factory=list)
    up: list[float] = field(default_factory=list)

    def summary(self) -> str:
        if not self.t_s:
            return f"vehicle sysid {self.sysid}: no position in the log"
        return (f"vehicle sysid {self.sysid}: {len(self.t_s)} positions over "
                f"{self.t_s[0]:.1f}..{self.t_s[-1]:.1f} s; last N {self.north[-1]:.2f} "
                f"E {self.east[-1]:.2f} height {self.up[-1]:.2f} m; highest "
                f"{max(self.up):.2f} m")


def read_tracks(tlog: Path) -> dict[int, Track]:
    """Each vehicle's LOCAL_POSITION_NED from a telemetry log, in time order (the log holds
    every link's copy: a time already seen is skipped)."""
    tracks: dict[int, Track] = {}
    seen: dict[int, set[int]] = {}
    log = mavutil.mavlink_connection(str(tlog), dialect="common")
    try:
        while (m := log.recv_match(type="LOCAL_POSITION_NED")) is not None:
            if m.get_srcComponent() != AUTOPILOT:
                continue
            sysid = m.get_srcSystem()
            if m.time_boot_ms in seen.setdefault(sysid, set()):
                continue
            seen[sysid].add(m.time_boot_ms)
            tr = tracks.setdefault(sysid, Track(sysid))
            tr.t_s.append(m.time_boot_ms / 1000.0)
            tr.north.append(m.x)
            tr.east.append(m.y)
            tr.up.append(-m.z)
    finally:
        log.close()
    for tr in tracks.values():
        order = sorted(range(len(tr.t_s)), key=tr.t_s.__getitem__)
        for name in ("t_s", "north", "east", "up"):
            values = getattr(tr, name)
            setattr(tr, name, [values[i] for i in order])
    return dict(sorted(tracks.items()))


def plot_flight(tlog: Path, png: Path, title: str) -> list[str]:
    """Draw the log's flight to ``png``; returns one summary line per vehicle."""
    tracks = read_tracks(tlog)
    fig = Figure(figsize=(11, 4.8), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    top, height = fig.subplots(1, 2, width_ratios=[1, 1.3])
    for tr in tracks.values():
        line, = top.plot(tr.east, tr.north, lw=1.4, label=f"sysid {tr.sysid}")
        if tr.t_s:
            top.plot(tr.east[0], tr.north[0], "o", color=line.get_color(), ms=6)
            top.plot(tr.east[-1], tr.north[-1], "x", color=line.get_color(), ms=8, mew=2)
        height.plot(tr.t_s, tr.up, lw=1.4, color=line.get_color(), label=f"sysid {tr.sysid}")
    top.set(xlabel="east (m)", ylabel="north (m)",
            title="top view (o start, x end; each vehicle's local frame)")
    top.set_aspect("equal", adjustable="datalim")
    top.grid(alpha=0.3)
    height.set(xlabel="time since boot (simulated s)", ylabel="height above spawn (m)",
               title="height")
    height.grid(alpha=0.3)
    if tracks:
        height.legend(loc="best", fontsize=8)
    else:
        top.text(0.5, 0.5, "no LOCAL_POSITION_NED in the log", ha="center",
                 transform=top.transAxes)
    fig.suptitle(title, fontsize=10)
    fig.savefig(png)
    return [tr.summary() for tr in tracks.values()]
