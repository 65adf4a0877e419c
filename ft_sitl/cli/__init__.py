"""The ``ft-sitl`` command (console script ``ft_sitl.cli:main``, and ``python -m ft_sitl``).

Every subcommand prints human-readable text by default; list-type commands take
``--json`` for machine-readable output. Errors are one line on stderr naming what was
wrong, with exit status 2 for bad input.

Layout: :mod:`~ft_sitl.cli.parsers` declares every command's options and names its handler
``"MODULE:FUNCTION"``; :func:`main` imports that command module (``platforms``, ``params``,
``demo``, ``sitl``, ``scenarios``, ``missions``, ``navigators``, ``navigate``, ``bridge``)
only when its command runs, so ``ft-sitl --help`` stays quick. Command modules import what
they need at their top, and share only :mod:`~ft_sitl.cli.common`.
"""

from __future__ import annotations

import importlib
import sys

from ft_sitl.autopilot.params import ParamError
from ft_sitl.autopilot.setpoints import SetpointError
from ft_sitl.cli.common import EXIT_BAD_INPUT, CliError
from ft_sitl.cli.parsers import build_parser
from ft_sitl.physics.platform import PlatformError

__all__ = ["EXIT_BAD_INPUT", "CliError", "build_parser", "main", "resolve_handler"]


def resolve_handler(name: str):
    """The function a ``"MODULE:FUNCTION"`` handler name refers to, in ft_sitl.cli."""
    module, _, function = name.partition(":")
    return getattr(importlib.import_module(f"{__name__}.{module}"), function)


def main(argv: list[str] | None = None) -> int:
    ap = build_parser()
    try:
        args = ap.parse_args(argv)
    except CliError as exc:  # a numeric option's value (common.number)
        print(f"ft-sitl: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    handler = resolve_handler(args.handler)
    try:
        return handler(args)
    except (CliError, PlatformError, ParamError, SetpointError) as exc:
        print(f"ft-sitl: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
