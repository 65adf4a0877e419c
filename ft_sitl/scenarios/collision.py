"""Collision world: a vehicle's collision sphere against the scenario mesh and its bounds.

World frame ENU (x east, y north, z up), metres. A vehicle is a sphere (its platform's
``collision_radius_m``, protocols 1-4, or its body's bounding sphere) centred on the body
origin; from protocol 5 its body (:class:`BodyProbe`: a box and the rotor disks, see
:meth:`CollisionWorld.body_distance`) settles what the sphere may touch. What it can hit:

* ``"obstacle"``: the scenario's triangle mesh (obstacles only), through one python-fcl
  bounding-volume hierarchy (``fcl.BVHModel``) built once in the constructor;
* ``"floor"``: the plane ``z = bounds_min[2]``; ``"ceiling"``: the plane ``z = bounds_max[2]``;
* ``"bounds"``: the four vertical sides of the scenario's area ``bounds_min[:2] ..
  bounds_max[:2]`` (an out-of-bounds event).

The boundary planes are handled analytically (no fcl). A contact means the sphere *surface*
is within ``contact_tol`` (1 µm by default) of an obstacle or plane, or past it.

Queries
-------
* :meth:`CollisionWorld.clearance` -- signed distance from the sphere surface to the nearest
  obstacle or boundary: positive when free, 0 when touching, ``-penetration`` when in
  contact; ``inf`` when nothing is checked.
* :meth:`CollisionWorld.check` -- the :class:`Contact` at one position (the deepest), or None.
* :meth:`CollisionWorld.sweep` -- the first contact along the straight segment p0 -> p1
  (one physics step of motion), or None. Never tunnels (see below).
* :class:`CollisionMonitor` -- per vehicle, stateful: checks every step but calls fcl only
  when the vehicle may have used up its last measured clearance, so the cost follows the
  proximity to obstacles rather than the step rate.

How an obstacle distance is computed
------------------------------------
fcl measures the distance from the sphere *centre* (a radius-0 fcl sphere, which still gives
a distance when the real sphere penetrates and is ~1.6x faster than a sphere of the real
radius) to the mesh and names the nearest triangle. Where the contact geometry is needed
(:meth:`~CollisionWorld.check`, :meth:`~CollisionWorld.clearance`, reported contacts) the
nearest point is recomputed exactly (float64) on that triangle. fcl's own contact output is
not used: its sphere-triangle contacts report negative depths and, for a centre lying on a
face, normals along neither the face nor the centre offset (measured on python-fcl 0.7).

Inside a closed mesh. When the mesh is watertight with consistent winding (every
``trimesh.creation`` primitive, and any union of them made by concatenation), a centre
*inside* an obstacle is recognised with the angle-weighted pseudonormal of the nearest
feature (face, edge or vertex; Baerentzen & Aanaes 2005) and the clearance is then
``-(distance + radius)``. An open mesh (e.g. a single wall quad) has no inside and is
treated as a surface. Overlapping bodies are not merged: a centre inside one body but
nearer to another body's surface counts as outside (its clearance is still <= 0 when that
surface is within the radius). The continuous checks (:meth:`~CollisionWorld.sweep`, the monitor)
start from the signed test and then stop at the first touch, so they never need it again.

Tunnelling: conservative advancement
------------------------------------
:meth:`~CollisionWorld.sweep` uses conservative advancement with the distance query: at a
point whose clearance is ``c`` the sphere cannot touch anything before it has moved ``c``
(the clearance is 1-Lipschitz in the centre position), so it advances exactly ``c`` along
the segment and queries again, until the clearance falls to ``contact_tol`` (contact) or the
ball of radius ``c`` covers the rest of the segment (no contact). Every step is safe, so no
wall of any thickness is crossed unseen at any speed or step length, and the step count
depends on the clearances met rather than on the speed: a 0.2 m wall crossed in one 1 m step
is found on its near face in a handful of queries. Sub-stepping at ``radius / 2`` was not
chosen: it costs ``2 * length / radius`` queries whatever the distance to obstacles and is
exact only for obstacles thicker than the sub-step.

Conservative advancement crawls when the sphere moves nearly tangentially within a hair of
a surface (each step is only as long as the clearance). After ``MAX_CA_STEPS`` steps the
rest of the segment is therefore tested in one query as a capsule (the exact swept volume
of the sphere, ``fcl.Capsule``), and if that touches, the first contact is bisected with
capsule queries to ``contact_tol``.

The mesh and the world are not thread-safe (one fcl probe object is reused) and the mesh
must not be modified after the world is built.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import fcl
import numpy as np
import trimesh

from ft_sitl.physics.body import VehicleBody

__all__ = [
    "BodyProbe",
    "CONTACT_TOL_M",
    "KINDS",
    "MAX_CA_STEPS",
    "CollisionMonitor",
    "CollisionWorld",
    "Contact",
]

#: What a contact can be with, in the order used to break ties between equal depths.
KINDS: tuple[str, ...] = ("obstacle", "floor", "ceiling", "bounds")

#: Default contact tolerance (m): a sphere surface this close to a surface touches it.
CONTACT_TOL_M = 1e-6

#: Conservative-advancement steps within one sweep before the capsule fallback.
MAX_CA_STEPS = 24


@dataclass(frozen=True, eq=False)
class Contact:
    """One contact of a vehicle's collision sphere (all vectors ENU, metres).

    ``point`` is the touched point on the obstacle surface or boundary plane; ``normal`` is a
    unit vector pointing out of the obstacle (or boundary) towards the vehicle, i.e. the
    direction that would separate them; ``penetration_m`` >= 0 is how far the sphere reaches
    past the surface (0 for a touch); ``triangle`` is the mesh triangle hit (-1 for the
    floor, ceiling and bounds); ``center`` is the sphere centre at the contact and ``t`` the
    fraction of the swept segment travelled when it happened (0 for a static check).
    """

    kind: str
    point: np.ndarray
    normal: np.ndarray
    penetration_m: float
    triangle: int = -1
    center: np.ndarray | None = None
    t: float = 0.0


# --------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------


def _vec(value, name: str) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be a finite 3-vector (ENU, m), got {value!r}")
    return a


def _xyz(value, name: str) -> list[float]:
    """A finite 3-vector as a list of floats (the per-step fast path of the monitor)."""
    a = np.asarray(value, dtype=float)
    v = a.tolist()
    if a.shape != (3,) or not (math.isfinite(v[0]) and math.isfinite(v[1])
                               and math.isfinite(v[2])):
        raise ValueError(f"{name} must be a finite 3-vector (ENU, m), got {value!r}")
    return v


def _radius(radius) -> float:
    r = float(radius)
    if not (math.isfinite(r) and r > 0.0):
        raise ValueError(f"radius must be a positive number of metres, got {radius!r}")
    return r


def _kinds(kinds: Iterable[str]) -> frozenset[str]:
    ks = frozenset([kinds] if isinstance(kinds, str) else kinds)
    unknown = ks - set(KINDS)
    if unknown:
        raise ValueError(f"unknown contact kinds {sorted(unknown)}; known: {list(KINDS)}")
    return ks


def _ro(a) -> np.ndarray:
    out = np.array(a, dtype=float)
    out.setflags(write=False)
    return out


def _closest_on_triangle(p, a, b, c) -> tuple[list[float], int]:
    """Closest point of triangle (a, b, c) to p (plain float lists; Ericson's regions).

    Returns ``(q, feature)``: feature -1 = face interior, 0/1/2 = vertex a/b/c,
    3/4/5 = edge ab/bc/ca. Degenerate triangles fall back to the closest edge point.
    """
    ab = [b[0] - a[0], b[1] - a[1], b[2] - a[2]]
    ac = [c[0] - a[0], c[1] - a[1], c[2] - a[2]]
    ap = [p[0] - a[0], p[1] - a[1], p[2] - a[2]]
    d1 = ab[0] * ap[0] + ab[1] * ap[1] + ab[2] * ap[2]
    d2 = ac[0] * ap[0] + ac[1] * ap[1] + ac[2] * ap[2]
    if d1 <= 0.0 and d2 <= 0.0:
        return list(a), 0
    bp = [p[0] - b[0], p[1] - b[1], p[2] - b[2]]
    d3 = ab[0] * bp[0] + ab[1] * bp[1] + ab[2] * bp[2]
    d4 = ac[0] * bp[0] + ac[1] * bp[1] + ac[2] * bp[2]
    if d3 >= 0.0 and d4 <= d3:
        return list(b), 1
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0 and d1 - d3 > 0.0:
        v = d1 / (d1 - d3)
        return [a[0] + v * ab[0], a[1] + v * ab[1], a[2] + v * ab[2]], 3
    cp = [p[0] - c[0], p[1] - c[1], p[2] - c[2]]
    d5 = ab[0] * cp[0] + ab[1] * cp[1] + ab[2] * cp[2]
    d6 = ac[0] * cp[0] + ac[1] * cp[1] + ac[2] * cp[2]
    if d6 >= 0.0 and d5 <= d6:
        return list(c), 2
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0 and d2 - d6 > 0.0:
        w = d2 / (d2 - d6)
        return [a[0] + w * ac[0], a[1] + w * ac[1], a[2] + w * ac[2]], 5
    va = d3 * d6 - d5 * d4
    e1, e2 = d4 - d3, d5 - d6
    if va <= 0.0 and e1 >= 0.0 and e2 >= 0.0 and e1 + e2 > 0.0:
        w = e1 / (e1 + e2)
        return [b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2])], 4
    denom = va + vb + vc
    if denom > 0.0:
        v, w = vb / denom, vc / denom
        return [a[k] + v * ab[k] + w * ac[k] for k in range(3)], -1
    # degenerate triangle (collinear or coincident corners): nearest of its three edges
    best: tuple[float, list[float], int] | None = None
    for (s, e, feat) in ((a, b, 3), (b, c, 4), (c, a, 5)):
        se = [e[k] - s[k] for k in range(3)]
        ll = se[0] * se[0] + se[1] * se[1] + se[2] * se[2]
        t = 0.0 if ll == 0.0 else sum((p[k] - s[k]) * se[k] for k in range(3)) / ll
        t = min(1.0, max(0.0, t))
        q = [s[k] + t * se[k] for k in range(3)]
        dd = sum((p[k] - q[k]) ** 2 for k in range(3))
        if best is None or dd < best[0]:
            best = (dd, q, feat)
    assert best is not None
    return best[1], best[2]


def _rotation_z_to(u: np.ndarray) -> np.ndarray:
    """A rotation matrix taking +z onto the unit vector u or -u (a capsule is symmetric)."""
    if u[2] < 0.0:
        u = -u
    c = float(u[2])
    v = np.array([-u[1], u[0], 0.0])  # z x u
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + k + (k @ k) / (1.0 + c)


# --------------------------------------------------------------------------------------
# the world
# --------------------------------------------------------------------------------------


class BodyProbe:
    """A vehicle body (:class:`~ft_sitl.physics.body.VehicleBody`) as fcl shapes, posed
    per query by :meth:`CollisionWorld.body_distance` and :meth:`CollisionWorld.body_contact`:
    a box for the central body and a cylinder (axis along body z) per rotor disk. Not
    thread-safe (the shapes are moved for each query)."""

    def __init__(self, body: VehicleBody) -> None:
        self.body = body
        shapes = [fcl.Box(*body.box.size)]
        shapes += [fcl.Cylinder(d.radius, d.thickness) for d in body.rotors]
        self.objects = [fcl.CollisionObject(s, fcl.Transform()) for s in shapes]
        self.offsets = [np.array(part.center, dtype=float) for part in body.parts]
        self.bounding_radius_m = body.bounding_radius_m


class CollisionWorld:
    """The scenario's obstacles (one fcl BVH) and its floor, ceiling and area bounds.

    ``mesh`` holds the obstacles only and may have no faces (then only the bounds apply).
    ``bounds_min`` / ``bounds_max`` are the ENU corners of the scenario area: the floor is
    ``bounds_min[2]``, the ceiling ``bounds_max[2]``. ``contact_tol`` (m) is how close
    counts as touching. ``queries`` counts the fcl calls made so far (all callers).
    """

    def __init__(self, mesh: trimesh.Trimesh, bounds_min, bounds_max, *,
                 contact_tol: float = CONTACT_TOL_M) -> None:
        if not isinstance(mesh, trimesh.Trimesh):
            raise TypeError(f"mesh must be a trimesh.Trimesh, got {type(mesh).__name__}")
        lo, hi = _vec(bounds_min, "bounds_min"), _vec(bounds_max, "bounds_max")
        if not np.all(hi > lo):
            raise ValueError(f"bounds are inverted or empty: bounds_max {hi.tolist()} must "
                             f"exceed bounds_min {lo.tolist()} on every axis")
        tol = float(contact_tol)
        if not (math.isfinite(tol) and tol >= 0.0):
            raise ValueError(f"contact_tol must be a non-negative number of metres, "
                             f"got {contact_tol!r}")
        self.bounds_min: np.ndarray = _ro(lo)
        self.bounds_max: np.ndarray = _ro(hi)
        self.contact_tol: float = tol
        self.queries: int = 0

        verts = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int64)
        self.n_triangles: int = int(len(faces))
        self._obj: fcl.CollisionObject | None = None
        self.closed: bool = False
        if self.n_triangles:
            self._build(mesh, verts, faces)
        # one reusable probe: a radius-0 sphere at the query centre
        self._probe = fcl.CollisionObject(fcl.Sphere(0.0), fcl.Transform())
        self._dreq = fcl.DistanceRequest()

        # boundary planes: (kind, axis, sign, value, normal); clearance of the sphere is
        # sign * (p[axis] - value) - r, the normal points into the area (towards the vehicle)
        planes = [("floor", 2, 1.0, lo[2]), ("ceiling", 2, -1.0, hi[2]),
                  ("bounds", 0, 1.0, lo[0]), ("bounds", 0, -1.0, hi[0]),
                  ("bounds", 1, 1.0, lo[1]), ("bounds", 1, -1.0, hi[1])]
        self._planes = []
        for kind, axis, sign, value in planes:
            n = np.zeros(3)
            n[axis] = sign
            self._planes.append((kind, axis, sign, float(value), _ro(n)))

    def _build(self, mesh: trimesh.Trimesh, verts: np.ndarray, faces: np.ndarray) -> None:
        if verts.ndim != 2 or verts.shape[1] != 3 or not np.all(np.isfinite(verts)):
            raise ValueError("mesh vertices must be a finite (N, 3) array")
        if faces.ndim != 2 or faces.shape[1] != 3 or faces.min() < 0 \
                or faces.max() >= len(verts):
            raise ValueError(f"mesh faces must be (M, 3) indices into its {len(verts)} "
                             "vertices")
        tris = verts[faces]
        cross = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
        area2 = np.linalg.norm(cross, axis=1)
        if not np.any(area2 > 0.0):
            raise ValueError(f"degenerate mesh: all {len(faces)} triangles have zero area")
        self._tri = np.ascontiguousarray(tris)
        self._faces = faces
        model = fcl.BVHModel()
        model.beginModel(len(verts), len(faces))
        model.addSubModel(verts, faces)
        model.endModel()
        self._obj = fcl.CollisionObject(model, fcl.Transform())

        with np.errstate(invalid="ignore", divide="ignore"):
            fn = np.where(area2[:, None] > 0.0, cross / area2[:, None], 0.0)
        self._fn = fn
        self.closed = bool(mesh.is_watertight and mesh.is_winding_consistent)
        if self.closed:
            # angle-weighted pseudonormals of vertices and edges decide inside vs outside
            self._orient = 1.0 if mesh.volume >= 0.0 else -1.0
            angles = np.nan_to_num(np.asarray(mesh.face_angles, dtype=float))
            vn = np.zeros((len(verts), 3))
            np.add.at(vn, faces, fn[:, None, :] * angles[:, :, None])
            fue = np.asarray(mesh.faces_unique_edges)
            en = np.zeros((int(fue.max()) + 1, 3))
            np.add.at(en, fue, np.broadcast_to(fn[:, None, :], (len(faces), 3, 3)))
            self._vn = vn
            self._en = en[fue]  # (M, 3 edges ab/bc/ca, 3)

    # --- boundary planes ------------------------------------------------------------------
    @property
    def floor_z(self) -> float:
        return float(self.bounds_min[2])

    @property
    def ceiling_z(self) -> float:
        return float(self.bounds_max[2])

    def _plane_clearances(self, p: np.ndarray, r: float, kinds: frozenset[str]):
        for kind, axis, sign, value, n in self._planes:
            if kind in kinds:
                yield kind, axis, value, n, sign * (float(p[axis]) - value) - r

    def _plane_contact(self, kind, axis, value, n, g, p, t) -> Contact:
        q = np.array(p, dtype=float)
        q[axis] = value
        return Contact(kind, _ro(q), n, max(0.0, -float(g)), -1, _ro(p), float(t))

    def _sweep_bounds(self, p0: np.ndarray, p1: np.ndarray, r: float,
                      kinds: frozenset[str]) -> Contact | None:
        """First contact with a boundary plane along p0 -> p1 (clearance is linear in t)."""
        tol = self.contact_tol
        best = None
        for (kind, axis, value, n, g0), (_, _, _, _, g1) in zip(
                self._plane_clearances(p0, r, kinds), self._plane_clearances(p1, r, kinds)):
            if g0 <= tol:
                t = 0.0
            elif g1 <= tol:
                t = (g0 - tol) / (g0 - g1)
            else:
                continue
            if best is None or t < best[0]:
                best = (t, kind, axis, value, n)
        if best is None:
            return None
        t, kind, axis, value, n = best
        x = p0 + t * (p1 - p0)
        g = (float(x[axis]) - value) * float(n[axis]) - r
        return self._plane_contact(kind, axis, value, n, g, x, t)

    # --- obstacles ------------------------------------------------------------------------
    def _dist_fast(self, p: np.ndarray) -> float:
        """Unsigned distance from the point p to the mesh (one fcl query)."""
        self._probe.setTranslation(p)
        self.queries += 1
        d = fcl.distance(self._probe, self._obj, self._dreq)
        return d if d > 1e-300 else 0.0  # fcl reports ~0 or -1 for a point on the surface

    def _nearest(self, p: np.ndarray) -> tuple[float, list[float], np.ndarray, int]:
        """(signed distance, nearest surface point, unit normal out of the surface towards p,
        triangle) for the point p; negative distance = inside a closed mesh."""
        self._probe.setTranslation(p)
        self.queries += 1
        res = fcl.DistanceResult()
        fcl.distance(self._probe, self._obj, self._dreq, res)
        tri = max(res.b1, res.b2)
        if tri < 0:  # not seen on python-fcl 0.7; name a triangle with a contact query
            self.queries += 1
            cres = fcl.CollisionResult()
            fcl.collide(self._probe, self._obj,
                        fcl.CollisionRequest(num_max_contacts=1, enable_contact=True), cres)
            if not cres.contacts:
                raise RuntimeError(f"fcl named no nearest triangle for {p.tolist()}")
            tri = max(cres.contacts[0].b1, cres.contacts[0].b2)
        a, b, c = self._tri[tri].tolist()
        pl = p.tolist()
        q, feat = _closest_on_triangle(pl, a, b, c)
        diff = [pl[0] - q[0], pl[1] - q[1], pl[2] - q[2]]
        d = math.sqrt(diff[0] ** 2 + diff[1] ** 2 + diff[2] ** 2)
        pn = None
        sign = 1.0
        if self.closed:
            if feat < 0:
                pn = self._fn[tri]
            elif feat < 3:
                pn = self._vn[self._faces[tri, feat]]
            else:
                pn = self._en[tri, feat - 3]
            pn = pn * self._orient
            if d > 0.0 and (diff[0] * pn[0] + diff[1] * pn[1] + diff[2] * pn[2]) < 0.0:
                sign = -1.0
        if d > 1e-12:
            normal = np.array(diff) * (sign / d)
        else:  # centre on the surface: the feature's (pseudo)normal
            normal = np.array(pn if pn is not None else self._fn[tri], dtype=float)
            nn = float(np.linalg.norm(normal))
            normal = normal / nn if nn > 0.0 else np.array([0.0, 0.0, 1.0])
        return sign * d, q, normal, int(tri)

    def _obstacle_contact(self, x: np.ndarray, r: float, t: float) -> tuple[float, Contact]:
        d, q, normal, tri = self._nearest(x)
        c = d - r
        return c, Contact("obstacle", _ro(q), _ro(normal), max(0.0, -float(c)), tri, _ro(x),
                          float(t))

    def _capsule_distance(self, a: np.ndarray, b: np.ndarray, r: float) -> float:
        """Distance from the capsule a-b of radius r (the swept sphere) to the mesh; <= 0 or
        -1 when they touch."""
        ab = b - a
        length = float(np.linalg.norm(ab))
        if length <= 0.0:
            return self._dist_fast(a) - r
        rot = _rotation_z_to(ab / length)
        cap = fcl.CollisionObject(fcl.Capsule(r, length), fcl.Transform(rot, 0.5 * (a + b)))
        self.queries += 1
        return fcl.distance(cap, self._obj, self._dreq)

    def _sweep_obstacles(self, p0: np.ndarray, p1: np.ndarray, r: float,
                         c0: float | None = None) -> tuple[float | None, float]:
        """First contact with the obstacles along p0 -> p1 by conservative advancement.

        ``c0`` is a known lower bound of the clearance at p0 (else a signed query is made).
        Returns ``(s, c)``: ``s`` the distance along the segment of the first contact (None
        if none) and, when there is none, ``c`` a lower bound of the clearance at p1.
        """
        tol = self.contact_tol
        if c0 is None:
            c = self._nearest(p0)[0] - r
        else:
            c = c0
        if c <= tol:
            return 0.0, c
        dp = p1 - p0
        length = float(np.linalg.norm(dp))
        if length == 0.0:
            return None, c
        u = dp / length
        s = 0.0
        for _ in range(MAX_CA_STEPS):
            if c - tol > length - s:  # the safe ball around x(s) holds the rest
                return None, c - (length - s)
            s = min(s + c, length)
            c = self._dist_fast(p0 + s * u) - r
            if c <= tol:
                return s, c
        # nearly tangential crawl: test the rest as one swept capsule, bisect if it touches
        D = self._capsule_distance(p0 + s * u, p1, r)
        if D > tol:
            return None, D
        lo, hi = s, length
        while hi - lo > max(tol, 1e-12 * length):
            mid = 0.5 * (lo + hi)
            if self._capsule_distance(p0 + lo * u, p0 + mid * u, r) > tol:
                lo = mid
            else:
                hi = mid
        return hi, 0.0

    def step_check(self, a: np.ndarray, b: np.ndarray, seg: float, r: float,
                   lb_a: float) -> tuple[Contact | None, float]:
        """Obstacle check of one step a -> b (length seg) of a sphere of radius r, given a
        lower bound lb_a of its clearance at a (-inf if unknown): ``(contact, c)`` with the
        first contact or None and, when free, a lower bound c of the clearance at b (-inf
        after a contact). One fcl query when that settles it, else a conservative sweep."""
        tol = self.contact_tol
        c_b = -math.inf
        if lb_a > tol:
            c_b = self._dist_fast(b) - r
            if c_b > tol and lb_a + c_b - seg > 2.0 * tol:
                # clearance >= max(lb_a - s, c_b - (seg - s)) > tol all along a-b
                return None, c_b
            s, c_end = self._sweep_obstacles(a, b, r, c0=lb_a)
        else:
            s, c_end = self._sweep_obstacles(a, b, r, c0=None)
        if s is None:
            return None, max(c_end, c_b)
        t = s / seg if seg > 0.0 else 0.0
        return self._obstacle_contact(a + (b - a) * t, r, t)[1], -math.inf

    # --- vehicle bodies ---------------------------------------------------------------------
    def body_distance(self, probe: BodyProbe, p: np.ndarray, rot: np.ndarray) -> float:
        """Distance (m) from the body posed at position p with rotation rot (body to
        world) to the obstacles: > contact_tol free, else touching or in contact (fcl
        reports -1 for shapes in contact); ``inf`` without obstacles. One fcl query per
        part."""
        if self._obj is None:
            return math.inf
        best = math.inf
        for obj, offset in zip(probe.objects, probe.offsets):
            obj.setTransform(fcl.Transform(rot, p + rot @ offset))
            self.queries += 1
            best = min(best, fcl.distance(obj, self._obj, self._dreq))
            if best <= self.contact_tol:
                break
        return best

    def body_contact(self, probe: BodyProbe, p: np.ndarray, rot: np.ndarray) -> Contact | None:
        """The contact of the body posed at (p, rot) with the obstacles, or None: the
        touched point and triangle from fcl, the normal from the centre's nearest obstacle
        point (fcl's shape-mesh normals are not reliable: module docstring)."""
        if self._obj is None:
            return None
        req = fcl.CollisionRequest(num_max_contacts=1, enable_contact=True)
        for obj, offset in zip(probe.objects, probe.offsets):
            obj.setTransform(fcl.Transform(rot, p + rot @ offset))
            self.queries += 1
            res = fcl.CollisionResult()
            if fcl.collide(obj, self._obj, req, res) and res.contacts:
                ct = res.contacts[0]
                normal = self._nearest(p)[2]
                return Contact("obstacle", _ro(np.asarray(ct.pos, dtype=float)), _ro(normal),
                               max(0.0, float(ct.penetration_depth)), max(ct.b1, ct.b2),
                               _ro(p.copy()), 1.0)
        return None

    # --- public queries -------------------------------------------------------------------
    def obstacle_distance(self, p) -> float:
        """Signed distance (m) from the point p to the obstacle surface (negative inside a
        closed mesh; ``inf`` without obstacles)."""
        pa = _vec(p, "p")
        if self._obj is None:
            return math.inf
        return self._nearest(pa)[0]

    def clearance(self, p, radius: float, kinds: Iterable[str] = KINDS) -> float:
        """Signed distance (m) from the surface of the sphere (centre p, ``radius``) to the
        nearest obstacle or boundary among ``kinds``: > 0 free, 0 touching, -depth in
        contact; ``inf`` if nothing among ``kinds`` exists."""
        pa, r, ks = _vec(p, "p"), _radius(radius), _kinds(kinds)
        best = math.inf
        if "obstacle" in ks and self._obj is not None:
            best = self._nearest(pa)[0] - r
        for *_, g in self._plane_clearances(pa, r, ks):
            best = min(best, g)
        return best

    def check(self, p, radius: float, kinds: Iterable[str] = KINDS) -> Contact | None:
        """The deepest contact of the sphere (centre p, ``radius``) among ``kinds``, or None.
        Ties go to the earlier kind in :data:`KINDS`."""
        pa, r, ks = _vec(p, "p"), _radius(radius), _kinds(kinds)
        tol = self.contact_tol
        best: tuple[float, Contact] | None = None
        if "obstacle" in ks and self._obj is not None:
            d, q, normal, tri = self._nearest(pa)
            if d - r <= tol:
                best = (d - r, Contact("obstacle", _ro(q), _ro(normal), max(0.0, r - d), tri,
                                       _ro(pa), 0.0))
        for kind, axis, value, n, g in self._plane_clearances(pa, r, ks):
            if g <= tol and (best is None or g < best[0]):
                best = (g, self._plane_contact(kind, axis, value, n, g, pa, 0.0))
        return None if best is None else best[1]

    def sweep(self, p0, p1, radius: float, kinds: Iterable[str] = KINDS) -> Contact | None:
        """First contact of the sphere moved in a straight line from p0 to p1, or None.

        The contact's ``t`` is the fraction of the segment travelled and ``center`` the
        sphere centre there (the first touch, penetration ~0, unless p0 is already in
        contact). Obstacles by conservative advancement (no tunnelling, see the module
        docstring), boundary planes exactly.
        """
        a, b, r, ks = _vec(p0, "p0"), _vec(p1, "p1"), _radius(radius), _kinds(kinds)
        hit_b = self._sweep_bounds(a, b, r, ks)
        hit_o = None
        if "obstacle" in ks and self._obj is not None:
            end = b if hit_b is None else a + hit_b.t * (b - a)  # nothing beyond matters
            s, _ = self._sweep_obstacles(a, end, r)
            if s is not None:
                length = float(np.linalg.norm(b - a))
                t = s / length if length > 0.0 else 0.0
                x = a + (b - a) * t
                hit_o = self._obstacle_contact(x, r, t)[1]
        if hit_o is not None and (hit_b is None or hit_o.t <= hit_b.t):
            return hit_o
        return hit_b


# --------------------------------------------------------------------------------------
# the per-vehicle monitor
# --------------------------------------------------------------------------------------


class CollisionMonitor:
    """Continuous collision checking of one vehicle at a cost that follows its proximity.

    After each fcl query the monitor keeps the anchor point ``a`` and its obstacle clearance
    ``c``: no obstacle can be touched while the vehicle stays within ``c`` of ``a``. It also
    keeps the distance flown since (the path length, an upper bound of the displacement), and
    calls fcl again only once that reaches ``c - margin_m``. Far from everything this is one
    query every ``c`` metres; near an obstacle, about every step. A refresh first queries the
    new position only; if that clearance and the one left at the previous position cannot
    prove the step free, the step is swept by conservative advancement
    (:meth:`CollisionWorld.sweep`'s algorithm), so nothing is tunnelled through.

    The boundary planes are checked analytically on every step (a few comparisons).

    ``update(p_prev, p_now, radius)`` must be called with consecutive positions
    (``p_prev`` = the previous call's ``p_now``); anything else, or a change of radius,
    restarts the monitor with a signed check at ``p_prev``. ``queries`` counts its fcl
    calls, ``steps`` the segments checked.
    """

    def __init__(self, world: CollisionWorld, *, kinds: Iterable[str] = KINDS,
                 margin_m: float | None = None) -> None:
        self.world = world
        self.kinds = _kinds(kinds)
        margin = 2.0 * world.contact_tol + 1e-9 if margin_m is None else float(margin_m)
        if not (math.isfinite(margin) and margin >= world.contact_tol):
            raise ValueError(f"margin_m must be >= the world's contact_tol "
                             f"({world.contact_tol} m), got {margin_m!r}")
        self.margin_m = margin
        self._obstacles = "obstacle" in self.kinds and world._obj is not None
        lo, hi = world.bounds_min, world.bounds_max
        inf = math.inf
        use_b, use_f, use_c = ("bounds" in self.kinds, "floor" in self.kinds,
                               "ceiling" in self.kinds)
        self._lo = (float(lo[0]) if use_b else -inf, float(lo[1]) if use_b else -inf,
                    float(lo[2]) if use_f else -inf)
        self._hi = (float(hi[0]) if use_b else inf, float(hi[1]) if use_b else inf,
                    float(hi[2]) if use_c else inf)
        self.queries = 0
        self.steps = 0
        self.reset()

    def reset(self) -> None:
        """Forget the anchor: the next update starts with a signed check."""
        self._last: list[float] | None = None
        self._radius: float | None = None
        self._c_anchor = -math.inf  # obstacle clearance at the anchor (invalid)
        self._flown = 0.0  # path length since the anchor

    @property
    def clearance_bound(self) -> float:
        """A lower bound (m) of the current obstacle clearance (-inf before the first
        update or after a contact)."""
        return self._c_anchor - self._flown

    # --- internals ------------------------------------------------------------------------
    def _bounds_hit(self, x: float, y: float, z: float, r: float) -> bool:
        tol = self.world.contact_tol
        lo, hi = self._lo, self._hi
        return (x - r - lo[0] <= tol or hi[0] - x - r <= tol or y - r - lo[1] <= tol
                or hi[1] - y - r <= tol or z - r - lo[2] <= tol or hi[2] - z - r <= tol)

    def _refresh(self, a: np.ndarray, b: np.ndarray, seg: float, r: float,
                 lb_a: float) -> Contact | None:
        """The vehicle moved a -> b (length seg) and may have used up its margin; lb_a is a
        lower bound of the obstacle clearance at a (-inf if unknown)."""
        w = self.world
        q0 = w.queries
        try:
            contact, c = w.step_check(a, b, seg, r, lb_a)
        finally:
            self.queries += w.queries - q0
        self._c_anchor, self._flown = c, 0.0
        return contact

    def _start(self, r: float) -> None:
        self._radius = r
        self._c_anchor, self._flown = -math.inf, 0.0

    @staticmethod
    def _earliest(hit_o: Contact | None, hit_b: Contact | None) -> Contact | None:
        if hit_o is not None and (hit_b is None or hit_o.t <= hit_b.t):
            return hit_o
        return hit_b

    # --- public ---------------------------------------------------------------------------
    def update(self, p_prev, p_now, radius: float) -> Contact | None:
        """Check the step p_prev -> p_now; the first contact on it, or None."""
        al, bl = _xyz(p_prev, "p_prev"), _xyz(p_now, "p_now")
        r = float(radius)
        if r != self._radius or al != self._last:
            self._start(_radius(r))
        self._last = bl
        self.steps += 1
        seg = math.dist(al, bl)
        hit_b = None
        if self._bounds_hit(bl[0], bl[1], bl[2], r) or self._bounds_hit(al[0], al[1], al[2], r):
            hit_b = self.world._sweep_bounds(np.array(al), np.array(bl), r, self.kinds)
        if not self._obstacles:
            return hit_b
        lb_a = self._c_anchor - self._flown
        self._flown += seg
        if self._flown < self._c_anchor - self.margin_m:
            return hit_b
        hit_o = self._refresh(np.array(al), np.array(bl), seg, r, lb_a)
        return self._earliest(hit_o, hit_b)

    def update_path(self, points, radius: float) -> tuple[int, Contact] | None:
        """Check the polyline ``points`` (N >= 2 consecutive positions, ``points[0]`` the
        previous position) in one call; vectorised between fcl queries.

        Returns ``(i, contact)`` for the first contact, on segment ``points[i] ->
        points[i + 1]``, or None. Checking stops at the first contact. Equivalent to calling
        :meth:`update` on each segment, with the same fcl queries (up to rounding of the
        accumulated path length).
        """
        P = np.asarray(points, dtype=float)
        if P.ndim != 2 or P.shape[1] != 3 or len(P) < 2:
            raise ValueError("points must be a finite (N >= 2, 3) array of positions")
        n_seg = len(P) - 1
        # (column-wise numpy: reductions along axis 0 of an (N, 3) array are ~20x slower)
        d = P[1:] - P[:-1]
        dx, dy, dz = d[:, 0], d[:, 1], d[:, 2]
        cum = np.empty(n_seg + 1)
        cum[0] = 0.0
        np.cumsum(np.sqrt(dx * dx + dy * dy + dz * dz), out=cum[1:])
        total = float(cum[-1])
        first = P[0].tolist()
        if not (math.isfinite(total) and math.isfinite(first[0]) and math.isfinite(first[1])
                and math.isfinite(first[2])):  # any NaN or inf makes the path length so
            raise ValueError("points must be a finite (N >= 2, 3) array of positions")
        r = float(radius)
        if r != self._radius or first != self._last:
            self._start(_radius(r))
        w = self.world
        tol = w.contact_tol

        # the first segment that meets a boundary plane: per-axis extremes first, the
        # per-point test only when one of them is out
        kb, hit_b = n_seg, None
        lo, hi = self._lo, self._hi
        cols = (P[:, 0], P[:, 1], P[:, 2])
        if any(float(cols[k].min()) - r - lo[k] <= tol or hi[k] - float(cols[k].max()) - r <= tol
               for k in range(3)):
            bad = np.any((P - r - np.array(lo) <= tol) | (np.array(hi) - P - r <= tol), axis=1)
            kb = max(0, int(np.argmax(bad)) - 1)
            hit_b = w._sweep_bounds(P[kb], P[kb + 1], r, self.kinds)

        result: tuple[int, Contact] | None = None
        if self._obstacles:
            off = -self._flown  # path length since the anchor at point k: cum[k] - off
            last = min(kb, n_seg - 1)  # last segment worth checking
            k = 1
            while True:
                # first point k whose flown distance reaches c_anchor - margin
                limit = self._c_anchor - self.margin_m + off
                if cum[last + 1] < limit:
                    break
                k = max(k, int(np.searchsorted(cum, limit, side="left")))
                lb_a = self._c_anchor - (cum[k - 1] - off)
                hit_o = self._refresh(P[k - 1], P[k], float(cum[k] - cum[k - 1]), r, lb_a)
                if hit_o is not None:
                    if k - 1 == kb:
                        hit_o = self._earliest(hit_o, hit_b)
                    result = (k - 1, hit_o)
                    break
                off = float(cum[k])
                if k - 1 >= last:
                    break
                k += 1
            if result is None:
                self._flown = float(cum[last + 1]) - off
        if result is None and hit_b is not None:
            result = (kb, hit_b)
            self._c_anchor, self._flown = -math.inf, 0.0
        end = n_seg if result is None else result[0] + 1
        self.steps += end
        self._last = P[end].tolist()
        return result
