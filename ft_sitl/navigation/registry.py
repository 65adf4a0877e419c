"""Navigators by name: the built-in ones and any third-party package's.

A package adds navigators with a Python entry point in the group ``ft_sitl.navigators``,
e.g. in its ``pyproject.toml``::

    [project.entry-points."ft_sitl.navigators"]
    my_planner = "my_pkg.nav:MyPlanner"

The entry point's name is the navigator's name in campaign files; it must load a
:class:`~ft_sitl.navigation.base.Navigator` subclass, which declares its parameters in its
``schema`` (a :class:`~ft_sitl.schema.Schema`; a navigator without one takes none).
Built-in navigators are registered in this module; a third-party name that clashes with a
built-in is refused with a clear error.
"""

from __future__ import annotations

from importlib.metadata import entry_points

from ft_sitl.config import did_you_mean
from ft_sitl.navigation.base import Navigator
from ft_sitl.navigation.learned.learned import Learned
from ft_sitl.navigation.learned.navrl import NavRL
from ft_sitl.navigation.planners.ego import EgoPlanner
from ft_sitl.navigation.planners.fast import FastPlanner
from ft_sitl.navigation.planners.pgo import PgoPlanner
from ft_sitl.navigation.planners.straight import StraightLine
from ft_sitl.schema import Schema, SchemaError

ENTRY_POINT_GROUP = "ft_sitl.navigators"


class NavigatorError(ValueError):
    """An unknown navigator name, or parameters it does not take."""


def _builtin() -> dict[str, type[Navigator]]:
    return {c.name: c for c in (StraightLine, EgoPlanner, FastPlanner, PgoPlanner, NavRL,
                                 Learned)}


def available() -> dict[str, type[Navigator] | str]:
    """Name -> navigator class (or an error text for an entry point that fails to load)."""
    found: dict[str, type[Navigator] | str] = dict(_builtin())
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in found:
            found[ep.name] = (f"entry point {ep.value!r} clashes with the built-in "
                              f"navigator {ep.name!r}")
            continue
        try:
            cls = ep.load()
        except Exception as exc:  # noqa: BLE001 - a broken plug-in must not stop the others
            found[ep.name] = f"entry point {ep.value!r} failed to load: {exc}"
            continue
        if not (isinstance(cls, type) and issubclass(cls, Navigator)):
            found[ep.name] = f"entry point {ep.value!r} is not a Navigator subclass"
            continue
        found[ep.name] = cls
    return found


def get_class(name: str) -> type[Navigator]:
    nav = available()
    if name not in nav:
        raise NavigatorError(f"unknown navigator {name!r}{did_you_mean(name, nav)} (available: "
                             f"{', '.join(sorted(nav))})")
    cls = nav[name]
    if isinstance(cls, str):
        raise NavigatorError(f"navigator {name!r}: {cls}")
    return cls


def parameters(cls: type[Navigator]) -> dict[str, object]:
    """The navigator's parameters and their defaults (from its declared schema)."""
    return cls.schema.defaults()


def describe(name: str) -> Schema:
    """The declared parameters of navigator ``name`` (NavigatorError if there is none by
    that name): ``describe(name).rows()`` gives name, default, unit, range and doc of each,
    ``.markdown()`` a table."""
    return get_class(name).schema


def create(name: str, params: dict | None = None) -> Navigator:
    """A new navigator ``name`` with ``params``; unknown or invalid parameters raise a
    NavigatorError naming the navigator, the key, the value and what is allowed."""
    cls = get_class(name)
    params = dict(params or {})
    try:
        cls.schema.validate(params, f"navigator {name!r}")
    except SchemaError as exc:
        raise NavigatorError(str(exc)) from None
    try:
        return cls(**params)
    except Exception as exc:  # noqa: BLE001 - a plug-in's constructor may raise anything
        raise NavigatorError(f"navigator {name!r}: {type(exc).__name__}: {exc}"
                             if not isinstance(exc, (TypeError, ValueError))
                             else f"navigator {name!r}: {exc}") from None
