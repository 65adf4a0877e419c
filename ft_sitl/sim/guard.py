"""Collision checking inside the lockstep physics loop: vehicles crash into what they hit.

A :class:`CollisionGuard` attached to a :class:`~ft_sitl.sim.lockstep.Simulation` checks every
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
* a :class:`~ft_sitl.scenarios.distance_grid.DistanceGrid`: a voxel grid of lower bounds
  of the distance to the obstacles, built once per scenario. When a step leaves the ball
  and the anchor no longer covers the new position, the loop reads the grid there; if the
  grid proves the step free (see :func:`guard_step`) that bound becomes the new anchor.

Only when both fail (the vehicle is within about half a metre of an obstacle, or the grid
does not cover it) does the loop stop that vehicle and hand the step to
:meth:`CollisionGuard.resolve`, which settles it exactly with python-fcl
(:meth:`CollisionWorld.step_check`: one distance query, or conservative advancement over the
step, so no wall is tunnelled through). A free step refreshes the anchor with the exact
clearance; a contact is reported and answered physically.

What a contact does (:meth:`CollisionGuard.resolve`): the vehicle is put back where its
sphere first touched (plus 1 mm), its velocity into the surface is removed and the
tangential velocity loses a Coulomb friction share (coefficient :data:`FRICTION`), and the
first contact of each vehicle is reported as a ``COLLISION`` :class:`GuardEvent` naming
what was hit. The fleet turns that into a crash (motors stopped, STATUSTEXT). Later contacts
of a crashed vehicle (sliding down a wall as it falls) are answered the same way, silently.

Vehicles with a body (``bodies``; trial protocol 5 on, and every Fleet): the sphere above
is the body's bounding sphere, the broad phase. Where the sphere may touch something,
:meth:`CollisionGuard.resolve` measures the body itself (its central box and rotor disks,
posed by the vehicle's attitude: :meth:`CollisionWorld.body_distance`); a free body becomes
a *body anchor* (its clearance c at a pose), and the compiled loop carries on while every
body point provably stays within c: the centre inside a free ball and the attitude within a
rotation budget (a point at distance R from the centre moves 2 R sin(dtheta / 2) under a
rotation dtheta). Once the bounding sphere is clear again, it is the sphere's check again.
A body contact puts the vehicle back at the step's start, with the same velocity response.

The flight volume (the scenario's area and ceiling; the floor belongs to the plant's ground
contact) is checked on the vehicle's *centre*: ``LEFT_VOLUME`` when it crosses out,
``ENTERED_VOLUME`` when it comes back; the benchmark scores the former as out of bounds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from numba import njit

from ft_sitl.physics import dynamics as d
from ft_sitl.physics.body import VehicleBody
from ft_sitl.rotations import matrix_from_quat
from ft_sitl.scenarios.collision import BodyProbe, CollisionMonitor, CollisionWorld, Contact
from ft_sitl.scenarios.distance_grid import GM_H, GRID_META_N, DistanceGrid, grid_lower_bound
from ft_sitl.sim.guard_movers import MoverChecks

# --- the guard row (one per vehicle) and the meta row ----------------------------------------
# G_ON: check obstacles (0/1); G_R: collision radius (m); G_ANCHOR: lower bound of the
# obstacle clearance (sphere surface, m) at the anchor point G_O*; G_B*, G_RR: the free
# ball (centre, radius squared; < 0: none): while the centre stays inside it no obstacle can
# be touched and the flight volume is not crossed, so the kernel does nothing else;
# G_A*: position before the step that tripped; G_LBA: clearance bound there;
# G_OUT: 1 while the centre is outside the flight volume (checked when G_BOUNDS is 1);
# G_TRIP: why the kernel stopped this vehicle (1 obstacles, 2 bounds, bit set).
# Vehicles with a body (CollisionGuard.probes[i]): G_R is its bounding radius, so the
# sphere rows above are its broad phase. While the bounding sphere is within reach of an
# obstacle, the anchor is the body's own (G_BMODE 1): G_ANCHOR is then the body's
# clearance at the anchor pose (position G_O*, attitude G_QW..G_QZ), and the kernel bounds
# the motion of every body point by |dp| + 2 R sin(dtheta / 2).
# In body mode the free ball also has an attitude: the kernel stays silent while the centre
# is inside the ball and the attitude within the rotation budget of G_BQW..G_BQZ
# (<q_ball, q>^2 > G_DOT2), which together keep every body point inside the anchor's reach.
(G_ON, G_R, G_ANCHOR, G_OX, G_OY, G_OZ, G_BX, G_BY, G_BZ, G_RR, G_AX, G_AY, G_AZ, G_LBA,
 G_OUT, G_BOUNDS, G_TRIP, G_BMODE, G_QW, G_QX, G_QY, G_QZ, G_BQW, G_BQX, G_BQY,
 G_BQZ, G_DOT2) = range(27)
G_N = 27
# guard meta row: the distance grid's layout first (origin (3), pitch, shape (3): what
# grid_lower_bound reads), then the flight volume lo x/y, hi x/y/z and the margin (m)
(M_LOX, M_LOY, M_HIX, M_HIY, M_HIZ, M_MARGIN) = range(GRID_META_N, GRID_META_N + 6)
M_N = GRID_META_N + 6


@njit(cache=True)
def body_motion_bound(g, x, qx, qy, qz):
    """How far any point of a body may have moved since its anchor pose: the centre's
    displacement plus 2 R sin(dtheta / 2) for the rotation dtheta (|<q_anchor, q>| is
    cos(dtheta / 2))."""
    dot = abs(g[G_QW] * x[d.X_QUAT] + g[G_QX] * x[d.X_QUAT + 1] + g[G_QY] * x[d.X_QUAT + 2]
              + g[G_QZ] * x[d.X_QUAT + 3])
    s2 = 1.0 - dot * dot
    rot = 2.0 * g[G_R] * np.sqrt(s2) if s2 > 0.0 else 0.0
    return np.sqrt((qx - g[G_OX]) ** 2 + (qy - g[G_OY]) ** 2 + (qz - g[G_OZ]) ** 2) + rot


@njit(cache=True)
def guard_step(g, grid, meta, px, py, pz, qx, qy, qz, x):
    """The full check after the step (px, py, pz) -> (qx, qy, qz) that left the free ball
    (x: the state after it). Sets a new free ball around q; returns the trip bits (0: the
    step is proven free and in the same in/out state as before)."""
    trip = 0
    free = np.inf
    if g[G_ON] > 0.0 and g[G_BMODE] > 0.0:
        margin = meta[M_MARGIN]
        left = g[G_ANCHOR] - body_motion_bound(g, x, qx, qy, qz) - 2.0 * margin
        if left > 0.0:
            # the body anchor covers this pose with `left` to spare: half of it for the
            # centre (the ball), half for the rotation from this attitude (chord lengths
            # add up, so every body point stays within the anchor's clearance)
            free = 0.5 * left
            for k in range(4):
                g[G_BQW + k] = x[d.X_QUAT + k]
            s = 0.25 * left / g[G_R] if g[G_R] > 0.0 else 1.0
            g[G_DOT2] = 1.0 - s * s if s < 1.0 else 0.0
        else:
            seg = np.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)
            lb = grid_lower_bound(grid, meta, qx, qy, qz) - g[G_R]
            if lb - seg > margin:
                # the bounding sphere is clear of the whole step again: back to it
                g[G_BMODE] = 0.0
                g[G_ANCHOR] = lb
                g[G_OX] = qx
                g[G_OY] = qy
                g[G_OZ] = qz
                free = lb - margin
            else:
                g[G_LBA] = -np.inf
                trip |= 1
                free = -1.0
    elif g[G_ON] > 0.0:
        margin = meta[M_MARGIN]
        ox, oy, oz = g[G_OX], g[G_OY], g[G_OZ]
        lb_p = g[G_ANCHOR] - np.sqrt((px - ox) ** 2 + (py - oy) ** 2 + (pz - oz) ** 2)
        lb_q = g[G_ANCHOR] - np.sqrt((qx - ox) ** 2 + (qy - oy) ** 2 + (qz - oz) ** 2)
        if not lb_q > 2.0 * margin:  # the anchor no longer covers q: try the grid
            seg = np.sqrt((qx - px) ** 2 + (qy - py) ** 2 + (qz - pz) ** 2)
            lb = grid_lower_bound(grid, meta, qx, qy, qz) - g[G_R]
            # clearance >= max(lb_p - s, lb - (seg - s)) > margin all along the step
            if lb > margin and lb_p + lb - seg > margin:
                g[G_ANCHOR] = lb
                g[G_OX] = qx
                g[G_OY] = qy
                g[G_OZ] = qz
                lb_q = lb
            else:
                g[G_LBA] = lb_p
                trip |= 1
        free = lb_q - margin
    if g[G_BOUNDS] > 0.0:
        d_in = min(qx - meta[M_LOX], meta[M_HIX] - qx, qy - meta[M_LOY], meta[M_HIY] - qy,
                   meta[M_HIZ] - qz)
        out = 1.0 if d_in < 0.0 else 0.0
        if out != g[G_OUT]:
            trip |= 2
        # how far the centre is from crossing a plane (inside) or from getting back in
        free = min(free, d_in if d_in >= 0.0 else max(meta[M_LOX] - qx, qx - meta[M_HIX],
                                                       meta[M_LOY] - qy, qy - meta[M_HIY],
                                                       qz - meta[M_HIZ]))
    g[G_BX] = qx
    g[G_BY] = qy
    g[G_BZ] = qz
    g[G_RR] = free * free if free > 0.0 else -1.0
    if trip:
        g[G_AX] = px
        g[G_AY] = py
        g[G_AZ] = pz
        g[G_TRIP] = trip
    return trip


#: separation (m) a resolved contact leaves between the sphere and the surface
SEPARATION_M = 1e-3
#: Coulomb friction coefficient of a contact with an obstacle
FRICTION = 0.5
#: a contact normal this close to vertical supports a crashed vehicle (it rests on it)
SUPPORT_NZ = 0.7


class GuardEventKind(StrEnum):
    """What a :class:`GuardEvent` reports."""

    COLLISION = "collision"
    #: a collision with a moving obstacle (scenarios.movers): ``what`` is its name
    MOVER_COLLISION = "mover_collision"
    LEFT_VOLUME = "left_volume"
    ENTERED_VOLUME = "entered_volume"


@dataclass(frozen=True)
class GuardEvent:
    """Something the guard saw: ``kind`` (:class:`GuardEventKind`); ``what`` names the
    obstacle or the side ("tree 7", "ceiling", "north edge"); ``position`` is the vehicle's
    ENU position; ``contact`` the contact of a collision."""

    time_us: int
    vehicle: int
    kind: GuardEventKind
    what: str
    position: np.ndarray
    speed_m_s: float
    contact: Contact | None = None


def check_vehicle(i: int, radius: float, body: VehicleBody | None) -> None:
    """Refuse a collision radius that is not a non-negative number of metres, or one that
    does not enclose vehicle i's body (the broad phase would miss contacts)."""
    if not (math.isfinite(radius) and radius >= 0.0):
        raise ValueError(f"collision radius must be a non-negative number of metres, "
                         f"got {radius!r}")
    if body is not None and radius < body.bounding_radius_m:
        raise ValueError(f"vehicle {i}: collision radius {radius} m is smaller than its "
                         f"body's bounding radius ({body.bounding_radius_m:.4f} m): the "
                         "broad phase would miss contacts")


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
                 check_volume: bool = True,
                 bodies: Sequence[VehicleBody | None] | None = None) -> None:
        self.world = world
        self.radii = [float(r) for r in radii]
        bodies = list(bodies) if bodies is not None else [None] * len(self.radii)
        if len(bodies) != len(self.radii):
            raise ValueError(f"{len(bodies)} bodies for {len(self.radii)} collision radii")
        for i, (r, b) in enumerate(zip(self.radii, bodies)):
            check_vehicle(i, r, b)
        #: per vehicle, its body as fcl shapes (None: the vehicle is its sphere)
        self.probes = [BodyProbe(b) if b is not None else None for b in bodies]
        self.grid = grid
        self.names = names or (lambda face: "obstacle")
        self.check_volume = bool(check_volume)
        self.handler: Callable[[GuardEvent], None] | None = None
        self.events: list[GuardEvent] = []
        self.crashed = [False] * len(self.radii)
        #: per vehicle, the last exact clearance() and the pose it was measured at
        #: (clearance, position, attitude quaternion), or None
        self._measured: list = [None] * len(self.radii)
        self.queries = 0  # exact (fcl) steps resolved
        self.trips = 0
        self._margin = CollisionMonitor(world).margin_m
        #: the checks against moving obstacles (None: none), see set_movers
        self._mover_checks: MoverChecks | None = None

    @classmethod
    def for_scenario(cls, scenario, radii: Sequence[float], **kw) -> CollisionGuard:
        """A guard for ``scenario``: its mesh, bounds and obstacle names, and its moving
        obstacles (``scenario.movers``, on their own clock: a field placed by
        :func:`~ft_sitl.scenarios.movers.with_movers` starts at simulation time 0): the
        guard a Fleet or a bridge builds for its scenario. (A trial builds its guard from
        its cached world and grid and sets the movers itself, on a clock started at
        navigation: missions.protocol.trial_vehicle.)"""
        world = CollisionWorld(scenario.mesh, scenario.bounds_min, scenario.bounds_max)
        grid = DistanceGrid.build(scenario.mesh, scenario.bounds_min, scenario.bounds_max)
        guard = cls(world, radii, grid=grid, names=scenario.obstacle_name, **kw)
        guard.set_movers(scenario.movers)
        return guard

    @classmethod
    def for_platforms(cls, scenario, platforms, *, body: bool = True, **kw) -> CollisionGuard:
        """A guard for vehicles of these platforms: their bodies (``body``; the bounding
        radius is the broad phase) or their collision spheres (protocols 1-4)."""
        if body:
            bodies = [p.body() for p in platforms]
            return cls.for_scenario(scenario, [b.bounding_radius_m for b in bodies],
                                    bodies=bodies, **kw)
        return cls.for_scenario(scenario, [p.collision_radius_m for p in platforms], **kw)

    def set_vehicle(self, i: int, radius: float, body: VehicleBody | None = None) -> None:
        """Vehicle i is now of collision radius ``radius`` (m) and ``body`` (None: its
        sphere), e.g. after :meth:`Simulation.set_platform
        <ft_sitl.sim.lockstep.Simulation.set_platform>`; its history is forgotten at the
        next ``Simulation.place``. The same checks as the constructor's."""
        r = float(radius)
        check_vehicle(i, r, body)
        self.radii[i] = r
        self.probes[i] = BodyProbe(body) if body is not None else None
        self._measured[i] = None

    # --- binding to a simulation ------------------------------------------------------
    def bind(self, sim) -> None:
        """Take the vehicles of ``sim`` (called by ``Simulation.attach_guard``, the one place
        a guard is wired): the per-vehicle rows and the meta row the compiled loop reads."""
        if len(self.radii) != sim.n:
            raise ValueError(f"{len(self.radii)} collision radii for {sim.n} vehicles")
        self.rows = np.zeros((sim.n, G_N))
        meta = np.zeros(M_N)
        if self.grid is not None:
            meta[:GRID_META_N] = self.grid.meta()
            self.grid_data = self.grid.data
        else:
            meta[GM_H] = 1.0  # an empty grid: every lookup is "unknown"
            self.grid_data = np.zeros((1, 1, 1), dtype=np.float32)
        lo, hi = self.world.bounds_min, self.world.bounds_max
        meta[[M_LOX, M_LOY, M_HIX, M_HIY, M_HIZ]] = (lo[0], lo[1], hi[0], hi[1], hi[2])
        meta[M_MARGIN] = self._margin
        self.meta = meta
        self._sim = sim
        for i in range(sim.n):
            self.reset(i)

    def reset(self, i: int) -> None:
        """Forget vehicle i's history (after it was placed somewhere new)."""
        g = self.rows[i]
        g[:] = 0.0
        self._measured[i] = None
        g[G_ON] = 1.0 if self.world._obj is not None else 0.0
        g[G_R] = self.radii[i]
        g[G_ANCHOR] = -math.inf
        g[G_RR] = -1.0
        g[G_BOUNDS] = 1.0 if self.check_volume else 0.0
        g[G_OUT] = 1.0 if self._outside(self._sim.x[i, d.X_POS:d.X_POS + 3]) else 0.0
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
        """Exact obstacle clearance (m) of vehicle i now: of its body (posed by its
        attitude; <= 0 in contact) or of its sphere (fcl queries)."""
        p = self._sim.x[i, d.X_POS:d.X_POS + 3]
        probe = self.probes[i]
        if probe is None:
            c = self.world.clearance(p, self.radii[i], kinds=("obstacle",))
        else:
            c = self.world.body_distance(probe, p.copy(), self._rot(i))
            c = c if c > self.world.contact_tol else min(c, 0.0)
        self._measured[i] = (c, p.copy(), self._sim.x[i, d.X_QUAT:d.X_QUAT + 4].copy())
        return c

    def _rot(self, i: int) -> np.ndarray:
        return matrix_from_quat(self._sim.x[i, d.X_QUAT:d.X_QUAT + 4], name="attitude")

    # --- the slow path ----------------------------------------------------------------
    def _emit(self, ev: GuardEvent) -> None:
        self.events.append(ev)
        if self.handler is not None:
            self.handler(ev)

    def resolve(self, sim, i: int, time_us: int) -> None:
        """Settle the step at which vehicle i's guard row stopped the kernel."""
        self.trips += 1
        g = self.rows[i]
        trip = int(g[G_TRIP])
        g[G_TRIP] = 0.0
        g[G_RR] = -1.0  # a full check at the next step
        x = sim.x[i]
        a = g[G_AX:G_AZ + 1].copy()
        b = x[d.X_POS:d.X_POS + 3].copy()
        r = self.radii[i]
        speed = float(np.linalg.norm(x[d.X_VEL:d.X_VEL + 3]))
        if trip & 1 and self.probes[i] is not None:
            self.queries += 1
            contact = self._body_step(g, i, a, b)
            if contact is not None:
                first = not self.crashed[i]
                self.crashed[i] = True
                self._respond_body(sim, i, a, contact)
                if first:
                    self._emit(GuardEvent(time_us, i, GuardEventKind.COLLISION,
                                          self.names(contact.triangle),
                                          np.array(contact.center), speed, contact))
                b = x[d.X_POS:d.X_POS + 3].copy()
        elif trip & 1:
            self.queries += 1
            seg = float(np.linalg.norm(b - a))
            contact, c = self.world.step_check(a, b, seg, r, float(g[G_LBA]))
            if contact is None:
                self._anchor(g, b, c)
            else:
                first = not self.crashed[i]
                self.crashed[i] = True
                self._respond(sim, i, contact)
                if first:
                    self._emit(GuardEvent(time_us, i, GuardEventKind.COLLISION,
                                          self.names(contact.triangle),
                                          np.array(contact.center), speed, contact))
                b = x[d.X_POS:d.X_POS + 3].copy()
        if trip & 2 or (g[G_BOUNDS] > 0.0 and (g[G_OUT] > 0.0) != bool(self._outside(b))):
            side = self._outside(b)
            g[G_OUT] = 1.0 if side else 0.0
            if side:
                self._emit(GuardEvent(time_us, i, GuardEventKind.LEFT_VOLUME, side, b, speed))
            else:
                self._emit(GuardEvent(time_us, i, GuardEventKind.ENTERED_VOLUME,
                                      "flight volume", b, speed))

    def _respond(self, sim, i: int, contact: Contact) -> None:
        """An inelastic contact with friction: back to where the sphere touched, no velocity
        into the surface, the tangential velocity reduced by FRICTION x the normal one."""
        x = sim.x[i]
        n = np.asarray(contact.normal, dtype=float)
        x[d.X_POS:d.X_POS + 3] = np.asarray(contact.center) + SEPARATION_M * n
        self._stop_into(sim, i, n)
        g = self.rows[i]
        p = x[d.X_POS:d.X_POS + 3].copy()
        c = self.world._nearest(p)[0] - self.radii[i]
        self._anchor(g, p, c if c > self.world.contact_tol else -math.inf)

    def _stop_into(self, sim, i: int, n: np.ndarray) -> None:
        """Vehicle i (already put back) loses its velocity into the surface of normal n, and
        its tangential velocity FRICTION x the normal one; a crashed vehicle lying on top of
        an obstacle rests there like on the floor (the plant's ground contact holds it),
        instead of touching it every step."""
        x = sim.x[i]
        v = x[d.X_VEL:d.X_VEL + 3]
        vn = float(v @ n)
        if vn < 0.0:
            vt = v - vn * n
            speed_t = float(np.linalg.norm(vt))
            keep = max(0.0, speed_t - FRICTION * (-vn)) / speed_t if speed_t > 0.0 else 0.0
            x[d.X_VEL:d.X_VEL + 3] = vt * keep
        if self.crashed[i] and n[2] > SUPPORT_NZ:
            env = sim.plant.env[i]
            env[d.E_GROUND_Z] = max(env[d.E_GROUND_Z], x[d.X_POS + 2])

    @staticmethod
    def _anchor(g, p, c: float) -> None:
        g[G_ANCHOR] = c
        g[G_OX:G_OZ + 1] = p
        g[G_RR] = -1.0

    # --- vehicles with a body ---------------------------------------------------------
    def _body_step(self, g, i: int, a: np.ndarray, b: np.ndarray) -> Contact | None:
        """Settle a tripped step a -> b of a vehicle with a body: its bounding sphere first
        (the sphere path's exact check, while it is in sphere mode; a point query in body
        mode), then, where the sphere touches, the body at the step's end pose. A free
        body becomes the anchor (body mode). The step itself is not swept: it is at most
        v dt long (4 mm at 4 m/s and 1 kHz), far thinner than any obstacle, and the kernel
        has proven every earlier pose free."""
        w = self.world
        r = self.radii[i]
        if g[G_BMODE] == 0.0:
            seg = float(np.linalg.norm(b - a))
            contact, c = w.step_check(a, b, seg, r, float(g[G_LBA]))
            if contact is None:
                self._anchor(g, b, c)
                return None
        else:
            c = w.obstacle_distance(b) - r
            if c > w.contact_tol:  # the bounding sphere is clear again
                g[G_BMODE] = 0.0
                self._anchor(g, b, c)
                return None
        rot = self._rot(i)
        c = w.body_distance(self.probes[i], b, rot)
        if c > w.contact_tol:
            self._body_anchor(g, i, b, c)
            return None
        contact = w.body_contact(self.probes[i], b, rot)
        if contact is None:  # distance and collision disagree within fcl's tolerance
            self._body_anchor(g, i, b, w.contact_tol)
        return contact

    def _body_anchor(self, g, i: int, p: np.ndarray, c: float) -> None:
        g[G_BMODE] = 1.0
        g[G_QW:G_QZ + 1] = self._sim.x[i, d.X_QUAT:d.X_QUAT + 4]
        self._anchor(g, p, c)

    def _respond_body(self, sim, i: int, a: np.ndarray, contact: Contact) -> None:
        """A contact of the body: back to the step's start a (free, as the kernel proved),
        no velocity into the obstacle (the normal: the centre's nearest obstacle point),
        the tangential velocity reduced by FRICTION x the normal one. The next step is
        checked in full."""
        x = sim.x[i]
        x[d.X_POS:d.X_POS + 3] = a
        self._stop_into(sim, i, np.asarray(contact.normal, dtype=float))
        g = self.rows[i]
        g[G_BMODE] = 1.0
        g[G_QW:G_QZ + 1] = x[d.X_QUAT:d.X_QUAT + 4]
        self._anchor(g, a, -math.inf)

    # --- moving obstacles (sim.guard_movers) -----------------------------------------
    def set_movers(self, movers) -> None:
        """Check every vehicle against these moving obstacles too (a
        :class:`~ft_sitl.scenarios.movers.Movers`; None or an empty one: none).

        The compiled loop does not see them: :meth:`Simulation.step
        <ft_sitl.sim.lockstep.Simulation.step>` advances in chunks no longer than
        :meth:`mover_horizon` (within which no vehicle can reach a mover) and calls
        :meth:`check_movers` after each, so a vehicle near a mover is checked after every
        physics step and one far from all of them costs one query per chunk."""
        self._mover_checks = MoverChecks(movers) if movers is not None and movers.count \
            else None

    @property
    def movers(self):
        """The moving obstacles checked (scenarios.movers.Movers; None: none)."""
        return self._mover_checks.movers if self._mover_checks is not None else None

    @property
    def mover_queries(self) -> int:
        """The fcl body-mover distance queries made since :meth:`set_movers`."""
        return self._mover_checks.queries if self._mover_checks is not None else 0

    def mover_horizon(self, sim, time_us: int) -> int:
        """How many physics steps from ``time_us`` no vehicle can touch a mover in
        (:meth:`MoverChecks.horizon <ft_sitl.sim.guard_movers.MoverChecks.horizon>`)."""
        return self._mover_checks.horizon(sim, time_us, self.radii, self.crashed)

    def check_movers(self, sim, time_us: int) -> None:
        """Check every vehicle against the movers at ``time_us`` (:meth:`MoverChecks.check
        <ft_sitl.sim.guard_movers.MoverChecks.check>`): a contact crashes the vehicle (a
        :attr:`GuardEventKind.MOVER_COLLISION` event naming the mover). A crashed vehicle
        is not checked again (movers are kinematic: one passing a wreck goes through it)."""
        def hit(i: int, what: str, p: np.ndarray, speed: float) -> None:
            self.crashed[i] = True
            self._emit(GuardEvent(time_us, i, GuardEventKind.MOVER_COLLISION, what, p, speed))

        self._mover_checks.check(sim, time_us, self.radii, self.probes, self.crashed,
                                 self.world.contact_tol, hit)

    def clearance_bound(self, i: int) -> float:
        """A lower bound (m) of vehicle i's obstacle clearance now, from the guard's
        anchor and the last :meth:`clearance` (no query; -inf when unknown)."""
        g = self.rows[i]
        x = self._sim.x[i]
        p = x[d.X_POS:d.X_POS + 3]
        if g[G_BMODE] > 0.0:
            bound = float(g[G_ANCHOR] - body_motion_bound(g, x, p[0], p[1], p[2]))
        else:
            r = p - g[G_OX:G_OZ + 1]
            bound = float(g[G_ANCHOR] - math.sqrt(r.dot(r)))  # np.linalg.norm's arithmetic
        # the last exact clearance less how far any point of the vehicle has moved since
        # (the guard's anchor in sphere mode is the bounding sphere's, far below the
        # body's clearance); a nanometre of margin for fcl's rounding
        m = self._measured[i]
        if m is not None and math.isfinite(m[0]):
            c0, p0, q0 = m
            moved = float(np.linalg.norm(p - p0))
            if self.probes[i] is not None:
                dot = min(1.0, abs(float(q0 @ x[d.X_QUAT:d.X_QUAT + 4])))
                moved += 2.0 * self.radii[i] * math.sqrt(max(0.0, 1.0 - dot * dot))
            bound = max(bound, c0 - moved - 1e-9)
        return bound
