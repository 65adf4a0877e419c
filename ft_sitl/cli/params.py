"""``ft-sitl params``: the flight controller's PX4-named parameters."""

from __future__ import annotations

import json

from ft_sitl.autopilot.params import PARAMS


def cmd_params_list(args) -> int:
    rows = [{"name": s.name, "default": s.default, "min": s.lo, "max": s.hi, "unit": s.unit,
             "description": s.doc} for s in PARAMS.values()]
    if args.json:
        print(json.dumps(rows, indent=2))
        return 0
    for r in rows:
        print(f"{r['name']:18s} {r['default']:>8g}  [{r['min']:g}, {r['max']:g}] {r['unit']:12s}"
              f" {r['description']}")
    return 0

