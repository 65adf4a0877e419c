"""What the command modules share: :class:`CliError`, the exit status of bad input, and
small helpers for options.

Light on purpose: ``ft_sitl.cli`` imports it to start up, before any command runs.
"""

from __future__ import annotations

import math
from pathlib import Path

from ft_sitl.physics.catalog import PlatformRegistry

__all__ = ["EXIT_BAD_INPUT", "CliError", "check_out_dir", "fmt_point", "number",
           "option_value", "platform_registry", "wind_option", "estimator_option",
           "settings_option", "actuators_option"]

EXIT_BAD_INPUT = 2


class CliError(Exception):
    """Bad input from the command line: printed as one line, exit status 2."""


def platform_registry(args) -> PlatformRegistry:
    """The catalog plus the ``--platform-file`` files of ``args``."""
    return PlatformRegistry(args.platform_file or ())


def number(option: str, *, minimum: float | None = None, maximum: float | None = None,
           above: float | None = None, integer: bool = False):
    """The argparse ``type`` of a numeric option: a finite number (an integer with
    ``integer``), at least ``minimum``, more than ``above``, at most ``maximum``.

    A bad value raises :class:`CliError` naming the option, which argparse lets through
    (it only turns ValueError and TypeError into its usage message), so the command
    prints the usual one line ``ft-sitl: error: --duration: nan is not a finite number``
    and exits 2 before anything starts."""
    kind = "an integer" if integer else "a number"
    if minimum is not None and maximum is not None:
        allowed = f"within {minimum:g}..{maximum:g}"
    elif above is not None:
        allowed = f"more than {above:g}" + (f" and at most {maximum:g}"
                                            if maximum is not None else "")
    elif minimum is not None:
        allowed = f"at least {minimum:g}"
    else:
        allowed = f"at most {maximum:g}" if maximum is not None else ""

    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise CliError(f"{option}: {text!r} is not {kind}") from None
        if not math.isfinite(value):
            raise CliError(f"{option}: {text} is not a finite number")
        if ((minimum is not None and value < minimum) or (above is not None and value <= above)
                or (maximum is not None and value > maximum)):
            raise CliError(f"{option}: {value:g} must be {allowed}")
        return value

    parse.__name__ = "integer" if integer else "number"  # (argparse names the type so)
    return parse


def option_value(option: str, parse, *values):
    """``parse(*values)``, its ValueError turned into a CliError naming ``option``."""
    try:
        return parse(*values)
    except ValueError as exc:
        raise CliError(f"{option}: {exc}") from None


def check_out_dir(option: str, path: Path) -> None:
    """An output file's directory must exist."""
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise CliError(f"{option}: directory {parent} does not exist")


def fmt_point(p) -> str:
    return "(" + ", ".join(f"{v:.2f}" for v in p) + ")"


def print_schema_rows(rows: list[dict[str, str]]) -> None:
    """A parameter schema's rows (ft_sitl.schema.Schema.rows) as an aligned text table."""
    if not rows:
        print("(no parameters)")
        return
    head = {"name": "parameter", "default": "default", "unit": "unit", "range": "allowed"}
    width = {k: max(len(head[k]), *(len(r[k]) for r in rows)) for k in head}
    print("  ".join(f"{head[k]:{width[k]}s}" for k in head) + "  meaning")
    for r in rows:
        print("  ".join(f"{r[k]:{width[k]}s}" for k in head) + f"  {r['doc']}")


def wind_option(text: str | None) -> dict | None:
    """``--wind KEY=VALUE[,KEY=VALUE...]`` as wind settings (ft_sitl.physics.wind),
    checked (:func:`settings_option`). None when not given."""
    if text is None:
        return None
    from ft_sitl.physics.wind import Wind  # (the model only for commands given --wind)
    return settings_option("--wind", text, Wind,
                           "speed_m_s=6,from_deg=270,turbulence=moderate")


def estimator_option(text: str | None) -> dict | None:
    """``--estimator KEY=VALUE[,...]`` as estimator settings (ft_sitl.autopilot.estimator),
    checked (:func:`settings_option`). None when not given."""
    if text is None:
        return None
    from ft_sitl.autopilot.estimator import Estimator  # (likewise: the model when given)
    return settings_option("--estimator", text, Estimator,
                           "position_noise_m=0.1,position_bias_m=0.5:0:0")


def actuators_option(text: str | None) -> dict | None:
    """``--actuators KEY=VALUE[,...]`` as actuator settings (ft_sitl.physics.actuators),
    checked (:func:`settings_option`; the motor numbers against the platform where it is
    applied). None when not given."""
    if text is None:
        return None
    from ft_sitl.physics.actuators import Actuators  # (likewise: the model when given)
    return settings_option("--actuators", text, Actuators,
                           "efficiency=0.9,fail_motor=2,fail_at_s=30")


def settings_option(option: str, text: str, model, example: str) -> dict:
    """``KEY=VALUE[,KEY=VALUE...]`` as a model's settings: numbers where they parse as
    numbers (integers where written as integers), ``A:B:C`` a vector of numbers, else
    text; checked by ``model(values, option)``: a CliError names the option, the key and
    the allowed range."""
    from ft_sitl.schema import SchemaError  # (as the models: only when an option is given)

    values: dict = {}
    for item in (s.strip() for s in text.split(",")):
        key, eq, raw = item.partition("=")
        if not eq or not key.strip() or not raw.strip():
            raise CliError(f"{option}: {item!r} is not KEY=VALUE (e.g. {option} {example})")
        value: object = raw.strip()
        try:
            if ":" in raw:
                value = [float(x) for x in raw.split(":")]
            else:
                value = float(raw)
                value = int(raw)  # (an integer where it is written as one: motor numbers)
        except ValueError:
            pass
        values[key.strip()] = value
    try:
        model(values, option)
    except SchemaError as exc:
        raise CliError(str(exc)) from None
    return values
