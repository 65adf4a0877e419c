"""The platform catalog: the 36 FLYINGTRUST platforms shipped with the package, and
platforms users add from TOML or YAML files.

A user file holds one ``platform`` table or a list of them. Each is given either

* by physical parameters: ``name``, ``layout`` and every key of
  :data:`ft_sitl.physics.platform.SCHEMA`; or
* by indicators: ``name``, ``layout``, ``mass_kg``, ``twr_max``,
  ``alpha_xy_max_rad_s2`` and ``alpha_z_max_rad_s2`` (the rest is synthesised exactly
  as for the catalog).

``category`` (default ``user``) and ``source`` are optional in both forms. Anything
else is rejected with a message naming the file, the entry and the key.
"""

from __future__ import annotations

import difflib
import functools
import math
import tomllib
from collections.abc import Iterable
from importlib import resources
from pathlib import Path

import yaml

from ft_sitl.physics.platform import (
    CATEGORIES,
    SCHEMA,
    VECTOR_FIELDS,
    Platform,
    PlatformError,
    validate,
)
from ft_sitl.physics.synthesis import synthesise

CATALOG_RESOURCE = "platforms.toml"
INDICATOR_KEYS = ("mass_kg", "twr_max", "alpha_xy_max_rad_s2", "alpha_z_max_rad_s2")
_COMMON_REQUIRED = ("name", "layout")
_COMMON_OPTIONAL = ("category", "source")
# Only in the packaged catalog: the paper's printed values, kept for cross-checks.
_PAPER_KEYS = ("paper_twr_max", "paper_alpha_xy_max_rad_s2", "paper_alpha_z_max_rad_s2")


def _read_document(path: Path) -> dict:
    suffix = path.suffix.lower()
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise PlatformError(f"{path}: cannot read the file ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise PlatformError(f"{path}: not a UTF-8 text file") from None
    try:
        if suffix == ".toml":
            doc = tomllib.loads(text)
        elif suffix in (".yaml", ".yml"):
            doc = yaml.safe_load(text)
        else:
            raise PlatformError(
                f"{path}: unknown file type {suffix or '(none)'}; use .toml, .yaml or .yml"
            )
    except (tomllib.TOMLDecodeError, yaml.YAMLError) as exc:
        raise PlatformError(f"{path}: not valid {suffix[1:].upper()}: {exc}") from None
    if not isinstance(doc, dict):
        raise PlatformError(f"{path}: the top level must be a table with a 'platform' key")
    return doc


def _entries(doc: dict, path: Path) -> list[dict]:
    extra = sorted(set(doc) - {"platform"})
    if extra:
        raise PlatformError(
            f"{path}: unknown top-level key(s) {', '.join(map(repr, extra))}; "
            "expected only 'platform'"
        )
    if "platform" not in doc:
        raise PlatformError(f"{path}: missing the 'platform' table (or list of tables)")
    entries = doc["platform"]
    if isinstance(entries, dict):
        entries = [entries]
    if not isinstance(entries, list) or not entries:
        raise PlatformError(f"{path}: 'platform' must be a table or a non-empty list of tables")
    for i, e in enumerate(entries):
        if not isinstance(e, dict):
            raise PlatformError(f"{path}: platform[{i}] must be a table, got {type(e).__name__}")
    return entries


def _number(where: str, key: str, v) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise PlatformError(f"{where}: {key}: {v!r} is not a finite number")
    return float(v)


def platform_from_mapping(entry: dict, where: str, *, allow_paper_keys: bool = False) -> Platform:
    """Build and validate one platform from a file entry (see the module docstring)."""
    keys = set(entry)
    indicator_form = "twr_max" in keys or any(k.startswith("alpha_") for k in keys)
    if indicator_form:
        allowed = set(_COMMON_REQUIRED + _COMMON_OPTIONAL + INDICATOR_KEYS)
        required = set(_COMMON_REQUIRED + INDICATOR_KEYS)
        form = "indicator form"
    else:
        allowed = set(_COMMON_REQUIRED + _COMMON_OPTIONAL) | set(SCHEMA)
        required = set(_COMMON_REQUIRED) | set(SCHEMA)
        form = "physical form"
    if allow_paper_keys:
        allowed |= set(_PAPER_KEYS)
    name = entry.get("name")
    if isinstance(name, str):
        where = f"{where} ({name!r})"
    unknown = sorted(keys - allowed)
    if unknown:
        hints = []
        for k in unknown:
            close = difflib.get_close_matches(k, sorted(allowed), n=1)
            hints.append(f"{k!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
        raise PlatformError(
            f"{where}: unknown key(s) {', '.join(hints)} for a platform in {form}; "
            f"allowed: {', '.join(sorted(allowed))}"
        )
    missing = sorted(required - keys)
    if missing:
        raise PlatformError(f"{where}: missing key(s) {', '.join(missing)} ({form})")
    if not isinstance(name, str) or not name.strip():
        raise PlatformError(f"{where}: name: must be a non-empty string")
    category = entry.get("category", "user")
    if category not in CATEGORIES:
        raise PlatformError(
            f"{where}: category: {category!r} is not one of {', '.join(CATEGORIES)}"
        )
    layout = entry["layout"]
    if not isinstance(layout, str):
        raise PlatformError(f"{where}: layout: must be a string such as 'quad_x'")
    source = entry.get("source", "")
    if not isinstance(source, str):
        raise PlatformError(f"{where}: source: must be a string")
    try:
        if indicator_form:
            values = {k: _number(where, k, entry[k]) for k in INDICATOR_KEYS}
            return synthesise(
                name, layout=layout, category=category, source=source, **values
            )
        kwargs = {}
        for key in SCHEMA:
            v = entry[key]
            if key in VECTOR_FIELDS:
                if not isinstance(v, list) or len(v) != 3:
                    raise PlatformError(f"{where}: {key}: needs a list of 3 numbers [x, y, z]")
                kwargs[key] = tuple(_number(where, key, x) for x in v)
            else:
                kwargs[key] = _number(where, key, v)
        p = Platform(name=name, category=category, layout=layout, source=source, **kwargs)
        return validate(p, where)
    except PlatformError as exc:
        msg = str(exc)
        inner = f"platform {name!r}: "
        if msg.startswith(inner):  # synthesise/validate name the platform; we name more
            msg = msg[len(inner):]
        raise PlatformError(msg if msg.startswith(where) else f"{where}: {msg}") from None


def load_platform_file(path: str | Path) -> list[Platform]:
    """All platforms of a user file, validated. Raises PlatformError naming what is wrong."""
    path = Path(path)
    doc = _read_document(path)
    out = []
    seen = set()
    for i, entry in enumerate(_entries(doc, path)):
        p = platform_from_mapping(entry, f"{path}: platform[{i}]")
        if p.name in seen:
            raise PlatformError(f"{path}: platform[{i}]: name {p.name!r} appears twice")
        seen.add(p.name)
        out.append(p)
    return out


@functools.cache
def _catalog_with_paper() -> tuple[tuple[Platform, dict], ...]:
    ref = resources.files("ft_sitl.physics.data").joinpath(CATALOG_RESOURCE)
    doc = tomllib.loads(ref.read_text(encoding="utf-8"))
    out = []
    for i, entry in enumerate(doc["platform"]):
        paper = {k: entry[k] for k in _PAPER_KEYS if k in entry}
        p = platform_from_mapping(
            entry, f"{CATALOG_RESOURCE}: platform[{i}]", allow_paper_keys=True
        )
        out.append((p, paper))
    return tuple(out)


def catalog() -> dict[str, Platform]:
    """The 36 FLYINGTRUST platforms, in the paper's Table 1 order."""
    return {p.name: p for p, _ in _catalog_with_paper()}


def paper_values() -> dict[str, dict[str, float]]:
    """The values printed in the paper's Table 1, keyed by platform name."""
    return {p.name: dict(paper) for p, paper in _catalog_with_paper()}


class PlatformRegistry:
    """The catalog plus user platforms; look-up by exact name with suggestions."""

    def __init__(self, extra_files: Iterable[str | Path] = ()):
        self._platforms: dict[str, Platform] = dict(catalog())
        for f in extra_files:
            for p in load_platform_file(f):
                if p.name in self._platforms:
                    raise PlatformError(
                        f"{f}: platform {p.name!r} has the name of a platform already loaded"
                    )
                self._platforms[p.name] = p

    def names(self) -> list[str]:
        return list(self._platforms)

    def all(self) -> list[Platform]:
        return list(self._platforms.values())

    def get(self, name: str) -> Platform:
        try:
            return self._platforms[name]
        except KeyError:
            close = difflib.get_close_matches(name, self._platforms, n=3, cutoff=0.5)
            hint = f"; did you mean {', '.join(map(repr, close))}?" if close else ""
            raise PlatformError(
                f"unknown platform {name!r}{hint} ('ft-sitl platforms list' shows all)"
            ) from None


def get_platform(name: str) -> Platform:
    """A catalog platform by name."""
    return PlatformRegistry().get(name)


def to_toml(platforms: Iterable[Platform], extra: dict[str, dict] | None = None) -> str:
    """Serialise platforms as a TOML user file (physical form) that load_platform_file reads."""
    lines = []
    for p in platforms:
        lines.append("[[platform]]")
        for key, value in p.physical_dict().items():
            lines.append(f"{key} = {_toml_value(value)}")
        for key, value in (extra or {}).get(p.name, {}).items():
            lines.append(f"{key} = {_toml_value(value)}")
        lines.append("")
    return "\n".join(lines)


def _toml_value(v) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, float):
        return repr(float(v))
    return str(v)
