"""What the command modules share: :class:`CliError`, the exit status of bad input, and
small helpers for options.

Light on purpose: ``ft_sitl.cli`` imports it to start up, before any command runs.
"""

from __future__ import annotations

from pathlib import Path

from ft_sitl.physics.catalog import PlatformRegistry

__all__ = ["EXIT_BAD_INPUT", "CliError", "check_out_dir", "fmt_point", "option_value",
           "platform_registry", "wind_option"]

EXIT_BAD_INPUT = 2


class CliError(Exception):
    """Bad input from the command line: printed as one line, exit status 2."""


def platform_registry(args) -> PlatformRegistry:
    """The catalog plus the ``--platform-file`` files of ``args``."""
    return PlatformRegistry(args.platform_file or ())


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
    """``--wind KEY=VALUE[,KEY=VALUE...]`` as wind settings (ft_sitl.physics.wind; numbers
    where they parse as numbers), checked: a CliError names the option, the key and the
    allowed range. None when not given."""
    if text is None:
        return None
    # (the wind model only for commands given --wind)
    from ft_sitl.physics.wind import Wind
    from ft_sitl.schema import SchemaError

    values: dict = {}
    for item in (s.strip() for s in text.split(",")):
        key, eq, raw = item.partition("=")
        if not eq or not key.strip() or not raw.strip():
            raise CliError(f"--wind: {item!r} is not KEY=VALUE (e.g. --wind "
                           f"speed_m_s=6,from_deg=270,turbulence=moderate)")
        try:
            value: object = float(raw)
        except ValueError:
            value = raw.strip()
        values[key.strip()] = value
    try:
        Wind(values, "--wind")
    except SchemaError as exc:
        raise CliError(str(exc)) from None
    return values
