"""The local map's signed ESDF: :class:`MapEsdf`, and the distance-transform and trilinear
kernels (numba) it and every ESDF reader use.

:meth:`LocalMap.update_esdf <ft_sitl.navigation.maps.mapping.LocalMap.update_esdf>` hands its
work to :meth:`MapEsdf.update`, after Fast-Planner's ``updateESDF3d``: the exact Euclidean
distance transform (Felzenszwalb-Huttenlocher lower envelope, three 1-D passes,
:func:`_edt_sq`) of the map's planning occupancy, over the whole window or a box of it,
signed by :func:`_signed_esdf`, and kept until the planning occupancy (the map's
``revision``), the window or the box changes. :func:`trilinear_point` reads a field between
voxel centres with its analytic gradient (:meth:`LocalMap.esdf
<ft_sitl.navigation.maps.mapping.LocalMap.esdf>`, :mod:`ft_sitl.navigation.maps.esdf`, the
optimisers' penalties). The field's conventions are in the module docstring of
:mod:`ft_sitl.navigation.maps.mapping`.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["MapEsdf", "box_xy", "esdf_eval", "trilinear_point"]


# --- kernels ------------------------------------------------------------------------------
@njit(cache=True)
def _envelope_1d(f, n, out, v, hv, zb, inv2):
    """Felzenszwalb-Huttenlocher 1-D squared distance transform of f[:n] into out[:n]
    (inf in f: no site). inv2[d] = 1 / (2 d): a product by the exact reciprocal instead of
    a division; intersections of distinct parabolas differ by >= 1 / (4 n^2), far more than
    the rounding, so the envelope (and the integer output) is the same."""
    k = -1
    s = 0.0
    for q in range(n):
        fq = f[q]
        if fq == np.inf:
            continue
        hq = fq + q * q
        if k < 0:
            k = 0
            v[0] = q
            hv[0] = hq
            zb[0] = -np.inf
            zb[1] = np.inf
            continue
        while True:
            s = (hq - hv[k]) * inv2[q - v[k]]
            if s <= zb[k]:
                k -= 1
            else:
                break
        k += 1
        v[k] = q
        hv[k] = hq
        zb[k] = s
        zb[k + 1] = np.inf
    if k < 0:
        for q in range(n):
            out[q] = np.inf
        return
    k = 0
    for q in range(n):
        while zb[k + 1] < q:
            k += 1
        p = v[k]
        out[q] = (q - p) * (q - p) + (hv[k] - p * p)


@njit(cache=True)
def _edt_sq(sites3, want, out3):
    """Squared EDT (voxel units) to the nearest voxel where sites3 == want (inf if none)."""
    nx, ny, nz = sites3.shape
    nmax = max(nx, max(ny, nz))
    g = np.empty(nmax)
    v = np.empty(nmax, np.int64)
    hv = np.empty(nmax)
    zb = np.empty(nmax + 1)
    inv2 = np.empty(nmax)
    inv2[0] = np.inf
    for d in range(1, nmax):
        inv2[d] = 1.0 / (2.0 * d)
    # pass 1 along z (contiguous): 1-D distance to the nearest site, two scans
    for x in range(nx):
        for y in range(ny):
            dist = np.inf
            for z in range(nz):
                if sites3[x, y, z] == want:
                    dist = 0.0
                else:
                    dist += 1.0
                out3[x, y, z] = dist
            dist = np.inf
            for z in range(nz - 1, -1, -1):
                if sites3[x, y, z] == want:
                    dist = 0.0
                else:
                    dist += 1.0
                m = min(dist, np.float64(out3[x, y, z]))
                out3[x, y, z] = m * m
    # passes 2 (along y) and 3 (along x), one (.., z) block at a time, transposed into buf
    # (out3's dtype: float32 holds these integer squared distances exactly) so each line is
    # contiguous; each line is worked in float64
    buf = np.empty((nz, nmax), out3.dtype)
    line = np.empty(nmax)
    for x in range(nx):
        for y in range(ny):
            for z in range(nz):
                buf[z, y] = out3[x, y, z]
        for z in range(nz):
            _line_edt(buf[z], line, ny, g, v, hv, zb, inv2)
        for y in range(ny):
            for z in range(nz):
                out3[x, y, z] = buf[z, y]
    for y in range(ny):
        for x in range(nx):
            for z in range(nz):
                buf[z, x] = out3[x, y, z]
        for z in range(nz):
            _line_edt(buf[z], line, nx, g, v, hv, zb, inv2)
        for x in range(nx):
            for z in range(nz):
                out3[x, y, z] = buf[z, x]


@njit(cache=True)
def _line_edt(row, line, n, g, v, hv, zb, inv2):
    """In-place 1-D pass over row[:n] (through the float64 line), skipped when the row is
    constant (all zeros, all inf, or any one value: then every minimum is the point's own)."""
    first = row[0]
    same = True
    for i in range(1, n):
        if row[i] != first:
            same = False
            break
    if same:
        return
    for i in range(n):
        line[i] = row[i]
    _envelope_1d(line, n, g, v, hv, zb, inv2)
    for i in range(n):
        row[i] = g[i]


@njit(cache=True)
def _signed_esdf(plan3, res, pos3, neg3, out3):
    """Fast-Planner's signed field into out3 (float64): free -> distance to the nearest
    occupied voxel centre; occupied -> res - distance to the nearest free voxel centre.
    pos3 / neg3: work arrays (float32: the squared voxel distances are exact in it)."""
    _edt_sq(plan3, 1, pos3)
    _edt_sq(plan3, 0, neg3)
    nx, ny, nz = plan3.shape
    for x in range(nx):
        for y in range(ny):
            for z in range(nz):
                p = res * math.sqrt(np.float64(pos3[x, y, z]))
                nd = np.float64(neg3[x, y, z])
                if nd > 0.0:
                    p += res - res * math.sqrt(nd)
                out3[x, y, z] = p


@njit(cache=True)
def _trilinear_axis(g, n):
    """Lower voxel index, fraction and whether g (in voxel-centre units) was clamped onto
    the field's 0 .. n-1 range."""
    clamped = False
    if g < 0.0:
        g = 0.0
        clamped = True
    elif g > n - 1.0:
        g = n - 1.0
        clamped = True
    j = int(math.floor(g))
    if j > n - 2:
        j = n - 2
    return j, g - j, clamped


@njit(cache=True)
def trilinear_point(esdf3, origin, inv_res, px, py, pz, grad):
    """Trilinear distance at (px, py, pz) between the voxel centres of ``esdf3`` (global
    index of its first voxel: ``origin``) and its analytic gradient, written into
    ``grad``; a point outside is clamped onto the field and the gradient along a clamped
    axis is 0. Shared by :meth:`LocalMap.esdf` and the planners' kernels."""
    nx, ny, nz = esdf3.shape
    x, dx, cx = _trilinear_axis(px * inv_res - origin[0] - 0.5, nx)
    y, dy, cy = _trilinear_axis(py * inv_res - origin[1] - 0.5, ny)
    z, dz, cz = _trilinear_axis(pz * inv_res - origin[2] - 0.5, nz)
    v000 = esdf3[x, y, z]
    v100 = esdf3[x + 1, y, z]
    v010 = esdf3[x, y + 1, z]
    v110 = esdf3[x + 1, y + 1, z]
    v001 = esdf3[x, y, z + 1]
    v101 = esdf3[x + 1, y, z + 1]
    v011 = esdf3[x, y + 1, z + 1]
    v111 = esdf3[x + 1, y + 1, z + 1]
    v00 = (1.0 - dx) * v000 + dx * v100
    v01 = (1.0 - dx) * v001 + dx * v101
    v10 = (1.0 - dx) * v010 + dx * v110
    v11 = (1.0 - dx) * v011 + dx * v111
    v0 = (1.0 - dy) * v00 + dy * v10
    v1 = (1.0 - dy) * v01 + dy * v11
    gz = (v1 - v0) * inv_res
    gy = ((1.0 - dz) * (v10 - v00) + dz * (v11 - v01)) * inv_res
    gx = ((1.0 - dz) * (1.0 - dy) * (v100 - v000) + (1.0 - dz) * dy * (v110 - v010)
          + dz * (1.0 - dy) * (v101 - v001) + dz * dy * (v111 - v011)) * inv_res
    grad[0] = 0.0 if cx else gx
    grad[1] = 0.0 if cy else gy
    grad[2] = 0.0 if cz else gz
    return (1.0 - dz) * v0 + dz * v1


@njit(cache=True)
def esdf_eval(esdf3, origin, inv_res, points, dist, grad):
    """Trilinear ESDF value and its analytic gradient; returns the number of non-finite
    points (NaN results)."""
    bad = 0
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        if not (np.isfinite(px) and np.isfinite(py) and np.isfinite(pz)):
            bad += 1
            dist[i] = np.nan
            grad[i, 0] = np.nan
            grad[i, 1] = np.nan
            grad[i, 2] = np.nan
            continue
        dist[i] = trilinear_point(esdf3, origin, inv_res, px, py, pz, grad[i])
    return bad


# --- the map's field ------------------------------------------------------------------------
def box_xy(shape, origin, inv_res: float, c, h: float) -> tuple[int, int, int, int]:
    """Window voxel range x0, x1, y0, y1 of the horizontal ESDF box of half extent h (m)
    centred on the voxel of c (x, y), clipped to the window of ``shape`` whose first voxel
    is the global index ``origin`` (``inv_res``: 1 / resolution)."""
    nx, ny = shape[:2]
    ci = np.floor(np.asarray(c, dtype=np.float64)[:2] * inv_res).astype(np.int64) \
        - origin[:2]
    nh = int(round(h * inv_res))
    lo, hi = ci - nh, ci + nh + 1  # 2 nh + 1 voxels centred on c's voxel
    x0, y0 = (int(v) for v in np.clip(lo, 0, [nx, ny]))
    x1, y1 = (int(v) for v in np.clip(hi, 0, [nx, ny]))
    return x0, x1, y0, y1


class MapEsdf:
    """The last signed ESDF of one :class:`~ft_sitl.navigation.maps.mapping.LocalMap`:
    ``field`` (float64, metres, at voxel centres; None before the first :meth:`update` or
    after :meth:`forget`), ``origin`` (global voxel index of its first voxel) and ``frame``
    (the map's ``frames_fused`` when it was last asked for, -1: never)."""

    def __init__(self) -> None:
        self.field: np.ndarray | None = None
        self.origin: np.ndarray | None = None
        self.frame = -1
        self._key: tuple | None = None

    def forget(self) -> None:
        """No field (the map was cleared)."""
        self.field = None
        self.origin = None
        self.frame = -1

    def update(self, local_map, center_m=None, half_extent_m: float | None = None,
               half_extent_z_m: float | None = None) -> np.ndarray:
        """The field of ``local_map``'s planning occupancy over the box
        :meth:`LocalMap.update_esdf <ft_sitl.navigation.maps.mapping.LocalMap.update_esdf>`
        describes, computed anew unless the same box of the same planning occupancy was
        asked for last time (then the same array)."""
        nx, ny, nz = local_map.shape
        origin = local_map.origin_index
        inv_res = 1.0 / local_map.resolution_m
        x0, x1, y0, y1 = 0, nx, 0, ny
        z0, z1 = 0, nz
        if half_extent_z_m is not None:
            hz = float(half_extent_z_m)
            if not (math.isfinite(hz) and hz > 0):
                raise ValueError(f"half_extent_z_m must be a positive number, got "
                                 f"{half_extent_z_m!r}")
            cz = None
            if center_m is not None and np.asarray(center_m).reshape(-1).shape == (3,):
                cz = float(np.asarray(center_m, dtype=np.float64).reshape(-1)[2])
            elif local_map.last_camera_m is not None:
                cz = float(local_map.last_camera_m[2])
            if cz is not None and math.isfinite(cz):
                ck = math.floor(cz * inv_res) - int(origin[2])
                nhz = int(round(hz * inv_res))
                z0, z1 = max(0, ck - nhz), min(nz, ck + nhz + 1)
                if z1 - z0 < 2:
                    z0, z1 = 0, nz
        if half_extent_m is not None:
            h = float(half_extent_m)
            if not (math.isfinite(h) and h > 0):
                raise ValueError(f"half_extent_m must be a positive number, got {half_extent_m!r}")
            if center_m is None:
                c = local_map.window_center_m[:2] if local_map.last_camera_m is None \
                    else local_map.last_camera_m[:2]
            else:
                c = np.asarray(center_m, dtype=np.float64).reshape(-1)[:2]
                if c.shape != (2,) or not np.all(np.isfinite(c)):
                    raise ValueError(f"center_m must be finite (x, y), got {center_m!r}")
            x0, x1, y0, y1 = box_xy(local_map.shape, origin, inv_res, c, h)
            if x1 - x0 < 2 or y1 - y0 < 2:
                raise ValueError("the ESDF box does not overlap the window (by >= 2 voxels)")
        key = (local_map.revision, int(origin[0]), int(origin[1]), x0, x1, y0, y1, z0, z1)
        if self.field is not None and key == self._key:
            # the same box of the same planning occupancy: the same field
            self.frame = local_map.frames_fused
            return self.field
        plan = np.ascontiguousarray(local_map.planning_grid()[x0:x1, y0:y1, z0:z1])
        pos = np.empty(plan.shape)
        _signed_esdf(plan, local_map.resolution_m, np.empty(plan.shape, np.float32),
                     np.empty(plan.shape, np.float32), pos)
        self.field = pos
        self._key = key
        self.origin = origin + np.array([x0, y0, z0])
        self.frame = local_map.frames_fused
        return pos
