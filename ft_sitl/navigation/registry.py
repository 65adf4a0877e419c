"""Navigators by name: the built-in ones and any third-party package's.

A package adds navigators with a Python entry point in the group ``ft_sitl.navigators``,
e.g. in its ``pyproject.toml``::

    [project.entry-points."ft_sitl.navigators"]
    my_planner = "my_pkg.nav:MyPlanner"

The entry point's name is the navigator's name in campaign files; it must load a
:class:`~ft_sitl.navigation.base.Navigator` subclass. Built-in navigators are registered in
this module; a third-party name that clashes with a built-in is refused with a clear error.
"""

from __future__ import annotations

import difflib
import inspect
from importlib.metadata import entry_points

from ft_sitl.navigation.base import Navigator

ENTRY_POINT_GROUP = "ft_sitl.navigators"


class NavigatorError(ValueError):
    """An unknown navigator name, or parameters it does not take."""


def _builtin() -> dict[str, type[Navigator]]:
    from ft_sitl.navigation.ego import EgoPlanner
    from ft_sitl.navigation.fast import FastPlanner
    from ft_sitl.navigation.navrl import NavRL
    from ft_sitl.navigation.pgo import PgoPlanner
    from ft_sitl.navigation.straight import StraightLine

    return {c.name: c for c in (StraightLine, EgoPlanner, FastPlanner, PgoPlanner, NavRL)}


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
        close = difflib.get_close_matches(str(name), list(nav), n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise NavigatorError(f"unknown navigator {name!r}{hint} (available: "
                             f"{', '.join(sorted(nav))})")
    cls = nav[name]
    if isinstance(cls, str):
        raise NavigatorError(f"navigator {name!r}: {cls}")
    return cls


def parameters(cls: type[Navigator]) -> dict[str, object]:
    """The navigator's parameters and their defaults (from its constructor)."""
    out = {}
    for p in inspect.signature(cls.__init__).parameters.values():
        if p.name == "self" or p.kind in (p.VAR_KEYWORD, p.VAR_POSITIONAL):
            continue
        out[p.name] = None if p.default is inspect.Parameter.empty else p.default
    return out


def create(name: str, params: dict | None = None) -> Navigator:
    """A new navigator ``name`` with ``params``; unknown or invalid parameters raise a
    NavigatorError naming them."""
    cls = get_class(name)
    params = dict(params or {})
    known = parameters(cls)
    for key in params:
        if key not in known:
            close = difflib.get_close_matches(key, list(known), n=1)
            hint = f"; did you mean {close[0]!r}?" if close else ""
            raise NavigatorError(f"navigator {name!r} has no parameter {key!r}{hint} "
                                 f"(parameters: {', '.join(known) or 'none'})")
    try:
        return cls(**params)
    except Exception as exc:  # noqa: BLE001 - a plug-in's constructor may raise anything
        raise NavigatorError(f"navigator {name!r}: {type(exc).__name__}: {exc}"
                             if not isinstance(exc, (TypeError, ValueError))
                             else f"navigator {name!r}: {exc}") from None
