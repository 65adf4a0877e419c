"""Collision checking inside the lockstep physics loop: vehicles crash into what they hit.

A :class:`CollisionGuard` attached to a :class:`~ft_sitl.lockstep.Simulation` checks every
physics step of every vehicle for contact with the scenario's obstacles and for leaving the
flight volume, without calling Python on most steps. Per vehicle the compiled loop keeps

* an *anchor*: a point and a lower bound ``c`` of the vehicle's obstacle clearance there.
  The clearance is 1-Lipschitz in the position, so anywhere within ``c`` of the anchor the
  vehicle touches nothing;
* a *free ball*: a ball around the position of the last full check, no larger than what
  the anchor guarantees and no larger than the distance to the flight-volume planes. A
  ball is convex, so while each step ends inside it the whole path does: the per-step
  check is one squared distance compared with a radius squared (no square root, no
  memory beyond the row);
* a :class:`DistanceGrid`: a voxel grid of lower bounds of the distance to the obstacles,
  built once per scenario. When a step leaves the ball and the anchor no longer covers the
  new position, the loop reads the grid there; if the grid proves the step free (see
  :func:`ft_sitl.lockstep.guard_step`) that bound becomes the new anchor.

Only when both fail (the vehicle is within about half a metre of an obstacle, or the grid
does not cover it) does the loop stop that vehicle and hand the step to
:meth:`CollisionGuard.resolve`, which settles it exactly with python-fcl
(:meth:`CollisionWorld.step_check`: one distance query, or conservative advancement over the
step, so no wall is tunnelled through). A free step refreshes the anchor with the exact
clearance; a contact is reported and answered physically.

What a contact does (:meth:`CollisionGuard.resolve`): the vehicle is put back where its
sphere first touched (plus 1 mm), its velocity into the surface is removed and the
tangential velocity loses a Coulomb friction share (coefficient :data:`FRICTION`), and the
first contact of each vehicle is reported as a ``"collision"`` :class:`GuardEvent` naming
what was hit. The fleet turns that into a crash (motors stopped, STATUSTEXT). Later contacts
of a crashed vehicle (sliding down a wall as it falls) are answered the same way, silently.

The flight volume (the scenario's area and ceiling; the floor belongs to the plant's ground
contact) is checked on the vehicle's *centre*: ``"left_volume"`` when it crosses out,
``"entered_volume"`` when it comes back; the benchmark scores the former as out of bounds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.ndimage import distance_transform_edt

from ft_sitl import lockstep as ls
from ft_sitl.physics import dynamics as d
from ft_sitl.scenarios.collision import CollisionMonitor, CollisionWorld, Contact

#: grid pitches (m) tried finest first: the finest whose grid has at most GRID_MAX_CELLS
#: cells is used (a finer grid gives tighter bounds, so fewer exact checks near obstacles)
GRID_PITCHES_M = (0.1, 0.125, 0.15, 0.2, 0.25)
#: the grid covers the flight volume grown by this much on every side (m)
GRID_PAD_M = 1.0
#: cell budget (float32: 4 bytes each); a volume too large for the coarsest pitch gets a
#: coarser one still
GRID_MAX_CELLS = 8_000_000
#: separation (m) a resolved contact leaves between the sphere and the surface
SEPARATION_M = 1e-3
#: Coulomb friction coefficient of a contact with an obstacle
FRICTION = 0.5
#: a contact normal this close to vertical supports a crashed vehicle (it rests on it)
SUPPORT_NZ = 0.7
_FAR = np.float32(1e9)


class DistanceGrid:
    """Lower bounds of the distance from voxel centres to a triangle mesh.

    ``data[i, j, k]`` <= the distance from the centre ``origin + (i + 0.5, j + 0.5, k + 0.5)
    * pitch`` to the nearest point of the mesh, for every voxel of the grid. Built from a
    sampling of the surface: every triangle gets a barycentric lattice of points no farther
    than ``sample_m`` from any point of it; voxels holding a sample are occupied; a Euclidean
    distance transform gives each centre its distance E to the nearest occupied centre; then
    distance >= E - pitch * sqrt(3) / 2 - sample_m. Surface outside the grid is projected onto
    its boundary first (projection onto a box never increases a distance from inside it), so
    the bound holds for obstacles of any extent.
    """

    def __init__(self, data: np.ndarray, origin, pitch: float):
        self.data = np.ascontiguousarray(data, dtype=np.float32)
        self.origin = np.asarray(origin, dtype=float)
        self.pitch = float(pitch)

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.data.shape)

    @classmethod
    def build(cls, mesh, lo, hi, *, pitch: float | None = None, pad: float = GRID_PAD_M,
              max_cells: int = GRID_MAX_CELLS) -> DistanceGrid:
        lo = np.asarray(lo, dtype=float) - pad
        hi = np.asarray(hi, dtype=float) + pad
        extent = hi - lo
        if pitch is None:
            pitch = next((p for p in GRID_PITCHES_M
                          if np.prod(np.ceil(extent / p)) <= max_cells), GRID_PITCHES_M[-1])
        while np.prod(np.ceil(extent / pitch)) > max_cells:
            pitch *= 1.25
        shape = np.ceil(extent / pitch).astype(np.int64)
        sample = pitch / 2.0
        occ = np.zeros(tuple(shape), dtype=bool)
        verts = np.asarray(mesh.vertices, dtype=float)
        faces = np.asarray(mesh.faces, dtype=np.int64)
        if len(faces) == 0:
            return cls(np.full(tuple(shape), _FAR, dtype=np.float32), lo, pitch)
        tri = verts[faces]
        e = np.stack([np.linalg.norm(tri[:, 1] - tri[:, 0], axis=1),
                      np.linalg.norm(tri[:, 2] - tri[:, 1], axis=1),
                      np.linalg.norm(tri[:, 0] - tri[:, 2], axis=1)], axis=1).max(axis=1)
        n_sub = np.maximum(1, np.ceil(e / sample)).astype(np.int64)
        top = shape - 1
        for n in np.unique(n_sub):
            a, b = np.triu_indices(n + 1)  # a <= b, so (a, n - b) covers i + j <= n
            u, v = a / n, (n - b) / n
            w = np.column_stack([1.0 - u - v, u, v])
            group = tri[n_sub == n]
            # chunks of about two million points
            step = max(1, 2_000_000 // len(w))
            for s in range(0, len(group), step):
                pts = np.einsum("pk,tkc->tpc", w, group[s:s + step]).reshape(-1, 3)
                idx = np.floor((pts - lo) / pitch).astype(np.int64)
                np.clip(idx, 0, top, out=idx)
                occ[idx[:, 0], idx[:, 1], idx[:, 2]] = True
        dist = distance_transform_edt(~occ, sampling=pitch)
        bound = dist - pitch * math.sqrt(3.0) / 2.0 - sample - 1e-6
        return cls(np.maximum(bound, 0.0).astype(np.float32), lo, pitch)

    def lower_bound(self, p) -> float:
        """Lower bound of the distance from point p to the mesh (-inf outside the grid)."""
        meta = np.zeros(ls.M_N)
        meta[ls.M_OX:ls.M_OZ + 1] = self.origin
        meta[ls.M_H] = self.pitch
        meta[ls.M_NX:ls.M_NZ + 1] = self.shape
        return float(ls.grid_lower_bound(self.data, meta, float(p[0]), float(p[1]),
                                         float(p[2])))


@dataclass(frozen=True)
class GuardEvent:
    """Something the guard saw: ``kind`` is "collision", "left_volume" or
    "entered_volume"; ``what`` names the obstacle or the side ("tree 7", "ceiling",
    "north edge"); ``position`` is the vehicle's ENU position; ``contact`` the contact of a
    collision."""

    time_us: int
    vehicle: int
    kind: str
    what: str
    position: np.ndarray
    speed_m_s: float
    contact: Contact | None = None


class CollisionGuard:
    """Collision and flight-volume checks for the vehicles of one Simulation in one world.

    ``radii``: each vehicle's collision radius (m). ``names`` maps a mesh triangle to the
    obstacle's name (e.g. ``Scenario.obstacle_name``). ``handler(event)`` is called for each
    :class:`GuardEvent` while the simulation steps (the fleet uses it to crash the vehicle
    at once); events are also kept in ``events``.
    """

    def __init__(self, world: CollisionWorld, radii: Sequence[float], *,
                 grid: DistanceGrid | None = None,
                 names: Callable[[int], str] | None = None,
                 check_volume: bool = True) -> None:
        self.world = world
        self.radii = [float(r) for r in radii]
        for r in self.radii:
            if not (math.isfinite(r) and r >= 0.0):
                raise ValueError(f"collision radius must be a non-negative number of metres, "
                                 f"got {r!r}")
        self.grid = grid
        self.names = names or (lambda face: "obstacle")
        self.check_volume = bool(check_volume)
        self.handler: Callable[[GuardEvent], None] | None = None
        self.events: list[GuardEvent] = []
        self.crashed = [False] * len(self.radii)
        self.queries = 0  # exact (fcl) steps resolved
        self.trips = 0
        self._margin = CollisionMonitor(world).margin_m

    @classmethod
    def for_scenario(cls, scenario, radii: Sequence[float], **kw) -> CollisionGuard:
        world = CollisionWorld(scenario.mesh, scenario.bounds_min, scenario.bounds_max)
        grid = DistanceGrid.build(scenario.mesh, scenario.bounds_min, scenario.bounds_max)
        return cls(world, radii, grid=grid, names=scenario.obstacle_name, **kw)

    # --- attaching ----------------------------------------------------------------------
    def attach(self, sim) -> None:
        if len(self.radii) != sim.n:
            raise ValueError(f"{len(self.radii)} collision radii for {sim.n} vehicles")
        sim.guard = self
        meta = np.zeros(ls.M_N)
        if self.grid is not None:
            meta[ls.M_OX:ls.M_OZ + 1] = self.grid.origin
            meta[ls.M_H] = self.grid.pitch
            meta[ls.M_NX:ls.M_NZ + 1] = self.grid.shape
            sim._grid = self.grid.data
        else:
            meta[ls.M_H] = 1.0  # an empty grid: every lookup is "unknown"
        lo, hi = self.world.bounds_min, self.world.bounds_max
        meta[[ls.M_LOX, ls.M_LOY, ls.M_HIX, ls.M_HIY, ls.M_HIZ]] = (lo[0], lo[1], hi[0],
                                                                    hi[1], hi[2])
        meta[ls.M_MARGIN] = self._margin
        sim._meta = meta
        self._sim = sim
        for i in range(sim.n):
            self.reset(i)

    def reset(self, i: int) -> None:
        """Forget vehicle i's history (after it was placed somewhere new)."""
        g = self._sim._gd[i]
        g[:] = 0.0
        g[ls.G_ON] = 1.0 if self.world._obj is not None else 0.0
        g[ls.G_R] = self.radii[i]
        g[ls.G_ANCHOR] = -math.inf
        g[ls.G_RR] = -1.0
        g[ls.G_BOUNDS] = 1.0 if self.check_volume else 0.0
        g[ls.G_OUT] = 1.0 if self._outside(self._sim.x[i, d.X_POS:d.X_POS + 3]) else 0.0
        self._sim.plant.env[i, d.E_GROUND_Z] = self.world.floor_z
        self.crashed[i] = False

    def _outside(self, p) -> str:
        """Which side of the flight volume the point p is beyond ("" inside)."""
        lo, hi = self.world.bounds_min, self.world.bounds_max
        if p[2] > hi[2]:
            return "ceiling"
        for k, (lo_name, hi_name) in enumerate((("west edge", "east edge"),
                                                ("south edge", "north edge"))):
            if p[k] < lo[k]:
                return lo_name
            if p[k] > hi[k]:
                return hi_name
        return ""

    def clearance(self, i: int) -> float:
        """Exact obstacle clearance (m) of vehicle i's sphere now (one fcl query)."""
        p = self._sim.x[i, d.X_POS:d.X_POS + 3]
        return self.world.clearance(p, self.radii[i], kinds=("obstacle",))

    # --- the slow path ----------------------------------------------------------------
    def _emit(self, ev: GuardEvent) -> None:
        self.events.append(ev)
        if self.handler is not None:
            self.handler(ev)

    def resolve(self, sim, i: int, time_us: int) -> None:
        """Settle the step at which vehicle i's guard row stopped the kernel."""
        self.trips += 1
        g = sim._gd[i]
        trip = int(g[ls.G_TRIP])
        g[ls.G_TRIP] = 0.0
        g[ls.G_RR] = -1.0  # a full check at the next step
        x = sim.x[i]
        a = g[ls.G_AX:ls.G_AZ + 1].copy()
        b = x[d.X_POS:d.X_POS + 3].copy()
        r = self.radii[i]
        speed = float(np.linalg.norm(x[d.X_VEL:d.X_VEL + 3]))
        if trip & 1:
            self.queries += 1
            seg = float(np.linalg.norm(b - a))
            contact, c = self.world.step_check(a, b, seg, r, float(g[ls.G_LBA]))
            if contact is None:
                self._anchor(g, b, c)
            else:
                first = not self.crashed[i]
                self.crashed[i] = True
                self._respond(sim, i, contact)
                if first:
                    self._emit(GuardEvent(time_us, i, "collision",
                                          self.names(contact.triangle),
                                          np.array(contact.center), speed, contact))
                b = x[d.X_POS:d.X_POS + 3].copy()
        if trip & 2 or (g[ls.G_BOUNDS] > 0.0 and (g[ls.G_OUT] > 0.0) != bool(self._outside(b))):
            side = self._outside(b)
            g[ls.G_OUT] = 1.0 if side else 0.0
            if side:
                self._emit(GuardEvent(time_us, i, "left_volume", side, b, speed))
            else:
                self._emit(GuardEvent(time_us, i, "entered_volume", "flight volume", b, speed))

    def _respond(self, sim, i: int, contact: Contact) -> None:
        """An inelastic contact with friction: back to where the sphere touched, no velocity
        into the surface, the tangential velocity reduced by FRICTION x the normal one."""
        x = sim.x[i]
        n = np.asarray(contact.normal, dtype=float)
        x[d.X_POS:d.X_POS + 3] = np.asarray(contact.center) + SEPARATION_M * n
        v = x[d.X_VEL:d.X_VEL + 3]
        vn = float(v @ n)
        if vn < 0.0:
            vt = v - vn * n
            speed_t = float(np.linalg.norm(vt))
            keep = max(0.0, speed_t - FRICTION * (-vn)) / speed_t if speed_t > 0.0 else 0.0
            x[d.X_VEL:d.X_VEL + 3] = vt * keep
        if self.crashed[i] and n[2] > SUPPORT_NZ:
            # a crashed vehicle lying on top of an obstacle rests there like on the floor
            # (the plant's ground contact holds it), instead of touching it every step
            env = sim.plant.env[i]
            env[d.E_GROUND_Z] = max(env[d.E_GROUND_Z], x[d.X_POS + 2])
        g = sim._gd[i]
        p = x[d.X_POS:d.X_POS + 3].copy()
        c = self.world._nearest(p)[0] - self.radii[i]
        self._anchor(g, p, c if c > self.world.contact_tol else -math.inf)

    @staticmethod
    def _anchor(g, p, c: float) -> None:
        g[ls.G_ANCHOR] = c
        g[ls.G_OX:ls.G_OZ + 1] = p
        g[ls.G_RR] = -1.0

    def clearance_bound(self, i: int) -> float:
        """A lower bound (m) of vehicle i's obstacle clearance now, from the guard's
        anchor (no query; -inf when unknown)."""
        g = self._sim._gd[i]
        p = self._sim.x[i, d.X_POS:d.X_POS + 3]
        r = p - g[ls.G_OX:ls.G_OZ + 1]
        return float(g[ls.G_ANCHOR] - math.sqrt(r.dot(r)))  # np.linalg.norm's arithmetic
