"""A voxel grid of lower bounds of the distance to a scenario's obstacles.

Built once per scenario; the collision guard (:mod:`ft_sitl.sim.guard`) reads it inside the
compiled lockstep loop to prove a physics step free of contact without an exact query.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.ndimage import distance_transform_edt

#: grid pitches (m) tried finest first: the finest whose grid has at most GRID_MAX_CELLS
#: cells is used (a finer grid gives tighter bounds, so fewer exact checks near obstacles)
GRID_PITCHES_M = (0.1, 0.125, 0.15, 0.2, 0.25)
#: the grid covers the flight volume grown by this much on every side (m)
GRID_PAD_M = 1.0
#: cell budget (float32: 4 bytes each); a volume too large for the coarsest pitch gets a
#: coarser one still
GRID_MAX_CELLS = 8_000_000
_FAR = np.float32(1e9)
#: the grid's layout in a meta row: origin x/y/z, pitch, shape x/y/z
(GM_OX, GM_OY, GM_OZ, GM_H, GM_NX, GM_NY, GM_NZ) = range(7)
GRID_META_N = 7


@njit(cache=True)
def grid_lower_bound(grid, meta, qx, qy, qz):
    """Lower bound of the distance from (qx, qy, qz) to the obstacles from the voxel grid
    (-inf outside it). ``meta`` starts with the grid's layout (:meth:`DistanceGrid.meta`);
    the collision guard's meta row extends it."""
    h = meta[GM_H]
    fx = (qx - meta[GM_OX]) / h
    fy = (qy - meta[GM_OY]) / h
    fz = (qz - meta[GM_OZ]) / h
    if not (fx >= 0.0 and fy >= 0.0 and fz >= 0.0 and fx < meta[GM_NX] and fy < meta[GM_NY]
            and fz < meta[GM_NZ]):
        return -np.inf
    ix, iy, iz = int(fx), int(fy), int(fz)
    cx = (fx - ix - 0.5) * h
    cy = (fy - iy - 0.5) * h
    cz = (fz - iz - 0.5) * h
    return grid[ix, iy, iz] - np.sqrt(cx * cx + cy * cy + cz * cz)


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
        return float(grid_lower_bound(self.data, self.meta(), float(p[0]), float(p[1]),
                                      float(p[2])))

    def meta(self) -> np.ndarray:
        """The grid's layout as the compiled lookup reads it: origin (3), pitch, shape (3)."""
        meta = np.zeros(GRID_META_N)
        meta[GM_OX:GM_OZ + 1] = self.origin
        meta[GM_H] = self.pitch
        meta[GM_NX:GM_NZ + 1] = self.shape
        return meta
