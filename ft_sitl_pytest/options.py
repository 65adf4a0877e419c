"""The options a test gives its vehicles (marker, indirect parametrisation, factory),
declared once, and their translation into ``ft-sitl sitl`` arguments.

Each option's range is the command's (ft_sitl/cli/parsers.py): a bad value is the
command's own one-line error, named with the option that carried it.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass


class OptionError(ValueError):
    """A vehicle option the plugin cannot pass on (unknown name, wrong type)."""


@dataclass(frozen=True)
class Option:
    flag: str | None  # the ft-sitl sitl option it becomes (None: the plugin's own)
    doc: str


OPTIONS: dict[str, Option] = {
    "platform": Option("--platform", "catalog or user platform name (default: the "
                       "sitl's, 0.98kg-EGO Planner DIY)"),
    "platform_file": Option("--platform-file", "user platform file(s), TOML/YAML (a path "
                            "or a list of paths)"),
    "scenario": Option("--scenario", "a scenario world, FAMILY:INDEX[:SEED] or a spec "
                       "file: the vehicles spawn at its takeoff point and crash on contact"),
    "home": Option("--home", "geodetic home: (lat_deg, lon_deg, alt_m) or 'LAT,LON,ALT' "
                   "(default: PX4 SITL's 47.397742, 8.545594, 488)"),
    "speed_factor": Option("--speed-factor", "simulated seconds per wall second, "
                           "0.01..1000 (default 1)"),
    "pace": Option("--pace", "'wall' (default) or 'client': the clock never runs more "
                   "than pace_span past the client's last MAVLink message"),
    "pace_span": Option("--pace-span", "with pace='client': simulated seconds the clock "
                        "may run ahead of the client, 0.004..60 (default 0.05)"),
    "instance": Option("--instance", "first instance number (ports 14540+i, 14580+i, "
                       "18570+i); default: a free one (--instance auto)"),
    "vehicles": Option("--instances", "number of vehicles, 1..64 (ft_sitl_fleet; "
                       "default 2 there, 1 for ft_sitl_vehicle)"),
    "wind": Option("--wind", "wind settings, KEY=VALUE,... (docs/platforms.md, Wind)"),
    "wind_seed": Option("--wind-seed", "turbulence and estimator-noise seed"),
    "estimator": Option("--estimator", "estimate errors, KEY=VALUE,... "
                        "(docs/control.md, Estimator)"),
    "actuators": Option("--actuators", "motor faults and limits, KEY=VALUE,..."),
    "mqtt": Option(None, "True: also publish on the MQTT bus (an embedded broker on a "
                   "free port; Vehicle.mqtt_url); default False"),
    "args": Option(None, "further ft-sitl sitl arguments, a list of strings"),
    "start_timeout": Option(None, "wall seconds to wait for the vehicles to serve "
                            "(default: --ft-sitl-start-timeout, 300)"),
}

#: the arguments every served vehicle process gets from the plugin (not options)
FIXED_FLAGS = ("--json", "--tlog", "--no-mqtt")
#: arguments the plugin cannot serve with: its readiness probe sends unsigned MAVLink
UNSUPPORTED_FLAGS = {"--signing-key": "the plugin's readiness probe is unsigned"}


def check_names(options: dict, where: str) -> None:
    """An OptionError naming the first unknown option and the known ones."""
    for name in options:
        if name not in OPTIONS:
            raise OptionError(f"{where}: unknown option {name!r} (options: "
                              f"{', '.join(OPTIONS)})")


def _text(name: str, value) -> str:
    if isinstance(value, bool) or not isinstance(value, (str, int, float)):
        raise OptionError(f"{name}: {value!r} must be a string or a number")
    return str(value)  # its range is the command's to check


def sitl_arguments(options: dict, where: str) -> list[str]:
    """The ``ft-sitl sitl`` arguments for ``options`` (names checked first); the instance
    is ``auto`` unless one is given."""
    check_names(options, where)
    argv: list[str] = []
    for name, value in options.items():
        opt = OPTIONS[name]
        if value is None or opt.flag is None:
            continue
        if name == "home" and isinstance(value, (tuple, list)):
            if len(value) != 3:
                raise OptionError(f"{where}: home: {value!r} must be (lat_deg, lon_deg, "
                                  f"alt_m)")
            argv.append(f"{opt.flag}={','.join(_text('home', v) for v in value)}")
        elif name == "platform_file" and isinstance(value, (tuple, list)):
            argv += [f"{opt.flag}={os.fspath(v)}" for v in value]
        else:
            # FLAG=VALUE: a value that starts with "-" (a southern latitude) stays a value
            text = _text(name, os.fspath(value) if isinstance(value, os.PathLike) else value)
            argv.append(f"{opt.flag}={text}")
    if options.get("instance") is None:
        argv += ["--instance", "auto"]
    if options.get("mqtt") not in (None, True, False):
        raise OptionError(f"{where}: mqtt: {options['mqtt']!r} must be True or False")
    if not options.get("mqtt"):
        argv.append("--no-mqtt")
    extra = options.get("args") or []
    if isinstance(extra, str) or not all(isinstance(a, str) for a in extra):
        raise OptionError(f"{where}: args: {extra!r} must be a list of strings")
    for a in extra:
        flag = a.split("=", 1)[0]
        if flag in FIXED_FLAGS:
            raise OptionError(f"{where}: args: {a} is set by the plugin")
        if flag in UNSUPPORTED_FLAGS:
            raise OptionError(f"{where}: args: {flag} is not supported "
                              f"({UNSUPPORTED_FLAGS[flag]})")
    return argv + list(extra)


def start_timeout(options: dict, default_s: float, where: str) -> float:
    """The start-up ceiling in wall seconds (a positive finite number)."""
    value = options.get("start_timeout")
    if value is None:
        return default_s
    if isinstance(value, bool) or not isinstance(value, (int, float)) or \
            not (math.isfinite(value) and value > 0):
        raise OptionError(f"{where}: start_timeout: {value!r} must be a number of seconds "
                          f"> 0")
    return float(value)
