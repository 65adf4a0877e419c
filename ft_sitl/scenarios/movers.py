"""Moving obstacles ("movers"): people, vehicles and balls on seeded paths through a scenario.

World frame ENU, metres, seconds. A mover is a kinematic primitive (it pushes nothing and
nothing pushes it) following a closed-form path, so every part of the simulator evaluates
where it is at any time without stepping any state:

* ``person``: a vertical cylinder standing on the floor (radius ``radius_m``, height
  ``height_m``);
* ``box``: a box standing on the floor, its long side along its direction of travel
  (length ``box_length_m``, width ``box_width_m``, height ``height_m``): a cart or a car;
* ``sphere``: a ball of radius ``radius_m`` flying level at the scenario's start altitude
  +- 0.5 m: a balloon or another drone.

Paths (``path``), each a polyline walked at ``speed_m_s``:

* ``line``: back and forth along a straight segment of ``path_length_m``;
* ``waypoints``: round a closed loop of 3-5 waypoints within ``path_length_m`` / 2 of a
  centre;
* ``random_walk``: a seeded random walk of 40 legs (1-4 m, the heading turning by a normal
  0.8 rad each leg) inside a square of side ``path_length_m``, walked back and forth;
* ``crossing``: back and forth along a segment of ``path_length_m`` across the start-goal
  line (at 25-85 % of its length), timed to reach the line ``crossing_s`` after the
  navigation starts;
* ``mixed``: each mover draws one of the four.

Placement is rejection sampling, deterministic for ``seed``: every leg of a path keeps the
mover's bounding radius plus :data:`STATIC_CLEARANCE_M` clear of the scenario's static
obstacles (tested on segments at the mover's bottom, middle and top heights, so a slanted
obstacle between those heights may still be grazed), stays inside the scenario's area, and
the mover's position at the navigation start is at least ``keep_out_m`` from the start
waypoint (and from the take-off spot). A mover that finds no such path in
:data:`MAX_TRIES` draws is dropped: :attr:`Movers.count` is what was placed, and the
trial's row records it.

Clock: a mover's time is ``(t_us - start_us) / 1e6`` clamped at 0: before its field is
started (the trial protocol starts it at the navigation start; ``ft-sitl sitl`` at 0) every
mover waits at its first position.

The numbers a compiled loop needs are flat arrays (:class:`Movers`); :func:`mover_poses`,
:func:`mover_distances` and :func:`ray_first_hit` are the compiled evaluations shared by the
collision guard, the depth camera, the bus and the metrics (one implementation of each).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from ft_sitl.mover_kinds import MAX_MOVERS, SHAPES, SIZE_FIELDS
from ft_sitl.scenarios.solvability import segment_mesh_distance
from ft_sitl.schema import Param, Schema, SchemaError

#: kinds of shape, as stored in :attr:`Movers.kind`: indices into SHAPES (declared, with
#: MAX_MOVERS, in ft_sitl.mover_kinds, which the bus shares)
CYLINDER, BOX, SPHERE = 0, 1, 2
PATHS = ("line", "waypoints", "random_walk", "crossing")
#: how a path is walked: back and forth, or round a loop
PINGPONG, LOOP = 0, 1
#: kept between a mover's path and the static obstacles (m), on top of its bounding radius
STATIC_CLEARANCE_M = 0.1
#: draws per mover before it is dropped
MAX_TRIES = 60
#: legs of a random walk
WALK_LEGS = 40
#: the clock of a field that has not been started (its movers wait at their first position)
NOT_STARTED = 2 ** 62
#: a sphere flies at the start altitude plus a uniform draw in +- this (m)
SPHERE_ALTITUDE_SPREAD_M = 0.5

SCHEMA = Schema((
    Param("count", 0, "-", (0, MAX_MOVERS), doc="how many moving obstacles (0: see density)"),
    Param("density_per_1000m2", 0.0, "1/1000 m^2", (0.0, 50.0),
          doc="movers per 1000 m^2 of the scenario's area, when count is 0"),
    Param("speed_m_s", 1.5, "m/s", (0.0, 10.0), doc="each mover's speed along its path"),
    Param("shape", "person", choices=SHAPES + ("mixed",),
          doc="person (standing cylinder), box (a cart or car), sphere (flying), or mixed"),
    Param("path", "mixed", choices=PATHS + ("mixed",),
          doc="line, waypoints, random_walk, crossing (the start-goal line), or mixed"),
    Param("radius_m", (0.3, 0.5), "m", (0.05, 5.0), kind="interval",
          doc="radius of a person or a sphere, drawn uniformly"),
    Param("height_m", (1.7, 2.2), "m", (0.2, 20.0), kind="interval",
          doc="height of a person or a box, drawn uniformly"),
    Param("box_length_m", (2.0, 4.0), "m", (0.2, 20.0), kind="interval",
          doc="length of a box (along its travel)"),
    Param("box_width_m", (1.0, 1.8), "m", (0.2, 20.0), kind="interval", doc="width of a box"),
    Param("path_length_m", (6.0, 20.0), "m", (1.0, 500.0), kind="interval",
          doc="length of a line or crossing, span of a loop or a walk's square"),
    Param("crossing_s", (2.0, 15.0), "s", (0.0, 600.0), kind="interval",
          doc="when a crossing mover reaches the start-goal line, after navigation starts"),
    Param("keep_out_m", 4.0, "m", (0.0, 100.0),
          doc="no mover starts nearer the start waypoint or the take-off spot"),
))


class MoverError(SchemaError):
    """Mover settings or a request for movers that cannot be met; the message says which."""


def settings(values, owner: str = "movers") -> dict:
    """``values`` validated against :data:`SCHEMA` with the defaults filled in
    (MoverError naming ``owner`` and the key)."""
    try:
        out = SCHEMA.resolve(values, owner)
    except SchemaError as exc:
        raise MoverError(str(exc)) from None
    if out["count"] and out["density_per_1000m2"]:
        raise MoverError(f"{owner}: give count or density_per_1000m2, not both")
    return out


class MoverSettings:
    """Validated mover settings (``.values``), the shape the trial spec's checks take."""

    def __init__(self, values, owner: str = "movers"):
        self.values = settings(values, owner)


@dataclass(frozen=True, eq=False)
class Movers:
    """The movers of one trial as flat arrays (M movers, K path points at most).

    ``kind`` (M,) :data:`CYLINDER` / :data:`BOX` / :data:`SPHERE`; ``dims`` (M, 3): a
    cylinder's (radius, half height, 0), a box's half (length, width, height), a sphere's
    (radius, 0, 0); ``points`` (M, K, 3) path points of the shape's centre, ``n_points``
    (M,) how many are used, ``cum`` (M, K) arc length at each point, ``length`` (M,) the
    path's length, ``mode`` (M,) :data:`PINGPONG` or :data:`LOOP`, ``s0`` (M,) the arc
    length at time 0, ``speed`` (M,) m/s; ``bounding`` (M,) radius of a sphere about the
    centre holding the shape. ``names`` ("person 1", "box 2", ...), ``paths`` (each
    mover's path kind) and ``settings`` (as resolved) describe them; ``start_us`` is the
    field's clock origin (:meth:`start`)."""

    kind: np.ndarray
    dims: np.ndarray
    points: np.ndarray
    n_points: np.ndarray
    cum: np.ndarray
    length: np.ndarray
    mode: np.ndarray
    s0: np.ndarray
    speed: np.ndarray
    bounding: np.ndarray
    names: tuple
    paths: tuple
    settings: dict
    clock: np.ndarray  # [start_us] (a one-element array: the frozen dataclass's mutable part)

    @property
    def count(self) -> int:
        return len(self.kind)

    @property
    def start_us(self) -> int:
        return int(self.clock[0])

    def start(self, t_us: int) -> None:
        """Start the movers' clock at simulation time ``t_us``."""
        self.clock[0] = int(t_us)

    def time_s(self, t_us: int) -> float:
        """The movers' time (s) at simulation time ``t_us`` (0 before the start)."""
        return max(0.0, (int(t_us) - int(self.clock[0])) * 1e-6)

    def poses(self, t_us: int, out: np.ndarray | None = None) -> np.ndarray:
        """(M, 4) centre x, y, z and heading (rad, ENU from east) at simulation time t_us."""
        out = np.empty((self.count, 4)) if out is None else out
        mover_poses(self.time_s(t_us), self.speed, self.length, self.mode, self.s0,
                    self.n_points, self.cum, self.points, out)
        return out

    def velocities(self, t_us: int) -> np.ndarray:
        """(M, 3) velocity (m/s) at simulation time t_us: 0 before the start."""
        v = np.zeros((self.count, 3))
        t = self.time_s(t_us)
        if t > 0.0:
            mover_velocities(t, self.speed, self.length, self.mode, self.s0, self.n_points,
                             self.cum, self.points, v)
        return v

    def boxes(self, t_us: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each mover as an axis-aligned box at simulation time t_us: centres (M, 3),
        velocities (M, 3) (m/s) and full sizes (M, 3) (m; a box turned by its heading
        gets the box around it)."""
        p = self.poses(t_us)
        size = np.empty((self.count, 3))
        for j in range(self.count):
            k, d = int(self.kind[j]), self.dims[j]
            if k == CYLINDER:
                size[j] = (2 * d[0], 2 * d[0], 2 * d[1])
            elif k == BOX:
                c, s = abs(math.cos(p[j, 3])), abs(math.sin(p[j, 3]))
                size[j] = (2 * (c * d[0] + s * d[1]), 2 * (s * d[0] + c * d[1]), 2 * d[2])
            else:
                size[j] = 2 * d[0]
        return p[:, :3].copy(), self.velocities(t_us), size

    def as_list(self) -> list[dict]:
        """The movers as :func:`movers_from_list` takes them (JSON types): what a scenario
        spec file writes so that loading it gives these paths exactly."""
        out = []
        for j in range(self.count):
            k = int(self.kind[j])
            dims = [float(v) for v in self.dims[j]]
            size = {CYLINDER: {"radius_m": dims[0], "height_m": 2.0 * dims[1]},
                    BOX: {"length_m": 2.0 * dims[0], "width_m": 2.0 * dims[1],
                          "height_m": 2.0 * dims[2]},
                    SPHERE: {"radius_m": dims[0]}}[k]
            pts = self.points[j, :int(self.n_points[j])]
            loop = int(self.mode[j]) == LOOP
            if loop:  # (movers_from_list closes the loop itself)
                pts = pts[:-1]
            out.append({"shape": SHAPES[k], **size, "points": pts.tolist(),
                        "speed_m_s": float(self.speed[j]), "loop": loop,
                        "start_m": float(self.s0[j])})
        return out

    def describe(self) -> list[dict]:
        """One dict per mover: name, shape, size and path (JSON types)."""
        out = []
        for j in range(self.count):
            k = int(self.kind[j])
            d = self.dims[j]
            values = {CYLINDER: (d[0], 2 * d[1]), BOX: (2 * d[0], 2 * d[1], 2 * d[2]),
                      SPHERE: (d[0],)}[k]
            size = dict(zip(SIZE_FIELDS[SHAPES[k]], values, strict=True))
            out.append({"name": self.names[j], "shape": SHAPES[k], "path": self.paths[j],
                        **{a: round(float(b), 4) for a, b in size.items()},
                        "speed_m_s": float(self.speed[j]),
                        "path_length_m": round(float(self.length[j]), 4)})
        return out


EMPTY_NAMES: tuple = ()


def no_movers() -> Movers:
    """An empty field (what a static scenario has)."""
    z = np.zeros(0)
    return Movers(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 2, 3)),
                  np.zeros(0, np.int64), np.zeros((0, 2)), z, np.zeros(0, np.int64), z, z, z,
                  EMPTY_NAMES, EMPTY_NAMES, {}, np.zeros(1, np.int64))


# --- compiled evaluations --------------------------------------------------------------------

@njit(cache=True)
def _leg(j, t, speed, length, mode, s0, n_points, cum):
    """Where mover j is at mover time t: its leg k (cum[k] <= s <= cum[k + 1]), the
    fraction along it and whether it walks the leg backwards; k = -1 for a mover that
    does not move (one point, or a path of no length)."""
    n = n_points[j]
    L = length[j]
    if n < 2 or L <= 0.0:
        return -1, 0.0, False
    s = s0[j] + speed[j] * t
    back = False
    if mode[j] == PINGPONG:
        s = s % (2.0 * L)
        if s > L:
            s = 2.0 * L - s
            back = True
    else:
        s = s % L
    lo, hi = 0, n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if cum[j, mid] <= s:
            lo = mid
        else:
            hi = mid
    seg = cum[j, lo + 1] - cum[j, lo]
    return lo, ((s - cum[j, lo]) / seg if seg > 0.0 else 0.0), back


@njit(cache=True)
def mover_poses(t, speed, length, mode, s0, n_points, cum, points, out):
    """Each mover's centre and heading at mover time t (s) into out (M, 4)."""
    for j in range(speed.shape[0]):
        k, f, back = _leg(j, t, speed, length, mode, s0, n_points, cum)
        if k < 0:
            out[j, 0] = points[j, 0, 0]
            out[j, 1] = points[j, 0, 1]
            out[j, 2] = points[j, 0, 2]
            out[j, 3] = 0.0
            continue
        dx = points[j, k + 1, 0] - points[j, k, 0]
        dy = points[j, k + 1, 1] - points[j, k, 1]
        out[j, 0] = points[j, k, 0] + f * dx
        out[j, 1] = points[j, k, 1] + f * dy
        out[j, 2] = points[j, k, 2] + f * (points[j, k + 1, 2] - points[j, k, 2])
        h = math.atan2(dy, dx)
        if back:
            h = h + math.pi if h <= 0.0 else h - math.pi
        out[j, 3] = h


@njit(cache=True)
def mover_velocities(t, speed, length, mode, s0, n_points, cum, points, out):
    """Each mover's velocity (m/s, along its current leg, the vertical included) at mover
    time t into out (M, 3); 0 for one that does not move."""
    for j in range(speed.shape[0]):
        k, _, back = _leg(j, t, speed, length, mode, s0, n_points, cum)
        seg = cum[j, k + 1] - cum[j, k] if k >= 0 else 0.0
        if seg <= 0.0:
            out[j, 0] = out[j, 1] = out[j, 2] = 0.0
            continue
        g = (-speed[j] if back else speed[j]) / seg
        for a in range(3):
            out[j, a] = g * (points[j, k + 1, a] - points[j, k, a])


@njit(cache=True)
def shape_distance(kind, dims, cx, cy, cz, heading, px, py, pz):
    """Signed distance (m) from the point p to one mover's surface (< 0 inside)."""
    if kind == SPHERE:
        return math.sqrt((px - cx) ** 2 + (py - cy) ** 2 + (pz - cz) ** 2) - dims[0]
    if kind == CYLINDER:
        a = math.sqrt((px - cx) ** 2 + (py - cy) ** 2) - dims[0]
        b = abs(pz - cz) - dims[1]
    else:
        c, s = math.cos(heading), math.sin(heading)
        rx, ry = px - cx, py - cy
        a = abs(c * rx + s * ry) - dims[0]
        b = abs(-s * rx + c * ry) - dims[1]
        e = abs(pz - cz) - dims[2]
        outside = math.sqrt(max(a, 0.0) ** 2 + max(b, 0.0) ** 2 + max(e, 0.0) ** 2)
        return outside + min(max(a, max(b, e)), 0.0)
    outside = math.sqrt(max(a, 0.0) ** 2 + max(b, 0.0) ** 2)
    return outside + min(max(a, b), 0.0)


@njit(cache=True)
def mover_distances(kind, dims, poses, p, out):
    """Signed distance from the point p (3,) to each mover's surface, into out (M,)."""
    for j in range(kind.shape[0]):
        out[j] = shape_distance(kind[j], dims[j], poses[j, 0], poses[j, 1], poses[j, 2],
                                poses[j, 3], p[0], p[1], p[2])


@njit(cache=True)
def _slab(o, d, lo, hi, t0, t1):
    """Clip the ray interval [t0, t1] to lo <= o + t d <= hi (t0 > t1: empty)."""
    if d == 0.0:
        if o < lo or o > hi:
            return 1.0, 0.0
        return t0, t1
    a, b = (lo - o) / d, (hi - o) / d
    if a > b:
        a, b = b, a
    return max(t0, a), min(t1, b)


@njit(cache=True)
def ray_shape(kind, dims, cx, cy, cz, heading, ox, oy, oz, dx, dy, dz):
    """Length along the unit ray o + t d (t >= 0) to one mover's surface; inf if missed
    (0 when o is inside)."""
    inf = np.inf
    rx, ry, rz = ox - cx, oy - cy, oz - cz
    if kind == SPHERE:
        r = dims[0]
        b = rx * dx + ry * dy + rz * dz
        c = rx * rx + ry * ry + rz * rz - r * r
        if c <= 0.0:
            return 0.0
        disc = b * b - c
        if disc < 0.0 or b > 0.0:
            return inf
        return -b - math.sqrt(disc)
    if kind == CYLINDER:
        r, hh = dims[0], dims[1]
        t0, t1 = _slab(rz, dz, -hh, hh, 0.0, inf)
        a = dx * dx + dy * dy
        c = rx * rx + ry * ry - r * r
        if a == 0.0:
            if c > 0.0:
                return inf
        else:
            b = rx * dx + ry * dy
            disc = b * b - a * c
            if disc < 0.0:
                return inf
            q = math.sqrt(disc)
            t0, t1 = max(t0, (-b - q) / a), min(t1, (-b + q) / a)
        return t0 if t0 <= t1 else inf
    c, s = math.cos(heading), math.sin(heading)
    lx, ly = c * rx + s * ry, -s * rx + c * ry
    ux, uy = c * dx + s * dy, -s * dx + c * dy
    t0, t1 = _slab(lx, ux, -dims[0], dims[0], 0.0, inf)
    t0, t1 = _slab(ly, uy, -dims[1], dims[1], t0, t1)
    t0, t1 = _slab(rz, dz, -dims[2], dims[2], t0, t1)
    return t0 if t0 <= t1 else inf


@njit(cache=True)
def ray_first_hit(kind, dims, bounding, poses, origin, dirs, length, max_len):
    """Shorten ``length`` (N,) where a unit ray ``dirs`` (N, 3) from ``origin`` hits a
    mover first. Movers whose bounding sphere is beyond ``max_len`` are skipped; each ray
    is tested against a mover's bounding sphere before its shape."""
    ox, oy, oz = origin[0], origin[1], origin[2]
    for j in range(kind.shape[0]):
        cx, cy, cz, h = poses[j, 0], poses[j, 1], poses[j, 2], poses[j, 3]
        R = bounding[j]
        rx, ry, rz = cx - ox, cy - oy, cz - oz
        c2 = rx * rx + ry * ry + rz * rz
        if math.sqrt(c2) - R > max_len:
            continue
        inside = c2 <= R * R
        for i in range(dirs.shape[0]):
            dx, dy, dz = dirs[i, 0], dirs[i, 1], dirs[i, 2]
            if not inside:
                b = rx * dx + ry * dy + rz * dz
                if b <= 0.0 or c2 - b * b > R * R or b - R >= length[i]:
                    continue
            t = ray_shape(kind[j], dims[j], cx, cy, cz, h, ox, oy, oz, dx, dy, dz)
            if t < length[i]:
                length[i] = t


@njit(cache=True)
def _project_rect(kind, dims, pose, origin, r_wo, width, height, fx, fy, cx_px, cy_px,
                  R, min_z):
    """The pixel rectangle (u0, u1, v0, v1) a mover can cover: the projected corners of
    its bounding box when all lie in front of the camera, else the exact bounding
    rectangle of its bounding sphere (tangent planes through the optical centre), else
    the whole image. u0 > u1: nothing in view."""
    if kind == CYLINDER:
        ex, ey, ez = dims[0], dims[0], dims[1]
    elif kind == BOX:
        ex, ey, ez = dims[0], dims[1], dims[2]
    else:
        ex, ey, ez = dims[0], dims[0], dims[0]
    ch, sh = math.cos(pose[3]), math.sin(pose[3])
    u_lo, u_hi, v_lo, v_hi = np.inf, -np.inf, np.inf, -np.inf
    front = True
    for k in range(8):
        lx = ex if k & 1 else -ex
        ly = ey if k & 2 else -ey
        lz = ez if k & 4 else -ez
        wx = pose[0] + ch * lx - sh * ly - origin[0]
        wy = pose[1] + sh * lx + ch * ly - origin[1]
        wz = pose[2] + lz - origin[2]
        X = r_wo[0, 0] * wx + r_wo[1, 0] * wy + r_wo[2, 0] * wz
        Y = r_wo[0, 1] * wx + r_wo[1, 1] * wy + r_wo[2, 1] * wz
        Z = r_wo[0, 2] * wx + r_wo[1, 2] * wy + r_wo[2, 2] * wz
        if Z < 0.5 * min_z:
            front = False
            break
        u, v = cx_px + fx * X / Z, cy_px + fy * Y / Z
        u_lo, u_hi = min(u_lo, u), max(u_hi, u)
        v_lo, v_hi = min(v_lo, v), max(v_hi, v)
    if front:
        return (max(0, int(math.floor(u_lo))), min(width - 1, int(math.ceil(u_hi))),
                max(0, int(math.floor(v_lo))), min(height - 1, int(math.ceil(v_hi))))
    wx, wy, wz = pose[0] - origin[0], pose[1] - origin[1], pose[2] - origin[2]
    X = r_wo[0, 0] * wx + r_wo[1, 0] * wy + r_wo[2, 0] * wz
    Y = r_wo[0, 1] * wx + r_wo[1, 1] * wy + r_wo[2, 1] * wz
    Z = r_wo[0, 2] * wx + r_wo[1, 2] * wy + r_wo[2, 2] * wz
    u0, u1, v0, v1 = 0, width - 1, 0, height - 1
    dxz, dyz = math.sqrt(X * X + Z * Z), math.sqrt(Y * Y + Z * Z)
    if Z > 0.0 and dxz > R:
        a, w = math.atan2(X, Z), math.asin(R / dxz)
        if a - w > -0.5 * math.pi and a + w < 0.5 * math.pi:
            u0 = max(u0, int(math.floor(cx_px + fx * math.tan(a - w))))
            u1 = min(u1, int(math.ceil(cx_px + fx * math.tan(a + w))))
    if Z > 0.0 and dyz > R:
        a, w = math.atan2(Y, Z), math.asin(R / dyz)
        if a - w > -0.5 * math.pi and a + w < 0.5 * math.pi:
            v0 = max(v0, int(math.floor(cy_px + fy * math.tan(a - w))))
            v1 = min(v1, int(math.ceil(cy_px + fy * math.tan(a + w))))
    return u0, u1, v0, v1


@njit(cache=True)
def image_first_hit(kind, dims, bounding, poses, origin, r_wo, dirs_world, cos_axis, width,
                    height, fx, fy, cx_px, cy_px, min_z, max_z, z):
    """Lower the z-depths ``z`` (H*W,) of a pinhole image where a mover is nearer.
    ``dirs_world`` (H*W, 3) are the pixels' unit rays in the world, ``cos_axis`` their
    cosines to the optical axis, ``r_wo`` the optical-to-world rotation. Each mover is
    tested only on the pixels of its projected bounding box (:func:`_project_rect`)."""
    for j in range(kind.shape[0]):
        wx, wy, wz = poses[j, 0] - origin[0], poses[j, 1] - origin[1], poses[j, 2] - origin[2]
        Z = r_wo[0, 2] * wx + r_wo[1, 2] * wy + r_wo[2, 2] * wz  # depth of the centre
        R = bounding[j]
        if Z + R < min_z or Z - R > 2.0 * max_z:  # behind, or beyond the range
            continue
        u0, u1, v0, v1 = _project_rect(kind[j], dims[j], poses[j], origin, r_wo, width,
                                       height, fx, fy, cx_px, cy_px, R, min_z)
        for v in range(v0, v1 + 1):
            for u in range(u0, u1 + 1):
                k = v * width + u
                t = ray_shape(kind[j], dims[j], poses[j, 0], poses[j, 1], poses[j, 2],
                              poses[j, 3], origin[0], origin[1], origin[2],
                              dirs_world[k, 0], dirs_world[k, 1], dirs_world[k, 2])
                zt = t * cos_axis[k]  # z-depth of the hit
                if zt < z[k] or not (z[k] == z[k]):
                    z[k] = zt


# --- placement -------------------------------------------------------------------------------

def _clear(mesh, a, b, r: float, heights) -> bool:
    """The horizontal leg a -> b (centre heights ``heights``) keeps r from the mesh."""
    if mesh is None or len(mesh.faces) == 0:
        return True
    for z in heights:
        pa = np.array([a[0], a[1], z])
        pb = np.array([b[0], b[1], z])
        if segment_mesh_distance(mesh, pa, pb, cutoff=r) <= r:
            return False
    return True


def _polyline(points: np.ndarray) -> tuple[np.ndarray, float]:
    seg = np.linalg.norm(np.diff(points, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    return cum, float(cum[-1])


def _uniform(rng, interval) -> float:
    lo, hi = interval
    return float(lo) if hi <= lo else float(rng.uniform(lo, hi))


def _shape(rng, shape: str, s: dict, fly_z: float, ceiling: float):
    """(kind, dims, centre height, bounding radius, [test heights]) of one mover."""
    if shape == "person":
        r, h = _uniform(rng, s["radius_m"]), min(_uniform(rng, s["height_m"]), ceiling)
        dims = (r, 0.5 * h, 0.0)
        return CYLINDER, dims, 0.5 * h, math.hypot(r, 0.5 * h), (0.5 * h,), r
    if shape == "box":
        ln, w = _uniform(rng, s["box_length_m"]), _uniform(rng, s["box_width_m"])
        h = min(_uniform(rng, s["height_m"]), ceiling)
        dims = (0.5 * ln, 0.5 * w, 0.5 * h)
        return BOX, dims, 0.5 * h, float(np.linalg.norm(dims)), (0.5 * h,), math.hypot(
            0.5 * ln, 0.5 * w)
    r = _uniform(rng, s["radius_m"])
    z = fly_z + float(rng.uniform(-SPHERE_ALTITUDE_SPREAD_M, SPHERE_ALTITUDE_SPREAD_M))
    z = min(max(z, r + 0.05), max(ceiling - r - 0.05, r + 0.05))
    return SPHERE, (r, 0.0, 0.0), z, r, (z,), r


def _path(rng, kind: str, s: dict, lo, hi, start, goal, z: float):
    """Path points (K, 3) of the centre, walk mode and arc length at time 0 (s0); None
    when the draw falls outside the area."""
    span = _uniform(rng, s["path_length_m"])
    speed = s["speed_m_s"]
    c = rng.uniform(lo, hi)
    if kind == "line":
        th = rng.uniform(0, 2 * math.pi)
        u = np.array([math.cos(th), math.sin(th)])
        pts = [c - 0.5 * span * u, c + 0.5 * span * u]
        mode, phase = PINGPONG, None
    elif kind == "waypoints":
        k = int(rng.integers(3, 6))
        ang = np.sort(rng.uniform(0, 2 * math.pi, k))
        rad = rng.uniform(0.3, 0.5, k) * span
        pts = [c + rr * np.array([math.cos(a), math.sin(a)]) for a, rr in zip(ang, rad)]
        pts.append(pts[0])
        mode, phase = LOOP, None
    elif kind == "random_walk":
        half = 0.5 * span
        box_lo, box_hi = np.maximum(lo, c - half), np.minimum(hi, c + half)
        p, th = c.copy(), rng.uniform(0, 2 * math.pi)
        pts = [p.copy()]
        for _ in range(WALK_LEGS):
            for _try in range(8):
                th = th + rng.normal(0.0, 0.8)
                q = p + rng.uniform(1.0, 4.0) * np.array([math.cos(th), math.sin(th)])
                if np.all(q >= box_lo) and np.all(q <= box_hi):
                    break
                th = th + math.pi  # turn back from the square's side
            else:
                continue
            p = q
            pts.append(p.copy())
        if len(pts) < 2:
            return None
        mode, phase = PINGPONG, None
    else:  # crossing
        sg = np.asarray(goal[:2] - start[:2], dtype=float)
        d = float(np.linalg.norm(sg))
        if d <= 0.0:
            return None
        n = np.array([-sg[1], sg[0]]) / d
        x = start[:2] + rng.uniform(0.25, 0.85) * sg
        side = 1.0 if rng.random() < 0.5 else -1.0
        pts = [x - side * 0.5 * span * n, x + side * 0.5 * span * n]
        tc = _uniform(rng, s["crossing_s"])
        mode, phase = PINGPONG, (0.5 * span - speed * tc) % (2.0 * span)
    pts = np.array([[p[0], p[1], z] for p in pts])
    if np.any(pts[:, :2] < lo) or np.any(pts[:, :2] > hi):
        return None
    cum, length = _polyline(pts)
    if length <= 0.0:
        return None
    if phase is None:
        phase = float(rng.uniform(0.0, (2.0 if mode == PINGPONG else 1.0) * length))
    return pts, cum, length, mode, float(phase)


def place_movers(scenario, values, seed: int, owner: str = "movers") -> Movers:
    """The movers ``values`` (:data:`SCHEMA`) ask for in ``scenario``, placed for ``seed``
    (see the module docs). MoverError for bad settings."""
    s = settings(values, owner)
    lo3, hi3 = np.asarray(scenario.bounds_min, float), np.asarray(scenario.bounds_max, float)
    area = float(np.prod(hi3[:2] - lo3[:2]))
    count = s["count"] or int(round(s["density_per_1000m2"] * area / 1000.0))
    if count > SCHEMA["count"].range[1]:
        raise MoverError(f"{owner}: density_per_1000m2 {s['density_per_1000m2']:g} gives "
                         f"{count} movers in {area:.0f} m^2; at most "
                         f"{SCHEMA['count'].range[1]:g}")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 0x6D6F76]))
    start, goal, takeoff = (np.asarray(p, float) for p in
                            (scenario.start, scenario.goal, scenario.takeoff))
    fly_z, ceiling = float(start[2]), float(hi3[2])
    rows = []
    for _ in range(count):
        shape = s["shape"] if s["shape"] != "mixed" else SHAPES[int(rng.integers(3))]
        path = s["path"] if s["path"] != "mixed" else PATHS[int(rng.integers(4))]
        for _ in range(MAX_TRIES):
            kind, dims, z, bound, heights, foot = _shape(rng, shape, s, fly_z, ceiling)
            margin = foot + 0.05
            lo, hi = lo3[:2] + margin, hi3[:2] - margin
            if np.any(hi <= lo):
                break
            got = _path(rng, path, s, lo, hi, start, goal, z)
            if got is None:
                continue
            pts, cum, length, mode, s0 = got
            pose = np.empty((1, 4))
            mover_poses(0.0, np.array([s["speed_m_s"]]), np.array([length]),
                        np.array([mode]), np.array([s0]), np.array([len(pts)]), cum[None],
                        pts[None], pose)
            d0 = min(np.linalg.norm(pose[0, :2] - start[:2]),
                     np.linalg.norm(pose[0, :2] - takeoff[:2])) - foot
            if d0 < s["keep_out_m"]:
                continue
            r = foot + STATIC_CLEARANCE_M
            if not all(_clear(scenario.mesh, pts[k], pts[k + 1], r, heights)
                       for k in range(len(pts) - 1)):
                continue
            rows.append((kind, dims, pts, cum, length, mode, s0, bound, path))
            break
    return _pack(rows, s)


def movers_from_list(items, owner: str = "movers") -> Movers:
    """Movers given one by one (a test's, or a user's scripted actors): each a dict with
    ``shape`` (person / box / sphere), its size (``radius_m``, ``height_m``,
    ``length_m``, ``width_m`` as the shape needs), ``points`` (the centre's path: [x, y]
    pairs, a person's or box's centre at half its height, a sphere's at ``z_m``; or
    [x, y, z] triples), ``speed_m_s``, and optionally ``loop`` (round the points; default
    back and forth) and ``start_m`` (arc length at time 0). MoverError naming the item."""
    rows = []
    for j, it in enumerate(items):
        w = f"{owner}[{j}]"
        if not isinstance(it, dict):
            raise MoverError(f"{w}: must be a table, got {it!r}")
        shape = it.get("shape")
        if shape not in SHAPES:
            raise MoverError(f"{w}.shape: {shape!r} is not one of {', '.join(SHAPES)}")

        def num(key, lo=0.0, default=None, it=it, w=w):
            v = it.get(key, default)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not \
                    math.isfinite(v) or v < lo:
                raise MoverError(f"{w}.{key}: needs a finite number >= {lo:g}, got {v!r}")
            return float(v)
        if shape == "person":
            r, h = num("radius_m", 1e-3), num("height_m", 1e-3)
            kind, dims, z, bound = CYLINDER, (r, 0.5 * h, 0.0), 0.5 * h, math.hypot(r, 0.5 * h)
        elif shape == "box":
            dims = (0.5 * num("length_m", 1e-3), 0.5 * num("width_m", 1e-3),
                    0.5 * num("height_m", 1e-3))
            kind, z, bound = BOX, dims[2], float(np.linalg.norm(dims))
        else:
            r = num("radius_m", 1e-3)
            kind, dims, z, bound = SPHERE, (r, 0.0, 0.0), num("z_m", 0.0, r), r
        try:
            pts = np.array(it.get("points"), dtype=float)
        except (TypeError, ValueError):
            raise MoverError(f"{w}.points: needs [x, y] or [x, y, z] points") from None
        if pts.ndim != 2 or pts.shape[1] not in (2, 3) or len(pts) < 1 or \
                not np.all(np.isfinite(pts)):
            raise MoverError(f"{w}.points: needs at least one finite [x, y] or [x, y, z] "
                             f"point, got {it.get('points')!r}")
        if pts.shape[1] == 2:
            pts = np.column_stack([pts, np.full(len(pts), z)])
        loop = bool(it.get("loop", False))
        if loop and len(pts) > 1:
            pts = np.vstack([pts, pts[:1]])
        cum, length = _polyline(pts)
        if len(pts) == 1:
            pts, cum = np.vstack([pts, pts]), np.zeros(2)
        rows.append((kind, dims, pts, cum, length, LOOP if loop else PINGPONG,
                     num("start_m", 0.0, 0.0), bound, "given", num("speed_m_s", 0.0)))
    m = _pack([r[:9] for r in rows], {**SCHEMA.defaults(), "count": len(rows),
                                      "speed_m_s": max((r[9] for r in rows), default=0.0)})
    if rows:
        m.speed[:] = [r[9] for r in rows]
    return m


def with_movers(scenario, values, seed: int, owner: str = "movers"):
    """``scenario`` with the movers ``values`` ask for placed in it (:func:`place_movers`;
    the mesh is shared, not copied)."""
    return replace(scenario, movers=place_movers(scenario, values, seed, owner))


def _pack(rows, s: dict) -> Movers:
    if not rows:
        return replace(no_movers(), settings=s)
    M, K = len(rows), max(len(r[2]) for r in rows)
    pts = np.zeros((M, K, 3))
    cum = np.zeros((M, K))
    counts = {CYLINDER: 0, BOX: 0, SPHERE: 0}
    names = []
    for j, r in enumerate(rows):
        n = len(r[2])
        pts[j, :n], cum[j, :n] = r[2], r[3]
        pts[j, n:], cum[j, n:] = r[2][-1], r[3][-1]
        counts[r[0]] += 1
        names.append(f"{('person', 'box', 'ball')[r[0]]} {counts[r[0]]}")
    return Movers(
        kind=np.array([r[0] for r in rows], np.int64),
        dims=np.array([r[1] for r in rows], float),
        points=pts, n_points=np.array([len(r[2]) for r in rows], np.int64), cum=cum,
        length=np.array([r[4] for r in rows]), mode=np.array([r[5] for r in rows], np.int64),
        s0=np.array([r[6] for r in rows]), speed=np.full(M, float(s["speed_m_s"])),
        bounding=np.array([r[7] for r in rows]), names=tuple(names),
        paths=tuple(r[8] for r in rows), settings=s, clock=np.zeros(1, np.int64))


# --- the scenario-string form: forest:3+dynamic(count=8, speed=1.5) ----------------------------

#: short keys the scenario-string form accepts for the settings
ALIASES = {"speed": "speed_m_s", "density": "density_per_1000m2", "radius": "radius_m",
           "height": "height_m", "keep_out": "keep_out_m", "length": "path_length_m"}


def parse_dynamic(text: str) -> dict:
    """The settings of ``dynamic(k=v, ...)`` (``text`` is what is inside the brackets):
    numbers, intervals as ``lo:hi``, words. MoverError naming the bad part."""
    out: dict = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        key, eq, val = part.partition("=")
        key, val = key.strip(), val.strip()
        if not eq or not key or not val:
            raise MoverError(f"dynamic({text}): {part!r} is not KEY=VALUE")
        key = ALIASES.get(key, key)
        if key not in SCHEMA:
            raise MoverError(f"dynamic({text}): unknown setting {key!r} (settings: "
                             f"{', '.join(SCHEMA.names())}; short forms: "
                             f"{', '.join(ALIASES)})")
        if key in out:
            raise MoverError(f"dynamic({text}): {key} given twice")
        out[key] = _value(val, text, key)
    return out


def _value(val: str, text: str, key: str):
    def num(x: str):
        try:
            f = float(x)
        except ValueError:
            return None
        return int(f) if f.is_integer() and "." not in x and "e" not in x.lower() else f

    if ":" in val:
        a, b = (num(x) for x in val.split(":", 1))
        if a is None or b is None:
            raise MoverError(f"dynamic({text}): {key}={val!r} is not an interval LO:HI")
        return [a, b]
    n = num(val)
    return val if n is None else n


def split_dynamic(spec: str) -> tuple[str, dict | None]:
    """``"forest:3+dynamic(count=8)"`` -> ``("forest:3", {"count": 8})``; a spec without
    ``+dynamic(...)`` comes back with None."""
    head, plus, tail = spec.partition("+")
    if not plus:
        return spec, None
    tail = tail.strip()
    if not (tail.startswith("dynamic(") and tail.endswith(")")):
        raise MoverError(f"scenario {spec!r}: after '+' expected dynamic(KEY=VALUE, ...)")
    return head, parse_dynamic(tail[len("dynamic("):-1])
