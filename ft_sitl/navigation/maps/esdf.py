"""The ESDF snapshot a plan reads: :class:`EsdfGrid`, the local map's signed ESDF
(:meth:`~ft_sitl.navigation.maps.mapping.LocalMap.update_esdf`) as it was when the plan
began, with the flight volume's bounds, and the voxel kernels that read it (numba).

Free voxels hold the distance to the nearest planning-occupied voxel centre (>= one
voxel), occupied voxels ``<= 0``. It is read two ways, as Fast-Planner reads its ESDF:
per voxel ("coarse", :func:`coarse_distance`: sample clearance, collision range, line of
sight by 3-D DDA, :func:`blocked`) and trilinearly with its gradient (:func:`trilinear`,
:meth:`EsdfGrid.evaluate`: the optimisers, the shortcut's push). Points outside the
snapshot are clamped onto it per axis (as ``LocalMap.esdf``); points outside the flight
volume (``bounds``) have coarse distance -1, i.e. they are blocked. Fast-Planner's and
PGO's optimisers and PGO's topological search all read this one type.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.ndimage import distance_transform_edt

from ft_sitl.navigation.maps.map_esdf import esdf_eval, trilinear_point

__all__ = ["ESDF_HALF_HEIGHT_M", "EsdfGrid", "as_path", "blocked", "coarse_distance", "inside",
           "path_free", "trilinear", "voxel_value"]

#: half height (m) of the ESDF box around a plan's centre: the originals' local update
#: range in z (4.5 m), so a high ceiling (Urban's 10 m) does not double the cost
ESDF_HALF_HEIGHT_M = 4.5
_BIG = 1e18  # "no bound" for the flight-volume box


# ---------------------------------------------------------------------------------------
# numba kernels on the ESDF snapshot: (field (nx, ny, nz), origin (3,) global voxel index of
# field[0, 0, 0], resolution, bounds lo (3,), hi (3,))
# ---------------------------------------------------------------------------------------
@njit(cache=True)
def voxel_value(fld, origin, i, j, k):
    """Field value of global voxel (i, j, k), clamped onto the field per axis."""
    nx, ny, nz = fld.shape
    x = i - origin[0]
    y = j - origin[1]
    z = k - origin[2]
    x = 0 if x < 0 else (nx - 1 if x > nx - 1 else x)
    y = 0 if y < 0 else (ny - 1 if y > ny - 1 else y)
    z = 0 if z < 0 else (nz - 1 if z > nz - 1 else z)
    return fld[x, y, z]


@njit(cache=True)
def inside(p, lo, hi):
    return (lo[0] <= p[0] <= hi[0]) and (lo[1] <= p[1] <= hi[1]) and (lo[2] <= p[2] <= hi[2])


@njit(cache=True)
def coarse_distance(fld, origin, res, lo, hi, p):
    """Fast-Planner's coarse distance: the value of the voxel containing ``p``; -1 outside
    the flight volume."""
    if not inside(p, lo, hi):
        return -1.0
    inv = 1.0 / res
    return voxel_value(fld, origin, int(math.floor(p[0] * inv)), int(math.floor(p[1] * inv)),
                  int(math.floor(p[2] * inv)))


@njit(cache=True)
def trilinear(fld, origin, res, p, grad):
    """Trilinear distance between voxel centres and its gradient (into ``grad``), with the
    clamping of ``LocalMap.esdf`` (the map's own kernel)."""
    return trilinear_point(fld, origin, 1.0 / res, p[0], p[1], p[2], grad)


@njit(cache=True)
def _dda_axis(a, b, inv):
    """Start voxel, voxels to cross, step, first crossing and crossing spacing (in units
    of the segment's parameter) along one axis."""
    g0 = a * inv
    g1 = b * inv
    c = int(math.floor(g0))
    n = abs(int(math.floor(g1)) - c)
    d = g1 - g0
    if d > 0.0:
        return c, n, 1, (c + 1.0 - g0) / d, 1.0 / d
    if d < 0.0:
        return c, n, -1, (g0 - c) / (-d), -1.0 / d
    return c, n, 0, np.inf, np.inf


@njit(cache=True)
def blocked(fld, origin, res, lo, hi, a, b, thresh, pc):
    """Whether the segment a -> b is blocked: an end outside the flight volume (``pc`` :=
    that end) or a traversed voxel (3-D DDA, a's voxel first) with value ``<= thresh``
    (``pc`` := its centre)."""
    if not inside(a, lo, hi):
        pc[:] = a
        return True
    if not inside(b, lo, hi):
        pc[:] = b
        return True
    inv = 1.0 / res
    cx, nx, sx, tx, dx = _dda_axis(a[0], b[0], inv)
    cy, ny, sy, ty, dy = _dda_axis(a[1], b[1], inv)
    cz, nz, sz, tz, dz = _dda_axis(a[2], b[2], inv)
    n = nx + ny + nz
    for s in range(n + 1):
        if voxel_value(fld, origin, cx, cy, cz) <= thresh:
            pc[0] = (cx + 0.5) * res
            pc[1] = (cy + 0.5) * res
            pc[2] = (cz + 0.5) * res
            return True
        if s == n:
            break
        if tx <= ty and tx <= tz:
            cx += sx
            tx += dx
        elif ty <= tz:
            cy += sy
            ty += dy
        else:
            cz += sz
            tz += dz
    return False



@njit(cache=True)
def path_free(path, fld, origin, res, lo, hi, thresh):
    pc = np.empty(3)
    for i in range(path.shape[0] - 1):
        if blocked(fld, origin, res, lo, hi, path[i], path[i + 1], thresh, pc):
            return False
    if path.shape[0] == 1:
        return not blocked(fld, origin, res, lo, hi, path[0], path[0], thresh, pc)
    return True


class EsdfGrid:
    """A snapshot of a signed ESDF on the map's voxel lattice (see the module docstring).

    ``field`` (nx, ny, nz) metres at voxel centres; ``origin_index`` the global voxel index
    of ``field[0, 0, 0]`` (voxel ``i`` covers ``[i, i+1) * resolution``); ``bounds`` an
    optional ``(lo, hi)`` flight volume outside which everything is blocked.
    """

    def __init__(self, esdf_field, origin_index, resolution: float, bounds=None):
        f = np.ascontiguousarray(esdf_field, dtype=np.float64)
        if f.ndim != 3 or min(f.shape) < 2:
            raise ValueError(f"field must be 3-D with >= 2 voxels per axis, got {f.shape}")
        o = np.asarray(origin_index, dtype=np.int64).reshape(-1)
        if o.shape != (3,):
            raise ValueError(f"origin: need 3 integers, got {origin_index!r}")
        resolution = float(resolution)
        if not (math.isfinite(resolution) and resolution > 0):
            raise ValueError(f"resolution must be positive, got {resolution!r}")
        self.field = f
        self.origin = o.copy()
        self.resolution = resolution
        if bounds is None:
            self.lo = np.full(3, -_BIG)
            self.hi = np.full(3, _BIG)
        else:
            self.lo = np.asarray(bounds[0], dtype=float).reshape(3).copy()
            self.hi = np.asarray(bounds[1], dtype=float).reshape(3).copy()

    @classmethod
    def from_map(cls, local_map, center_m=None, half_extent_m: float | None = None,
                 bounds=None) -> EsdfGrid:
        """Recompute ``local_map``'s ESDF (over the window, or the box ``center_m +-
        half_extent_m``, see :meth:`LocalMap.update_esdf`; +-4.5 m in height, the
        originals' local update range, so a high ceiling does not double the cost) and take
        it."""
        fld = local_map.update_esdf(center_m, half_extent_m, ESDF_HALF_HEIGHT_M)
        return cls(fld, local_map.esdf_origin_index, local_map.resolution_m, bounds)

    @classmethod
    def from_occupancy(cls, occupied, origin_index, resolution: float,
                       bounds=None) -> EsdfGrid:
        """The signed field of a boolean voxel array, with the local map's conventions
        (free: distance to the nearest occupied centre; occupied: resolution minus the
        distance to the nearest free centre). For synthetic maps."""

        occ = np.asarray(occupied, dtype=bool)
        res = float(resolution)
        if not occ.any():
            fld = np.full(occ.shape, 1e3)
        elif occ.all():
            fld = np.full(occ.shape, -1e3)
        else:
            fld = res * distance_transform_edt(~occ)
            fld[occ] = res - res * distance_transform_edt(occ)[occ]
        return cls(fld, origin_index, res, bounds)

    def kernel_args(self):
        """``(field, origin, resolution, lo, hi)``: what the voxel kernels take."""
        return self.field, self.origin, self.resolution, self.lo, self.hi

    def distance(self, points) -> np.ndarray:
        """Coarse (per-voxel) distance of points (N, 3); -1 outside the bounds."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        return _coarse_many(p, *self.kernel_args())

    def evaluate(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Trilinear distance (N,) and gradient (N, 3), as ``LocalMap.esdf`` (NaN at a
        non-finite point)."""
        p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        d = np.empty(len(p))
        g = np.empty((len(p), 3))
        esdf_eval(self.field, self.origin, 1.0 / self.resolution, p, d, g)
        return d, g

    __call__ = evaluate

    def in_bounds(self, points) -> np.ndarray:
        """Whether points (N, 3) lie in the flight volume."""
        p = np.asarray(points, dtype=float).reshape(-1, 3)
        return np.all((p >= self.lo) & (p <= self.hi), axis=1)

    def occupied(self, points) -> np.ndarray:
        """Planning occupancy (distance <= 0, or outside the bounds) of points (N, 3)."""
        return self.distance(points) <= 0.0

    def visible(self, a, b, thresh: float = 0.0) -> bool:
        """Line of sight a -> b: no traversed voxel with distance ``<= thresh``."""
        pc = np.empty(3)
        return not blocked(*self.kernel_args(), np.asarray(a, dtype=float).reshape(3),
                            np.asarray(b, dtype=float).reshape(3), float(thresh), pc)

    def path_free(self, path, thresh: float = 0.0) -> bool:
        """Every piece of the polyline has line of sight."""
        return bool(path_free(as_path(path), *self.kernel_args(), float(thresh)))


@njit(cache=True)
def _coarse_many(p, fld, origin, res, lo, hi):
    out = np.empty(p.shape[0])
    for i in range(p.shape[0]):
        out[i] = coarse_distance(fld, origin, res, lo, hi, p[i])
    return out


def as_path(path) -> np.ndarray:
    p = np.ascontiguousarray(path, dtype=float)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] < 1:
        raise ValueError(f"a path must have shape (K >= 1, 3), got {p.shape}")
    return p
