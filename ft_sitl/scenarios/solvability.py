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

Shortest paths
--------------
``find_path(..., shortest=True)`` searches the same grid with A* over the 26 neighbours of
a cell (a diagonal move only where every cell of the 2 x 2 (x 2) block it crosses is free,
so the connectivity is the breadth-first search's and the segment between the centres stays
in free cells), then pulls the polyline tight (:func:`tauten`) among the pieces grown by the
shape (:class:`GrownPieces`: the planes and boxes of step 2, as polytopes). A segment is
kept only if it meets no grown piece and stays in the shrunk bounds (:func:`segment_free`,
an exact line-polytope test), so every point of the result keeps the shape clear, as the
grid's path does; vertices may now lie anywhere, against the grown obstacles. The result is
never shorter than the true shortest path and, on the test geometry, within a millimetre of
it; it goes round each obstacle on the side the grid search chose.

The narrowest passage along a path (:func:`narrowest_passage`) is measured among the same
grown pieces: the chord of the shape's free space across the nearest face, i.e. the room
the shape has to spare in the passage.

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

import heapq
import math
from dataclasses import dataclass, replace

import numpy as np
from numba import njit
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
    return _segment_distance(tri, None, p, q, cutoff)


def _segment_distance(tri: np.ndarray, boxes, p, q, cutoff: float) -> float:
    """:func:`segment_mesh_distance` with the triangles' bounding boxes (lo, hi), when a
    caller asks about many segments, computed once (None: here)."""
    if len(tri) == 0:
        return float("inf")
    p, q = np.asarray(p, dtype=float), np.asarray(q, dtype=float)
    if np.isfinite(cutoff):
        tlo, thi = boxes if boxes is not None else (tri.min(axis=1), tri.max(axis=1))
        lo, hi = np.minimum(p, q) - cutoff, np.maximum(p, q) + cutoff
        keep = np.all((tlo <= hi) & (thi >= lo), axis=1)
        tri = tri[keep]
        if len(tri) == 0:
            return float("inf")
    return float(segment_triangles_distance(p, q, tri).min())


def polyline_clearance(mesh, points, cutoff: float = np.inf) -> float:
    """Exact smallest distance from a polyline (N, 3) to the mesh (``inf`` beyond cutoff)."""
    pts = np.asarray(points, dtype=float)
    tri = _triangles(mesh)
    boxes = (tri.min(axis=1), tri.max(axis=1)) if np.isfinite(cutoff) and len(tri) else None
    return min(
        (_segment_distance(tri, boxes, pts[i], pts[i + 1], cutoff)
         for i in range(len(pts) - 1)),
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
    """Convex pieces that together cover the mesh's surface (see the module docstring).

    Each connected component that is closed and convex becomes one piece (its distinct
    face planes, in order of first appearance); any other component, one piece per
    triangle. Components with the same number of faces are handled together (a Perlin
    field has ~40,000 boxes: one pass over each was 7 s of a solvability check)."""
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
    starts = np.concatenate([[0], bounds])
    sizes = np.diff(np.concatenate([starts, [len(order)]]))
    scale = max(1.0, float(np.abs(verts).max()))
    out: list[list[ConvexPiece]] = [[] for _ in starts]
    for size in np.unique(sizes):
        which = np.flatnonzero(sizes == size)
        group_faces = faces[order[starts[which][:, None] + np.arange(size)]]
        for w, pieces in zip(which, _component_pieces(group_faces, verts, scale)):
            out[w] = pieces
    return [piece for pieces in out for piece in pieces]


def _component_pieces(f: np.ndarray, verts: np.ndarray, scale: float):
    """The pieces of components of equal face count, ``f`` (g, faces, 3): per component,
    [one ConvexPiece] if it is closed and convex, else one per triangle."""
    g, s = f.shape[:2]
    tri = verts[f]                                                     # (g, s, 3, 3)
    n = np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])
    ln = np.linalg.norm(n, axis=2)
    good = ln > _EPS * scale * scale
    # closed: every edge is shared by exactly two faces of the component
    edges = np.sort(np.concatenate([f[:, :, [0, 1]], f[:, :, [1, 2]], f[:, :, [2, 0]]],
                                   axis=1), axis=2)
    key = np.sort(edges[:, :, 0] * (int(verts.shape[0]) + 1) + edges[:, :, 1], axis=1)
    if key.shape[1] % 2:
        closed = np.zeros(g, dtype=bool)
    else:
        closed = np.all(key[:, 0::2] == key[:, 1::2], axis=1) & \
            np.all(key[:, 1:-1:2] != key[:, 2::2], axis=1)
    closed &= good.any(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        normals = n / ln[:, :, None]
    offsets = np.einsum("gij,gij->gi", normals, tri[:, :, 0])
    # the distinct planes (equal when equal rounded to 1e-9), in order of first appearance
    plane = np.round(np.concatenate([normals, offsets[:, :, None]], axis=2), 9)
    same = np.all(plane[:, :, None, :] == plane[:, None, :, :], axis=3)
    same &= good[:, None, :] & good[:, :, None]
    earlier = np.tril(np.ones((s, s), dtype=bool), -1)
    keep = good & ~np.any(same & earlier[None], axis=2)
    corners = tri.reshape(g, -1, 3)
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    out = []
    for c in range(g):
        if closed[c]:
            nm, off = normals[c, keep[c]], offsets[c, keep[c]]
            if (corners[c] @ nm.T - off).max() <= 1e-9 * scale:
                out.append([ConvexPiece(nm, off, lo[c], hi[c])])
                continue
        out.append(_triangle_pieces(tri[c]))
    return out


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


@dataclass(frozen=True)
class GrownPieces:
    """The convex pieces grown by a shape (a ball or a :class:`LevelBody`): where the
    shape's centre may not be. Piece k is the polytope ``{x : normals[j] @ x <= offsets[j]
    for j in first[k] .. first[k + 1] - 1}`` cut to the box ``lo[k] .. hi[k]``: each face
    plane pushed out by the shape's support along it and the bounding box widened by the
    shape's reach (step 2 of the module docstring; it contains every centre at which the
    shape touches the piece). ``free_lo .. free_hi`` is the box the centre must keep to: the
    bounds shrunk by the reach. ``radius`` is the shape's bounding radius."""

    normals: np.ndarray  # (J, 3), unit
    offsets: np.ndarray  # (J,)
    first: np.ndarray  # (P + 1,) int64
    lo: np.ndarray  # (P, 3)
    hi: np.ndarray  # (P, 3)
    bounds_min: np.ndarray
    bounds_max: np.ndarray
    reach_lo: np.ndarray  # how far the shape reaches along -x, -y, -z from its centre
    reach_hi: np.ndarray  # ... and along +x, +y, +z
    radius: float
    shape: float | LevelBody

    @property
    def free_lo(self) -> np.ndarray:
        return self.bounds_min + self.reach_lo

    @property
    def free_hi(self) -> np.ndarray:
        return self.bounds_max - self.reach_hi

    def __len__(self) -> int:
        return len(self.lo)

    def width(self, u) -> float:
        """The shape's own width along the unit vector ``u`` (m): its supports along u and
        -u added."""
        return _support(self.shape, u) + _support(self.shape, -np.asarray(u, dtype=float))


def grow_pieces(mesh, bounds_min, bounds_max, shape: float | LevelBody,
                pieces: list[ConvexPiece] | None = None) -> GrownPieces:
    """The mesh's convex pieces (:func:`convex_pieces`, or ``pieces`` when given) grown by
    ``shape``: a ball's radius (m) or a :class:`LevelBody`."""
    if isinstance(shape, LevelBody):
        radius = shape.body.bounding_radius_m
    elif not np.isfinite(shape) or shape < 0:
        raise ValueError(f"radius must be a non-negative number of metres, got {shape!r}")
    else:
        radius = float(shape)
    eye = np.eye(3)
    reach_hi = np.array([_support(shape, eye[a]) for a in range(3)])
    reach_lo = np.array([_support(shape, -eye[a]) for a in range(3)])
    normals, offsets, first, lo, hi = [], [], [0], [], []
    supports: dict[bytes, float] = {}  # by normal: a box-built mesh has six of them

    def support_against(n):
        key = n.tobytes()
        if key not in supports:
            supports[key] = _support(shape, -n)
        return supports[key]

    for piece in convex_pieces(mesh) if pieces is None else pieces:
        normals.append(piece.normals)
        offsets.append(piece.offsets + np.array([support_against(n) for n in piece.normals]))
        first.append(first[-1] + len(piece.offsets))
        lo.append(piece.lo - reach_hi)
        hi.append(piece.hi + reach_lo)
    return GrownPieces(
        np.ascontiguousarray(np.vstack(normals) if normals else np.zeros((0, 3))),
        np.ascontiguousarray(np.concatenate(offsets) if offsets else np.zeros(0)),
        np.array(first, dtype=np.int64),
        np.array(lo, dtype=float).reshape(-1, 3), np.array(hi, dtype=float).reshape(-1, 3),
        np.asarray(bounds_min, dtype=float), np.asarray(bounds_max, dtype=float),
        reach_lo, reach_hi, radius, shape)


def occupancy_grid(mesh, bounds_min, bounds_max, radius: float | LevelBody,
                   pitch=DEFAULT_PITCH_M) -> OccupancyGrid:
    """The conservative free-space grid of the module docstring, for a ball of ``radius``
    or a :class:`LevelBody` (then a free cell holds the body's centre with the body clear,
    ``OccupancyGrid.radius`` its bounding radius)."""
    return _grid(grow_pieces(mesh, bounds_min, bounds_max, radius), pitch)


def _grid(grown: GrownPieces, pitch) -> OccupancyGrid:
    bmin, bmax = grown.bounds_min, grown.bounds_max
    reach_lo, reach_hi = grown.reach_lo, grown.reach_hi
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
    for k in range(len(grown)):
        # centres whose shape touches the piece lie in the grown piece
        lo = np.floor((grown.lo[k] - bmin) / p).astype(int)
        hi = np.ceil((grown.hi[k] - bmin) / p).astype(int)
        lo, hi = np.maximum(lo, 0), np.minimum(hi, shape)
        if np.any(hi <= lo):
            continue
        cx = centres[0][lo[0]:hi[0]][:, None, None]
        cy = centres[1][lo[1]:hi[1]][None, :, None]
        cz = centres[2][lo[2]:hi[2]][None, None, :]
        separated = np.zeros((hi - lo), dtype=bool)
        j0, j1 = grown.first[k], grown.first[k + 1]
        for n, b in zip(grown.normals[j0:j1], grown.offsets[j0:j1]):
            support = np.abs(n) @ half
            separated |= (n[0] * cx + n[1] * cy + n[2] * cz) - support > b
        free[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] &= separated
    return OccupancyGrid(bmin, p, free, float(grown.radius))


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
    return _walk_back(came, offsets, start, goal)


@njit(cache=True)
def _walk_back(came, offsets, start, goal):
    """The flat cell indices from start to goal of a search that reached goal, each cell
    having come from the one ``offsets[came[cell]]`` before it (compiled: the A* search
    calls it from its kernel)."""
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


# --------------------------------------------------------------------------------------
# shortest paths and passage widths among the grown pieces (compiled)
# --------------------------------------------------------------------------------------


@njit(cache=True)
def _line_in_piece(a, d, t0, t1, k, normals, offsets, first, lo, hi):
    """Does the line a + t d, t in [t0, t1], meet grown piece k (closed)? Returns (hit,
    entry t, exit t)."""
    for ax in range(3):
        if d[ax] == 0.0:
            if a[ax] < lo[k, ax] or a[ax] > hi[k, ax]:
                return False, t0, t1
        else:
            ta = (lo[k, ax] - a[ax]) / d[ax]
            tb = (hi[k, ax] - a[ax]) / d[ax]
            if ta > tb:
                ta, tb = tb, ta
            t0 = max(t0, ta)
            t1 = min(t1, tb)
            if t0 > t1:
                return False, t0, t1
    for j in range(first[k], first[k + 1]):
        den = normals[j, 0] * d[0] + normals[j, 1] * d[1] + normals[j, 2] * d[2]
        num = offsets[j] - (normals[j, 0] * a[0] + normals[j, 1] * a[1] + normals[j, 2] * a[2])
        if den == 0.0:
            if num < 0.0:
                return False, t0, t1
        elif den > 0.0:
            t1 = min(t1, num / den)
        else:
            t0 = max(t0, num / den)
        if t0 > t1:
            return False, t0, t1
    return True, t0, t1


@njit(cache=True)
def _in_free_box(a, b, free_lo, free_hi):
    """Is the segment a-b inside the box the centre must keep to?"""
    for ax in range(3):
        if min(a[ax], b[ax]) < free_lo[ax] or max(a[ax], b[ax]) > free_hi[ax]:
            return False
    return True


@njit(cache=True)
def _segment_free(a, b, normals, offsets, first, lo, hi, free_lo, free_hi):
    """Is the segment a-b inside the free box and outside every grown piece?"""
    if not _in_free_box(a, b, free_lo, free_hi):
        return False
    d = b - a
    for k in range(lo.shape[0]):
        if _line_in_piece(a, d, 0.0, 1.0, k, normals, offsets, first, lo, hi)[0]:
            return False
    return True


#: the cells of :class:`PieceIndex` (m): a tauten step's segments are at most 0.5 m, and
#: Perlin's grown voxel boxes 0.3-2 m across
INDEX_CELL_M = 1.0
#: how far a piece's box and a segment's footprint are widened when they are put into
#: cells: a box that touches a cell's edge is in the cells on both sides
_INDEX_PAD_M = 1e-6


@dataclass(frozen=True)
class PieceIndex:
    """Which grown pieces' boxes overlap each ``cell`` x ``cell`` column of the plane
    (x, y from ``origin``, ``nx`` x ``ny`` columns): the pieces of column (i, j) are
    ``items[start[i * ny + j]:start[i * ny + j + 1]]``, in ascending order. Only a piece
    whose box meets a segment can block it (:func:`_line_in_piece` clips to the box
    first), and such a box overlaps a column the segment crosses, so testing the pieces of
    those columns gives the answer of testing them all."""

    origin: np.ndarray  # (2,)
    inv_cell: float
    dims: np.ndarray  # (2,) int64: nx, ny
    start: np.ndarray  # (nx * ny + 1,) int64
    items: np.ndarray  # int64

    def kernel_args(self) -> tuple:
        """The index as the kernels take it (one tuple argument)."""
        return (self.origin, self.inv_cell, self.dims, self.start, self.items)

    @classmethod
    def build(cls, lo: np.ndarray, hi: np.ndarray, cell: float = INDEX_CELL_M):
        if not len(lo):
            return cls(np.zeros(2), 1.0 / cell, np.ones(2, np.int64), np.zeros(2, np.int64),
                       np.zeros(0, np.int64))
        origin = lo[:, :2].min(axis=0) - 2 * _INDEX_PAD_M
        inv = 1.0 / cell
        i0 = np.floor((lo[:, :2] - _INDEX_PAD_M - origin) * inv).astype(np.int64)
        i1 = np.floor((hi[:, :2] + _INDEX_PAD_M - origin) * inv).astype(np.int64)
        dims = i1.max(axis=0) + 1
        start, items = _fill_index(i0, i1, int(dims[0]), int(dims[1]))
        return cls(origin, inv, dims.astype(np.int64), start, items)


@njit(cache=True)
def _fill_index(i0, i1, nx, ny):
    """CSR of the pieces per column (pieces in ascending order within a column)."""
    count = np.zeros(nx * ny + 1, np.int64)
    for k in range(i0.shape[0]):
        for i in range(i0[k, 0], i1[k, 0] + 1):
            for j in range(i0[k, 1], i1[k, 1] + 1):
                count[i * ny + j + 1] += 1
    start = np.cumsum(count)
    fill = start[:-1].copy()
    items = np.empty(start[-1], np.int64)
    for k in range(i0.shape[0]):
        for i in range(i0[k, 0], i1[k, 0] + 1):
            for j in range(i0[k, 1], i1[k, 1] + 1):
                items[fill[i * ny + j]] = k
                fill[i * ny + j] += 1
    return start, items


@njit(cache=True)
def _index_cell(x, origin, inv, n):
    i = int(math.floor((x - origin) * inv))
    return min(max(i, 0), n - 1)


@njit(cache=True)
def _segment_free_indexed(a, b, normals, offsets, first, lo, hi, free_lo, free_hi, index):
    """:func:`_segment_free` testing only the pieces of the index columns the segment's
    footprint crosses (each column's x extent of the segment, row by row, widened by the
    index's pad): the same answer. ``index``: :meth:`PieceIndex.kernel_args`."""
    if not _in_free_box(a, b, free_lo, free_hi):
        return False
    i_origin, i_inv, i_dims, i_start, i_items = index
    d = b - a
    nx, ny = i_dims[0], i_dims[1]
    pad = _INDEX_PAD_M
    j0 = _index_cell(min(a[1], b[1]) - pad, i_origin[1], i_inv, ny)
    j1 = _index_cell(max(a[1], b[1]) + pad, i_origin[1], i_inv, ny)
    cell = 1.0 / i_inv
    for j in range(j0, j1 + 1):
        # the part of the segment within this row's y band (widened by pad)
        y_lo = i_origin[1] + j * cell - pad
        y_hi = y_lo + cell + 2 * pad
        t0, t1 = 0.0, 1.0
        if d[1] != 0.0:
            ta = (y_lo - a[1]) / d[1]
            tb = (y_hi - a[1]) / d[1]
            if ta > tb:
                ta, tb = tb, ta
            t0, t1 = max(t0, ta), min(t1, tb)
            if t0 > t1:
                continue
        xa, xb = a[0] + t0 * d[0], a[0] + t1 * d[0]
        i0 = _index_cell(min(xa, xb) - pad, i_origin[0], i_inv, nx)
        i1 = _index_cell(max(xa, xb) + pad, i_origin[0], i_inv, nx)
        for i in range(i0, i1 + 1):
            c = i * ny + j
            for q in range(i_start[c], i_start[c + 1]):
                if _line_in_piece(a, d, 0.0, 1.0, i_items[q], normals, offsets, first, lo,
                                  hi)[0]:
                    return False
    return True


@njit(cache=True)
def _ray_length(p, u, tmax, normals, offsets, first, lo, hi, free_lo, free_hi, pieces):
    """How far the centre can move from p along the unit vector u (at most tmax) before
    it meets one of ``pieces`` (indices of grown pieces) or leaves the free box."""
    t_end = tmax
    for ax in range(3):
        if u[ax] > 0.0:
            t_end = min(t_end, (free_hi[ax] - p[ax]) / u[ax])
        elif u[ax] < 0.0:
            t_end = min(t_end, (free_lo[ax] - p[ax]) / u[ax])
    t_end = max(t_end, 0.0)
    for k in pieces:
        hit, t0, _ = _line_in_piece(p, u, 0.0, t_end, k, normals, offsets, first, lo, hi)
        if hit:
            t_end = t0
    return t_end


@njit(cache=True)
def _astar(free, start, goal, pitch):
    """Flat indices of a shortest 26-connected path of free cells (cost: the distance
    between cell centres), or an empty array. A diagonal move needs every cell of the
    2 x 2 (x 2) block it crosses free, so the segment between the two centres stays in free
    cells and the connectivity is that of the 6-connected search."""
    nx, ny, nz = free.shape
    flat = free.ravel()
    offs = np.empty(26, np.int64)
    costs = np.empty(26)
    need = np.zeros((26, 7), np.int64)
    n_need = np.zeros(26, np.int64)
    m = 0
    for dx in range(-1, 2):
        for dy in range(-1, 2):
            for dz in range(-1, 2):
                if dx == 0 and dy == 0 and dz == 0:
                    continue
                offs[m] = dx * ny * nz + dy * nz + dz
                costs[m] = math.sqrt((dx * pitch[0]) ** 2 + (dy * pitch[1]) ** 2
                                     + (dz * pitch[2]) ** 2)
                for ex in range(2):
                    for ey in range(2):
                        for ez in range(2):
                            if (ex and dx == 0) or (ey and dy == 0) or (ez and dz == 0) \
                                    or ex + ey + ez == 0:
                                continue
                            need[m, n_need[m]] = ex * dx * ny * nz + ey * dy * nz + ez * dz
                            n_need[m] += 1
                m += 1
    gi, gj, gk = goal // (ny * nz), (goal // nz) % ny, goal % nz

    def heuristic(c):
        return math.sqrt(((c // (ny * nz) - gi) * pitch[0]) ** 2
                         + (((c // nz) % ny - gj) * pitch[1]) ** 2
                         + ((c % nz - gk) * pitch[2]) ** 2)

    g = np.full(flat.size, np.inf)
    came = np.full(flat.size, -1, np.int8)
    closed = np.zeros(flat.size, np.bool_)
    g[start] = 0.0
    heap = [(heuristic(start), start)]
    while heap:
        _, c = heapq.heappop(heap)
        if closed[c]:
            continue
        if c == goal:
            break
        closed[c] = True
        for m in range(26):
            nb = c + offs[m]
            if not flat[nb] or closed[nb]:
                continue
            ok = True
            for q in range(n_need[m]):
                if not flat[c + need[m, q]]:
                    ok = False
                    break
            if not ok:
                continue
            cost = g[c] + costs[m]
            if cost < g[nb]:
                g[nb] = cost
                came[nb] = m
                heapq.heappush(heap, (cost + heuristic(nb), nb))
    if not np.isfinite(g[goal]):
        return np.zeros(0, np.int64)
    return _walk_back(came, offs, start, goal)


@njit(cache=True)
def _polyline_length(pts):
    total = 0.0
    for i in range(len(pts) - 1):
        total += math.sqrt(((pts[i + 1] - pts[i]) ** 2).sum())
    return total


def _unit_moves() -> np.ndarray:
    """The 26 directions to the neighbours of a cell, as unit vectors."""
    moves = [(dx, dy, dz) for dx in (-1, 0, 1) for dy in (-1, 0, 1) for dz in (-1, 0, 1)
             if dx or dy or dz]
    m = np.array(moves, dtype=float)
    return np.ascontiguousarray(m / np.linalg.norm(m, axis=1)[:, None])


_MOVES = _unit_moves()


@njit(cache=True)
def _pair_free(a, w, b, normals, offsets, first, lo, hi, free_lo, free_hi, index):
    return _segment_free_indexed(a, w, normals, offsets, first, lo, hi, free_lo, free_hi,
                                 index) and \
        _segment_free_indexed(w, b, normals, offsets, first, lo, hi, free_lo, free_hi, index)


@njit(cache=True)
def _place(a, v, b, moves, normals, offsets, first, lo, hi, free_lo, free_hi, index):
    """A better place for the vertex v between a and b: |a - v| + |v - b| smaller, both
    segments free. First towards the segment a-b as far as free (bisection); where an
    obstacle stops that, a pattern search with steps halving to 1e-5 m lets the vertex
    slide along the obstacle's faces and edges: towards a or b (along its own segments,
    which stay free on one side) and along ``moves``."""
    ab = b - a
    den = (ab * ab).sum()
    t = 0.0 if den == 0.0 else min(max(((v - a) * ab).sum() / den, 0.0), 1.0)
    step = a + t * ab - v
    reach = math.sqrt((step * step).sum())
    if reach < 1e-12:
        return v
    if _pair_free(a, v + step, b, normals, offsets, first, lo, hi, free_lo, free_hi, index):
        return v + step
    good, bad = 0.0, 1.0
    for _ in range(30):
        mid = 0.5 * (good + bad)
        if _pair_free(a, v + mid * step, b, normals, offsets, first, lo, hi, free_lo, free_hi,
                      index):
            good = mid
        else:
            bad = mid
    v = v + good * step
    cost = math.sqrt(((a - v) ** 2).sum()) + math.sqrt(((b - v) ** 2).sum())
    h = min(0.25, reach)
    while h > 1e-5:
        moved = True
        while moved:
            moved = False
            for k in range(moves.shape[0] + 2):
                if k < 2:
                    d = (a if k == 0 else b) - v
                    norm = math.sqrt((d * d).sum())
                    if norm <= h:
                        continue
                    w = v + (h / norm) * d
                else:
                    w = v + h * moves[k - 2]
                c = math.sqrt(((a - w) ** 2).sum()) + math.sqrt(((b - w) ** 2).sum())
                if c < cost - 1e-12 and _pair_free(a, w, b, normals, offsets, first, lo, hi,
                                                   free_lo, free_hi, index):
                    v, cost, moved = w, c, True
                    break
        h *= 0.5
    return v


@njit(cache=True)
def _tauten(path, moves, normals, offsets, first, lo, hi, free_lo, free_hi, index,
            max_rounds):
    """Pull a free polyline tight, keeping every segment free: move each vertex to a
    better place between its neighbours (:func:`_place`), then drop the vertices whose
    neighbours see each other; repeat until the length stops falling. The ends stay where
    they are."""
    pts = path.copy()
    last = _polyline_length(pts)
    for _ in range(max_rounds):
        for i in range(1, len(pts) - 1):
            pts[i] = _place(pts[i - 1], pts[i], pts[i + 1], moves, normals, offsets, first,
                            lo, hi, free_lo, free_hi, index)
        # shortcut: from each kept vertex, the farthest vertex in an unbroken run of sight
        keep = [0]
        i = 0
        n = len(pts)
        while i < n - 1:
            j = i + 1
            while j + 1 < n and _segment_free_indexed(pts[i], pts[j + 1], normals, offsets,
                                                      first, lo, hi, free_lo, free_hi, index):
                j += 1
            keep.append(j)
            i = j
        pts = pts[np.array(keep)].copy()
        now = _polyline_length(pts)
        if last - now <= 1e-7 * max(1.0, now):
            break
        last = now
    return pts


@njit(cache=True)
def _nearest_normal(p, normals, offsets, first, lo, hi, free_lo, free_hi):
    """The outward normal of the face nearest to p among the grown pieces' faces and
    bounding-box faces and the free box's faces, judged by how far p lies outside each
    piece (its largest signed plane distance: the distance itself where the nearest point
    is inside a face)."""
    best = np.inf
    u = np.zeros(3)
    for ax in range(3):
        for sign in (1.0, -1.0):
            d = p[ax] - free_lo[ax] if sign > 0 else free_hi[ax] - p[ax]
            if d < best:
                best = d
                u[:] = 0.0
                u[ax] = sign
    for k in range(lo.shape[0]):
        sep, n_ax, n_sign = -np.inf, 0, 1.0
        for ax in range(3):  # the bounding box (a lower bound of the whole test)
            if lo[k, ax] - p[ax] > sep:
                sep, n_ax, n_sign = lo[k, ax] - p[ax], ax, -1.0
            if p[ax] - hi[k, ax] > sep:
                sep, n_ax, n_sign = p[ax] - hi[k, ax], ax, 1.0
        if sep >= best:
            continue
        plane = -1
        for j in range(first[k], first[k + 1]):
            d = normals[j, 0] * p[0] + normals[j, 1] * p[1] + normals[j, 2] * p[2] - offsets[j]
            if d > sep:
                sep, plane = d, j
        if sep < best:
            best = sep
            if plane >= 0:
                u[:] = normals[plane]
            else:
                u[:] = 0.0
                u[n_ax] = n_sign
    return u


@njit(cache=True)
def _narrowest(samples, normals, offsets, first, lo, hi, free_lo, free_hi):
    """The shortest of the chords of the free space through ``samples`` across the nearest
    face (:func:`_nearest_normal`): (length, sample index, direction)."""
    best, bi = np.inf, -1
    bu = np.zeros(3)
    n_pieces = lo.shape[0]
    cand = np.empty(n_pieces, np.int64)
    for i in range(samples.shape[0]):
        p = samples[i]
        u = _nearest_normal(p, normals, offsets, first, lo, hi, free_lo, free_hi)
        m = 0
        for k in range(n_pieces):
            d2 = 0.0
            for ax in range(3):
                e = max(lo[k, ax] - p[ax], 0.0, p[ax] - hi[k, ax])
                d2 += e * e
            if d2 < best * best:
                cand[m] = k
                m += 1
        near = cand[:m]
        ahead = _ray_length(p, u, best, normals, offsets, first, lo, hi, free_lo, free_hi,
                            near)
        if ahead >= best:
            continue
        back = _ray_length(p, -u, best - ahead, normals, offsets, first, lo, hi, free_lo,
                           free_hi, near)
        if ahead + back < best:
            best, bi = ahead + back, i
            bu[:] = u
    return best, bi, bu


def _kernel_args(grown: GrownPieces) -> tuple:
    return (grown.normals, grown.offsets, grown.first, grown.lo, grown.hi,
            np.ascontiguousarray(grown.free_lo), np.ascontiguousarray(grown.free_hi))


def segment_free(grown: GrownPieces, a, b) -> bool:
    """Is the segment a -> b clear for the grown pieces' shape (outside every grown piece,
    inside the shrunk bounds)?"""
    return bool(_segment_free(np.asarray(a, dtype=float), np.asarray(b, dtype=float),
                              *_kernel_args(grown)))


def _densify(points: np.ndarray, step: float) -> np.ndarray:
    """The polyline with points inserted so that no segment is longer than ``step``."""
    out = [points[:1]]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, math.ceil(float(np.linalg.norm(b - a)) / step))
        out.append(a + (b - a) * (np.arange(1, n + 1)[:, None] / n))
    return np.vstack(out)


#: :func:`tauten` re-tightens the path after splitting its segments to this length (m),
#: so that vertices can also slide along an obstacle, not only towards their neighbours
TAUTEN_SPLIT_M = 0.5


def _pieces_within(grown: GrownPieces, path: np.ndarray) -> GrownPieces:
    """The grown pieces that a polyline no longer than ``path`` between its ends can meet.

    Every point of such a polyline lies in the ellipsoid whose foci are the ends and whose
    major axis is ``path``'s length; :func:`_tauten` only ever tests segments inside it (it
    accepts a vertex only where the path gets shorter, bisects towards the chord, and
    shortcuts between path vertices, all inside that convex set). A piece whose box misses
    the ellipsoid's bounding box cannot meet any of them, so leaving it out changes no
    answer: the same path, faster (a Perlin version-2 field's 40,000 boxes made this 100 s
    per configuration)."""
    if len(path) < 2 or not len(grown.lo):
        return grown
    start, end = path[0], path[-1]
    chord = end - start
    dist = float(np.linalg.norm(chord))
    semi_major = 0.5 * _polyline_length(path)
    semi_minor = math.sqrt(max(semi_major ** 2 - (0.5 * dist) ** 2, 0.0))
    u2 = (chord / dist) ** 2 if dist > 0.0 else np.zeros(3)
    half = np.sqrt(semi_major ** 2 * u2 + semi_minor ** 2 * (1.0 - u2)) + 1e-6
    centre = 0.5 * (start + end)
    keep = np.flatnonzero(np.all((grown.lo <= centre + half) & (grown.hi >= centre - half),
                                 axis=1))
    if len(keep) == len(grown.lo):
        return grown
    counts = np.diff(grown.first)[keep]
    first = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    planes = np.repeat(grown.first[keep], counts) + (np.arange(first[-1]) -
                                                    np.repeat(first[:-1], counts))
    return replace(grown, normals=np.ascontiguousarray(grown.normals[planes]),
                   offsets=np.ascontiguousarray(grown.offsets[planes]), first=first,
                   lo=np.ascontiguousarray(grown.lo[keep]),
                   hi=np.ascontiguousarray(grown.hi[keep]))


def tauten(grown: GrownPieces, path, max_rounds: int = 200) -> np.ndarray:
    """A free polyline pulled tight among the grown pieces: the same ends, never longer,
    every segment still free (:func:`_tauten`); then split into segments of at most
    :data:`TAUTEN_SPLIT_M` and pulled tight again while that still shortens it (by more
    than a millionth). A local optimum: it goes round each obstacle on the side the
    polyline did."""
    path = np.ascontiguousarray(path, dtype=float)
    near = _pieces_within(grown, path)
    args = (_MOVES, *_kernel_args(near), PieceIndex.build(near.lo, near.hi).kernel_args())
    pts = _tauten(path, *args, int(max_rounds))
    for _ in range(8):
        finer = _tauten(_densify(pts, TAUTEN_SPLIT_M), *args, int(max_rounds))
        gain = _polyline_length(pts) - _polyline_length(finer)
        if gain < 0.0:
            break
        pts = finer
        if gain <= 1e-6 * _polyline_length(pts):
            break
    moved = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0.0, axis=1)])
    return pts[moved]


#: the narrowest chord's direction is refined within this angle (rad) of the nearest face's
#: normal: a chord through a point that touches a face, tilted further into it, would
#: only measure the way out on the other side
CHORD_CONE_RAD = math.radians(20.0)


@dataclass(frozen=True)
class Passage:
    """The narrowest passage along a path (see :func:`narrowest_passage`)."""

    spare_m: float  # the chord of the free (configuration) space: room left for the shape
    width_m: float  # spare_m plus the shape's own width along the chord
    point: np.ndarray  # where on the path (ENU, m)
    direction: np.ndarray  # the chord's direction (unit; either sense)
    along_m: float  # distance of ``point`` along the path from its start


def _chord(grown: GrownPieces, p, u, pieces) -> float:
    args = _kernel_args(grown)
    ahead = _ray_length(p, u, np.inf, *args, pieces)
    return ahead + _ray_length(p, -u, np.inf, *args, pieces)


def narrowest_passage(grown: GrownPieces, path, step: float = 0.05) -> Passage:
    """The narrowest passage a free polyline goes through, among the grown pieces.

    The passage at a point of the path is the chord of the free space -- where the shape's
    centre may be -- through that point across the nearest face (of a grown obstacle, or
    the floor, the ceiling or a side shrunk by the shape's reach): from that face, through
    the point, along its normal to whatever the line meets next. Between the two faces of
    a slot it is the slot's width less the shape's width across it: the room the shape
    has to spare (``spare_m``). It is measured at points ``step`` apart along the path (and
    at its vertices); at the narrowest one a pattern search over the point's position (within
    ``step``) and the chord's direction (within :data:`CHORD_CONE_RAD` of the normal)
    refines it. ``width_m`` adds the shape's own width along the chord: the passage's
    width, exact between parallel faces."""
    pts = np.asarray(path, dtype=float)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])

    def at(s):
        s = min(max(s, 0.0), cum[-1])
        return np.array([np.interp(s, cum, pts[:, a]) for a in range(3)])

    s_samples = np.unique(np.concatenate([cum, np.arange(0.0, cum[-1], step)]))
    samples = np.ascontiguousarray(np.array([at(s) for s in s_samples]))
    best, i, u0 = _narrowest(samples, *_kernel_args(grown))
    s0 = float(s_samples[i])
    az, el = math.atan2(u0[1], u0[0]), math.asin(min(1.0, max(-1.0, u0[2])))

    def unit(a, e):
        return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])

    p0 = at(s0)
    dist = np.linalg.norm(np.maximum(np.maximum(grown.lo - p0, p0 - grown.hi), 0.0), axis=1)
    near = np.flatnonzero(dist < best + 2 * step).astype(np.int64)
    x, u = np.array([s0, az, el]), u0
    steps = np.array([step / 2, math.radians(4.0), math.radians(4.0)])
    for _ in range(14):
        improved = True
        while improved:
            improved = False
            for k in range(3):
                for sign in (1.0, -1.0):
                    y = x.copy()
                    y[k] += sign * steps[k]
                    v = unit(y[1], y[2])
                    if abs(y[0] - s0) > step or v @ u0 < math.cos(CHORD_CONE_RAD):
                        continue
                    c = _chord(grown, at(y[0]), v, near)
                    if c < best - 1e-12:
                        best, x, u, improved = c, y, v, True
        steps /= 2
    return Passage(float(best), float(best + grown.width(u)), at(x[0]), u, float(x[0]))


def find_path(mesh, start, goal, bounds_min, bounds_max, radius: float | LevelBody,
              pitch=DEFAULT_PITCH_M, shortest: bool = False) -> np.ndarray | None:
    """A polyline (N, 3) from start to goal keeping ``radius`` clear (or the level body at
    its yaw), or None if the grid has none (which, the grid being conservative, does not
    prove that none exists).

    ``shortest``: instead of the breadth-first path through cell centres, the 26-connected
    A* path pulled tight among the grown pieces (:func:`tauten`): close to the shortest
    path, never shorter than it (see "Shortest paths" in the module docstring)."""
    grown = grow_pieces(mesh, bounds_min, bounds_max, radius)
    grid = _grid(grown, pitch)
    s, g = grid.cell_of(start), grid.cell_of(goal)
    if s is None or g is None or not grid.free[s] or not grid.free[g]:
        return None
    s, g = np.ravel_multi_index(s, grid.shape), np.ravel_multi_index(g, grid.shape)
    if shortest:
        flat = _astar(grid.free, s, g, grid.pitch)
        if not len(flat):
            return None
    else:
        flat = _bfs(grid.free, s, g)
        if flat is None:
            return None
    cells = np.column_stack(np.unravel_index(flat, grid.shape))
    pts = _simplify(np.vstack([np.asarray(start, dtype=float), grid.centre(cells),
                               np.asarray(goal, dtype=float)]))
    return tauten(grown, pts) if shortest else pts


def scenario_pitch(scenario) -> np.ndarray:
    """The grid pitch a scenario asks for (provenance ``solvability_pitch_m``) or 0.25 m."""
    return _pitch3(scenario.provenance.get("solvability_pitch_m", DEFAULT_PITCH_M))


def scenario_path(scenario, radius: float | LevelBody, pitch=None,
                  shortest: bool = False) -> np.ndarray | None:
    """:func:`find_path` from the scenario's start to its goal within its bounds."""
    return find_path(scenario.mesh, scenario.start, scenario.goal, scenario.bounds_min,
                     scenario.bounds_max, radius,
                     scenario_pitch(scenario) if pitch is None else pitch, shortest)


def is_solvable(scenario, radius: float, pitch=None) -> bool:
    """True when a path with clearance ``radius`` is found (a proof; False is not one)."""
    return scenario_path(scenario, radius, pitch) is not None


def body_path(scenario, body: VehicleBody, pitch=None,
              yaws_deg=(0.0, 45.0, 15.0, 30.0, 60.0, 75.0),
              shortest: bool = False) -> tuple[np.ndarray, float] | None:
    """A path for the vehicle body held level at one yaw (the start yaw plus each of
    ``yaws_deg`` in turn) from the scenario's start to its goal: ``(path, yaw)`` for the
    first yaw that has one, or None. A quadrotor's body repeats every 90 degrees of yaw,
    so 0-75 in 15-degree steps covers it. ``shortest``: as in :func:`find_path`."""
    for dyaw in yaws_deg:
        yaw = scenario.start_yaw + math.radians(dyaw)
        path = scenario_path(scenario, LevelBody(body, yaw), pitch, shortest)
        if path is not None:
            return path, yaw
    return None
