"""Is a scenario solvable? A conservative occupancy grid and a breadth-first search.

The question is whether a ball of radius ``r`` (a platform's collision radius) can fly
from the start to the goal without touching an obstacle, the floor, the flight ceiling or
the sides of the scenario's area. The answer is a *proof*: a returned path is a polyline
every point of which is at least ``r`` from the mesh and from the bounds.

How
---
1. The obstacle mesh is split into its connected components. A closed convex component
   (every box, prism and voxel column the generators emit is one) is the polytope
   ``P = {x : n_i . x <= b_i}`` of its face planes. Any other component is replaced by its
   triangles, each a flat convex polytope (a closed surface still walls its inside off).
2. Every point within ``r`` of ``P`` lies in ``P_r = {x : n_i . x <= b_i + r}`` (unit
   normals). A grid cell -- a closed axis-aligned box -- is *free* only if, for every
   piece, one plane of ``P_r`` or an axis of ``P``'s bounding box widened by ``r``
   separates the whole cell from it, and the cell lies inside ``[bounds_min + r,
   bounds_max - r]``. This never calls a cell free that is not (it may call a free cell
   blocked near a corner of a piece: conservative).
3. A breadth-first search over face-adjacent (6-connected) free cells joins the cell that
   holds the start to the one that holds the goal. The segment between the centres of two
   face-adjacent cells lies in the union of the two cells, so the polyline start -> cell
   centres -> goal keeps a clearance of at least ``r`` everywhere.

The vehicle's body (protocol 5)
-------------------------------
The same grid keeps a :class:`LevelBody` clear instead of a ball: the body held level at
one yaw, whose support function h replaces the radius in step 2 (a centre x puts the body
on P only inside ``{x : n_i . x <= b_i + h(-n_i)}``, and the bounds shrink by h along each
axis). A multirotor can translate at any yaw it holds, so a path found for one yaw is
flyable; :func:`body_path` tries the start yaw first, then others.

Pitch
-----
Cells are boxes of ``pitch`` metres per axis (a scalar or one value per axis). A passage
is found when it is wider than about ``2 (r + pitch)``. The default is 0.25 m; the
Narrow-Gap family needs 0.025 m across its gaps (0.85 m gap, 0.768 m vehicle) and says so
in its provenance (``solvability_pitch_m``), which :func:`scenario_path` uses.

:func:`segment_mesh_distance` is an exact segment-to-triangle-mesh distance, used by
``Scenario.line_blocked`` and to re-check found paths independently of the grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ft_sitl.physics.body import VehicleBody

DEFAULT_PITCH_M = 0.25
_EPS = 1e-12


# --------------------------------------------------------------------------------------
# exact distances
# --------------------------------------------------------------------------------------


def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def _closest_on_triangles(p, a, b, c):
    """Closest points of triangles (a, b, c) to points p (all (M, 3)); Ericson's regions."""
    ab, ac, ap = b - a, c - a, p - a
    bp, cp = p - b, p - c
    d1, d2 = _dot(ab, ap), _dot(ac, ap)
    d3, d4 = _dot(ab, bp), _dot(ac, bp)
    d5, d6 = _dot(ab, cp), _dot(ac, cp)
    vc = d1 * d4 - d3 * d2
    vb = d5 * d2 - d1 * d6
    va = d3 * d6 - d5 * d4

    def div(n, d):
        return n / np.where(np.abs(d) > _EPS, d, 1.0)

    v_ab = div(d1, d1 - d3)[:, None]
    w_ac = div(d2, d2 - d6)[:, None]
    w_bc = div(d4 - d3, (d4 - d3) + (d5 - d6))[:, None]
    den = va + vb + vc
    v_in = div(vb, den)[:, None]
    w_in = div(vc, den)[:, None]
    conds = [
        (d1 <= 0) & (d2 <= 0),
        (d3 >= 0) & (d4 <= d3),
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),
        (d6 >= 0) & (d5 <= d6),
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),
        (va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0),
    ]
    choices = [a, b, a + v_ab * ab, c, a + w_ac * ac, b + w_bc * (c - b)]
    out = a + v_in * ab + w_in * ac
    for cond, choice in zip(reversed(conds), reversed(choices)):
        out = np.where(cond[:, None], choice, out)
    return out


def segment_segment_distance(p1, q1, p2, q2):
    """Distances between segments p1q1 and p2q2 (arrays (M, 3)); Ericson's clamping."""
    d1, d2, r = q1 - p1, q2 - p2, p1 - p2
    a, e, f = _dot(d1, d1), _dot(d2, d2), _dot(d2, r)
    c, b = _dot(d1, r), _dot(d1, d2)
    a_ok, e_ok = a > _EPS, e > _EPS
    safe_a = np.where(a_ok, a, 1.0)
    safe_e = np.where(e_ok, e, 1.0)
    denom = a * e - b * b
    s = np.where(denom > _EPS * np.maximum(a * e, _EPS), (b * f - c * e) / np.where(
        denom > 0, denom, 1.0), 0.0)
    s = np.clip(s, 0.0, 1.0)
    t = (b * s + f) / safe_e
    s = np.where(t < 0, np.clip(-c / safe_a, 0.0, 1.0), np.where(
        t > 1, np.clip((b - c) / safe_a, 0.0, 1.0), s))
    t = np.clip(t, 0.0, 1.0)
    # degenerate segments
    s = np.where(~a_ok, 0.0, np.where(~e_ok, np.clip(-c / safe_a, 0.0, 1.0), s))
    t = np.where(~e_ok, 0.0, np.where(~a_ok, np.clip(f / safe_e, 0.0, 1.0), t))
    return np.linalg.norm((p1 + s[:, None] * d1) - (p2 + t[:, None] * d2), axis=1)


def _segment_crosses_triangles(p, q, a, b, c):
    """Does segment pq pass through the triangles (Moller-Trumbore, t in [0, 1])?"""
    d = q - p
    e1, e2 = b - a, c - a
    h = np.cross(d, e2)
    det = _dot(e1, h)
    ok = np.abs(det) > _EPS
    inv = 1.0 / np.where(ok, det, 1.0)
    s = p - a
    u = inv * _dot(s, h)
    qv = np.cross(s, e1)
    v = inv * _dot(d, qv)
    t = inv * _dot(e2, qv)
    return ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t >= 0) & (t <= 1)


def segment_triangles_distance(p, q, triangles) -> np.ndarray:
    """Exact distance from the segment p->q to each triangle of ``triangles`` (M, 3, 3)."""
    tri = np.asarray(triangles, dtype=float).reshape(-1, 3, 3)
    m = len(tri)
    if m == 0:
        return np.zeros(0)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    P = np.broadcast_to(np.asarray(p, dtype=float), (m, 3))
    Q = np.broadcast_to(np.asarray(q, dtype=float), (m, 3))
    degenerate = np.linalg.norm(np.cross(b - a, c - a), axis=1) <= _EPS
    dist = np.minimum(
        np.linalg.norm(P - _closest_on_triangles(P, a, b, c), axis=1),
        np.linalg.norm(Q - _closest_on_triangles(Q, a, b, c), axis=1),
    )
    dist = np.where(degenerate, np.inf, dist)  # a flat triangle is its edges, below
    for u, v in ((a, b), (b, c), (c, a)):
        dist = np.minimum(dist, segment_segment_distance(P, Q, u, v))
    return np.where(_segment_crosses_triangles(P, Q, a, b, c) & ~degenerate, 0.0, dist)


def _triangles(mesh) -> np.ndarray:
    if isinstance(mesh, np.ndarray):
        return mesh.reshape(-1, 3, 3)
    return np.asarray(mesh.vertices, dtype=float)[np.asarray(mesh.faces)]


def segment_mesh_distance(mesh, p, q, cutoff: float = np.inf) -> float:
    """Exact distance from the segment p->q to a triangle mesh (or an (M, 3, 3) array).

    Triangles whose bounding box is farther than ``cutoff`` from the segment's are not
    examined; if none is nearer, the result is ``inf`` (the distance exceeds ``cutoff``).
    """
    tri = _triangles(mesh)
    if len(tri) == 0:
        return float("inf")
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    if np.isfinite(cutoff):
        lo, hi = np.minimum(p, q) - cutoff, np.maximum(p, q) + cutoff
        keep = np.all((tri.min(axis=1) <= hi) & (tri.max(axis=1) >= lo), axis=1)
        tri = tri[keep]
        if len(tri) == 0:
            return float("inf")
    return float(segment_triangles_distance(p, q, tri).min())


def polyline_clearance(mesh, points, cutoff: float = np.inf) -> float:
    """Exact smallest distance from a polyline (N, 3) to the mesh (``inf`` beyond cutoff)."""
    pts = np.asarray(points, dtype=float)
    tri = _triangles(mesh)
    return min(
        (segment_mesh_distance(tri, pts[i], pts[i + 1], cutoff) for i in range(len(pts) - 1)),
        default=float("inf"),
    )


# --------------------------------------------------------------------------------------
# convex pieces
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class ConvexPiece:
    """A convex polytope {x : normals @ x <= offsets} and its bounding box."""

    normals: np.ndarray  # (k, 3), unit
    offsets: np.ndarray  # (k,)
    lo: np.ndarray
    hi: np.ndarray


def _unique_planes(normals, offsets):
    key = np.round(np.column_stack([normals, offsets]), 9)
    _, idx = np.unique(key, axis=0, return_index=True)
    idx = np.sort(idx)
    return normals[idx], offsets[idx]


def _triangle_pieces(tri: np.ndarray) -> list[ConvexPiece]:
    out = []
    for t in tri:
        a, b, c = t
        n = np.cross(b - a, c - a)
        ln = np.linalg.norm(n)
        planes, offs = [], []
        if ln > _EPS:
            n = n / ln
            planes += [n, -n]
            offs += [n @ a, -(n @ a)]
            for u, v, w in ((a, b, c), (b, c, a), (c, a, b)):
                m = np.cross(v - u, n)
                lm = np.linalg.norm(m)
                if lm <= _EPS:
                    continue
                m = m / lm
                if m @ w > m @ u:
                    m = -m
                planes.append(m)
                offs.append(m @ u)
        # a degenerate triangle keeps only its bounding box (conservative)
        out.append(ConvexPiece(np.array(planes).reshape(-1, 3), np.array(offs, dtype=float),
                               t.min(axis=0), t.max(axis=0)))
    return out


def convex_pieces(mesh) -> list[ConvexPiece]:
    """Convex pieces that together cover the mesh's surface (see the module docstring)."""
    faces = np.asarray(mesh.faces, dtype=np.int64)
    verts = np.asarray(mesh.vertices, dtype=float)
    if len(faces) == 0:
        return []
    nv = len(verts)
    i = np.concatenate([faces[:, 0], faces[:, 1], faces[:, 2]])
    j = np.concatenate([faces[:, 1], faces[:, 2], faces[:, 0]])
    graph = coo_matrix((np.ones(len(i), dtype=np.int8), (i, j)), shape=(nv, nv))
    _, labels = connected_components(graph, directed=False)
    face_label = labels[faces[:, 0]]
    order = np.argsort(face_label, kind="stable")
    bounds = np.flatnonzero(np.diff(face_label[order])) + 1
    scale = max(1.0, float(np.abs(verts).max()))
    pieces: list[ConvexPiece] = []
    for group in np.split(order, bounds):
        f = faces[group]
        tri = verts[f]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        ln = np.linalg.norm(n, axis=1)
        good = ln > _EPS * scale * scale
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        _, counts = np.unique(edges, axis=0, return_counts=True)
        closed = bool(np.all(counts == 2)) and good.any()
        if closed:
            normals = n[good] / ln[good, None]
            offsets = np.einsum("ij,ij->i", normals, tri[good, 0])
            normals, offsets = _unique_planes(normals, offsets)
            vidx = np.unique(f)
            excess = verts[vidx] @ normals.T - offsets
            if excess.max() <= 1e-9 * scale:
                pieces.append(ConvexPiece(normals, offsets, verts[vidx].min(axis=0),
                                          verts[vidx].max(axis=0)))
                continue
        pieces.extend(_triangle_pieces(tri))
    return pieces


# --------------------------------------------------------------------------------------
# the grid
# --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class OccupancyGrid:
    """Free cells for a ball of ``radius``: cell (i, j, k) spans origin + [i, i+1] * pitch."""

    origin: np.ndarray
    pitch: np.ndarray
    free: np.ndarray  # bool (nx, ny, nz)
    radius: float

    @property
    def shape(self) -> tuple[int, int, int]:
        return self.free.shape

    def cell_of(self, point) -> tuple[int, int, int] | None:
        idx = np.floor((np.asarray(point, dtype=float) - self.origin) / self.pitch).astype(int)
        if np.any(idx < 0) or np.any(idx >= np.array(self.shape)):
            return None
        return tuple(int(v) for v in idx)

    def centre(self, ijk) -> np.ndarray:
        return self.origin + (np.asarray(ijk, dtype=float) + 0.5) * self.pitch


def _pitch3(pitch) -> np.ndarray:
    p = np.broadcast_to(np.asarray(pitch, dtype=float), (3,)).copy()
    if not np.all(np.isfinite(p)) or np.any(p <= 0):
        raise ValueError(f"pitch must be positive metres (one value or three), got {pitch!r}")
    return p


class LevelBody:
    """A vehicle body (:class:`~ft_sitl.physics.body.VehicleBody`) held level at a fixed
    ``yaw`` (rad, ENU): the shape the grid keeps clear instead of a ball. A multirotor
    translates at any yaw it holds, so a path for the body at one yaw is a path the vehicle
    can fly. Only the support function is needed: h(n) = max over points y of the body of
    n . y (the parts' supports, maximised: the convex hull of the body, conservative)."""

    def __init__(self, body: VehicleBody, yaw: float) -> None:
        self.body, self.yaw = body, float(yaw)
        c, s_ = math.cos(yaw), math.sin(yaw)
        rot = np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
        self._box = (rot @ np.asarray(body.box.center, float), rot,
                     np.asarray(body.box.size, float) / 2)
        self._disks = [(rot @ np.asarray(d.center, float), d.radius, d.thickness / 2)
                       for d in body.rotors]

    def support(self, n) -> float:
        n = np.asarray(n, dtype=float)
        centre, rot, half = self._box
        best = float(centre @ n + np.abs(rot.T @ n) @ half)
        horizontal = math.hypot(n[0], n[1])
        for centre, radius, half_t in self._disks:
            best = max(best, float(centre @ n + radius * horizontal + half_t * abs(n[2])))
        return best


def _support(shape: float | LevelBody, n) -> float:
    return shape.support(n) if isinstance(shape, LevelBody) else float(shape)


def occupancy_grid(mesh, bounds_min, bounds_max, radius: float | LevelBody,
                   pitch=DEFAULT_PITCH_M) -> OccupancyGrid:
    """The conservative free-space grid of the module docstring, for a ball of ``radius``
    or a :class:`LevelBody` (then a free cell holds the body's centre with the body clear,
    ``OccupancyGrid.radius`` its bounding radius)."""
    keep = radius  # what the grid keeps clear
    if isinstance(keep, LevelBody):
        radius = keep.body.bounding_radius_m
    elif not np.isfinite(radius) or radius < 0:
        raise ValueError(f"radius must be a non-negative number of metres, got {radius!r}")
    eye = np.eye(3)
    # how far the shape reaches along +axis and -axis from its centre
    reach_hi = np.array([_support(keep, eye[a]) for a in range(3)])
    reach_lo = np.array([_support(keep, -eye[a]) for a in range(3)])
    bmin = np.asarray(bounds_min, dtype=float)
    bmax = np.asarray(bounds_max, dtype=float)
    p = _pitch3(pitch)
    shape = np.floor((bmax - bmin) / p + 1e-9).astype(int)
    if np.any(shape < 1):
        raise ValueError(f"bounds {bmin} .. {bmax} hold no cell of pitch {p}")
    half = p / 2
    centres = [bmin[a] + (np.arange(shape[a]) + 0.5) * p[a] for a in range(3)]
    # inside the bounds, shrunk by the radius
    inside = [(c - half[a] >= bmin[a] + reach_lo[a]) & (c + half[a] <= bmax[a] - reach_hi[a])
              for a, c in enumerate(centres)]
    free = inside[0][:, None, None] & inside[1][None, :, None] & inside[2][None, None, :]
    free[[0, -1], :, :] = False  # a blocked rim keeps the flat-index search in range
    free[:, [0, -1], :] = False
    free[:, :, [0, -1]] = False
    for piece in convex_pieces(mesh):
        # centres whose shape touches the piece lie in piece - shape
        lo = np.floor((piece.lo - reach_hi - bmin) / p).astype(int)
        hi = np.ceil((piece.hi + reach_lo - bmin) / p).astype(int)
        lo, hi = np.maximum(lo, 0), np.minimum(hi, shape)
        if np.any(hi <= lo):
            continue
        cx = centres[0][lo[0]:hi[0]][:, None, None]
        cy = centres[1][lo[1]:hi[1]][None, :, None]
        cz = centres[2][lo[2]:hi[2]][None, None, :]
        separated = np.zeros((hi - lo), dtype=bool)
        for n, b in zip(piece.normals, piece.offsets):
            support = np.abs(n) @ half
            separated |= (n[0] * cx + n[1] * cy + n[2] * cz) - support > b + _support(keep, -n)
        free[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] &= separated
    return OccupancyGrid(bmin, p, free, float(radius))


def _bfs(free: np.ndarray, start: int, goal: int) -> np.ndarray | None:
    """Flat indices of a shortest 6-connected path of free cells, or None."""
    nx, ny, nz = free.shape
    offsets = np.array([1, -1, nz, -nz, ny * nz, -ny * nz], dtype=np.int64)
    visited = ~free.ravel()
    came = np.full(free.size, -1, dtype=np.int8)
    visited[start] = True
    frontier = np.array([start], dtype=np.int64)
    while frontier.size and not visited[goal]:
        new = []
        for d, off in enumerate(offsets):
            nb = frontier + off
            nb = nb[~visited[nb]]
            visited[nb] = True
            came[nb] = d
            new.append(nb)
        frontier = np.concatenate(new)
    if not visited[goal]:
        return None
    path = [goal]
    cur = goal
    while cur != start:
        cur -= offsets[came[cur]]
        path.append(cur)
    return np.array(path[::-1], dtype=np.int64)


def _simplify(points: np.ndarray) -> np.ndarray:
    """Drop the interior points of straight runs."""
    if len(points) <= 2:
        return points
    keep = [0]
    for i in range(1, len(points) - 1):
        d0 = points[i] - points[keep[-1]]
        d1 = points[i + 1] - points[i]
        if np.linalg.norm(np.cross(d0, d1)) > 1e-9 * max(1.0, np.linalg.norm(d0)) or \
                d0 @ d1 <= 0:
            keep.append(i)
    keep.append(len(points) - 1)
    return points[keep]


def find_path(mesh, start, goal, bounds_min, bounds_max, radius: float | LevelBody,
              pitch=DEFAULT_PITCH_M) -> np.ndarray | None:
    """A polyline (N, 3) from start to goal keeping ``radius`` clear (or the level body at
    its yaw), or None if the grid has none (which, the grid being conservative, does not
    prove that none exists)."""
    grid = occupancy_grid(mesh, bounds_min, bounds_max, radius, pitch)
    s, g = grid.cell_of(start), grid.cell_of(goal)
    if s is None or g is None or not grid.free[s] or not grid.free[g]:
        return None
    flat = _bfs(grid.free, np.ravel_multi_index(s, grid.shape),
                np.ravel_multi_index(g, grid.shape))
    if flat is None:
        return None
    cells = np.column_stack(np.unravel_index(flat, grid.shape))
    pts = np.vstack([np.asarray(start, dtype=float), grid.centre(cells),
                     np.asarray(goal, dtype=float)])
    return _simplify(pts)


def scenario_pitch(scenario) -> np.ndarray:
    """The grid pitch a scenario asks for (provenance ``solvability_pitch_m``) or 0.25 m."""
    return _pitch3(scenario.provenance.get("solvability_pitch_m", DEFAULT_PITCH_M))


def scenario_path(scenario, radius: float | LevelBody, pitch=None) -> np.ndarray | None:
    """:func:`find_path` from the scenario's start to its goal within its bounds."""
    return find_path(scenario.mesh, scenario.start, scenario.goal, scenario.bounds_min,
                     scenario.bounds_max, radius,
                     scenario_pitch(scenario) if pitch is None else pitch)


def is_solvable(scenario, radius: float, pitch=None) -> bool:
    """True when a path with clearance ``radius`` is found (a proof; False is not one)."""
    return scenario_path(scenario, radius, pitch) is not None


def body_path(scenario, body: VehicleBody, pitch=None,
              yaws_deg=(0.0, 45.0, 15.0, 30.0, 60.0, 75.0)) -> tuple[np.ndarray, float] | None:
    """A path for the vehicle body held level at one yaw (the start yaw plus each of
    ``yaws_deg`` in turn) from the scenario's start to its goal: ``(path, yaw)`` for the
    first yaw that has one, or None. A quadrotor's body repeats every 90 degrees of yaw,
    so 0-75 in 15-degree steps covers it."""
    for dyaw in yaws_deg:
        yaw = scenario.start_yaw + math.radians(dyaw)
        path = scenario_path(scenario, LevelBody(body, yaw), pitch)
        if path is not None:
            return path, yaw
    return None
