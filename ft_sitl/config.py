"""Reading TOML and YAML configuration files: one reader for campaign files, user platform
files and scenario specs.

* :func:`read_document` reads a ``.toml``, ``.yaml`` or ``.yml`` file (chosen by suffix)
  into a dict, with one clear error naming the file for an unknown suffix, a missing or
  unreadable file, a syntax error (with the line the parser gives) or a top level that is
  not a table.
* :func:`check_keys` refuses keys a table does not allow, with a "did you mean" hint.
* :class:`Table` wraps one table of a document with where it came from and offers typed
  getters (required or optional; type; range) whose messages name the file, the key path
  and what was expected.

Every error is raised as the caller's exception class (``error=``, default
:class:`ConfigError`), so each caller keeps its own (PlatformError, ScenarioError,
CampaignError). This module imports nothing from the rest of ft_sitl.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path

import yaml

SUFFIXES = (".toml", ".yaml", ".yml")
#: how close a key must be to an allowed one to be suggested (difflib ratio)
SUGGEST_CUTOFF = 0.5
_MISSING = object()


class ConfigError(ValueError):
    """A configuration file is invalid; the message names the file and the key."""


def read_document(path: str | Path, *, what: str = "file", hint: str = "",
                  expected: str = "", error: type[Exception] = ConfigError) -> dict:
    """The top-level table of a TOML or YAML file.

    ``what`` names the kind of file in messages ("campaign file"); ``hint`` is appended to
    the not-found message (e.g. the presets); ``expected`` lists the keys a top-level table
    should hold, for the message when it is something else."""
    path = Path(path)
    suffix = path.suffix.lower()
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise error(f"{path}: no such {what}{hint}") from None
    except OSError as exc:
        raise error(f"{path}: cannot read the {what} ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise error(f"{path}: not a UTF-8 text file") from None
    # after the read: a missing file is "no such file" whatever its name (a mistyped preset)
    if suffix not in SUFFIXES:
        raise error(f"{path}: unknown {what} type {suffix or '(none)'}; "
                    "use .toml, .yaml or .yml")
    if suffix == ".toml":
        try:
            doc = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:  # its message ends "(at line L, column C)"
            raise error(f"{path}: not valid TOML: {exc}") from None
    else:
        try:
            doc = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            mark = getattr(exc, "problem_mark", None)
            where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark else ""
            problem = getattr(exc, "problem", None) or str(exc)
            raise error(f"{path}: not valid YAML{where}: {' '.join(problem.split())}") \
                from None
    if not isinstance(doc, dict):
        keys = f" ({expected})" if expected else ""
        got = "nothing" if doc is None else type(doc).__name__
        raise error(f"{path}: the top level must be a table of keys{keys}, got {got}")
    return doc


def suggestion(key, allowed: Iterable[str]) -> str | None:
    """The allowed key closest to ``key`` (difflib), or None."""
    close = difflib.get_close_matches(str(key), list(allowed), n=1, cutoff=SUGGEST_CUTOFF)
    return close[0] if close else None


def did_you_mean(key, choices: Iterable[str], *, n: int = 1) -> str:
    """``"; did you mean 'x'?"`` (up to ``n`` close choices), or ``""``: the one "did you
    mean" of every name lookup (configuration keys, navigators, platforms, parameters)."""
    close = difflib.get_close_matches(str(key), list(choices), n=n, cutoff=SUGGEST_CUTOFF)
    return f"; did you mean {', '.join(map(repr, close))}?" if close else ""


def check_keys(where: str, table: Mapping, allowed: Iterable[str], *, context: str = "",
               error: type[Exception] = ConfigError) -> None:
    """Refuse the keys of ``table`` not in ``allowed``: all of them in one message, each with
    the closest allowed key, then the allowed keys (``context`` goes before them, e.g. " for
    a platform in indicator form")."""
    allowed = list(allowed)
    unknown = [k for k in table if k not in allowed]
    if not unknown:
        return
    hints = []
    for k in unknown:
        close = suggestion(k, allowed)
        hints.append(f"{k!r}" + (f" (did you mean {close!r}?)" if close else ""))
    raise error(f"{where}: unknown key(s) {', '.join(hints)}{context}; "
                f"allowed: {', '.join(allowed)}")


class Table:
    """One table of a configuration document and where it is: ``where`` (the file, perhaps
    an entry: "c.toml: algorithms[0]") and ``prefix`` (the key path to it: "limits.").
    Getters take the value of a key, ``default`` when the key is absent (without a default
    the key is required), and check it."""

    def __init__(self, data: Mapping, where: str, *, prefix: str = "",
                 error: type[Exception] = ConfigError):
        self.data = data
        self.where = where
        self.prefix = prefix
        self.error = error

    def __contains__(self, key) -> bool:
        return key in self.data

    def fail(self, key: str, message: str) -> Exception:
        """The error for ``key``: "WHERE: PATH.KEY: message"."""
        return self.error(f"{self.where}: {self.prefix}{key}: {message}")

    def check_keys(self, allowed: Iterable[str], *, context: str = "") -> None:
        where = f"{self.where}: {self.prefix[:-1]}" if self.prefix else self.where
        check_keys(where, self.data, allowed, context=context, error=self.error)

    def require(self, keys: Iterable[str], *, context: str = "") -> None:
        """Refuse a table without all of ``keys``, naming every missing one."""
        missing = [k for k in keys if k not in self.data]
        if missing:
            raise self.error(f"{self.where}: missing key(s) "
                             f"{', '.join(self.prefix + k for k in missing)}{context}")

    def get(self, key: str, default=_MISSING):
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            raise self.error(f"{self.where}: missing key {self.prefix + key!r}")
        return default

    def integer(self, key: str, default=_MISSING, *, lo: int = 0,
                hi: int | None = None) -> int:
        """An integer within lo..hi (bools refused)."""
        return integer(self.get(key, default), self.fail, key, lo=lo, hi=hi)

    def number(self, key: str, default=_MISSING, *, lo: float | None = None,
               hi: float | None = None) -> float:
        """A finite number (an int or a float; bools refused), within lo..hi if given."""
        return number(self.get(key, default), self.fail, key, lo=lo, hi=hi)

    def string(self, key: str, default=_MISSING, *, nonempty: bool = True) -> str:
        v = self.get(key, default)
        if not isinstance(v, str) or (nonempty and not v.strip()):
            raise self.fail(key, f"must be a {'non-empty ' if nonempty else ''}string, "
                                 f"got {v!r}")
        return v

    def vector3(self, key: str, default=_MISSING) -> list[float]:
        """A list of 3 finite numbers [x, y, z]; an element's message names key[i]."""
        v = self.get(key, default)
        if not isinstance(v, list) or len(v) != 3:
            raise self.fail(key, f"needs a list of 3 numbers [x, y, z], got {v!r}")
        return [number(x, self.fail, f"{key}[{i}]") for i, x in enumerate(v)]

    def table(self, key: str, default=_MISSING) -> Table:
        """A nested table, as a :class:`Table` whose key paths start with ``key.``."""
        v = self.get(key, default)
        if not isinstance(v, Mapping):
            raise self.fail(key, f"must be a table, got {v!r}")
        return Table(v, self.where, prefix=f"{self.prefix}{key}.", error=self.error)

    def items(self, key: str, default=_MISSING) -> list:
        """A non-empty list; a lone string or table counts as a list of one."""
        v = self.get(key, default)
        if isinstance(v, (str, Mapping)):
            return [v]
        if not isinstance(v, list) or not v:
            raise self.fail(key, f"must be a non-empty list, got {v!r}")
        return v


def integer(v, fail, key: str, *, lo: int = 0, hi: int | None = None) -> int:
    """``v`` if it is an integer (not a bool) within lo..hi; else ``fail(key, message)`` (a
    :meth:`Table.fail`) is raised. For list elements: ``integer(x, table.fail, "indices")``."""
    if isinstance(v, bool) or not isinstance(v, int) or v < lo or (hi is not None and v > hi):
        rng = f"{lo}..{hi}" if hi is not None else f">= {lo}"
        raise fail(key, f"must be an integer {rng}, got {v!r}")
    return v


def number(v, fail, key: str, *, lo: float | None = None, hi: float | None = None) -> float:
    """``v`` as a float if it is a finite number within lo..hi; else ``fail(key, message)``
    (a :meth:`Table.fail`) is raised."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise fail(key, f"must be a number, got {v!r}")
    if not math.isfinite(v):
        raise fail(key, f"{v!r} is not a finite number")
    if (lo is not None and v < lo) or (hi is not None and v > hi):
        rng = (f"within {lo:g}..{hi:g}" if lo is not None and hi is not None
               else f">= {lo:g}" if lo is not None else f"<= {hi:g}")
        raise fail(key, f"must be {rng}, got {v!r}")
    return float(v)
