"""The platform catalog: the 36 FLYINGTRUST platforms shipped with the package, and
platforms users add from TOML or YAML files.

A user file holds one ``platform`` table or a list of them. Each is given either

* by physical parameters: ``name``, ``layout`` and every key of
  :data:`ft_sitl.physics.platform.SCHEMA`; or
* by indicators: ``name``, ``layout``, ``mass_kg``, ``twr_max``,
  ``alpha_xy_max_rad_s2`` and ``alpha_z_max_rad_s2`` (the rest is synthesised exactly
  as for the catalog).

``category`` (default ``user``) and ``source`` are optional in both forms, and so are
the collision body's dimensions (:data:`ft_sitl.physics.platform.BODY_SCHEMA`:
``body_size_m``, ``rotor_disk_thickness_m``, ``rotor_height_m``; omitted, they follow the
rules of :mod:`ft_sitl.physics.body`). Anything else is rejected with a message naming
the file, the entry and the key.

Beside the catalog ship the controlled series (:mod:`ft_sitl.physics.series`, category
``series``): built from catalog bodies, then loaded as file entries in physical form, so
they pass exactly a user file's checks. A registry looks them up by name and lists them,
but its :meth:`PlatformRegistry.all` (a campaign's ``"all"``) leaves them out.
"""

from __future__ import annotations

import functools
from collections.abc import Iterable
from dataclasses import replace
from importlib import resources
from pathlib import Path

from ft_sitl.config import Table, check_keys, did_you_mean, read_document
from ft_sitl.physics.platform import (
    BODY_SCHEMA,
    CATEGORIES,
    SCHEMA,
    VECTOR_FIELDS,
    Platform,
    PlatformError,
    validate,
)
from ft_sitl.physics.series import build_series
from ft_sitl.physics.synthesis import synthesise

CATALOG_RESOURCE = "platforms.toml"
INDICATOR_KEYS = ("mass_kg", "twr_max", "alpha_xy_max_rad_s2", "alpha_z_max_rad_s2")
_COMMON_REQUIRED = ("name", "layout")
_COMMON_OPTIONAL = ("category", "source")
# Only in the packaged catalog: the paper's printed values, kept for cross-checks.
_PAPER_KEYS = ("paper_twr_max", "paper_alpha_xy_max_rad_s2", "paper_alpha_z_max_rad_s2")


def _entries(doc: dict, path: Path) -> list[dict]:
    check_keys(str(path), doc, ("platform",), error=PlatformError)
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
    allowed |= set(BODY_SCHEMA)  # optional in both forms
    if allow_paper_keys:
        allowed |= set(_PAPER_KEYS)
    name = entry.get("name")
    if isinstance(name, str):
        where = f"{where} ({name!r})"
    t = Table(entry, where, error=PlatformError)
    t.check_keys(sorted(allowed), context=f" for a platform in {form}")
    t.require(sorted(required), context=f" ({form})")
    name = t.string("name")
    category = entry.get("category", "user")
    if category not in CATEGORIES:
        raise t.fail("category", f"{category!r} is not one of {', '.join(CATEGORIES)}")
    layout = entry["layout"]
    if not isinstance(layout, str):
        raise t.fail("layout", f"must be a string such as 'quad_x', got {layout!r}")
    source = t.string("source", "", nonempty=False)
    body = {k: (tuple(t.vector3(k)) if k in VECTOR_FIELDS else t.number(k))
            for k in BODY_SCHEMA if k in entry}
    try:
        if indicator_form:
            values = {k: t.number(k) for k in INDICATOR_KEYS}
            p = synthesise(name, layout=layout, category=category, source=source, **values)
            return validate(replace(p, **body), where) if body else p
        kwargs = {}
        for key in SCHEMA:
            kwargs[key] = tuple(t.vector3(key)) if key in VECTOR_FIELDS else t.number(key)
        p = Platform(name=name, category=category, layout=layout, source=source, **kwargs,
                     **body)
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
    doc = read_document(path, what="platform file", expected="platform",
                        error=PlatformError)
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
    doc = read_document(Path(str(ref)), what="platform catalog", error=PlatformError)
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


def as_file_entry(p: Platform, where: str) -> Platform:
    """``p`` passed through the user-file path (:func:`platform_from_mapping` of its
    physical fields): the checks a platform file's entry gets, and the platform such a
    file would give."""
    return platform_from_mapping(p.physical_dict(), where)


@functools.cache
def _series() -> tuple[Platform, ...]:
    return tuple(as_file_entry(p, "series platform") for p in build_series(catalog()))


def series() -> dict[str, Platform]:
    """The controlled series (ft_sitl.physics.series), each validated as a user file's
    entry is: per base body, its TWR series then its alpha series."""
    return {p.name: p for p in _series()}


def largest_platform() -> Platform:
    """The catalog platform whose body reaches farthest (largest bounding radius): every
    scenario configuration must be solvable for its body (protocol 5), and scenario
    difficulty is measured with it."""
    return max(catalog().values(), key=lambda p: p.body().bounding_radius_m)


def paper_values() -> dict[str, dict[str, float]]:
    """The values printed in the paper's Table 1, keyed by platform name."""
    return {p.name: dict(paper) for p, paper in _catalog_with_paper()}


class PlatformRegistry:
    """The catalog, the controlled series and user platforms; look-up by exact name with
    suggestions."""

    def __init__(self, extra_files: Iterable[str | Path] = ()):
        self._platforms: dict[str, Platform] = dict(catalog()) | series()
        for f in extra_files:
            for p in load_platform_file(f):
                if p.name in self._platforms:
                    raise PlatformError(
                        f"{f}: platform {p.name!r} has the name of a platform already loaded"
                    )
                self._platforms[p.name] = p

    def _listed(self, with_series: bool) -> list[Platform]:
        shipped = series()
        return [p for name, p in self._platforms.items()
                if with_series or name not in shipped]

    def names(self, *, with_series: bool = False) -> list[str]:
        return [p.name for p in self._listed(with_series)]

    def all(self, *, with_series: bool = False) -> list[Platform]:
        """The catalog (Table 1 order) and the user files' platforms: what a campaign's
        ``"all"`` flies. ``with_series`` puts the controlled series after the catalog."""
        return self._listed(with_series)

    def category(self, name: str) -> list[Platform]:
        """Every platform of one category (``series`` included), in listing order."""
        return [p for p in self._listed(True) if p.category == name]

    def get(self, name: str) -> Platform:
        try:
            return self._platforms[name]
        except KeyError:
            hint = did_you_mean(name, self._platforms, n=3)
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
