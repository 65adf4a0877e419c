"""Feasibility study for Random Perlin-Noise generator version 2 (mockamap's reading).

Builds the 10 configurations (seed 0) of the *existing* v1 generator (families.perlin)
with parameters that give mockamap's convention -- no generator code changed: the same
`_rng` stream, the same 3 % top-fill, 3 m clear radius and line-blocking rule -- and
measures, per configuration:

* filled cells, blobs (scipy.ndimage.label, 6-connected, as v1 counts them), blobs
  (3-D components) with a cell within 0.3 m of the start->goal line at z = 1.75-2.25 m,
  the fraction of the flight volume filled;
* the shortest collision-free path for three catalog bodies, on the occupancy
  (subdivided to ~0.1 m if coarser) with the obstacles grown by the body, modelled as a
  level disk of the body's bounding radius and its half-height: 26-connected A* (numba),
  then greedy line-of-sight shortening on the same grid; its time under the protocol's
  FlightBudget via difficulty.flight_time_s on difficulty.simplify(path);
* mesh boxes / triangles and build time; one depth frame render time (config 1).

Run (from the repo root, under nice -n 19, /tmp/p2 must exist):
  .venv/bin/python docs/results/perlin-v2-study/perlin_v2_study.py READING [all|1,2,..] [light]
      READING: mock01 (0.1 m, 1.0 cycles/m), mock038 (0.38 m), v1; -> /tmp/p2/results.jsonl
  ... perlin_v2_study.py practical     collision world, distance grid, camera (config 1)
  ... perlin_v2_study.py fill          fill sweep 0.06/0.10/0.15 at 0.1 m -> /tmp/p2/fill.jsonl
  ... perlin_v2_study.py figure OUT    the figure (needs the config-1 .npz of each reading)
"""
import heapq
import json
import math
import sys
import time

import numba
import numpy as np
from scipy import ndimage

import ft_sitl  # noqa: F401  (before numpy)
from ft_sitl.missions.spec import flight_budget
from ft_sitl.scenarios import families
from ft_sitl.scenarios.difficulty import flight_time_s, simplify
from ft_sitl.scenarios.families import build_scenario

READINGS = {
    # name: (generator params, subdivision for planning)
    "mock01": ({"voxel_m": 0.1, "noise_frequency_per_voxel": 0.1, "octaves": 1}, 1),
    "v1": ({}, 2),
    "mock038": ({"voxel_m": 0.38, "noise_frequency_per_voxel": 0.1, "octaves": 1}, 4),
}
# catalog bodies: bounding radius (m), half-height (m) -- from LevelBody supports
BODIES = {
    "largest (5.45kg-JFRC)": (0.469, 0.059),
    "median (2.00kg-T-MOTOR)": (0.314, 0.040),
    "smallest (0.55kg-UAV 1)": (0.187, 0.024),
}
W, L, C = 40.0, 50.0, 4.0
START, GOAL = np.array([20.0, 3.0, 2.0]), np.array([20.0, 47.0, 2.0])

_captured = {}
_orig_label = families.label


def _spy_label(a, *args, **kw):
    _captured["filled"] = np.array(a, dtype=bool)
    return _orig_label(a, *args, **kw)


families.label = _spy_label  # in this process only: capture the generator's occupancy


OFFS = np.array([(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)
                 if (a, b, c) != (0, 0, 0)], dtype=np.int64)
COST = np.sqrt((OFFS ** 2).sum(1)).astype(np.float64)


@numba.njit
def astar(free, s, g, offs, cost):
    nx, ny, nz = free.shape
    n = nx * ny * nz
    gs = np.full(n, np.inf)
    par = np.full(n, -1, dtype=np.int64)
    closed = np.zeros(n, dtype=np.bool_)
    si = (s[0] * ny + s[1]) * nz + s[2]
    gi = (g[0] * ny + g[1]) * nz + g[2]
    gs[si] = 0.0
    h0 = math.sqrt((s[0] - g[0]) ** 2 + (s[1] - g[1]) ** 2 + (s[2] - g[2]) ** 2)
    heap = [(h0, si)]
    expanded = 0
    while len(heap) > 0:
        f, cur = heapq.heappop(heap)
        if closed[cur]:
            continue
        closed[cur] = True
        expanded += 1
        if cur == gi:
            break
        k = cur % nz
        j = (cur // nz) % ny
        i = cur // (ny * nz)
        for m in range(offs.shape[0]):
            a = i + offs[m, 0]
            b = j + offs[m, 1]
            c = k + offs[m, 2]
            if a < 0 or b < 0 or c < 0 or a >= nx or b >= ny or c >= nz:
                continue
            if not free[a, b, c]:
                continue
            q = (a * ny + b) * nz + c
            if closed[q]:
                continue
            ng = gs[cur] + cost[m]
            if ng < gs[q]:
                gs[q] = ng
                par[q] = cur
                h = math.sqrt((a - g[0]) ** 2 + (b - g[1]) ** 2 + (c - g[2]) ** 2)
                heapq.heappush(heap, (ng + h, q))
    if not closed[gi]:
        return np.empty((0, 3), dtype=np.int64), expanded
    cnt = 0
    q = gi
    while q != -1:
        cnt += 1
        q = par[q]
    out = np.empty((cnt, 3), dtype=np.int64)
    q = gi
    for t in range(cnt - 1, -1, -1):
        out[t, 0] = q // (ny * nz)
        out[t, 1] = (q // nz) % ny
        out[t, 2] = q % nz
        q = par[q]
    return out, expanded


@numba.njit
def visible(free, p, q, step):
    d = q - p
    n = int(math.ceil(math.sqrt((d * d).sum()) / step)) + 1
    for t in range(n + 1):
        x = p + d * (t / n)
        i, j, k = int(round(x[0])), int(round(x[1])), int(round(x[2]))
        if not free[i, j, k]:
            return False
    return True


@numba.njit
def shorten(free, pts):
    """Greedy line-of-sight shortening: from each kept vertex, jump to the farthest
    later vertex visible from it (segments sampled every 0.25 cell)."""
    out = [0]
    i = 0
    n = pts.shape[0]
    while i < n - 1:
        j = n - 1
        while j > i + 1 and not visible(free, pts[i], pts[j], 0.25):
            j -= 1
        out.append(j)
        i = j
    res = np.empty((len(out), 3))
    for t in range(len(out)):
        res[t] = pts[out[t]]
    return res


def plan(occ, d, r, h, keep=False, zband=None):
    """occ on a grid of pitch d (cell i centre at (i + 0.5) d); body: disk radius r,
    half-height h. Returns dict."""
    free = free_grid(occ, d, r, h)
    if zband is not None:
        cz = (np.arange(occ.shape[2]) + 0.5) * d
        free &= ((cz >= zband[0]) & (cz <= zband[1]))[None, None, :]
    s = np.floor(START / d).astype(np.int64)
    g = np.floor(GOAL / d).astype(np.int64)
    out = {"blocked_fraction": round(float(1 - free.mean()), 4)}
    if not (free[tuple(s)] and free[tuple(g)]):
        out.update(solvable=False, why="start or goal blocked")
        return out, None
    lab, _ = ndimage.label(free, structure=np.ones((3, 3, 3)))
    if lab[tuple(s)] != lab[tuple(g)]:
        out.update(solvable=False, why="start and goal in different free components")
        return out, None
    del lab
    t0 = time.time()
    cells, expanded = astar(free, s, g, OFFS, COST)
    grid_len = float(np.linalg.norm(np.diff(cells, axis=0), axis=1).sum() * d)
    pts = shorten(free, cells.astype(np.float64))
    pts_m = (pts + 0.5) * d
    pts_m[0], pts_m[-1] = START, GOAL
    length = float(np.linalg.norm(np.diff(pts_m, axis=0), axis=1).sum())
    budget = flight_budget()
    t_fly = float(flight_time_s(simplify(pts_m), budget))
    straight = float(np.linalg.norm(GOAL - START))
    out.update(solvable=True, grid_path_m=round(grid_len, 2), path_m=round(length, 2),
               ratio=round(length / straight, 3), time_s=round(t_fly, 1),
               fits_90s=bool(t_fly <= budget.time_s), astar_s=round(time.time() - t0, 1),
               expanded=int(expanded), z_range=[round(float(pts_m[:, 2].min()), 2),
                                                round(float(pts_m[:, 2].max()), 2)])
    return out, pts_m


def free_grid(occ, d, r, h):
    """Cells whose centre the body (level disk, radius r, half-height h) may occupy.
    Conservative, so that any point a path sample rounds to a free cell is clear: the
    cell corner (d / sqrt 2) plus the rounding of a sample to its cell (d / sqrt 2
    across, d / 2 up) are added to the body."""
    nx, ny, nz = occ.shape
    dh = ndimage.distance_transform_edt(~occ, sampling=(d, d, 1e4)).astype(np.float32)
    dk = int(math.floor((h + d) / d - 1e-9))
    m = dh.copy()
    for s in range(1, dk + 1):
        m[:, :, s:] = np.minimum(m[:, :, s:], dh[:, :, :-s])
        m[:, :, :-s] = np.minimum(m[:, :, :-s], dh[:, :, s:])
    free = m >= r + d * math.sqrt(2.0)
    cx = (np.arange(nx) + 0.5) * d
    cy = (np.arange(ny) + 0.5) * d
    cz = (np.arange(nz) + 0.5) * d
    free &= ((cx >= r) & (cx <= W - r))[:, None, None]
    free &= ((cy >= r) & (cy <= L - r))[None, :, None]
    free &= ((cz >= h) & (cz <= C - h))[None, None, :]
    return free


def max_radius(occ, d, h, lo=0.05, hi=2.5, tol=0.01, ball=False):
    """The largest disk radius (half-height h) for which start and goal share a free
    component (26-connected): bisection on connectivity only."""
    s = tuple(np.floor(START / d).astype(np.int64))
    g = tuple(np.floor(GOAL / d).astype(np.int64))

    def ok(r):
        free = free_grid(occ, d, r, r if ball else h)
        if not (free[s] and free[g]):
            return False
        lab, _ = ndimage.label(free, structure=np.ones((3, 3, 3)))
        return lab[s] == lab[g]

    if not ok(lo):
        return 0.0
    while hi - lo > tol:
        mid = (lo + hi) / 2
        lo, hi = (mid, hi) if ok(mid) else (lo, mid)
    return round(lo, 3)


def verify(pts, filled, v, r, h, step=0.02):
    """Exact check of a path against the filled cells (boxes): the smallest horizontal
    distance from the path to a box that overlaps the body's height, minus r (>= 0: clear)."""
    from scipy.spatial import cKDTree
    idx = np.argwhere(filled)
    cen = (idx + 0.5) * v
    tree = cKDTree(cen)
    seg = []
    for a, b in zip(pts[:-1], pts[1:]):
        n = max(2, int(np.linalg.norm(b - a) / step) + 1)
        seg.append(a + (b - a) * np.linspace(0, 1, n)[:, None])
    P = np.concatenate(seg)
    reach = r + 0.6
    best = np.inf
    for i, nb in enumerate(tree.query_ball_point(P, reach)):
        if not nb:
            continue
        c = cen[nb]
        zov = np.abs(c[:, 2] - P[i, 2]) < v / 2 + h
        if not zov.any():
            continue
        c = c[zov]
        dx = np.maximum(np.abs(P[i, 0] - c[:, 0]) - v / 2, 0)
        dy = np.maximum(np.abs(P[i, 1] - c[:, 1]) - v / 2, 0)
        best = min(best, float(np.hypot(dx, dy).min()))
    return round(best - r, 3) if np.isfinite(best) else None


def line_blobs(filled, v, alt=2.0, grow=0.3):
    lab, _ = ndimage.label(filled)
    cx = (np.arange(filled.shape[0]) + 0.5) * v
    cy = (np.arange(filled.shape[1]) + 0.5) * v
    cz = (np.arange(filled.shape[2]) + 0.5) * v
    near = (np.abs(cx - 20.0) <= grow + v / 2)[:, None, None] \
        & ((cy > 3.0) & (cy < 47.0))[None, :, None] \
        & (np.abs(cz - alt) <= 0.25 + v / 2)[None, None, :]
    ids = np.unique(lab[near & filled])
    # length of the line at altitude inside filled cells
    i = int(20.0 / v) if abs(20.0 / v - round(20.0 / v)) > 1e-9 else None
    cols = [int(20.0 / v) - 1, int(20.0 / v)] if i is None else [i]
    k = int(alt / v)
    js = np.flatnonzero((cy > 3.0) & (cy < 47.0))
    on = filled[np.ix_(cols, js, [k])].any(axis=(0, 2))
    return len(ids), float(on.sum() * v)


def render(sc, step=1):
    from ft_sitl.scenarios.camera import CameraConfig, DepthCamera
    t0 = time.time()
    cam = DepthCamera(CameraConfig().subsampled(step), sc.mesh)
    t_init = time.time() - t0
    yaw = sc.start_yaw
    q = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
    ts = []
    valid = []
    for n, y in enumerate([3.0, 10.0, 20.0, 30.0, 40.0, 3.0]):
        t0 = time.time()
        fr = cam.capture(n * 33334, np.array([20.0, y, 2.0]), q)
        ts.append(time.time() - t0)
        valid.append(float(np.isfinite(fr.depth).mean()))
    return {"camera_init_s": round(t_init, 2), "first_frame_s": round(ts[0], 3),
            "frame_ms_median_next5": round(1000 * float(np.median(ts[1:])), 1),
            "valid_pixel_fraction": [round(x, 3) for x in valid]}


def main(reading, configs=range(1, 11), light=False):
    """light: the largest body only, no max-radius bisection, no altitude band (the smaller
    bodies' free space contains the largest's, so they are solvable whenever it is)."""
    params, sub = READINGS[reading]
    for idx in configs:
        rec = {"reading": reading, "config": idx}
        t0 = time.time()
        sc = build_scenario("perlin", idx, 0, params)
        rec["build_s"] = round(time.time() - t0, 1)
        filled = _captured.pop("filled")
        lay = sc.provenance["layout"]
        v = float(sc.provenance["parameters"]["voxel_m"])
        rec.update(voxel_m=v, cells=list(filled.shape),
                   cycles_per_m=sc.provenance["parameters"]["noise_frequency_per_m"],
                   filled_cells=int(filled.sum()), blobs=int(lay["blobs"]),
                   x_shift_voxels=lay["x_shift_voxels"],
                   filled_fraction=round(float(filled.mean()), 4),
                   boxes=int(sc.provenance["mesh_pieces"]),
                   triangles=int(len(sc.mesh.faces)))
        nb, onlen = line_blobs(filled, v)
        rec.update(line_blobs=nb, line_inside_m=round(onlen, 1))
        occ = filled
        if sub > 1:
            occ = filled.repeat(sub, 0).repeat(sub, 1).repeat(sub, 2)
        d = v / sub
        rec["plan_pitch_m"] = d
        t1 = time.time()
        if not light:
            rec["max_radius_largest_h_m"] = max_radius(occ, d, BODIES["largest (5.45kg-JFRC)"][1])
            rec["max_radius_ball_m"] = max_radius(occ, d, 0.0, hi=2.0, ball=True)
            rec["max_radius_s"] = round(time.time() - t1, 1)
            res, _ = plan(occ, d, *BODIES["largest (5.45kg-JFRC)"], zband=(1.5, 2.5))
            rec["largest_z_1.5_2.5"] = res
        rec["bodies"] = {}
        keep = {}
        for name, (r, h) in BODIES.items():
            if light and not name.startswith("largest"):
                continue
            t1 = time.time()
            res, pts = plan(occ, d, r, h, keep=(idx == 1))
            res["total_s"] = round(time.time() - t1, 1)
            rec["bodies"][name] = res
            if pts is not None:
                res["verify_clearance_m"] = verify(pts, filled, v, r, h)
                if idx == 1:
                    keep[name] = pts
            print(reading, idx, name, res, flush=True)
        if idx == 1:
            if not light:
                rec["render"] = render(sc)
            k = int(2.0 / v)
            np.savez_compressed(f"/tmp/p2/{reading}_c1.npz", slice=filled[:, :, k],
                                voxel=v, **{f"path{n}": p for n, p in
                                            enumerate(keep.get(b) for b in BODIES)
                                            if p is not None})
        print(json.dumps(rec), flush=True)
        with open("/tmp/p2/results.jsonl", "a") as f:
            f.write(json.dumps(rec) + "\n")


def fill_sweep(fills=(0.06, 0.10, 0.15), configs=range(1, 11)):
    """mockamap 0.1 m reading at higher fill: largest body only."""
    params, _ = READINGS["mock01"]
    r, h = BODIES["largest (5.45kg-JFRC)"]
    for fill in fills:
        for idx in configs:
            t0 = time.time()
            sc = build_scenario("perlin", idx, 0, dict(params, fill_rate=fill))
            filled = _captured.pop("filled")
            rec = {"reading": "mock01", "fill_rate": fill, "config": idx,
                   "blobs": int(sc.provenance["layout"]["blobs"]),
                   "line_blobs": line_blobs(filled, 0.1)[0]}
            res, pts = plan(filled, 0.1, r, h)
            if pts is not None:
                res["verify_clearance_m"] = verify(pts, filled, 0.1, r, h)
            rec["largest"] = res
            rec["s"] = round(time.time() - t0, 1)
            print(json.dumps(rec), flush=True)
            with open("/tmp/p2/fill.jsonl", "a") as f:
                f.write(json.dumps(rec) + "\n")


def practical():
    """Config 1 of each reading: collision world build and query cost, depth frames."""
    from ft_sitl.scenarios.collision import CollisionWorld
    for n in ("mock01", "mock038", "v1"):
        sc = build_scenario("perlin", 1, 0, READINGS[n][0])
        _captured.pop("filled", None)
        t0 = time.time()
        cw = CollisionWorld(sc.mesh, sc.bounds_min, sc.bounds_max)
        t_build = time.time() - t0
        ys = np.linspace(3.5, 46.5, 2000)
        pts = np.column_stack([np.full_like(ys, 20.0), ys, np.full_like(ys, 2.0)])
        t0 = time.time()
        cl = [cw.clearance(p, 0.469) for p in pts]
        t_q = (time.time() - t0) / len(pts)
        from ft_sitl.scenarios.distance_grid import DistanceGrid
        t0 = time.time()
        DistanceGrid.build(sc.mesh, sc.bounds_min, sc.bounds_max)
        t_grid = time.time() - t0
        rec = {"reading": n, "collision_world_build_s": round(t_build, 2),
               "clearance_query_us": round(1e6 * t_q, 1),
               "line_points_in_contact": int(sum(c <= 0 for c in cl)),
               "distance_grid_build_s": round(t_grid, 2),
               "render_640x480": render(sc), "render_160x120": render(sc, 4)}
        print(json.dumps(rec), flush=True)
        with open("/tmp/p2/practical.jsonl", "a") as f:
            f.write(json.dumps(rec) + "\n")


def figure(out):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = [("mock01", "mockamap, 0.1 m cells (1.0 cycles/m)"),
             ("mock038", "mockamap default, 0.38 m cells (0.26 cycles/m)"),
             ("v1", "v1 (0.25 m voxels, 0.2 cycles/m + octave)")]
    fig, axes = plt.subplots(1, 3, figsize=(15, 6.8))
    for ax, (n, title) in zip(axes, names):
        z = np.load(f"/tmp/p2/{n}_c1.npz")
        v = float(z["voxel"])
        sl = z["slice"]
        ax.imshow(sl.T, origin="lower", extent=(0, sl.shape[0] * v, 0, sl.shape[1] * v),
                  cmap="Greys", vmin=0, vmax=1.4, interpolation="nearest")
        if "path0" in z:
            p = z["path0"]
            sc_ = ax.scatter(p[:, 0], p[:, 1], c=p[:, 2], cmap="viridis", vmin=0, vmax=4,
                             s=8, zorder=3)
            ax.plot(p[:, 0], p[:, 1], "r-", lw=1.0, zorder=2)
        ax.plot([20, 20], [3, 47], "b:", lw=0.8)
        ax.plot([20, 20], [3, 47], "b^", ms=5)
        ax.set_title(f"{title}\nconfig 1, filled cells in the layer at z = 2 m", fontsize=9)
        ax.set_xlim(0, 40)
        ax.set_ylim(0, 50)
        ax.set_aspect("equal")
        ax.set_xlabel("x (m)")
    axes[0].set_ylabel("y (m)")
    fig.colorbar(sc_, ax=axes, shrink=0.6, label="path altitude z (m), largest body")
    fig.savefig(out, dpi=110, bbox_inches="tight")


if __name__ == "__main__":
    if sys.argv[1] == "fill":
        fill_sweep()
        sys.exit()
    if sys.argv[1] == "practical":
        practical()
        sys.exit()
    if sys.argv[1] == "figure":
        figure(sys.argv[2])
        sys.exit()
    r = sys.argv[1]
    cfgs = [int(x) for x in sys.argv[2].split(",")] \
        if len(sys.argv) > 2 and sys.argv[2] != "all" else range(1, 11)
    main(r, cfgs, light="light" in sys.argv[3:])
