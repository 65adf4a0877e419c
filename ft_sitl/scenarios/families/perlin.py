"""Random Perlin-Noise (theoretical): the highest-noise cells of a Perlin field filled,
one blob across the start->goal line. Declared in :mod:`ft_sitl.scenarios.families`."""

from __future__ import annotations

import numpy as np
from scipy.ndimage import label

from ft_sitl.scenarios.families.common import (
    START_MARGIN_M,
    Family,
    MeshBuilder,
    make_scenario,
    start_altitude,
)
from ft_sitl.scenarios.families.noise import column_runs, fbm3, mockamap_noise, voxel_boxes
from ft_sitl.scenarios.scenario import Scenario, ScenarioError


def perlin(fam: Family, p: dict, rng: np.random.Generator, index: int, seed: int) -> Scenario:
    """Random Perlin-Noise (version 1): 40 x 50 m, ceiling 4 m, noise frequency 0.05 per
    0.25 m voxel, fill rate 0.03.

    The flight volume is cut into 0.25 m voxels (160 x 200 x 16). Perlin noise is sampled
    at their centres with the paper's frequency 0.05 taken per voxel -- voxel generators
    multiply integer voxel indices by it -- i.e. 0.2 cycles/m (features ~5 m across), plus
    a second octave (lacunarity 2, gain 0.5) for irregular edges; the permutation and the
    offset are random. The filling and the line rule are :func:`_perlin_fill`'s. Filled
    voxels are merged into one box per run in each voxel column.
    """
    voxel = p["voxel_m"]
    frequency = p["noise_frequency_per_voxel"] / voxel  # cycles per metre

    def noise(x, y, z, perm):
        return fbm3(x, y, z, perm, frequency, p["octaves"], p["lacunarity"], p["gain"])

    filled, shape, offset, shift, alt = _perlin_fill(p, rng, index, noise)
    i0, j0, k0, k1 = column_runs(filled)
    b = MeshBuilder()
    b.boxes(np.column_stack([i0, j0, k0]) * voxel, np.column_stack([i0 + 1, j0 + 1, k1]) * voxel,
            "noise column")

    _, blobs = label(filled)
    return make_scenario(
        fam, index, seed, b, p, altitude=alt, obstacle_count=blobs,
        derived={"noise_frequency_per_m": frequency, "start_altitude_m": alt},
        layout={"voxels": list(shape), "filled_voxels": int(filled.sum()),
                "noise_offset_m": offset, "x_shift_voxels": shift, "blobs": blobs},
    )


#: the most cells a Perlin field may have (the paper's area at 0.1 m: 8 M; each cell costs
#: ~100 bytes while the field is built)
PERLIN_MAX_CELLS = 40_000_000


def _perlin_fill(p: dict, rng: np.random.Generator, index: int, noise):
    """The filled voxels of a Perlin field (both versions): ``noise(x, y, z, perm)`` (x, y,
    z in metres, broadcast) sampled at the voxel centres plus a random offset (the
    permutation, then the offset, are the first draws of ``rng``); exactly ``fill_rate``
    of the voxels -- those with the highest values, outside ``clear_radius_m`` of the
    takeoff column and the goal -- are filled. If that leaves the start->goal line clear,
    the noise is shifted along x (whole voxels) until a filled 2 x 2 voxel block surrounds
    the line. Returns (filled (nx, ny, nz) bool, shape, offset, x shift in voxels, start
    altitude)."""
    width, length = p["size_m"]
    ceiling = p["ceiling_m"]
    alt = start_altitude(ceiling)
    voxel, fill_rate = p["voxel_m"], p["fill_rate"]
    shape = (int(width / voxel), int(length / voxel), int(ceiling / voxel))
    cells = shape[0] * shape[1] * shape[2]
    if cells > PERLIN_MAX_CELLS:
        raise ScenarioError(
            f"perlin #{index}: {width:g} x {length:g} x {ceiling:g} m in {voxel:g} m cells "
            f"is {cells:,} cells, more than {PERLIN_MAX_CELLS:,} (the field needs ~100 "
            f"bytes per cell): raise voxel_m or shrink size_m / ceiling_m")
    perm = rng.permutation(256)
    offset = rng.uniform(0.0, 1000.0, 3)
    n_fill = round(fill_rate * cells)
    cx = (np.arange(shape[0]) + 0.5) * voxel
    cy = (np.arange(shape[1]) + 0.5) * voxel
    cz = (np.arange(shape[2]) + 0.5) * voxel
    line_x = width / 2.0
    sy, gy = START_MARGIN_M, length - START_MARGIN_M
    clear = p["clear_radius_m"]
    near = ((np.hypot(cx[:, None] - line_x, cy[None, :] - sy) < clear)
            | (np.hypot(cx[:, None] - line_x, cy[None, :] - gy) < clear))
    # voxels around the line: columns either side of x = 20, layers either side of z = alt
    ix = [int(line_x / voxel) - 1, int(line_x / voxel)]
    iz = [int(alt / voxel) - 1, int(alt / voxel)]
    route = (cy > sy) & (cy < gy)

    def fill(shift):
        val = noise((cx[:, None, None] + offset[0] + shift * voxel),
                    (cy[None, :, None] + offset[1]), (cz[None, None, :] + offset[2]), perm)
        val = np.where(near[:, :, None], -np.inf, val)
        return val, _largest(val.ravel(), n_fill).reshape(shape)

    def blocks_line(filled):
        sub = filled[np.ix_(ix, np.flatnonzero(route), iz)]
        return bool(sub.all(axis=(0, 2)).any())

    val, filled = fill(0)
    shift = 0
    if not blocks_line(filled):
        # move the strongest filled voxels (blob cores) onto the line, one by one
        cand = np.argsort(-np.where(filled, val, -np.inf).ravel(), kind="stable")[:200]
        for flat in cand:
            i, j, _ = np.unravel_index(flat, shape)
            if not route[j]:
                continue
            s = int(i) - ix[1]
            val2, filled2 = fill(s)
            if blocks_line(filled2):
                shift, filled = s, filled2
                break
        else:
            raise RuntimeError(f"perlin #{index}: could not put an obstacle on the line")
    return filled, shape, offset, shift, alt


def _largest(values: np.ndarray, n: int) -> np.ndarray:
    """Mask of the ``n`` largest of ``values`` (1-D), ties at the threshold going to the
    lowest indices: the first ``n`` of a stable sort by decreasing value, found by a
    partition (a sort of a 0.1 m field's 8 M cells took 1 s)."""
    mask = np.zeros(values.size, dtype=bool)
    if n <= 0:
        return mask
    if n >= values.size:
        mask[:] = True
        return mask
    threshold = np.partition(values, values.size - n)[values.size - n]
    mask = values > threshold
    mask[np.flatnonzero(values == threshold)[:n - int(mask.sum())]] = True
    return mask


def perlin_v2(fam: Family, p: dict, rng: np.random.Generator, index: int,
              seed: int) -> Scenario:
    """Random Perlin-Noise (version 2): 40 x 50 m, ceiling 4 m, mockamap's reading of
    frequency 0.05 and fill rate 0.03.

    The flight volume is cut into 0.1 m cells (400 x 500 x 40, mockamap's resolution in
    EGO-Planner's own simulator launch). mockamap samples Perlin noise at 2 x complexity
    per cell index for its one octave; with the paper's 0.05 as complexity that is 1.0
    cycles/m. The permutation and offset are random; filling and the line rule are
    :func:`_perlin_fill`'s (3 % of the cells, those of highest noise, outside 3 m of the
    takeoff column and the goal; an obstacle across the line). Filled cells are merged into
    disjoint boxes (:func:`voxel_boxes`).
    """
    voxel = p["voxel_m"]
    per_m = p["complexity"] / voxel

    def noise(x, y, z, perm):
        return mockamap_noise(x, y, z, perm, per_m, p["fractal"], p["attenuation"])

    filled, shape, offset, shift, alt = _perlin_fill(p, rng, index, noise)
    lo, hi = voxel_boxes(filled)
    b = MeshBuilder()
    b.boxes(lo * voxel, hi * voxel, "noise blob")
    _, blobs = label(filled)
    return make_scenario(
        fam, index, seed, b, p, altitude=alt, obstacle_count=blobs,
        derived={"noise_frequency_per_m": 2.0 * per_m, "start_altitude_m": alt},
        layout={"voxels": list(shape), "filled_voxels": int(filled.sum()),
                "noise_offset_m": offset, "x_shift_voxels": shift, "blobs": blobs,
                "boxes": len(lo)},
    )
