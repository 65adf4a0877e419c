"""Declared parameters: one :class:`Param` per parameter (name, default, unit, allowed
range or choices, a line of documentation) and a :class:`Schema` that validates a user's
mapping against them, fills in the defaults and renders itself for display.

Navigators (:mod:`ft_sitl.navigation`) and scenario families
(:mod:`ft_sitl.scenarios.families`) declare their parameters this way. The style follows
the autopilot's :class:`~ft_sitl.autopilot.params.ParamSpec` (name, default, bounds, unit,
doc), extended to the values those parameters take: optional numbers, strings with a set of
choices, flags, fixed-length vectors and ``[lo, hi]`` intervals.

A parameter marked ``derived`` is not set by the user: its value follows from the others
(a tree count from a density and an area). It is declared so that it is documented and so
that a record of the parameters (a scenario's provenance) lists every value in one order.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace

from ft_sitl import markdown as md
from ft_sitl.config import did_you_mean

KINDS = ("float", "int", "bool", "str", "vector", "interval")


class SchemaError(ValueError):
    """A value a schema refuses; the message names the owner, the key, the value and what is
    allowed."""


def _is_number(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)


def _fmt(v) -> str:
    if v is None:
        return "none"
    if isinstance(v, bool):
        return str(v).lower()
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, (tuple, list)):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return str(v)


@dataclass(frozen=True)
class Param:
    """One parameter. ``kind`` is inferred from ``default`` unless given: ``float`` (any
    finite number), ``int``, ``bool``, ``str``, ``vector`` (a fixed number of numbers, the
    default's length) or ``interval`` (``[lo, hi]`` with lo <= hi). ``range`` bounds every
    number (inclusive); ``choices`` lists a string's allowed values. ``nullable``: None is
    allowed too (inferred when the default is None)."""

    name: str
    default: object
    unit: str = "-"
    range: tuple[float, float] | None = None
    choices: tuple | None = None
    doc: str = ""
    kind: str = ""
    nullable: bool = False
    derived: bool = False

    def __post_init__(self):
        kind = self.kind
        d = self.default
        if not kind:
            if d is None and not self.derived:
                raise ValueError(f"{self.name}: give the kind of a parameter without default")
            kind = ("bool" if isinstance(d, bool) else "int" if isinstance(d, int)
                    else "float" if isinstance(d, float) else "str" if isinstance(d, str)
                    else "vector" if isinstance(d, (tuple, list)) else "float")
        if kind not in KINDS:
            raise ValueError(f"{self.name}: kind {kind!r} is not one of {', '.join(KINDS)}")
        object.__setattr__(self, "kind", kind)
        if d is None:
            object.__setattr__(self, "nullable", True)
        if isinstance(d, list):
            object.__setattr__(self, "default", tuple(d))
        if not self.derived:
            self.check(self.default, f"parameter {self.name!r} (its default)")

    @property
    def size(self) -> int | None:
        """How many numbers a vector or interval holds."""
        if self.kind == "interval":
            return 2
        if self.kind == "vector" and self.default is not None:
            return len(self.default)
        return None

    def allowed(self) -> str:
        """What the parameter accepts, in words: ``0.5..20``, ``'a' or 'b'``."""
        if self.derived:
            return "derived"
        if self.choices is not None:
            text = " or ".join(repr(c) for c in self.choices)
        elif self.kind == "bool":
            text = "true or false"
        elif self.kind == "str":
            text = "a string"
        else:
            lo, hi = self.range if self.range is not None else (-math.inf, math.inf)
            num = "an integer" if self.kind == "int" else "a number"
            text = (f"{num} {_fmt(lo)}..{_fmt(hi)}" if self.range is not None
                    else num)
            if self.kind == "vector":
                text = f"{self.size} numbers, each {_fmt(lo)}..{_fmt(hi)}"
            elif self.kind == "interval":
                text = f"[lo, hi] with {_fmt(lo)} <= lo <= hi <= {_fmt(hi)}"
        return text + (", or none" if self.nullable else "")

    def check(self, value, owner: str) -> None:
        """Raise SchemaError unless ``value`` is allowed."""
        if value is None and self.nullable:
            return
        if self._ok(value):
            return
        unit = f" ({self.unit})" if self.unit not in ("-", "") else ""
        raise SchemaError(f"{owner}: {self.name}: must be {self.allowed()}{unit}, "
                          f"got {value!r}")

    def _ok(self, value) -> bool:
        k = self.kind
        if k == "bool":
            return isinstance(value, bool)
        if k == "str":
            return isinstance(value, str) and (self.choices is None or value in self.choices)
        if k in ("float", "int"):
            if not _is_number(value) or (k == "int" and not isinstance(value, int)):
                return False
            return self._in_range(value)
        if not isinstance(value, (tuple, list)) or len(value) != self.size:
            return False
        if not all(_is_number(x) and self._in_range(x) for x in value):
            return False
        if self.default is not None and all(isinstance(x, int) for x in self.default) \
                and not all(isinstance(x, int) for x in value):
            return False
        return k != "interval" or value[0] <= value[1]

    def _in_range(self, x) -> bool:
        return self.range is None or self.range[0] <= x <= self.range[1]

    def row(self) -> dict[str, str]:
        """The parameter for display: name, default, unit, range, doc (all text)."""
        return {"name": self.name, "default": "-" if self.derived else _fmt(self.default),
                "unit": self.unit, "range": self.allowed(), "doc": self.doc}


@dataclass(frozen=True)
class Schema:
    """An ordered set of parameters."""

    params: tuple[Param, ...] = field(default_factory=tuple)

    def __post_init__(self):
        object.__setattr__(self, "params", tuple(self.params))
        names = [p.name for p in self.params]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"parameters declared twice: {', '.join(dup)}")

    def __iter__(self):
        return iter(self.params)

    def __len__(self) -> int:
        return len(self.params)

    def __contains__(self, name) -> bool:
        return any(p.name == name for p in self.params)

    def __getitem__(self, name: str) -> Param:
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(name)

    def names(self) -> list[str]:
        """The names a user may set (derived parameters left out)."""
        return [p.name for p in self.params if not p.derived]

    def defaults(self) -> dict[str, object]:
        """Name -> default of every parameter a user may set, in declaration order."""
        return {p.name: p.default for p in self.params if not p.derived}

    def extend(self, *params: Param) -> Schema:
        """This schema followed by ``params``."""
        return Schema(self.params + tuple(params))

    def with_defaults(self, **defaults) -> Schema:
        """The same parameters with other defaults (checked against their ranges)."""
        for key in defaults:
            if key not in self.names():
                raise KeyError(f"no parameter {key!r} to give a default")
        return Schema(tuple(replace(p, default=defaults[p.name]) if p.name in defaults else p
                            for p in self.params))

    def validate(self, values: Mapping | None, owner: str) -> dict[str, object]:
        """``values`` checked: an unknown or derived key, a value of the wrong type or out of
        range raises SchemaError naming ``owner`` ("navigator 'ego'"), the key, the value
        and what is allowed. Returns a copy of ``values``."""
        values = dict(values or {})
        names = self.names()
        for key, value in values.items():
            if key not in self:
                raise SchemaError(f"{owner} has no parameter {key!r}{did_you_mean(key, names)} "
                                  f"(parameters: {', '.join(names) or 'none'})")
            param = self[key]
            if param.derived:
                raise SchemaError(f"{owner}: {key} is derived from the other parameters and "
                                  f"cannot be set ({param.doc})")
            param.check(value, owner)
        return values

    def resolve(self, values: Mapping | None, owner: str) -> dict[str, object]:
        """The defaults updated with the validated ``values`` (declaration order)."""
        out = self.defaults()
        out.update(self.validate(values, owner))
        return out

    def record(self, values: Mapping, derived: Mapping) -> dict[str, object]:
        """Every parameter's value in declaration order: ``values`` for the ones a user
        sets, ``derived`` for the derived ones (each must be given)."""
        missing = [p.name for p in self.params if p.derived and p.name not in derived]
        extra = sorted(set(derived) - {p.name for p in self.params if p.derived})
        if missing or extra:
            raise ValueError(f"derived values: missing {missing}, undeclared {extra}")
        return {p.name: derived[p.name] if p.derived else values[p.name] for p in self.params}

    def rows(self) -> list[dict[str, str]]:
        """One row per parameter for display: name, default, unit, range, doc."""
        return [p.row() for p in self.params]

    def markdown(self) -> str:
        """The rows as a Markdown table (for the documentation)."""
        return md.table(["parameter", "default", "unit", "allowed", "meaning"],
                     [[f"`{r['name']}`", r["default"], r["unit"], r["range"], r["doc"]]
                      for r in self.rows()])
