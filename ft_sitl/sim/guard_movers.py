"""The collision guard's checks against moving obstacles (:mod:`ft_sitl.scenarios.movers`).

The compiled loop of :mod:`ft_sitl.sim.guard` does not see movers. :class:`MoverChecks`
tells :meth:`Simulation.step <ft_sitl.sim.lockstep.Simulation.step>` how many physics steps
no vehicle can reach a mover in (:meth:`MoverChecks.horizon`), and checks every vehicle
against the movers after each such chunk (:meth:`MoverChecks.check`): its bounding sphere
against each mover's shape, then, where they touch, its body (fcl). A
:class:`~ft_sitl.sim.guard.CollisionGuard` owns one and reports what it finds.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import fcl
import numpy as np

from ft_sitl import G
from ft_sitl.physics import dynamics as d
from ft_sitl.rotations import matrix_from_quat
from ft_sitl.scenarios import movers as mv
from ft_sitl.scenarios.collision import BodyProbe

#: the longest the simulation runs between two checks against moving obstacles (s)
MOVER_HORIZON_S = 0.1
#: a vehicle's acceleration is bounded by this times (1 + TWR_max) g in the mover checks
MOVER_ACCEL_MARGIN = 1.5


def vehicle_accel_bound(sim, i: int) -> float:
    """An upper bound (m/s^2) of vehicle i's acceleration: full thrust plus gravity, with a
    margin for drag and contact responses."""
    p = sim.platforms[i]
    return MOVER_ACCEL_MARGIN * (G + p.thrust_max_n / p.mass_kg)


class MoverChecks:
    """Every vehicle against these moving obstacles (a non-empty
    :class:`~ft_sitl.scenarios.movers.Movers`): their fcl shapes, the poses and gaps of the
    last check, and ``queries``, the fcl body-mover distance queries made."""

    def __init__(self, movers) -> None:
        self.movers = movers
        self._objs = []
        for k, dims in zip(movers.kind, movers.dims):
            if k == mv.CYLINDER:
                shape = fcl.Cylinder(dims[0], 2.0 * dims[1])
            elif k == mv.BOX:
                shape = fcl.Box(*(2.0 * dims))
            else:
                shape = fcl.Sphere(dims[0])
            self._objs.append(fcl.CollisionObject(shape, fcl.Transform()))
        self._poses = np.empty((movers.count, 4))
        self._gap = np.empty(movers.count)
        self._dreq = fcl.DistanceRequest()
        self.queries = 0

    def horizon(self, sim, time_us: int, radii: Sequence[float],
                crashed: Sequence[bool]) -> int:
        """How many physics steps from ``time_us`` no vehicle can touch a mover in: the gap
        between each bounding sphere (``radii``; ``crashed`` vehicles are skipped) and each
        mover shape against the closing distance (|v| + mover speed) T + a T^2 / 2, at most
        :data:`MOVER_HORIZON_S`; at least 1."""
        m = self.movers
        m.poses(time_us, self._poses)
        horizon = MOVER_HORIZON_S
        speed = float(m.speed.max())
        for i in range(sim.n):
            if crashed[i]:
                continue
            x = sim.x[i]
            mv.mover_distances(m.kind, m.dims, self._poses, x[d.X_POS:d.X_POS + 3], self._gap)
            gap = float(self._gap.min()) - radii[i]
            if gap <= 0.0:
                return 1
            v = float(np.linalg.norm(x[d.X_VEL:d.X_VEL + 3])) + speed
            a = vehicle_accel_bound(sim, i)
            t = (-v + math.sqrt(v * v + 2.0 * a * gap)) / a  # (v T + a T^2 / 2 = gap)
            horizon = min(horizon, t)
        return max(1, int(horizon / sim.dt))

    def check(self, sim, time_us: int, radii: Sequence[float],
              probes: Sequence[BodyProbe | None], crashed: Sequence[bool], tol: float,
              hit: Callable[[int, str, np.ndarray, float], None]) -> None:
        """Check every vehicle not ``crashed`` against the movers at ``time_us``: where its
        bounding sphere (``radii``) touches a mover's shape within ``tol``, its body
        (``probes``; fcl) or its sphere settles it. A contact takes away the vehicle's
        velocity towards the mover, then ``hit(i, mover name, position, relative speed)``
        reports it (the caller crashes the vehicle); one contact per vehicle."""
        m = self.movers
        m.poses(time_us, self._poses)
        for i in range(sim.n):
            if crashed[i]:
                continue
            x = sim.x[i]
            p = x[d.X_POS:d.X_POS + 3].copy()
            mv.mover_distances(m.kind, m.dims, self._poses, p, self._gap)
            for j in np.flatnonzero(self._gap - radii[i] <= tol):
                probe = probes[i]
                if probe is not None and self._body_distance(sim, i, probe, p, int(j),
                                                             tol) > tol:
                    continue
                c = self._poses[j, :3]
                n = p - c
                if m.kind[j] != mv.SPHERE:
                    n[2] = 0.0
                nn = float(np.linalg.norm(n))
                n = n / nn if nn > 0.0 else np.array([1.0, 0.0, 0.0])
                v_rel = x[d.X_VEL:d.X_VEL + 3] - m.velocities(time_us)[j]
                speed = float(np.linalg.norm(v_rel))
                vn = float(v_rel @ n)
                if vn < 0.0:
                    x[d.X_VEL:d.X_VEL + 3] -= vn * n
                hit(i, m.names[j], p, speed)
                break

    def _body_distance(self, sim, i: int, probe: BodyProbe, p: np.ndarray, j: int,
                       tol: float) -> float:
        """Distance (m) between vehicle i's body at p and mover j (fcl; <= 0 in contact;
        the parts stop being measured once one is within ``tol``)."""
        pose = self._poses[j]
        obj = self._objs[j]
        ch, sh = math.cos(pose[3]), math.sin(pose[3])
        obj.setTransform(fcl.Transform(np.array([[ch, -sh, 0.0], [sh, ch, 0.0],
                                                 [0.0, 0.0, 1.0]]), pose[:3].copy()))
        rot = matrix_from_quat(sim.x[i, d.X_QUAT:d.X_QUAT + 4], name="attitude")
        best = math.inf
        for part, offset in zip(probe.objects, probe.offsets):
            part.setTransform(fcl.Transform(rot, p + rot @ offset))
            self.queries += 1
            best = min(best, fcl.distance(part, obj, self._dreq))
            if best <= tol:
                break
        return best
