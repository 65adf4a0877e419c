"""Geofence and rally points, as PX4's navigator keeps them.

A :class:`Fence` is what a ground station uploads with the MAVLink mission protocol's
fence type (``MAV_MISSION_TYPE_FENCE``): inclusion and exclusion polygons and circles,
and an optional return point, here in the local ENU frame (m). PX4's rule decides
whether a position is inside: inside at least one inclusion area (when there is any) and
outside every exclusion area. Two parameters add PX4's simple fences around home:
``GF_MAX_HOR_DIST`` (horizontal distance from home) and ``GF_MAX_VER_DIST`` (height above
home); 0 disables each.

What a breach does is the commander's (``GF_ACTION``: 0 none, 1 warning, 2 hold, 3
return, 4 terminate, 5 land, PX4's values: :data:`GF_ACTIONS`); this module only answers
whether and why a position breaches, and checks what makes a fence (:func:`polygon`,
:func:`circle`, :func:`check_items`) for every way one arrives (a MAVLink upload, a trial
spec's ``fence``).

Rally points (``MAV_MISSION_TYPE_RALLY``) are positions RTL may return to instead of
home: PX4 returns to the nearest of home and the rally points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: the most fence or rally items a vehicle stores (PX4's dataman holds a few hundred)
MAX_ITEMS = 256
#: GF_ACTION's values (PX4's geofence_result constants), by name
GF_ACTIONS = {0: "none", 1: "warning", 2: "hold", 3: "return", 4: "terminate", 5: "land"}
#: the actions by which the flight controller takes the vehicle from whoever flies it (a
#: mode of its own, or termination); "none" and "warning" leave the flight as it was
TAKEOVER_ACTIONS = ("hold", "return", "terminate", "land")


class FenceError(ValueError):
    """A fence or rally upload PX4 would refuse; the message names the item."""


@dataclass(frozen=True)
class Polygon:
    vertices: np.ndarray  # (n, 2) ENU x, y (m)
    inclusion: bool

    def contains(self, x: float, y: float) -> bool:
        """Even-odd ray casting (a point on an edge counts as either)."""
        v = self.vertices
        inside = False
        j = len(v) - 1
        for i in range(len(v)):
            xi, yi = v[i]
            xj, yj = v[j]
            if (yi > y) != (yj > y) and x < (xj - xi) * (y - yi) / (yj - yi) + xi:
                inside = not inside
            j = i
        return inside


@dataclass(frozen=True)
class Circle:
    center: np.ndarray  # (2,) ENU x, y (m)
    radius_m: float
    inclusion: bool

    def contains(self, x: float, y: float) -> bool:
        return math.hypot(x - self.center[0], y - self.center[1]) <= self.radius_m


@dataclass
class Fence:
    """Inclusion/exclusion polygons and circles (local ENU) and a return point."""

    areas: list = field(default_factory=list)
    return_point: np.ndarray | None = None

    @property
    def empty(self) -> bool:
        return not self.areas

    @property
    def n_items(self) -> int:
        """How many fence items it takes (MAV_MISSION_TYPE_FENCE): a polygon's vertices,
        one per circle, one for the return point."""
        return (sum(len(a.vertices) if isinstance(a, Polygon) else 1 for a in self.areas)
                + (self.return_point is not None))

    def inside_areas(self, x: float, y: float) -> bool:
        """PX4's rule: inside an inclusion area (if any) and outside every exclusion."""
        had_inclusion = inside_inclusion = False
        for a in self.areas:
            inside = a.contains(x, y)
            if a.inclusion:
                had_inclusion = True
                inside_inclusion = inside_inclusion or inside
            elif inside:
                return False
        return inside_inclusion or not had_inclusion

    def breach(self, position, home, max_hor_m: float, max_ver_m: float) -> str | None:
        """Why ``position`` (local ENU) breaches the fence around ``home``, or None."""
        p = np.asarray(position, dtype=float)
        if max_hor_m > 0 and math.hypot(p[0] - home[0], p[1] - home[1]) > max_hor_m:
            return f"more than {max_hor_m:g} m from home"
        if max_ver_m > 0 and p[2] - home[2] > max_ver_m:
            return f"more than {max_ver_m:g} m above home"
        if not self.inside_areas(p[0], p[1]):
            return "outside the fence"
        return None


def _segments_cross(a, b, c, d) -> bool:
    """True when segments ab and cd properly cross (shared end points do not count)."""
    def orient(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    d1, d2 = orient(c, d, a), orient(c, d, b)
    d3, d4 = orient(a, b, c), orient(a, b, d)
    return (d1 * d2 < 0) and (d3 * d4 < 0)


def fits(n_items: int) -> bool:
    """Whether ``n_items`` fence (or rally) items fit in the vehicle (:data:`MAX_ITEMS`)."""
    return n_items <= MAX_ITEMS


def check_items(n: int, where: str) -> None:
    """FenceError unless ``n`` fence (or rally) items fit in the vehicle (:func:`fits`)."""
    if not fits(n):
        raise FenceError(f"{where}: {n} items, more than the {MAX_ITEMS} fence or rally items "
                         f"a vehicle stores")


def _numbers(values, where: str, what: str) -> np.ndarray:
    """``values`` (a sequence of numbers, or of such sequences) as a float array; FenceError
    naming ``what`` for anything else (a string, a flag, a ragged list)."""
    def leaves(v):
        if isinstance(v, (list, tuple, np.ndarray)):
            for x in v:
                yield from leaves(x)
        else:
            yield v
    try:
        flat = list(leaves(values))
        ok = all(isinstance(x, (int, float, np.number)) and not isinstance(x, (bool, np.bool_))
                 for x in flat)
        array = np.asarray(values, dtype=float) if ok else None
    except (TypeError, ValueError):
        array = None
    if array is None:
        raise FenceError(f"{where}: {what} must be numbers (m), got {values!r}")
    return array


def polygon(vertices, inclusion: bool, where: str) -> Polygon:
    """A checked polygon: at least 3 finite [x, y] vertices, edges that do not cross."""
    v = _numbers(vertices, where, "the polygon's vertices")
    if v.ndim != 2 or v.shape[1] != 2:
        raise FenceError(f"{where}: the polygon's vertices must be [x, y] pairs (m), got "
                         f"{vertices!r}")
    if len(v) < 3:
        raise FenceError(f"{where}: a polygon needs at least 3 vertices, got {len(v)}")
    if not np.all(np.isfinite(v)):
        raise FenceError(f"{where}: a polygon vertex is not a finite position")
    n = len(v)
    for i in range(n):
        for j in range(i + 1, n):
            if j == i + 1 or (i == 0 and j == n - 1):
                continue  # neighbouring edges share a vertex
            if _segments_cross(v[i], v[(i + 1) % n], v[j], v[(j + 1) % n]):
                raise FenceError(f"{where}: the polygon's edges {i}-{i + 1} and {j}-"
                                 f"{(j + 1) % n} cross (a self-intersecting polygon)")
    return Polygon(v, inclusion)


def circle(center, radius_m: float, inclusion: bool, where: str) -> Circle:
    """A checked circle: a finite [x, y] centre, a positive finite radius (m)."""
    c = _numbers(center, where, "the circle's centre")
    if c.shape != (2,):
        raise FenceError(f"{where}: the circle's centre must be [x, y] (m), got {center!r}")
    if not np.all(np.isfinite(c)):
        raise FenceError(f"{where}: the circle's centre is not a finite position")
    if isinstance(radius_m, bool) or not isinstance(radius_m, (int, float, np.number)) or \
            not (math.isfinite(radius_m) and radius_m > 0):
        raise FenceError(f"{where}: the circle's radius must be a positive number of "
                         f"metres, got {radius_m!r}")
    return Circle(c, float(radius_m), inclusion)


def nearest_safe_point(position, home, rally: list) -> np.ndarray:
    """Where RTL goes: the nearest (horizontally) of home and the rally points."""
    p = np.asarray(position, dtype=float)
    best = np.asarray(home, dtype=float)
    best_d = math.hypot(*(best[:2] - p[:2]))
    for r in rally:
        d = math.hypot(*(r[:2] - p[:2]))
        if d < best_d:
            best, best_d = np.asarray(r, dtype=float), d
    return best.copy()
