""".parm parameter files as ArduPilot reads them (AP_Param::load_defaults_file, SITL's
``--defaults FILE[,FILE]``) and MAVProxy / Mission Planner write them: one ``NAME VALUE``
per line, name and value separated by spaces, tabs or a comma, ``#`` starting a comment
(a whole line or the rest of one), blank lines ignored. Files given together are read in
order, a later value of a name replacing an earlier one.

ArduPilot SITL skips a name it does not know and stores an out-of-range value; ft-sitl
refuses both, naming the file, the line, the name and the range (ParmError), so a
misspelled or impossible setting never flies silently (docs/mavlink.md).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

from ft_sitl.autopilot.params import ParamError
from ft_sitl.mavlink.ardupilot.params import ApParamSet

_SEPARATORS = re.compile(r"[\s,]+")


class ParmError(ValueError):
    """A .parm file ft-sitl refuses; the message names the file and line."""


def read(path: Path | str) -> list[tuple[str, float, int]]:
    """The (name, value, line number) settings of one file, checked against ArduCopter's
    declarations (names known, values within range) without setting anything."""
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise ParmError(f"{path}: cannot read ({exc})") from None
    out = []
    for n, raw in enumerate(text.splitlines(), 1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = _SEPARATORS.split(line)
        if len(fields) != 2:
            raise ParmError(f"{path}:{n}: expected NAME VALUE (or NAME,VALUE), got {line!r}")
        name, text_value = fields
        try:
            value = float(text_value)
        except ValueError:
            raise ParmError(f"{path}:{n}: {name}: {text_value!r} is not a number") from None
        try:
            spec = ApParamSet.spec(name)
            if math.isfinite(value) and (spec.is_int or value.is_integer()):
                value = round(value)  # (as ArduPilot stores an integer parameter)
            spec.check(value)
        except ParamError as exc:
            raise ParmError(f"{path}:{n}: {exc}") from None
        out.append((name, value, n))
    return out


def read_all(paths: str) -> list[tuple[str, float, str]]:
    """The settings of ``--defaults``' comma-separated files, in order: (name, value,
    "file:line" it came from)."""
    out = []
    for p in paths.split(","):
        if not p.strip():
            raise ParmError(f"--defaults: empty file name in {paths!r}")
        out.extend((name, value, f"{p.strip()}:{n}") for name, value, n in read(p.strip()))
    return out


def format_parm(values) -> str:
    """(name, value) pairs as .parm text, MAVProxy's ``param save`` layout: the name
    padded to 16, the value as ``%f`` would print it shortened (%g, exact for the
    integers)."""
    return "".join(f"{name:<16} {value:.9g}\n" for name, value in values)


def write(path: Path | str, params: ApParamSet) -> None:
    """Every parameter of ``params`` as a .parm file ArduPilot SITL's --defaults (and
    ft-sitl's) reads back."""
    Path(path).write_text(format_parm(params.items()))


def apply(settings: list[tuple[str, float, str]], parameters) -> None:
    """Set each (name, value, where) through ``parameters`` (the face's parameter
    protocol, so honoured ones reach the controller); a value the controller cannot fly is
    refused naming where it came from."""
    for name, value, where in settings:
        try:
            parameters.set(name, value)
        except ParamError as exc:
            raise ParmError(f"{where}: {exc}") from None
