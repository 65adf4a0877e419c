"""``ft-sitl navigators``: the registered navigation algorithms (list, install weights)."""

from __future__ import annotations

import json
import shutil
import sys

from ft_sitl.cli.common import CliError, print_schema_rows
from ft_sitl.navigation.learned.navrl import CHECKPOINT_NAME, data_dir
from ft_sitl.navigation.learned.navrl_policy import CheckpointError, NavRLPolicy
from ft_sitl.navigation.registry import NavigatorError, available, describe, parameters


def cmd_navigators_list(args) -> int:
    rows = []
    for name, cls in sorted(available().items()):
        if isinstance(cls, str):
            rows.append({"name": name, "error": cls})
            continue
        doc = (cls.__doc__ or sys.modules[cls.__module__].__doc__ or "").strip()
        rows.append({"name": name, "class": f"{cls.__module__}.{cls.__qualname__}",
                     "rate_hz": cls.rate_hz, "depth_camera": cls.camera is not None,
                     "unavailable": cls.unavailable(),
                     "parameters": {k: v for k, v in parameters(cls).items()},
                     "summary": doc.splitlines()[0] if doc else ""})
    if args.json:
        print(json.dumps(rows, indent=2, default=str))
        return 0
    for r in rows:
        if "error" in r:
            print(f"{r['name']:14s} UNAVAILABLE: {r['error']}")
            continue
        params = ", ".join(f"{k}={v!r}" for k, v in r["parameters"].items()) or "-"
        print(f"{r['name']:14s} {r['rate_hz']:g} Hz  params: {params}")
        if r["summary"]:
            print(f"{'':14s} {r['summary']}")
        if r["unavailable"]:
            print(f"{'':14s} not runnable here: {r['unavailable']}")
    return 0


def cmd_navigators_show(args) -> int:
    """One navigator's declared parameters (its schema)."""
    try:
        schema = describe(args.name)
    except NavigatorError as exc:
        raise CliError(str(exc)) from None
    rows = schema.rows()
    if args.json:
        print(json.dumps({"name": args.name, "parameters": rows}, indent=2))
        return 0
    n = f"{len(rows)} parameter{'s' if len(rows) != 1 else ''}"
    print(f"navigator {args.name}: {n} (set them in a campaign's algorithms table, e.g. "
          f"{{name = \"{args.name}\", params = {{...}}}})")
    print_schema_rows(rows)
    return 0


def cmd_navigators_install(args) -> int:
    """Check a NavRL checkpoint and copy it where the navrl navigator looks."""

    if args.name != "navrl":
        raise CliError(f"install: {args.name!r} has no files to install (only navrl "
                       "needs model weights)")
    try:
        NavRLPolicy.from_checkpoint(args.path)
    except CheckpointError as exc:
        raise CliError(f"install navrl: {exc}") from None
    except OSError as exc:
        raise CliError(f"install navrl: {args.path}: {exc}") from None
    dest = data_dir() / CHECKPOINT_NAME
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_suffix(".tmp")
    shutil.copyfile(args.path, tmp)
    tmp.replace(dest)
    print(f"navrl: checkpoint installed at {dest}")
    return 0
