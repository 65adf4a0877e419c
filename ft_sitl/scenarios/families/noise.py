"""The noise the Perlin family fills its volume with: improved Perlin gradient noise
(:func:`perlin3`), its fractal sum (:func:`fbm3`), mockamap's octave sum
(:func:`mockamap_noise`), and filled voxels as boxes (:func:`column_runs`,
:func:`voxel_boxes`)."""

from __future__ import annotations

import numpy as np

_GRAD = np.array([[1, 1, 0], [-1, 1, 0], [1, -1, 0], [-1, -1, 0], [1, 0, 1], [-1, 0, 1],
                  [1, 0, -1], [-1, 0, -1], [0, 1, 1], [0, -1, 1], [0, 1, -1], [0, -1, -1],
                  [1, 1, 0], [0, -1, 1], [-1, 1, 0], [0, -1, -1]], dtype=float)
#: the gradients' components, gathered one at a time (a gather of (n, 3) rows was 2 s of
#: a 0.1 m field's 3 s)
_GRAD_X, _GRAD_Y, _GRAD_Z = (np.ascontiguousarray(_GRAD[:, c]) for c in range(3))


def perlin3(x, y, z, perm: np.ndarray) -> np.ndarray:
    """Improved Perlin gradient noise (Perlin 2002) at points (arrays), about in [-1, 1].

    ``perm`` is a permutation of 0..255 (draw it from a seeded Generator).
    """
    p = np.concatenate([perm, perm]).astype(np.int64)
    x, y, z = (np.asarray(v, dtype=float) for v in (x, y, z))
    fx, fy, fz = np.floor(x), np.floor(y), np.floor(z)
    xi, yi, zi = (f.astype(np.int64) & 255 for f in (fx, fy, fz))
    x, y, z = x - fx, y - fy, z - fz

    def fade(t):
        return t * t * t * (t * (t * 6 - 15) + 10)

    u, v, w = fade(x), fade(y), fade(z)
    a = p[xi] + yi
    aa, ab = p[a] + zi, p[a + 1] + zi
    b = p[xi + 1] + yi
    ba, bb = p[b] + zi, p[b + 1] + zi

    def grad(h, dx, dy, dz):
        k = h & 15
        return _GRAD_X[k] * dx + _GRAD_Y[k] * dy + _GRAD_Z[k] * dz

    def lerp(t, a0, a1):
        return a0 + t * (a1 - a0)

    x1, y1, z1 = x - 1, y - 1, z - 1
    return lerp(w,
                lerp(v, lerp(u, grad(p[aa], x, y, z), grad(p[ba], x1, y, z)),
                     lerp(u, grad(p[ab], x, y1, z), grad(p[bb], x1, y1, z))),
                lerp(v, lerp(u, grad(p[aa + 1], x, y, z1), grad(p[ba + 1], x1, y, z1)),
                     lerp(u, grad(p[ab + 1], x, y1, z1), grad(p[bb + 1], x1, y1, z1))))


def fbm3(x, y, z, perm, frequency: float, octaves: int = 4, lacunarity: float = 2.0,
         gain: float = 0.5) -> np.ndarray:
    """Fractal sum of :func:`perlin3` octaves; ``frequency`` in cycles per metre."""
    total = np.zeros(np.broadcast(x, y, z).shape)
    f, amp = frequency, 1.0
    for _ in range(octaves):
        total += amp * perlin3(x * f, y * f, z * f, perm)
        f *= lacunarity
        amp *= gain
    return total


def mockamap_noise(x, y, z, perm, complexity_per_m: float, fractal: int,
                   attenuation: float) -> np.ndarray:
    """The noise of mockamap's Perlin map (HKUST-Aerial-Robotics/mockamap, src/maps.cpp):
    the sum over octaves it = 1..``fractal`` of (attenuation / it) x Perlin noise at
    2^it x complexity -- with ``complexity_per_m`` its complexity per cell over the cell
    edge -- at the point (x, y, z in metres)."""
    total = np.zeros(np.broadcast(x, y, z).shape)
    for it in range(1, fractal + 1):
        f = 2 ** it * complexity_per_m
        total += (attenuation / it) * perlin3(x * f, y * f, z * f, perm)
    return total


def column_runs(filled: np.ndarray):
    """The runs of filled voxels in each voxel column (along z): index arrays i, j, k0, k1
    (k1 exclusive), in C order (column by column, bottom up)."""
    pad = np.zeros(filled.shape[:2] + (1,), dtype=np.int8)
    step = np.diff(np.concatenate([pad, filled.astype(np.int8), pad], axis=2), axis=2)
    i0, j0, k0 = np.nonzero(step == 1)
    k1 = np.nonzero(step == -1)[2]
    return i0, j0, k0, k1


def _join_consecutive(keys: tuple[np.ndarray, ...], pos: np.ndarray):
    """Group items whose ``keys`` are all equal and whose ``pos`` values are consecutive
    integers: (order, first, last) -- ``order`` sorts the items by keys then pos, and
    group g is ``order[first[g]:last[g] + 1]``."""
    order = np.lexsort((pos,) + tuple(reversed(keys)))
    p = pos[order]
    joins = np.ones(len(p), dtype=bool)
    joins[:1] = False
    for k in keys:
        ks = k[order]
        joins[1:] &= ks[1:] == ks[:-1]
    joins[1:] &= p[1:] == p[:-1] + 1
    first = np.flatnonzero(~joins)
    last = np.append(first[1:] - 1, len(p) - 1)
    return order, first, last


def voxel_boxes(filled: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Filled voxels (a 3-D bool array) as disjoint axis-aligned boxes of voxel indices,
    (lo, hi) arrays (n, 3), hi exclusive, that together cover exactly the filled voxels:
    the runs of each voxel column, joined along x where neighbouring columns have a run
    over the same z range, then along y where neighbouring slabs match. Deterministic;
    about 0.64 x the column runs of a Perlin version-2 field (docs/scenarios.md)."""
    i, j, k0, k1 = column_runs(filled)
    if not len(i):
        return np.zeros((0, 3), dtype=np.int64), np.zeros((0, 3), dtype=np.int64)
    order, first, last = _join_consecutive((j, k0, k1), i)
    i0, i1 = i[order][first], i[order][last] + 1
    j, k0, k1 = j[order][first], k0[order][first], k1[order][first]
    order, first, last = _join_consecutive((i0, i1, k0, k1), j)
    lo = np.column_stack([i0[order][first], j[order][first], k0[order][first]])
    hi = np.column_stack([i1[order][first], j[order][last] + 1, k1[order][first]])
    return lo, hi
