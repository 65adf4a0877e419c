"""``ft-sitl params``: the flight controller's PX4-named parameters, honoured (ft-sitl acts
on them) or stored (accepted, remembered and echoed over MAVLink, no effect)."""

from __future__ import annotations

import json

from ft_sitl.autopilot.params import (
    PARAMS,
    PX4_COMMIT,
    PX4_RELEASE,
    PX4_TABLE,
    ParamSet,
    ParamSpec,
    px4_differences,
)


def _num(spec: ParamSpec, v: float) -> str:
    return str(int(v)) if spec.is_int else f"{v:g}"


def _row(s: ParamSpec) -> dict:
    return {"name": s.name, "status": "honoured" if s.honoured else "stored",
            "honoured": s.honoured, "type": s.px4_type, "default": s.default,
            "min": s.lo if s.bounded_lo else None, "max": s.hi if s.bounded_hi else None,
            "unit": s.unit, "group": s.group, "kind": s.kind or None, "description": s.doc}


def _range(s: ParamSpec) -> str:
    lo = _num(s, s.lo) if s.bounded_lo else "-"
    hi = _num(s, s.hi) if s.bounded_hi else "-"
    return f"[{lo}, {hi}]"


def cmd_params_list(args) -> int:
    specs = [s for s in PARAMS.values()
             if not (args.honoured and not s.honoured) and not (args.stored and s.honoured)]
    if args.json:
        print(json.dumps([_row(s) for s in specs], indent=2))
        return 0
    for s in specs:
        status = "honoured" if s.honoured else "stored"
        print(f"{s.name:16s} {status:8s} {_num(s, s.default):>8s}  {_range(s):18s} "
              f"{s.unit:12s} {s.doc}")
    return 0


def cmd_params_show(args) -> int:
    s = ParamSet.spec(args.name)  # ParamError (exit 2) for an unknown name, with hints
    row = _row(s)
    px4 = PX4_TABLE.get(s.name)
    diff = px4_differences().get(s.name, {}) if s.honoured else {}
    row["px4"] = None if px4 is None else {
        "release": PX4_RELEASE, "commit": PX4_COMMIT, "type": px4.px4_type,
        "default": px4.default, "min": px4.lo if px4.bounded_lo else None,
        "max": px4.hi if px4.bounded_hi else None, "unit": px4.unit,
        "differs": sorted(diff)}
    if args.json:
        print(json.dumps(row, indent=2))
        return 0
    status = "honoured: ft-sitl acts on it" if s.honoured \
        else "stored: accepted, remembered and echoed; no effect on the flight"
    print(f"{s.name}  ({status})")
    print(f"  {s.doc}")
    print(f"  type     {s.px4_type}{' (' + s.kind + ')' if s.kind else ''}")
    print(f"  default  {_num(s, s.default)}")
    print(f"  range    {_range(s)}{' ' + s.unit if s.unit else ''}")
    print(f"  group    {s.group}")
    if px4 is None:
        print(f"  PX4      not a parameter of PX4 {PX4_RELEASE}'s emulated modules")
    elif diff:
        unit = f" {px4.unit}" if px4.unit else ""
        print(f"  PX4 {PX4_RELEASE}: default {_num(px4, px4.default)}, range {_range(px4)}{unit}"
              f" (ft-sitl differs: {', '.join(sorted(diff))})")
    else:
        print(f"  PX4 {PX4_RELEASE}: as above")
    return 0
