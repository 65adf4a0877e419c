"""Perlin geometry: ours (0.05 per 0.25 m voxel = 0.2 c/m) vs other readings of 'frequency 0.05'."""

import json

import numpy as np
from scipy import ndimage

from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.solvability import convex_pieces


def slice_grid(sc, step=0.1):
    """The cell centres (cx, cy) of a horizontal slice of the scenario's bounds, and its
    lower and upper corners."""
    lo = np.array(sc.bounds_min, float)
    hi = np.array(sc.bounds_max, float)
    nx = int(round((hi[0] - lo[0]) / step))
    ny = int(round((hi[1] - lo[1]) / step))
    cx = lo[0] + (np.arange(nx) + 0.5) * step
    cy = lo[1] + (np.arange(ny) + 0.5) * step
    return cx, cy, lo, hi


def slice_boxes(sc, z, step=0.1):
    """Occupancy of the horizontal slice at height z from the pieces' bounding boxes: exact
    for Perlin's axis-aligned boxes, an over-estimate for tilted cylinders (figures.py's
    slice_occ tests the pieces' faces)."""
    cx, cy, _, _ = slice_grid(sc, step)
    nx, ny = len(cx), len(cy)
    occ = np.zeros((nx, ny), bool)
    for p in convex_pieces(sc.mesh):
        if not (p.lo[2] <= z <= p.hi[2]):
            continue
        ix = (cx >= p.lo[0]) & (cx <= p.hi[0])
        iy = (cy >= p.lo[1]) & (cy <= p.hi[1])
        occ[np.ix_(ix, iy)] = True
    return occ, cx, cy


def runs(a):
    # lengths of True runs along axis 0 for 2-D array a (each column independently), interior runs only
    out = []
    for col in a.T:
        x = np.concatenate([[0], col.astype(int), [0]])
        dx = np.diff(x)
        s = np.flatnonzero(dx == 1)
        e = np.flatnonzero(dx == -1)
        for a0, b0 in zip(s, e):
            if a0 > 0 and b0 < len(col):
                out.append(b0 - a0)
    return np.array(out)


def main():
    rows = []
    for fpm in [0.2, 0.5, 1.0]:
        for idx in range(1, 11):
            params = {} if fpm == 0.2 else {"noise_frequency_per_voxel": fpm * 0.25}
            sc = build_scenario("perlin", idx, 0, params=params)
            occ, cx, cy = slice_boxes(sc, 2.0)
            y0, y1 = 6.0, 44.0
            band = (cy > y0) & (cy < y1)
            o = occ[:, band]
            lab, nb = ndimage.label(o)
            sizes = ndimage.sum(np.ones_like(o), lab, range(1, nb + 1)) * 0.01  # m^2
            # lateral free gaps between obstacles in x (per y row), metres
            gaps = runs(~o) * 0.1  # runs along x (axis0) of free cells, interior
            # free path along +y starting from free cells in x 15..25 (straight flight ahead)
            line = np.abs(cx - 20) < 0.05
            # straight line at x=20: obstacles crossed (grown by 0.3 m body radius)
            grown = ndimage.binary_dilation(o, iterations=3)
            lc = grown[np.argmin(np.abs(cx - 20)), :]
            crossings = int(np.sum(np.diff(lc.astype(int)) == 1) + lc[0])
            # mean free path along y at 2 m in the route band
            fp = runs(~o.T) * 0.1
            rows.append(
                dict(
                    freq_per_m=fpm,
                    index=idx,
                    blobs=sc.provenance["layout"]["blobs"],
                    filled_slice=float(o.mean()),
                    n_pieces_slice=int(nb),
                    median_piece_m2=float(np.median(sizes)),
                    gap_x_median=float(np.median(gaps)),
                    gap_x_p10=float(np.percentile(gaps, 10)),
                    free_run_y_median=float(np.median(fp)),
                    line_crossings_grown=crossings,
                )
            )
            print(rows[-1], flush=True)
    json.dump(rows, open("/tmp/pd/perlin_geo.json", "w"), indent=1)

    # ---- difficulty of Perlin variants and of Random-Angle Cylinder variants -----------------
    # (run separately in the investigation: /tmp/pd/perlin_diff.py and /tmp/pd/rac_geo.py;
    #  reproduced here in one file)
    from ft_sitl.missions.spec import flight_budget
    from ft_sitl.physics.catalog import largest_platform
    from ft_sitl.scenarios.difficulty import measure_difficulty

    P, B = largest_platform(), flight_budget()
    variants = [
        ("perlin", i, {"noise_frequency_per_voxel": f * 0.25})
        for f in (0.5, 1.0)
        for i in (1, 5, 10)
    ]
    variants += [
        ("random_angle_cylinder", i, {"min_axis_gap_m": g})
        for g in (1.0, 0.0)
        for i in range(1, 11)
    ]
    variants += [("random_angle_cylinder", i, {"length_m": 16.0}) for i in range(1, 11)]
    for fam, i, params in variants:
        d = measure_difficulty(build_scenario(fam, i, 0, params=params), P, B)
        print(
            fam,
            i,
            params,
            "path/line",
            d.path_ratio,
            "narrowest",
            d.passage_width_m,
            "spare",
            d.passage_spare_m,
            "flyable",
            d.flyable,
            flush=True,
        )


if __name__ == "__main__":
    main()
