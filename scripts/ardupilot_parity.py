"""Parity of ft-sitl's ArduCopter face with a real ArduCopter SITL (issue 46): the same
pymavlink session against either, observations written as JSON, the two compared.

The session (``observe``), over one TCP connection to SERIAL0, in this order:

1. the first HEARTBEAT (type, autopilot, base_mode, custom_mode, system_status, ids) and
   what streams with the default SRn_* rates (nothing asked: 6 wall seconds);
2. AUTOPILOT_VERSION by MAV_CMD_REQUEST_MESSAGE;
3. arming in LAND (not armable), then an early arming attempt in GUIDED (PreArm texts;
   disarmed again if it armed);
4. mode changes on the ground, disarmed, with no mission: MAV_CMD_DO_SET_MODE for
   GUIDED, LOITER, ALT_HOLD, RTL, LAND, AUTO, BRAKE, STABILIZE (COMMAND_ACK, the
   HEARTBEAT after, STATUSTEXTs), the SET_MODE message, and an unknown mode number;
5. REQUEST_DATA_STREAM(ALL, 4 Hz): the message set and rates (by the vehicle's own
   time_boot_ms, over 10 wall seconds);
6. the parameter list (count, every name with type and value) and PARAM_SET answers: a
   good value, an out-of-range value, an unknown name;
7. a mission upload with home at 0 (home placeholder, NAV_TAKEOFF, NAV_WAYPOINT,
   NAV_RETURN_TO_LAUNCH: the vehicle's requests and its MISSION_ACK), its download
   (count and each item), AUTO on the ground with the mission, MISSION_CLEAR_ALL;
8. arming in LAND again (the estimator settled by now), arming in GUIDED (retried until
   accepted), a GUIDED take-off to 5 m (MAV_CMD_NAV_TAKEOFF), a 10 m goto east
   (SET_POSITION_TARGET_LOCAL_NED, position only, yaw ignored), then BRAKE (3 s), RTL
   (6 s), LOITER (5 s), each timed by the vehicle's clock (time_boot_ms), LAND until
   disarmed.

Every STATUSTEXT of the session is kept in order.

    .venv/bin/python scripts/ardupilot_parity.py observe tcp:127.0.0.1:5810 \\
        --label arducopter --out real.json
    .venv/bin/python scripts/ardupilot_parity.py compare real.json ours.json > parity.md
    .venv/bin/python scripts/ardupilot_parity.py run --arducopter BUILD/bin/arducopter \\
        --defaults ARDUPILOT/Tools/autotest/default_params/copter.parm --out DIR

``run`` starts the given ``arducopter --model quad`` (ArduPilot's own multicopter physics)
on the first free instance number from 5 (TCP 5760+10k, its lock file held meanwhile),
observes it, stops it, then starts ``ft-sitl sitl --autopilot ardupilot --instance auto``,
observes that, and writes DIR/arducopter.json, DIR/ft-sitl.json and DIR/parity.md. Both
fly from the same home (PX4 SITL's) at speed 1. Nothing of ArduPilot is part of ft-sitl:
the binary is one the user built.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

import ft_sitl  # noqa: F401  (first: the numeric pins before numpy loads)

os.environ.setdefault("MAVLINK20", "1")
from pymavlink import mavutil  # noqa: E402

from ft_sitl.mavlink.ardupilot.server import (  # noqa: E402
    serial_ports_free,
    tcp_port_free,
    tcp_ports,
)
from ft_sitl.mavlink.instances import free_instances  # noqa: E402

M = mavutil.mavlink
#: the home both sides fly from (PX4 SITL's default, ft-sitl's default)
HOME = (47.397742, 8.545594, 488.0)
#: ArduCopter's mode numbers the session switches to (ArduCopter/mode.h)
MODES = {"GUIDED": 4, "LOITER": 5, "ALT_HOLD": 2, "RTL": 6, "LAND": 9, "AUTO": 3,
         "BRAKE": 17, "STABILIZE": 0}
#: the parameters whose type and value the comparison shows
SAMPLE_PARAMS = ("SYSID_THISMAV", "FRAME_CLASS", "WPNAV_SPEED", "WPNAV_SPEED_UP",
                 "WPNAV_SPEED_DN", "WPNAV_ACCEL", "WPNAV_RADIUS", "PSC_POSXY_P",
                 "PSC_VELXY_P", "PSC_POSZ_P", "ANGLE_MAX", "RTL_ALT", "RTL_SPEED",
                 "RTL_LOIT_TIME", "RTL_ALT_FINAL", "LAND_SPEED", "PILOT_SPEED_UP",
                 "GUID_TIMEOUT", "FENCE_ENABLE", "FENCE_TYPE", "FENCE_ALT_MAX",
                 "FENCE_RADIUS", "FENCE_ACTION", "ARMING_CHECK", "DISARM_DELAY",
                 "FS_THR_ENABLE", "FS_GCS_ENABLE", "BATT_MONITOR", "SR0_POSITION",
                 "SR0_EXTRA1", "SR1_POSITION", "WP_YAW_BEHAVIOR")
PARAM_TYPES = {M.MAV_PARAM_TYPE_INT8: "INT8", M.MAV_PARAM_TYPE_INT16: "INT16",
               M.MAV_PARAM_TYPE_INT32: "INT32", M.MAV_PARAM_TYPE_REAL32: "REAL32",
               M.MAV_PARAM_TYPE_UINT8: "UINT8", M.MAV_PARAM_TYPE_UINT16: "UINT16",
               M.MAV_PARAM_TYPE_UINT32: "UINT32"}


def _result(r: int | None) -> str | None:
    return None if r is None else M.enums["MAV_RESULT"][r].name.removeprefix("MAV_RESULT_")


class Session:
    """One pymavlink connection; every message received is seen by :meth:`pump`, which
    keeps the STATUSTEXTs and the latest of each type."""

    def __init__(self, url: str):
        self.conn = mavutil.mavlink_connection(url, source_system=250, source_component=190,
                                               dialect="ardupilotmega", autoreconnect=False)
        self.texts: list[tuple[float, str]] = []
        self.latest: dict[str, object] = {}
        self.t0 = time.monotonic()

    @property
    def ts(self) -> tuple[int, int]:
        return self.conn.target_system, self.conn.target_component

    def now(self) -> float:
        return round(time.monotonic() - self.t0, 2)

    def recv(self, timeout_s: float):
        m = self.conn.recv_match(blocking=True, timeout=timeout_s)
        if m is None or m.get_type() == "BAD_DATA":
            return None
        self.latest[m.get_type()] = m
        if m.get_type() == "STATUSTEXT":
            self.texts.append((self.now(), m.text))
        return m

    def pump(self, seconds: float, on=lambda m: None) -> None:
        """Read for ``seconds`` wall seconds, handing each message to ``on``."""
        end = time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            m = self.recv(min(left, 0.5))
            if m is not None:
                on(m)

    def wait(self, types, what=lambda m: True, timeout_s: float = 10.0):
        """The first message of ``types`` for which ``what`` holds, or None."""
        types = {types} if isinstance(types, str) else set(types)
        end = time.monotonic() + timeout_s
        while (left := end - time.monotonic()) > 0:
            m = self.recv(min(left, 0.5))
            if m is not None and m.get_type() in types and what(m):
                return m
        return None

    def texts_since(self, t: float) -> list[str]:
        return [s for ts, s in self.texts if ts >= t]

    def command(self, cmd: int, *params: float, timeout_s: float = 5.0) -> str | None:
        p = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(*self.ts, cmd, 0, *p)
        ack = self.wait("COMMAND_ACK", lambda m: m.command == cmd, timeout_s)
        return _result(None if ack is None else ack.result)

    def set_mode(self, number: int, message: bool = False) -> dict:
        """MAV_CMD_DO_SET_MODE by COMMAND_LONG (pymavlink's set_mode for ArduPilot, and
        MAVProxy's), or the SET_MODE message: the ack, the HEARTBEAT after, the texts."""
        t = self.now()
        flag = M.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if message:
            self.conn.mav.set_mode_send(self.conn.target_system, flag, number)
            ack = self.wait("COMMAND_ACK", lambda m: m.command in (
                M.MAVLINK_MSG_ID_SET_MODE, M.MAV_CMD_DO_SET_MODE), 3.0)
            ack = None if ack is None else f"{_result(ack.result)} (command {ack.command})"
        else:
            ack = self.command(M.MAV_CMD_DO_SET_MODE, flag, number)
        hb = self.heartbeat(2.5)
        return {"ack": ack,
                "custom_mode": None if hb is None else hb.custom_mode,
                "base_mode": None if hb is None else hb.base_mode,
                "texts": self.texts_since(t)}

    def heartbeat(self, timeout_s: float = 3.0):
        """The vehicle's next HEARTBEAT after a fresh one (so it reflects what was sent)."""
        sysid = self.conn.target_system
        self.wait("HEARTBEAT", lambda m: m.get_srcSystem() == sysid, timeout_s)
        return self.wait("HEARTBEAT", lambda m: m.get_srcSystem() == sysid, timeout_s)

    def arm(self, arm: bool = True, force: bool = False) -> dict:
        t = self.now()
        r = self.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0 if arm else 0.0,
                         (2989.0 if arm else 21196.0) if force else 0.0)
        self.pump(1.0)
        return {"ack": r, "texts": self.texts_since(t)}

    def armed(self) -> bool:
        hb = self.heartbeat()
        return bool(hb is not None and hb.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED)


def rates(s: Session, seconds: float) -> dict:
    """Each message type's rate over ``seconds`` wall seconds, per second of the vehicle's
    own clock (time_boot_ms of the timestamped messages; wall seconds when none came)."""
    counts: dict[str, int] = {}
    boot = []

    def on(m):
        if m.get_srcSystem() != s.conn.target_system:
            return
        counts[m.get_type()] = counts.get(m.get_type(), 0) + 1
        if hasattr(m, "time_boot_ms"):
            boot.append(m.time_boot_ms)

    t = time.monotonic()
    s.pump(seconds, on)
    wall = time.monotonic() - t
    span = (max(boot) - min(boot)) / 1000.0 if len(boot) > 1 else 0.0
    clock, base = ("vehicle", span) if span > 0.5 * seconds else ("wall", wall)
    return {"clock": clock, "seconds": round(base, 2),
            "hz": {k: round(v / base, 1) for k, v in sorted(counts.items())}}


def params(s: Session) -> dict:
    """PARAM_REQUEST_LIST: the count the vehicle says and every parameter received (the
    indices missing after a 2 s lull asked for once by PARAM_REQUEST_READ, as MAVProxy
    does)."""
    got: dict[str, tuple[str, float]] = {}
    said, seen = [], set()

    def on(m):
        if m.get_type() == "PARAM_VALUE":
            got[m.param_id] = (PARAM_TYPES.get(m.param_type, str(m.param_type)), m.param_value)
            said.append(m.param_count)
            seen.add(m.param_index)

    s.conn.mav.param_request_list_send(*s.ts)
    last, retried, end = -1, False, time.monotonic() + 180.0
    while time.monotonic() < end and (not said or len(got) < said[-1]):
        s.pump(2.0, on)
        if len(got) == last:
            if retried or not said:
                break
            for i in sorted(set(range(said[-1])) - seen):
                s.conn.mav.param_request_read_send(*s.ts, b"", i)
            retried = True
        last = len(got)
    return {"param_count": said[-1] if said else None, "received": len(got),
            "all": {k: list(v) for k, v in sorted(got.items())}}


def param_set(s: Session, name: str, value: float, type_: int) -> dict:
    """PARAM_SET: the PARAM_VALUE answer (or none within 3 s) and the texts."""
    t = s.now()
    s.conn.mav.param_set_send(*s.ts, name.encode(), value, type_)
    m = s.wait("PARAM_VALUE", lambda m: m.param_id == name, 3.0)
    s.pump(0.5)
    return {"sent": value, "answer": None if m is None else m.param_value,
            "texts": s.texts_since(t)}


def upload(s: Session, items: list[tuple]) -> dict:
    """Mission upload, vehicle-driven: what the vehicle asks for and its MISSION_ACK."""
    s.conn.mav.mission_count_send(*s.ts, len(items), M.MAV_MISSION_TYPE_MISSION)
    asked = []
    end = time.monotonic() + 30.0
    ack = None
    while time.monotonic() < end:
        m = s.wait(("MISSION_REQUEST", "MISSION_REQUEST_INT", "MISSION_ACK"), timeout_s=3.0)
        if m is None:
            break
        if m.get_type() == "MISSION_ACK":
            ack = M.enums["MAV_MISSION_RESULT"][m.type].name
            break
        asked.append([m.get_type(), m.seq])
        frame, cmd, p1, p2, p3, p4, lat, lon, alt = items[m.seq]
        s.conn.mav.mission_item_int_send(*s.ts, m.seq, frame, cmd, 0, 1, p1, p2, p3, p4,
                                         lat, lon, alt, M.MAV_MISSION_TYPE_MISSION)
    return {"requests": asked, "ack": ack}


def download(s: Session) -> dict:
    s.conn.mav.mission_request_list_send(*s.ts, M.MAV_MISSION_TYPE_MISSION)
    c = s.wait("MISSION_COUNT", timeout_s=5.0)
    if c is None:
        return {"count": None, "items": []}
    items = []
    for seq in range(c.count):
        s.conn.mav.mission_request_int_send(*s.ts, seq, M.MAV_MISSION_TYPE_MISSION)
        m = s.wait("MISSION_ITEM_INT", lambda m, q=seq: m.seq == q, 5.0)
        items.append(None if m is None else
                     {"seq": m.seq, "frame": m.frame, "command": m.command,
                      "current": m.current, "autocontinue": m.autocontinue,
                      "params": [round(p, 3) for p in (m.param1, m.param2, m.param3,
                                                       m.param4)],
                      "x": m.x, "y": m.y, "z": round(m.z, 2)})
    s.conn.mav.mission_ack_send(*s.ts, M.MAV_MISSION_ACCEPTED, M.MAV_MISSION_TYPE_MISSION)
    return {"count": c.count, "items": items}


def position(s: Session):
    return s.wait("GLOBAL_POSITION_INT", lambda m: m.get_srcSystem() == s.conn.target_system,
                  5.0)


def flight(s: Session) -> dict:
    """Arm in GUIDED (retried), take off to 5 m, a 10 m goto east, BRAKE, RTL, LOITER,
    LAND until disarmed."""
    out: dict = {"guided": s.set_mode(MODES["GUIDED"])}
    t, tries, ack = s.now(), 0, None
    while tries < 60 and ack != "ACCEPTED":
        tries += 1
        ack = s.command(M.MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        if ack != "ACCEPTED":
            s.pump(2.0)
    out["arm"] = {"tries": tries, "ack": ack, "seconds": round(s.now() - t, 1),
                  "texts": sorted(set(s.texts_since(t)))}
    if ack != "ACCEPTED":
        return out
    t = s.now()
    out["takeoff_ack"] = s.command(M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5.0)
    boot0 = position(s)
    m = s.wait("GLOBAL_POSITION_INT", lambda m: m.relative_alt >= 4750, 60.0)
    peak = []
    s.pump(4.0, lambda m: peak.append(m.relative_alt) if m.get_type() ==
           "GLOBAL_POSITION_INT" else None)
    out["takeoff"] = {
        "reached_4.75m": m is not None,
        "seconds": None if m is None or boot0 is None else
        round((m.time_boot_ms - boot0.time_boot_ms) / 1000.0, 1),
        "peak_m": round(max(peak) / 1000.0, 2) if peak else None,
        "texts": s.texts_since(t),
        "mode": s.heartbeat().custom_mode}
    if m is None:
        return out
    lp = s.wait("LOCAL_POSITION_NED", timeout_s=5.0)
    att0 = s.wait("ATTITUDE", timeout_s=5.0)
    target = (lp.x, lp.y + 10.0, -5.0) if lp is not None else None
    t = s.now()
    if target is not None:
        s.conn.mav.set_position_target_local_ned_send(
            0, *s.ts, M.MAV_FRAME_LOCAL_NED, 3576, *target, 0, 0, 0, 0, 0, 0, 0, 0)
        vmax, start = [0.0], lp.time_boot_ms

        def near(m):
            vmax[0] = max(vmax[0], math.hypot(m.vx, m.vy))
            return math.hypot(m.x - target[0], m.y - target[1]) < 0.5 and \
                math.hypot(m.vx, m.vy) < 0.3

        m = s.wait("LOCAL_POSITION_NED", near, 60.0)
        att1 = s.wait("ATTITUDE", timeout_s=5.0)
        out["goto"] = {
            "reached_0.5m": m is not None,
            "seconds": None if m is None else round((m.time_boot_ms - start) / 1000.0, 1),
            "max_speed_m_s": round(vmax[0], 2),
            "yaw_change_deg": None if att0 is None or att1 is None else
            round(math.degrees((att1.yaw - att0.yaw + math.pi) % (2 * math.pi) - math.pi)),
            "texts": s.texts_since(t)}

    def alt_change(mode: str, seconds: float) -> dict:
        """The height change over ``seconds`` of the vehicle's own clock
        (GLOBAL_POSITION_INT.time_boot_ms) from just before the mode change: set_mode
        returns a second or two after it (two HEARTBEATs), by when a vehicle that starts
        climbing at once is metres up; and a side running slower than wall time (ft-sitl
        on a loaded machine) is measured over the same flight time."""
        a = position(s)
        r = s.set_mode(MODES[mode])
        b = a
        if a is not None:
            end_ms = a.time_boot_ms + seconds * 1000.0
            b = s.wait("GLOBAL_POSITION_INT",
                       lambda m: m.get_srcSystem() == s.conn.target_system and
                       m.time_boot_ms >= end_ms, 10.0 * seconds)
        r["alt_change_m"] = None if a is None or b is None else \
            round((b.relative_alt - a.relative_alt) / 1000.0, 2)
        return r

    out["brake"] = alt_change("BRAKE", 3.0)
    out["rtl"] = alt_change("RTL", 6.0)
    out["loiter"] = alt_change("LOITER", 5.0)
    t = s.now()
    out["land"] = s.set_mode(MODES["LAND"])
    sysid = s.conn.target_system
    m = s.wait("HEARTBEAT", lambda m: m.get_srcSystem() == sysid and
               not m.base_mode & M.MAV_MODE_FLAG_SAFETY_ARMED, 120.0)
    out["land"]["disarmed"] = m is not None
    out["land"]["texts"] = s.texts_since(t)
    return out


def observe(url: str, label: str) -> dict:
    """The whole session against ``url`` (module docstring)."""
    s = Session(url)
    hb = s.conn.wait_heartbeat(timeout=60)
    if hb is None:
        raise SystemExit(f"ardupilot_parity: no HEARTBEAT from {url} within 60 s")
    obs: dict = {"label": label, "url": url,
                 "heartbeat": {"sysid": hb.get_srcSystem(), "compid": hb.get_srcComponent(),
                               "type": hb.type, "autopilot": hb.autopilot,
                               "base_mode": hb.base_mode, "custom_mode": hb.custom_mode,
                               "system_status": hb.system_status,
                               "mavlink_version": hb.mavlink_version}}
    obs["streams_default"] = rates(s, 6.0)
    s.conn.mav.command_long_send(*s.ts, M.MAV_CMD_REQUEST_MESSAGE, 0,
                                 M.MAVLINK_MSG_ID_AUTOPILOT_VERSION, 0, 0, 0, 0, 0, 0)
    ack = s.wait("COMMAND_ACK", lambda m: m.command == M.MAV_CMD_REQUEST_MESSAGE, 5.0)
    av = s.wait("AUTOPILOT_VERSION", timeout_s=5.0)
    obs["autopilot_version"] = {
        "ack": _result(None if ack is None else ack.result),
        "capabilities": None if av is None else
        sorted(e.name.removeprefix("MAV_PROTOCOL_CAPABILITY_")
               for v, e in M.enums["MAV_PROTOCOL_CAPABILITY"].items()
               if av.capabilities & v and not e.name.endswith("ENUM_END")),
        "flight_sw_version": None if av is None else hex(av.flight_sw_version)}

    obs["arm_in_land"] = {"mode": s.set_mode(MODES["LAND"]), **s.arm()}
    s.set_mode(MODES["GUIDED"])
    early = s.arm()
    early["armed"] = s.armed()
    if early["armed"]:
        early["disarm"] = s.arm(False)["ack"]
    obs["arm_early_guided"] = early

    obs["modes_ground"] = {name: s.set_mode(n) for name, n in MODES.items()}
    s.set_mode(MODES["LOITER"])
    obs["set_mode_message_guided"] = s.set_mode(MODES["GUIDED"], message=True)
    obs["mode_unknown_99"] = s.set_mode(99)

    s.conn.mav.request_data_stream_send(*s.ts, M.MAV_DATA_STREAM_ALL, 4, 1)
    s.pump(1.0)
    obs["streams_all_4hz"] = rates(s, 10.0)

    plist = params(s)
    obs["params"] = {"param_count": plist["param_count"], "received": plist["received"],
                     "sample": {k: plist["all"].get(k) for k in SAMPLE_PARAMS}}
    obs["param_names"] = plist["all"]
    real32 = M.MAV_PARAM_TYPE_REAL32
    obs["param_set"] = {
        "WPNAV_SPEED=600": param_set(s, "WPNAV_SPEED", 600.0, real32),
        "WPNAV_SPEED=1e6": param_set(s, "WPNAV_SPEED", 1e6, real32),
        "NO_SUCH_PARAM=1": param_set(s, "NO_SUCH_PARAM", 1.0, real32),
        "WPNAV_SPEED=1000": param_set(s, "WPNAV_SPEED", 1000.0, real32)}

    lat, lon = round(HOME[0] * 1e7), round(HOME[1] * 1e7)
    rel = M.MAV_FRAME_GLOBAL_RELATIVE_ALT
    items = [(M.MAV_FRAME_GLOBAL, M.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, 0, 0, 0),
             (rel, M.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, 0, 0, 0, 5.0),
             (rel, M.MAV_CMD_NAV_WAYPOINT, 0, 0, 0, 0, lat + 900, lon, 5.0),
             (rel, M.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 0, 0, 0, 0, 0, 0)]
    obs["mission_upload"] = upload(s, items)
    obs["mission_download"] = download(s)
    obs["auto_with_mission"] = s.set_mode(MODES["AUTO"])
    t = s.now()
    s.conn.mav.mission_clear_all_send(*s.ts, M.MAV_MISSION_TYPE_MISSION)
    ack = s.wait("MISSION_ACK", timeout_s=5.0)
    obs["mission_clear"] = {"ack": None if ack is None else
                            M.enums["MAV_MISSION_RESULT"][ack.type].name,
                            "count_after": download(s)["count"], "texts": s.texts_since(t)}

    obs["arm_in_land_late"] = {"mode": s.set_mode(MODES["LAND"]), **s.arm()}
    obs["flight"] = flight(s)
    obs["statustexts"] = [text for _, text in s.texts]
    s.conn.close()
    return obs


# -- the comparison ----------------------------------------------------------------------


def _brief(v) -> str:
    if isinstance(v, dict):
        return ", ".join(f"{k} {_brief(x)}" for k, x in v.items() if x not in ([], {}))
    if isinstance(v, list):
        return "[" + "; ".join(_brief(x) for x in v) + "]"
    if v is None:
        return "none"
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def rows(a: dict, b: dict) -> list[tuple[str, str, str, str]]:
    """(behaviour, A's answer, B's answer, same/differs) for each observation."""
    out = []

    def add(name, x, y):
        out.append((name, _brief(x), _brief(y), "same" if x == y else "differs"))

    add("HEARTBEAT", {k: v for k, v in a["heartbeat"].items()},
        {k: v for k, v in b["heartbeat"].items()})
    add("streams, default SRn_* (Hz)", a["streams_default"]["hz"], b["streams_default"]["hz"])
    add("AUTOPILOT_VERSION", a["autopilot_version"], b["autopilot_version"])
    add("arm in LAND", a["arm_in_land"], b["arm_in_land"])
    add("early arm in GUIDED", a["arm_early_guided"], b["arm_early_guided"])
    add("arm in LAND (after the mission steps)", a["arm_in_land_late"], b["arm_in_land_late"])
    for mode in MODES:
        add(f"DO_SET_MODE {mode} (ground, disarmed, no mission)", a["modes_ground"][mode],
            b["modes_ground"][mode])
    add("SET_MODE message GUIDED", a["set_mode_message_guided"], b["set_mode_message_guided"])
    add("SET_MODE 99", a["mode_unknown_99"], b["mode_unknown_99"])
    sa, sb = a["streams_all_4hz"]["hz"], b["streams_all_4hz"]["hz"]
    add("REQUEST_DATA_STREAM ALL 4 Hz: messages in both (Hz)",
        {k: sa[k] for k in sorted(set(sa) & set(sb))},
        {k: sb[k] for k in sorted(set(sa) & set(sb))})
    add("REQUEST_DATA_STREAM ALL 4 Hz: messages only one side sends",
        sorted(set(sa) - set(sb)), sorted(set(sb) - set(sa)))
    add("PARAM_REQUEST_LIST count", {k: a["params"][k] for k in ("param_count", "received")},
        {k: b["params"][k] for k in ("param_count", "received")})
    for k in SAMPLE_PARAMS:
        add(f"param {k}", a["params"]["sample"][k], b["params"]["sample"][k])
    na, nb = set(a["param_names"]), set(b["param_names"])
    add("parameter names only one side has (count)", len(na - nb), len(nb - na))
    add("parameter names ft-sitl has that ArduCopter lacks" if a["label"] == "arducopter"
        else "parameter names B has that A lacks", [], sorted(nb - na))
    common = sorted(na & nb)
    add("parameters in both: type or value differs",
        {k: a["param_names"][k] for k in common if a["param_names"][k] != b["param_names"][k]},
        {k: b["param_names"][k] for k in common if a["param_names"][k] != b["param_names"][k]})
    for k in a["param_set"]:
        add(f"PARAM_SET {k}", a["param_set"][k], b["param_set"][k])
    add("mission upload", a["mission_upload"], b["mission_upload"])
    add("mission download: count", a["mission_download"]["count"],
        b["mission_download"]["count"])
    ia, ib = a["mission_download"]["items"], b["mission_download"]["items"]
    for i in range(max(len(ia), len(ib))):
        add(f"mission download: item {i}", ia[i] if i < len(ia) else None,
            ib[i] if i < len(ib) else None)
    add("AUTO with a mission (ground, disarmed)", a["auto_with_mission"],
        b["auto_with_mission"])
    add("MISSION_CLEAR_ALL", a["mission_clear"], b["mission_clear"])
    fa, fb = a["flight"], b["flight"]
    for k in ("guided", "arm", "takeoff_ack", "takeoff", "goto", "brake", "rtl", "loiter",
              "land"):
        add(f"flight: {k}", fa.get(k), fb.get(k))
    add("STATUSTEXTs only one side sent", sorted(set(a["statustexts"]) -
                                                 set(b["statustexts"])),
        sorted(set(b["statustexts"]) - set(a["statustexts"])))
    return out


def compare(a: dict, b: dict) -> str:
    def cell(s: str) -> str:
        return s.replace("|", "\\|").replace("\n", " ")

    lines = [f"| behaviour | {a['label']} | {b['label']} | |", "| --- | --- | --- | --- |"]
    lines += [f"| {cell(n)} | {cell(x)} | {cell(y)} | {d} |" for n, x, y, d in rows(a, b)]
    return "\n".join(lines) + "\n"


# -- running both sides ------------------------------------------------------------------


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(30)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


@contextmanager
def arducopter(binary: Path, defaults: Path, log: Path):
    """``arducopter --model quad`` on the first free instance >= 5 (its lock held), in a
    scratch directory (its eeprom and logs); yields SERIAL0's URL."""
    home = ",".join(str(x) for x in HOME) + ",0"
    with free_instances(1, serial_ports_free, base=5, slots=15) as k, \
            tempfile.TemporaryDirectory(prefix="arducopter-") as scratch:
        shutil.copy(defaults, Path(scratch) / "defaults.parm")
        with open(log, "w") as fh:
            proc = subprocess.Popen(
                [str(binary), "--model", "quad", "--speedup", "1", "-w", "-I", str(k),
                 "--home", home, "--defaults", "defaults.parm"],
                cwd=scratch, stdout=fh, stderr=subprocess.STDOUT)
            try:
                port = tcp_ports(k)[0]
                end = time.monotonic() + 60.0
                while serial_ports_free(k) and proc.poll() is None and time.monotonic() < end:
                    time.sleep(0.2)
                if proc.poll() is not None or tcp_port_free("127.0.0.1", port):
                    raise SystemExit(f"ardupilot_parity: {binary} did not listen on {port} "
                                     f"(see {log})")
                yield f"tcp:127.0.0.1:{port}"
            finally:
                _stop(proc)


@contextmanager
def ft_sitl_face(log: Path):
    """``ft-sitl sitl --autopilot ardupilot --instance auto``; yields SERIAL0's URL."""
    with open(log, "w") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "ft_sitl", "sitl", "--autopilot", "ardupilot", "--instance",
             "auto", "--json", "--no-mqtt", "--home", ",".join(str(x) for x in HOME)],
            stdout=subprocess.PIPE, stderr=err, text=True)
        try:
            text, said = "", None
            while said is None:
                line = proc.stdout.readline()
                if not line:
                    raise SystemExit(f"ardupilot_parity: ft-sitl sitl did not start (see {log})")
                text += line
                if text.lstrip().startswith("{") and line.startswith("}"):
                    said = json.loads(text)
            yield said["vehicles"][0]["serial"][0]
        finally:
            _stop(proc)
            proc.stdout.close()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    o = sub.add_parser("observe", help="run the session against one endpoint")
    o.add_argument("url", help="pymavlink URL of SERIAL0, e.g. tcp:127.0.0.1:5810")
    o.add_argument("--label", required=True)
    o.add_argument("--out", type=Path, required=True)
    c = sub.add_parser("compare", help="a Markdown table of two observations")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    r = sub.add_parser("run", help="observe a real arducopter, then ft-sitl, and compare")
    r.add_argument("--arducopter", type=Path, required=True, help="the arducopter binary")
    r.add_argument("--defaults", type=Path, required=True,
                   help="its defaults file (Tools/autotest/default_params/copter.parm)")
    r.add_argument("--out", type=Path, required=True, help="directory for the results")
    args = p.parse_args(argv)
    if args.cmd == "observe":
        args.out.write_text(json.dumps(observe(args.url, args.label), indent=1) + "\n")
    elif args.cmd == "compare":
        sys.stdout.write(compare(json.loads(args.a.read_text()), json.loads(args.b.read_text())))
    else:
        for f, what in ((args.arducopter, "--arducopter"), (args.defaults, "--defaults")):
            if not f.is_file():
                p.error(f"{what}: {f}: no such file")
        args.out.mkdir(parents=True, exist_ok=True)
        with arducopter(args.arducopter.resolve(), args.defaults.resolve(),
                        args.out / "arducopter.log") as url:
            real = observe(url, "arducopter")
        (args.out / "arducopter.json").write_text(json.dumps(real, indent=1) + "\n")
        with ft_sitl_face(args.out / "ft-sitl.log") as url:
            ours = observe(url, "ft-sitl")
        (args.out / "ft-sitl.json").write_text(json.dumps(ours, indent=1) + "\n")
        (args.out / "parity.md").write_text(compare(real, ours))
        print(args.out / "parity.md")
    return 0


if __name__ == "__main__":
    sys.exit(main())
