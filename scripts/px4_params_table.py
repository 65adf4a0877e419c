"""Build ft-sitl's table of PX4 parameters, ``ft_sitl/autopilot/data/px4_params.json``,
from a PX4-Autopilot source tree (docs/control.md, "Parameters").

The facts of each parameter (name, type, default, min, max, unit, PX4 group, whether it is
a boolean, an enum or a bitmask) are read from the parameter definitions of the PX4
modules that ft-sitl emulates (:data:`SOURCES`): the ``PARAM_DEFINE_*`` blocks of their
``*params*.c`` files and the ``parameters:`` (and ``serial_config:``) sections of their
``module.yaml`` files, instanced parameters (``BAT${i}_...``) expanded as PX4's build
expands them. The one-line descriptions are ft-sitl's own, written for this table, kept in
``scripts/px4_param_descriptions.tsv`` (name, tab, description); PX4's own texts are not
copied into the table.

Produced with PX4 v1.15.2 (release/1.15 at upstream commit 4817c0618a, 2024-11-06)::

    git -C PX4-Autopilot archive 4817c0618a src | tar -x -C /tmp/px4
    .venv/bin/python scripts/px4_params_table.py --px4 /tmp/px4 \\
        --release v1.15.2 --commit 4817c0618a

``--missing`` writes nothing: it lists the parameters that have no description in the
TSV yet (with PX4's short text beside each, as a reading aid for whoever writes ours), and
the TSV rows that name no parameter; the table is not written while either list is not
empty. ``--check`` writes nothing and exits 1 when the committed table differs from what
would be written. The PX4 sources are read, never committed.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "ft_sitl" / "autopilot" / "data" / "px4_params.json"
DESCRIPTIONS = ROOT / "scripts" / "px4_param_descriptions.tsv"

#: PX4 parameter definition files of the modules ft-sitl emulates, relative to the tree
SOURCES = (
    # commander, its failsafes, failure detector, circuit breakers, system basics
    "src/modules/commander/commander_params.c",
    "src/modules/commander/module.yaml",
    "src/modules/commander/failure_detector/failure_detector_params.c",
    "src/lib/circuit_breaker/circuit_breaker_params.c",
    "src/lib/systemlib/system_params.c",
    # navigator: mission, geofence, return
    "src/modules/navigator/navigator_params.c",
    "src/modules/navigator/mission_params.c",
    "src/modules/navigator/geofence_params.c",
    "src/modules/navigator/rtl_params.c",
    # multicopter position control and its flight tasks (follow target, orbit, slow mode)
    "src/modules/mc_pos_control/multicopter_altitude_mode_params.c",
    "src/modules/mc_pos_control/multicopter_autonomous_params.c",
    "src/modules/mc_pos_control/multicopter_nudging_params.c",
    "src/modules/mc_pos_control/multicopter_position_control_gain_params.c",
    "src/modules/mc_pos_control/multicopter_position_control_limits_params.c",
    "src/modules/mc_pos_control/multicopter_position_control_params.c",
    "src/modules/mc_pos_control/multicopter_position_mode_params.c",
    "src/modules/mc_pos_control/multicopter_responsiveness_params.c",
    "src/modules/mc_pos_control/multicopter_stabilized_mode_params.c",
    "src/modules/mc_pos_control/multicopter_takeoff_land_params.c",
    "src/modules/flight_mode_manager/flight_mode_manager_params.c",
    "src/modules/flight_mode_manager/tasks/AutoFollowTarget/follow_target_params.c",
    "src/modules/flight_mode_manager/tasks/ManualAccelerationSlow/"
    "flight_task_acceleration_slow_params.c",
    "src/modules/flight_mode_manager/tasks/Orbit/flight_task_orbit_params.c",
    # multicopter attitude and rate control
    "src/modules/mc_att_control/mc_att_control_params.c",
    "src/modules/mc_rate_control/mc_rate_control_params.c",
    "src/modules/mc_rate_control/mc_acro_params.c",
    # land detector (multicopter)
    "src/modules/land_detector/land_detector_params.c",
    "src/modules/land_detector/land_detector_params_mc.c",
    # battery
    "src/lib/battery/battery_params_common.c",
    "src/lib/battery/battery_params_deprecated.c",
    "src/lib/battery/module.yaml",
    # EKF2's main settings (not the multi-instance, selector or learned volatile ones)
    "src/modules/ekf2/module.yaml",
    # MAVLink
    "src/modules/mavlink/mavlink_params.c",
    "src/modules/mavlink/module.yaml",
)

INT32_MIN, INT32_MAX = -(2**31), 2**31 - 1
#: the values PX4's serial-port configuration parameters (``*_CONFIG``) give port names
SERIAL_PORTS = {"": 0, "TEL1": 101, "TEL2": 102, "TEL3": 103, "TEL4": 104,
                "GPS1": 201, "GPS2": 202, "GPS3": 203, "ETHERNET": 1000}

_BLOCK = re.compile(r"/\*\*((?:(?!\*/).)*)\*/\s*PARAM_DEFINE_(INT32|FLOAT)\(\s*(\w+)\s*,"
                    r"\s*([^)]*?)\s*\)\s*;", re.S)


class TableError(Exception):
    """A definition this script cannot read, named with its file."""


def _number(text, where: str) -> float:
    if isinstance(text, bool):  # module.yaml writes a boolean's default as true/false
        return int(text)
    t = str(text).strip().rstrip("fF")
    try:
        v = float(t)
    except ValueError:
        raise TableError(f"{where}: cannot read {text!r} as a number") from None
    return int(v) if v == int(v) and "." not in t and "e" not in t.lower() else v


def _short(lines: list[str]) -> str:
    """The first sentence or paragraph of a comment's text (reading aid only)."""
    out = []
    for line in lines:
        if not line.strip():
            break
        out.append(line.strip())
        if line.rstrip().endswith("."):
            break
    return " ".join(out)


def parse_c(path: Path, rel: str) -> list[dict]:
    rows = []
    for m in _BLOCK.finditer(path.read_text()):
        body, ptype, name, default = m.groups()
        lines = [re.sub(r"^\s*\*\s?", "", ln) for ln in body.splitlines()]
        text, tags = [], {}
        kind = None
        for ln in lines:
            s = ln.strip()
            if s.startswith("@"):
                tag, _, rest = s[1:].partition(" ")
                tags.setdefault(tag, rest.strip())
                if tag == "boolean":
                    kind = "boolean"
                elif tag == "value" and kind is None:
                    kind = "enum"
                elif tag == "bit":
                    kind = "bitmask"
            elif not tags:
                text.append(ln)
        while text and not text[0].strip():
            text.pop(0)
        where = f"{rel}: {name}"
        rows.append({
            "name": name, "type": "INT32" if ptype == "INT32" else "FLOAT",
            "default": _number(default, where),
            "min": _number(tags["min"], where) if "min" in tags else None,
            "max": _number(tags["max"], where) if "max" in tags else None,
            "unit": tags.get("unit", ""), "group": tags.get("group", ""), "kind": kind,
            "px4_short": _short(text), "source": rel,
        })
    return rows


def _instances(d: dict) -> list[int]:
    n = int(d.get("num_instances", 1))
    start = int(d.get("instance_start", 0))
    return list(range(start, start + n))


def parse_yaml(path: Path, rel: str) -> list[dict]:
    doc = yaml.safe_load(path.read_text())
    rows = []
    for sc in doc.get("serial_config", []) or []:
        pc = sc["port_config_param"]
        defaults = pc.get("default", "")
        for k, i in enumerate(_instances(sc)):
            port = defaults[k] if isinstance(defaults, list) else defaults
            if port not in SERIAL_PORTS:
                raise TableError(f"{rel}: {pc['name']}: unknown serial port {port!r}")
            rows.append({
                "name": pc["name"].replace("${i}", str(i)), "type": "INT32",
                "default": SERIAL_PORTS[port], "min": None, "max": None, "unit": "",
                "group": pc.get("group", ""), "kind": "enum",
                "px4_short": "serial port configuration", "source": rel,
            })
    for group in doc.get("parameters", []) or []:
        for tmpl, d in group["definitions"].items():
            t = d["type"]
            if t not in ("int32", "float", "enum", "boolean", "bitmask"):
                raise TableError(f"{rel}: {tmpl}: unknown type {t!r}")
            names = _instances(d) if "${i}" in tmpl else [None]
            default = d.get("default")
            for k, i in enumerate(names):
                name = tmpl if i is None else tmpl.replace("${i}", str(i))
                v = default[k] if isinstance(default, list) else default
                if v is None:
                    raise TableError(f"{rel}: {name}: no default")
                short = str(d.get("description", {}).get("short", ""))
                rows.append({
                    "name": name, "type": "FLOAT" if t == "float" else "INT32",
                    "default": _number(v, f"{rel}: {name}"),
                    "min": _number(d["min"], name) if "min" in d else None,
                    "max": _number(d["max"], name) if "max" in d else None,
                    "unit": str(d.get("unit", "")), "group": group.get("group", ""),
                    "kind": t if t in ("enum", "boolean", "bitmask") else None,
                    "px4_short": short.replace("${i}", str(i)), "source": rel,
                })
    return rows


def read_px4(tree: Path) -> list[dict]:
    rows: dict[str, dict] = {}
    for rel in SOURCES:
        path = tree / rel
        if not path.is_file():
            raise TableError(f"{path}: not found (is --px4 the root of a PX4 source tree?)")
        parsed = parse_yaml(path, rel) if rel.endswith(".yaml") else parse_c(path, rel)
        for r in parsed:
            if r["name"] in rows:
                raise TableError(f"{rel}: {r['name']} is also defined in "
                                 f"{rows[r['name']]['source']}")
            rows[r["name"]] = r
    for r in rows.values():
        _check_row(r)
    return sorted(rows.values(), key=lambda r: r["name"])


def _check_row(r: dict) -> None:
    where = f"{r['source']}: {r['name']}"
    if len(r["name"]) > 16:
        raise TableError(f"{where}: longer than MAVLink's 16 characters")
    if r["type"] == "INT32" and not isinstance(r["default"], int):
        if r["default"] != int(r["default"]):
            raise TableError(f"{where}: INT32 with a fractional default")
        r["default"] = int(r["default"])
    if r["type"] == "FLOAT":
        r["default"] = float(r["default"])
        for key in ("min", "max"):
            if r[key] is not None:
                r[key] = float(r[key])
    lo = r["min"] if r["min"] is not None else -math.inf
    hi = r["max"] if r["max"] is not None else math.inf
    if not lo <= r["default"] <= hi:
        raise TableError(f"{where}: default {r['default']} outside [{lo}, {hi}]")


def read_descriptions(path: Path) -> dict[str, str]:
    out: dict[str, str] = {}
    for n, line in enumerate(path.read_text().splitlines(), 1):
        if not line.strip() or line.startswith("#"):
            continue
        name, sep, text = line.partition("\t")
        if not sep or not text.strip():
            raise TableError(f"{path}:{n}: expected NAME<TAB>description")
        if name in out:
            raise TableError(f"{path}:{n}: {name} described twice")
        out[name] = text.strip()
    return out


def render(rows: list[dict], desc: dict[str, str], release: str, commit: str) -> str:
    head = {
        "px4_release": release, "px4_commit": commit,
        "about": "PX4 parameters of the modules ft-sitl emulates: facts from PX4's "
                 "parameter definitions, descriptions ft-sitl's own; generated by "
                 "scripts/px4_params_table.py",
        "fields": ["name", "type", "default", "min", "max", "unit", "group", "kind",
                   "description"],
        "count": len(rows),
    }
    lines = ["{"]
    for k, v in head.items():
        lines.append(f"  {json.dumps(k)}: {json.dumps(v)},")
    lines.append('  "params": [')
    body = []
    for r in rows:
        row = [r["name"], r["type"], r["default"], r["min"], r["max"], r["unit"],
               r["group"], r["kind"], desc[r["name"]]]
        body.append("    " + json.dumps(row, ensure_ascii=False))
    lines.append(",\n".join(body))
    lines.append("  ]")
    lines.append("}")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--px4", type=Path, required=True, help="root of a PX4 source tree")
    ap.add_argument("--release", default="v1.15.2", help="PX4 release recorded in the table")
    ap.add_argument("--commit", default="4817c0618a", help="PX4 commit recorded in the table")
    ap.add_argument("--descriptions", type=Path, default=DESCRIPTIONS)
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--missing", action="store_true",
                    help="list parameters without a description (and stale TSV rows)")
    ap.add_argument("--check", action="store_true",
                    help="exit 1 if the committed table differs from what would be written")
    args = ap.parse_args(argv)
    try:
        rows = read_px4(args.px4)
        desc = read_descriptions(args.descriptions) if args.descriptions.exists() else {}
    except TableError as exc:
        print(f"px4_params_table: error: {exc}", file=sys.stderr)
        return 2
    names = {r["name"] for r in rows}
    missing = [r for r in rows if r["name"] not in desc]
    stale = sorted(set(desc) - names)
    if args.missing or missing or stale:
        for r in missing:
            print(f"{r['name']}\t[{r['group']}] {r['px4_short']}")
        for name in stale:
            print(f"{name}\t(described, but not a parameter of these sources)")
        print(f"{len(rows)} parameters, {len(missing)} without a description, "
              f"{len(stale)} stale descriptions", file=sys.stderr)
        return 0 if args.missing else 1
    text = render(rows, desc, args.release, args.commit)
    if args.check:
        same = args.out.exists() and args.out.read_text() == text
        print(f"{args.out}: {'up to date' if same else 'differs'}")
        return 0 if same else 1
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"wrote {args.out} ({len(rows)} parameters)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
