"""QGC WPL 110 ``.waypoints`` files, the mission files of MAVProxy, Mission Planner and
ArduPilot's autotest: a first line ``QGC WPL 110``, then one item a line, twelve fields
separated by tabs (or spaces): index, current, frame, command, param1..4, x (latitude in
degrees in the global frames), y (longitude), z (altitude) and autocontinue. Item 0 is
home, as ArduCopter numbers its mission (:mod:`ft_sitl.mavlink.ardupilot.mission`).

Items are read as the MISSION_ITEM_INT messages an upload carries (degE7 in the global
frames, metres * 1e4 in LOCAL_NED), so a file loads exactly as a ground station's upload
of it would.
"""

from __future__ import annotations

import math
from pathlib import Path

from pymavlink.dialects.v20 import ardupilotmega as apm

from ft_sitl.mavlink.mission_items import GLOBAL_FRAMES, SUPPORTED_FRAMES, deg_e7

HEADER = "QGC WPL 110"
_FIELDS = 12


class WaypointsError(ValueError):
    """A file that is not a valid QGC WPL 110 mission (the message names file and line)."""


def _xy_int(frame: int, v: float) -> int:
    if frame in GLOBAL_FRAMES:
        return deg_e7(v)
    if frame == apm.MAV_FRAME_LOCAL_NED:
        return deg_e7(v * 1e-3)  # (m * 1e4, as MISSION_ITEM_INT carries LOCAL_NED)
    return 0


def _xy_float(frame: int, v: int) -> float:
    if frame in GLOBAL_FRAMES:
        return v * 1e-7
    if frame == apm.MAV_FRAME_LOCAL_NED:
        return v * 1e-4
    return 0.0


def parse(text: str, name: str = "<waypoints>") -> list:
    """The items of a QGC WPL 110 text, in order (WaypointsError: the first bad line)."""
    lines = text.splitlines()
    if not lines or lines[0].strip() != HEADER:
        raise WaypointsError(f"{name}:1: the first line must be '{HEADER}' "
                             f"(got {lines[0].strip()[:40]!r})" if lines else
                             f"{name}:1: empty file, expected '{HEADER}'")
    items = []
    for n, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        f = line.split()
        if len(f) != _FIELDS:
            raise WaypointsError(f"{name}:{n}: {len(f)} fields, a QGC WPL 110 item has "
                                 f"{_FIELDS} (index current frame command p1 p2 p3 p4 x y "
                                 f"z autocontinue)")
        try:
            seq, current, frame, command = (int(v) for v in f[:4])
            p = [float(v) for v in f[4:11]]
            autocontinue = int(float(f[11]))
        except ValueError:
            raise WaypointsError(f"{name}:{n}: index, current, frame, command and "
                                 f"autocontinue must be integers, the params numbers") \
                from None
        if seq != len(items):
            raise WaypointsError(f"{name}:{n}: index {seq}, expected {len(items)} (items "
                                 f"are numbered from 0, home, in order)")
        if frame not in SUPPORTED_FRAMES:
            raise WaypointsError(f"{name}:{n}: frame {frame} is not supported (allowed: "
                                 f"{', '.join(str(x) for x in sorted(SUPPORTED_FRAMES))})")
        if not 0 <= command <= 65535:
            raise WaypointsError(f"{name}:{n}: command {command} must be within 0..65535")
        if not all(math.isfinite(v) for v in p):
            raise WaypointsError(f"{name}:{n}: params must be finite numbers")
        items.append(apm.MAVLink_mission_item_int_message(
            0, 0, seq, frame, command, 1 if current else 0, 1 if autocontinue else 0,
            *p[:4], _xy_int(frame, p[4]), _xy_int(frame, p[5]), p[6],
            apm.MAV_MISSION_TYPE_MISSION))
    if not items:
        raise WaypointsError(f"{name}:1: no items (item 0, home, at least)")
    return items


def read(path: Path) -> list:
    """The items of a ``.waypoints`` file (WaypointsError: naming the file and line)."""
    try:
        text = Path(path).read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise WaypointsError(f"{path}: cannot read: {getattr(exc, 'strerror', exc)}") \
            from None
    return parse(text, str(path))


def dumps(items: list) -> str:
    """MISSION_ITEM_INT messages as a QGC WPL 110 text."""
    out = [HEADER]
    for k, it in enumerate(items):
        fields = [k, it.current, it.frame, it.command, it.param1, it.param2, it.param3,
                  it.param4, _xy_float(it.frame, it.x), _xy_float(it.frame, it.y), it.z,
                  it.autocontinue]
        out.append("\t".join(f"{v:.8f}" if isinstance(v, float) else str(v)
                             for v in fields))
    return "\n".join(out) + "\n"


def write(path: Path, items: list) -> None:
    Path(path).write_text(dumps(items))
