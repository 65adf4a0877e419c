"""Local perception map shared by the planners: log-odds voxels from depth frames, ESDF.

Our re-implementation of the grid map of EGO-Planner (``plan_env/grid_map``) and Fast-Planner
(``plan_env/sdf_map``), which the EGO, Fast-Planner and PGO navigators share. It knows only
what the depth camera saw (:class:`~ft_sitl.scenarios.camera.DepthFrame`); it never reads the
scenario mesh. World frame ENU, metres.

Grid
----
Voxels of ``resolution_m`` (0.1 m) aligned to the world: voxel ``(i, j, k)`` (a *global*
index, the same for the whole flight) covers ``[i, i+1) x [j, j+1) x [k, k+1)`` times the
resolution; its centre is ``(index + 0.5) * resolution``. A point's voxel is
``floor(p / resolution)`` (computed as ``floor(p * (1 / resolution))``).

The map holds a **window** of voxels: ``window_xy_m`` (13 m) square horizontally, centred on
the camera, and vertically from ``z_margin_m`` below the floor to ``z_margin_m`` above the
ceiling (fixed: the vehicle flies between them). When the camera moves more than
``recentre_distance_m`` (1 m, per axis) from the window centre, the window re-centres on it:
the arrays are shifted by whole voxels, so what stays inside keeps its world coordinates and
what falls out is forgotten (unknown again when seen next). The originals allocate a global
map (e.g. 40 x 40 x 3 m) but update only ``camera +- local_update_range`` (5.5, 5.5, 4.5 m,
half extents) per frame and forget everything beyond that box plus ``local_map_margin``; our
window keeps at least 5.5 m around the camera in every horizontal direction
(``window_xy_m / 2 - recentre_distance_m``), which the configuration checks, so every voxel
a frame may update is inside the arrays.

Fusing one depth frame (:meth:`LocalMap.fuse`), as the originals' ``projectDepthImage`` and
``raycastProcess``:

1. Pixels ``(v, u)`` for ``v = m, m+s, ... < H - m`` and ``u = m, m+s, ... < W - m``
   (``skip_pixel`` s = 2, ``depth_margin_px`` m = 2): 318 x 238 = 75,684 rays at 640 x 480.
2. Each pixel's z-depth z (metres along the optical axis):

   * NaN (the camera's "no return": nothing within its range, or a dropout; this also
     covers surfaces closer than the camera's ``min_range_m``, as a RealSense's 0 does in
     the originals) -> a **free ray**: z := ``max_ray_length_m + 0.1`` (4.6 m);
   * ``z < min_depth_m`` (0.2 m) -> the pixel is skipped;
   * ``z > max_depth_m`` (5 m) -> a free ray, z := ``max_ray_length_m + 0.1``;
   * otherwise the end point ``R (z (u-cx)/fx, z (v-cy)/fy, z) + p_camera``.

   An end point farther than ``max_ray_length_m`` (4.5 m, Euclidean, from the camera) is
   pulled back to that length and becomes a **miss** instead of a hit. So free rays are
   4.5 m long (the 4.6 m z-depth never survives the cut), and obstacles seen between 4.5 m
   and 5 m are *not* marked: free space is carved up to 4.5 m in front of them.
3. Rays are clipped to ``camera +- local_update_range_m`` intersected with the window; an
   end point outside becomes a miss at the box face (the originals' ``closetPointInMap``).
4. Each end point is traced back to the camera with a 3-D DDA (Amanatides-Woo along the
   exact segment; ties go to the lowest axis), end-point voxel first, camera voxel last.
   (The originals' ray caster walks from the exact end point along the integer difference
   of the two voxel indices and leaves out the camera voxel.) Speed-ups as in the
   originals: a ray whose end-point voxel is already a ray end this frame is not traced,
   and a trace stops as soon as it enters a voxel already traversed this frame.

   These early stops are **not exact**: two rays that share a voxel part again on the way
   to the camera, and the voxels only the stopped ray would have crossed stay unobserved
   this frame. Hits are unaffected. Measured (tests, ``bench/bench_mapping.py``): one frame
   of a wall 3 m ahead marks ~45 % of the free voxels in front of it that full tracing
   marks, and the *same* ones every frame, so a static camera never clears the rest (a
   wall removed in front of a hovering vehicle stays about half occupied); along a flight
   the poses vary and the gap closes (94 % of full tracing's known voxels after 20 frames
   at 4 m/s in Forest; occupied voxels 275 vs 256: grazing rays clear fewer surface
   voxels). It is ~40x faster (~2.3 vs ~115 ms a 640 x 480 frame). Unknown counts as free
   for planning, so for the planners this means slower clearing of stale obstacles, as in
   the originals. ``fuse(..., early_stop=False)`` traces every ray in full.
5. Every voxel touched this frame gets exactly one log-odds update: ``+logit(p_hit)`` if
   any ray *ended* in it with a hit, else ``+logit(p_miss)``; then clamped to
   ``[logit(p_min), logit(p_max)]``. The originals vote (hit if hits >= misses, counted
   along the partial traces); since same-voxel end points skip their traces, a voxel with a
   hit end point almost always wins the vote there. "Hits win" gives the same result in
   that common case, does not depend on the order of the rays, and lets the early stop
   change nothing but the set of traversed voxels.

Occupancy: unknown voxels start at ``logit(p_min) - 0.01`` (just below the clamp, so any
miss makes them known-free); occupied means log-odds ``> logit(p_occ)``. With the defaults
(p_hit 0.65, p_occ 0.80) a newly seen surface needs 6 consecutive hits (0.3 s at 20 Hz) to
become occupied, and an occupied voxel at the clamp (p_max 0.90) 2 misses to become free.

Planning occupancy (:meth:`LocalMap.occupied_inflated`, and what the ESDF is built from):
occupied voxels dilated by ``inflation_voxels`` (1: the 3x3x3 neighbourhood; the originals'
``obstacles_inflation`` 0.099 m rounds up to one voxel), plus two virtual layers that hold
everywhere, inside the window or not:

* the **ceiling**: voxels ``k >= floor(ceiling_m / res)``, i.e. the voxel containing the
  ceiling height and everything above (``z >= 3.0`` for a 3 m ceiling). The originals mark
  one layer at that index; everything above it is out of their map;
* the **floor**: voxels ``k < floor(floor_m / res)``, i.e. ``z < floor_m`` (``z < 0``):
  the scenarios have no floor mesh, and below it the originals' map ends.

Unknown voxels count as free for planning, as in the originals. Neither virtual layer is
inflated.

ESDF (:meth:`LocalMap.update_esdf`), after Fast-Planner's ``updateESDF3d``: exact Euclidean
distance transform (Felzenszwalb-Huttenlocher lower envelope, three 1-D passes) of the
planning occupancy over the whole window, voxel centre to voxel centre. Free voxels hold the
distance to the nearest planning-occupied voxel centre (> 0); occupied voxels hold
``res - (distance to the nearest free voxel centre)``: 0 on an obstacle's surface layer,
negative deeper inside. :meth:`LocalMap.esdf` interpolates it trilinearly between voxel
centres and returns the analytic gradient of that interpolant. Points beyond the window are
clamped onto its outermost voxel centres per axis (the gradient along a clamped axis is 0);
Fast-Planner returns 0 with a zero gradient outside its (much larger, global) map, which
in our 13 m window would read as "touching an obstacle" a few metres ahead. The whole
window (Forest: 130 x 130 x 41 voxels) takes ~16 ms on one core, a 10 m ceiling ~48 ms;
``update_esdf(half_extent_m=...)`` computes a local box instead (Fast-Planner's choice:
exact only with respect to what lies inside the box).

Moving obstacles: a voxel is freed by misses only where a traced ray crosses it, so with
the early stop a hovering camera keeps part of a passer-by's trail occupied (measured in
tests/navigation/test_mapping.py); as the originals, the planners' maps have no other
remedy. NavRL's map (its deployment's ``map_manager``) removes the boxes of the moving
obstacles its detector tracks: :meth:`LocalMap.fuse` leaves out the end points in given
boxes (``exclude_boxes``) and :meth:`LocalMap.set_free` makes the voxels of boxes free.

All kernels are numba ``@njit(cache=True)``; the ESDF's (the distance transform, the
trilinear read) and the field's cache live in :mod:`~ft_sitl.navigation.maps.map_esdf`, the
others in this module.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from ft_sitl.navigation.base import Task
from ft_sitl.navigation.maps.map_esdf import MapEsdf, box_xy, esdf_eval
from ft_sitl.scenarios.camera import CameraConfig, DepthFrame

__all__ = ["FuseStats", "LocalMap", "MapConfig", "logit"]

# per-frame voxel flags
_HIT = np.uint8(1)
_TRAV = np.uint8(2)
_END = np.uint8(4)

# query kinds (kernel switch)
_Q_OCC, _Q_PLAN, _Q_KNOWN, _Q_WINDOW = 0, 1, 2, 3

# voxels per axis the arrays may hold (keeps memory and int32 flat indices sane)
_MAX_VOXELS_PER_AXIS = 4000
_MAX_VOXELS = 200_000_000


def logit(p: float) -> float:
    """log(p / (1 - p))."""
    return math.log(p / (1.0 - p))


# --- configuration ----------------------------------------------------------------------------
@dataclass(frozen=True)
class MapConfig:
    """Local map parameters (defaults: EGO-Planner's ``advanced_param.xml`` grid map).

    ============================  =========  ==================================================
    field                         default    meaning (source)
    ============================  =========  ==================================================
    resolution_m                  0.1        voxel edge (m) (``grid_map/resolution``)
    local_update_range_m          5.5,5.5,   half extents (m) of the box around the camera one
                                  4.5        frame may update (``local_update_range_x/y/z``)
    window_xy_m                   13.0       horizontal side (m) of the held window; must be
                                             >= 2 (update range + recentre distance)
    recentre_distance_m           1.0        camera offset (m, per axis) from the window
                                             centre that triggers a re-centring shift
    z_margin_m                    0.5        window extends this far (m) below the floor and
                                             above the ceiling (>= one voxel)
    p_hit, p_miss                 0.65,0.35  hit / miss probabilities (``p_hit``, ``p_miss``)
    p_min, p_max                  0.12,0.90  log-odds clamp (``p_min``, ``p_max``)
    p_occ                         0.80       occupied above this (``p_occ``)
    unknown_offset                0.01       unknown = logit(p_min) - this (``unknown_flag``)
    skip_pixel                    2          pixel subsampling step (``skip_pixel``)
    depth_margin_px               2          image border skipped (``depth_filter_margin``)
    min_depth_m                   0.2        closer pixels skipped (``depth_filter_mindist``)
    max_depth_m                   5.0        farther pixels -> free rays
                                             (``depth_filter_maxdist``)
    max_ray_length_m              4.5        rays cut to this length (m); cut rays are misses
                                             (``max_ray_length``)
    inflation_voxels              1          dilation radius (voxels) for planning
                                             (``obstacles_inflation`` 0.099 m -> 1; from
                                             protocol 4 on the footprint: 0..8)
    ============================  =========  ==================================================
    """

    resolution_m: float = 0.1
    local_update_range_m: tuple[float, float, float] = (5.5, 5.5, 4.5)
    window_xy_m: float = 13.0
    recentre_distance_m: float = 1.0
    z_margin_m: float = 0.5
    p_hit: float = 0.65
    p_miss: float = 0.35
    p_min: float = 0.12
    p_max: float = 0.90
    p_occ: float = 0.80
    unknown_offset: float = 0.01
    skip_pixel: int = 2
    depth_margin_px: int = 2
    min_depth_m: float = 0.2
    max_depth_m: float = 5.0
    max_ray_length_m: float = 4.5
    inflation_voxels: int = 1

    def __post_init__(self):
        try:
            rng = tuple(float(c) for c in np.asarray(self.local_update_range_m,
                                                     dtype=float).ravel())
        except (TypeError, ValueError):
            rng = ()
        object.__setattr__(self, "local_update_range_m", rng)
        self.validate()

    def validate(self) -> None:
        """Raise ValueError naming the first offending field and its allowed range."""

        def num(name: str, lo: float, hi: float, lo_open: bool = False,
                hi_open: bool = False) -> float:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
                raise ValueError(f"MapConfig.{name} must be a finite number, got {v!r}")
            v = float(v)
            bad = (v <= lo if lo_open else v < lo) or (v >= hi if hi_open else v > hi)
            if bad:
                lb, rb = ("(" if lo_open else "["), (")" if hi_open else "]")
                raise ValueError(f"MapConfig.{name} must be in {lb}{lo}, {hi}{rb}, got {v!r}")
            return v

        def integer(name: str, lo: int, hi: int) -> int:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int | np.integer) or not lo <= v <= hi:
                raise ValueError(f"MapConfig.{name} must be an integer in [{lo}, {hi}], "
                                 f"got {v!r}")
            return int(v)

        res = num("resolution_m", 0.005, 1.0)
        r = self.local_update_range_m
        if len(r) != 3 or not all(math.isfinite(c) and c > 0 for c in r):
            raise ValueError("MapConfig.local_update_range_m must be 3 positive finite numbers "
                             f"(half extents, m), got {r!r}")
        win = num("window_xy_m", 2 * res, 1e4, lo_open=True)
        rc = num("recentre_distance_m", 0.0, 1e4)
        if win / 2.0 < max(r[0], r[1]) + rc - 1e-9:
            raise ValueError(f"MapConfig.window_xy_m must be >= 2 * (max horizontal "
                             f"local_update_range_m + recentre_distance_m) = "
                             f"{2 * (max(r[0], r[1]) + rc)} so every update stays inside the "
                             f"window, got {win!r}")
        if round(win / res) > _MAX_VOXELS_PER_AXIS:
            raise ValueError(f"MapConfig.window_xy_m / resolution_m must be <= "
                             f"{_MAX_VOXELS_PER_AXIS} voxels, got {round(win / res)}")
        num("z_margin_m", res, 1e3)
        for name in ("p_hit", "p_miss", "p_min", "p_max", "p_occ"):
            num(name, 0.0, 1.0, lo_open=True, hi_open=True)
        if not self.p_hit > 0.5:
            raise ValueError(f"MapConfig.p_hit must be > 0.5 (a hit raises occupancy), "
                             f"got {self.p_hit!r}")
        if not self.p_miss < 0.5:
            raise ValueError(f"MapConfig.p_miss must be < 0.5 (a miss lowers occupancy), "
                             f"got {self.p_miss!r}")
        if not self.p_min < self.p_occ:
            raise ValueError(f"MapConfig.p_min must be < p_occ ({self.p_occ}), "
                             f"got {self.p_min!r}")
        if not self.p_max > self.p_occ:
            raise ValueError(f"MapConfig.p_max must be > p_occ ({self.p_occ}) or nothing can "
                             f"ever be occupied, got {self.p_max!r}")
        num("unknown_offset", 0.0, 10.0, lo_open=True)
        integer("skip_pixel", 1, 64)
        integer("depth_margin_px", 0, 1000)
        lo = num("min_depth_m", 0.0, 1e3)
        num("max_depth_m", lo, 1e3, lo_open=True)
        num("max_ray_length_m", 0.0, 1e3, lo_open=True)
        integer("inflation_voxels", 0, 8)

    # log-odds
    @property
    def l_hit(self) -> float:
        return logit(self.p_hit)

    @property
    def l_miss(self) -> float:
        return logit(self.p_miss)

    @property
    def l_min(self) -> float:
        return logit(self.p_min)

    @property
    def l_max(self) -> float:
        return logit(self.p_max)

    @property
    def l_occ(self) -> float:
        return logit(self.p_occ)

    @property
    def l_unknown(self) -> float:
        return logit(self.p_min) - self.unknown_offset

    @property
    def free_ray_depth_m(self) -> float:
        """z-depth given to free-ray pixels (the originals' ``max_ray_length + 0.1``)."""
        return self.max_ray_length_m + 0.1

    def hits_to_occupy(self) -> int:
        """Consecutive hit frames that turn an unknown voxel occupied (6 with the defaults)."""
        v, k = self.l_unknown, 0
        while not v > self.l_occ:
            v = min(max(v + self.l_hit, self.l_min), self.l_max)
            k += 1
        return k

    def misses_to_free(self) -> int:
        """Consecutive miss frames that turn a saturated voxel free (2 with the defaults)."""
        v, k = self.l_max, 0
        while v > self.l_occ:
            v = min(max(v + self.l_miss, self.l_min), self.l_max)
            k += 1
        return k


class FuseStats(NamedTuple):
    """What one :meth:`LocalMap.fuse` did."""

    rays: int  #: pixels turned into rays (after subsampling, margin and the min-depth cut)
    hit_rays: int  #: rays ending in a hit
    voxels_updated: int  #: voxels given a log-odds update
    shifted: bool  #: whether the window re-centred before this frame


# --- kernels ----------------------------------------------------------------------------------
@njit(cache=True)
def _project(depth, fx, fy, cx, cy, r, cam, skip, margin, min_depth, max_depth, max_ray,
             free_depth, out_pts, out_hit):
    """Depth pixels -> world end points (N, 3) and hit flags; returns N."""
    h, w = depth.shape
    n = 0
    for v in range(margin, h - margin, skip):
        for u in range(margin, w - margin, skip):
            z = np.float64(depth[v, u])
            if not np.isfinite(z):
                z = free_depth
            elif z < min_depth:
                continue
            elif z > max_depth:
                z = free_depth
            px = (u - cx) * z / fx
            py = (v - cy) * z / fy
            pz = z
            dx = r[0, 0] * px + r[0, 1] * py + r[0, 2] * pz
            dy = r[1, 0] * px + r[1, 1] * py + r[1, 2] * pz
            dz = r[2, 0] * px + r[2, 1] * py + r[2, 2] * pz
            length = math.sqrt(dx * dx + dy * dy + dz * dz)
            hit = 1
            if length > max_ray:
                s = max_ray / length
                dx *= s
                dy *= s
                dz *= s
                hit = 0
            out_pts[n, 0] = cam[0] + dx
            out_pts[n, 1] = cam[1] + dy
            out_pts[n, 2] = cam[2] + dz
            out_hit[n] = hit
            n += 1
    return n


@njit(cache=True)
def _clamp_index(g, n):
    i = int(math.floor(g))
    if i < 0:
        return 0
    if i > n - 1:
        return n - 1
    return i


@njit(cache=True)
def _touch(flags, touched, nt, idx, bit):
    f = flags[idx]
    if f == 0:
        touched[nt] = idx
        nt += 1
    flags[idx] = f | bit
    return nt


@njit(cache=True)
def _integrate(pts, hit, n_rays, cam, inv_res, origin, box_lo, box_hi, dims, logodds, flags,
               touched, infl, early_stop, l_hit, l_miss, l_min, l_max, l_occ, infl_r):
    """Ray-cast n_rays end points back to cam and apply one update per touched voxel.

    Positions are world metres; origin (3,) is the window's first global voxel index;
    box_lo/box_hi (3,) the clip box in grid coordinates. Returns (voxels updated,
    change in occupied count, hit rays after clipping, voxels whose occupancy flipped).
    """
    nx, ny, nz = dims[0], dims[1], dims[2]
    c = np.empty(3)
    for a in range(3):
        c[a] = cam[a] * inv_res - origin[a]
    e = np.empty(3)
    d = np.empty(3)
    st = np.empty(3)
    ie = np.empty(3, np.int64)
    js = np.empty(3, np.int64)
    step = np.empty(3, np.int64)
    tmax = np.empty(3)
    tdel = np.empty(3)
    nt = 0
    n_hit = 0
    for k in range(n_rays):
        for a in range(3):
            e[a] = pts[k, a] * inv_res - origin[a]
            d[a] = e[a] - c[a]
        # clip the segment cam -> end to the box (Liang-Barsky)
        t0, t1 = 0.0, 1.0
        empty = False
        for a in range(3):
            if d[a] == 0.0:
                if c[a] < box_lo[a] or c[a] > box_hi[a]:
                    empty = True
            else:
                ta = (box_lo[a] - c[a]) / d[a]
                tb = (box_hi[a] - c[a]) / d[a]
                if ta > tb:
                    ta, tb = tb, ta
                if ta > t0:
                    t0 = ta
                if tb < t1:
                    t1 = tb
        if empty or t0 > t1:
            continue
        is_hit = hit[k] != 0
        if t1 < 1.0:
            is_hit = False
            for a in range(3):
                e[a] = c[a] + t1 * d[a]
        for a in range(3):
            st[a] = c[a] + t0 * d[a]
        ie[0] = _clamp_index(e[0], nx)
        ie[1] = _clamp_index(e[1], ny)
        ie[2] = _clamp_index(e[2], nz)
        js[0] = _clamp_index(st[0], nx)
        js[1] = _clamp_index(st[1], ny)
        js[2] = _clamp_index(st[2], nz)
        idx = (ie[0] * ny + ie[1]) * nz + ie[2]
        if is_hit:
            n_hit += 1
            nt = _touch(flags, touched, nt, idx, _HIT)
        if early_stop and (flags[idx] & _END) != 0:
            continue
        nt = _touch(flags, touched, nt, idx, _END)
        # DDA from the end-point voxel to the camera-side voxel, both included
        n_steps = 0
        for a in range(3):
            diff = js[a] - ie[a]
            n_steps += abs(diff)
            ddir = st[a] - e[a]
            if diff > 0:
                step[a] = 1
                tmax[a] = (ie[a] + 1.0 - e[a]) / ddir if ddir > 0.0 else np.inf
                tdel[a] = 1.0 / ddir if ddir > 0.0 else np.inf
            elif diff < 0:
                step[a] = -1
                tmax[a] = (e[a] - ie[a]) / (-ddir) if ddir < 0.0 else np.inf
                tdel[a] = -1.0 / ddir if ddir < 0.0 else np.inf
            else:
                step[a] = 0
                tmax[a] = np.inf
                tdel[a] = np.inf
        x, y, z = ie[0], ie[1], ie[2]
        if early_stop and (flags[idx] & _TRAV) != 0:
            continue
        nt = _touch(flags, touched, nt, idx, _TRAV)
        # the walk in scalars: the axis with the smallest tmax steps (ties: lowest axis)
        sx, sy, sz = step[0], step[1], step[2]
        tx, ty, tz = tmax[0], tmax[1], tmax[2]
        dx, dy, dz = tdel[0], tdel[1], tdel[2]
        jx, jy, jz = js[0], js[1], js[2]
        for _ in range(n_steps):
            if sx != 0 and (sy == 0 or tx <= ty) and (sz == 0 or tx <= tz):
                x += sx
                tx += dx
                if x == jx:
                    sx = 0
            elif sy != 0 and (sz == 0 or ty <= tz):
                y += sy
                ty += dy
                if y == jy:
                    sy = 0
            else:
                z += sz
                tz += dz
                if z == jz:
                    sz = 0
            idx = (x * ny + y) * nz + z
            f = flags[idx]
            if early_stop and (f & _TRAV) != 0:
                break
            if f == 0:
                touched[nt] = idx
                nt += 1
            flags[idx] = f | _TRAV
    # one log-odds update per touched voxel; hits win
    d_occ = 0
    n_flip = 0
    for k in range(nt):
        idx = touched[k]
        f = flags[idx]
        flags[idx] = 0
        old = logodds[idx]
        new = old + (l_hit if (f & _HIT) != 0 else l_miss)
        if new < l_min:
            new = l_min
        elif new > l_max:
            new = l_max
        new32 = np.float32(new)  # compare what is stored
        logodds[idx] = new32
        was = old > l_occ
        now = new32 > l_occ
        if was != now:
            delta = 1 if now else -1
            d_occ += delta
            n_flip += 1
            _add_inflation(infl, nx, ny, nz, idx, infl_r, delta)
    return nt, d_occ, n_hit, n_flip


@njit(cache=True)
def _add_inflation(infl, nx, ny, nz, idx, radius, delta):
    """Add delta to the dilation count of every voxel within radius (Chebyshev) of idx."""
    z0 = idx % nz
    y0 = (idx // nz) % ny
    x0 = idx // (ny * nz)
    for x in range(max(x0 - radius, 0), min(x0 + radius + 1, nx)):
        for y in range(max(y0 - radius, 0), min(y0 + radius + 1, ny)):
            base = (x * ny + y) * nz
            for z in range(max(z0 - radius, 0), min(z0 + radius + 1, nz)):
                infl[base + z] += delta


@njit(cache=True)
def _drop_in_boxes(pts, hit, n, lo, hi):
    """Compact the first n end points (and their hit flags) in place, leaving out those
    inside any box lo[b] <= p <= hi[b] (world, m); returns how many are left."""
    m = 0
    for k in range(n):
        inside = False
        for b in range(lo.shape[0]):
            if lo[b, 0] <= pts[k, 0] <= hi[b, 0] and lo[b, 1] <= pts[k, 1] <= hi[b, 1] \
                    and lo[b, 2] <= pts[k, 2] <= hi[b, 2]:
                inside = True
                break
        if not inside:
            pts[m, 0], pts[m, 1], pts[m, 2] = pts[k, 0], pts[k, 1], pts[k, 2]
            hit[m] = hit[k]
            m += 1
    return m


@njit(cache=True)
def _set_free(lo, hi, inv_res, origin, logodds, infl, dims, l_min, l_occ, infl_r):
    """Set every voxel of the window from the one holding lo[b] to the one holding hi[b]
    (world, m; both included) to log-odds l_min; returns (change in occupied count,
    voxels that were occupied)."""
    nx, ny, nz = dims[0], dims[1], dims[2]
    lm = np.float32(l_min)
    d_occ = 0
    for b in range(lo.shape[0]):
        i0 = np.empty(3, np.int64)
        i1 = np.empty(3, np.int64)
        for a in range(3):
            i0[a] = max(int(math.floor(lo[b, a] * inv_res)) - origin[a], 0)
            i1[a] = min(int(math.floor(hi[b, a] * inv_res)) - origin[a], dims[a] - 1)
        for x in range(i0[0], i1[0] + 1):
            for y in range(i0[1], i1[1] + 1):
                for z in range(i0[2], i1[2] + 1):
                    idx = (x * ny + y) * nz + z
                    if logodds[idx] > l_occ:
                        d_occ -= 1
                        _add_inflation(infl, nx, ny, nz, idx, infl_r, -1)
                    logodds[idx] = lm
    return d_occ, -d_occ


@njit(cache=True)
def _recount_box(logodds3, l_occ, radius, out3, x0, x1, y0, y1):
    """out3[x0:x1, y0:y1, :] = number of occupied voxels within radius (Chebyshev), as
    three separable window sums (z, then y, then x) over the box grown by radius."""
    nx, ny, nz = logodds3.shape
    x0, x1 = max(x0, 0), min(x1, nx)
    y0, y1 = max(y0, 0), min(y1, ny)
    if x1 <= x0 or y1 <= y0:
        return
    ax0, ax1 = max(x0 - radius, 0), min(x1 + radius, nx)
    ay0, ay1 = max(y0 - radius, 0), min(y1 + radius, ny)
    sx, sy = ax1 - ax0, ay1 - ay0
    a = np.zeros((sx, sy, nz), np.int32)  # occupied voxels within radius along z
    for i in range(sx):
        for j in range(sy):
            for z in range(nz):
                if logodds3[ax0 + i, ay0 + j, z] > l_occ:
                    for q in range(max(z - radius, 0), min(z + radius + 1, nz)):
                        a[i, j, q] += 1
    b = np.zeros((sx, y1 - y0, nz), np.int32)  # ... then along y
    for i in range(sx):
        for y in range(y0, y1):
            for j in range(max(y - radius, ay0), min(y + radius + 1, ay1)):
                for z in range(nz):
                    b[i, y - y0, z] += a[i, j - ay0, z]
    for x in range(x0, x1):  # ... then along x
        for y in range(y1 - y0):
            for z in range(nz):
                c = 0
                for i in range(max(x - radius, ax0), min(x + radius + 1, ax1)):
                    c += b[i - ax0, y, z]
                out3[x, y0 + y, z] = c


@njit(cache=True)
def _planning_grid(infl3, k0, k_floor, k_ceil, out3):
    """1 where planning-occupied: inflated occupancy or the floor/ceiling layers."""
    nx, ny, nz = infl3.shape
    for x in range(nx):
        for y in range(ny):
            for z in range(nz):
                k = k0 + z
                out3[x, y, z] = 1 if (infl3[x, y, z] > 0 or k < k_floor or k >= k_ceil) else 0


@njit(cache=True)
def _query(points, inv_res, origin, logodds3, infl3, kind, l_occ, l_known, k_floor, k_ceil,
           out):
    """Per point: raw occupied / planning occupied / known / in window. Returns the number
    of non-finite points (their result is False)."""
    nx, ny, nz = logodds3.shape
    bad = 0
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        if not (np.isfinite(px) and np.isfinite(py) and np.isfinite(pz)):
            bad += 1
            out[i] = 0
            continue
        gz = int(math.floor(pz * inv_res))
        if kind == 1 and (gz < k_floor or gz >= k_ceil):
            out[i] = 1
            continue
        x = int(math.floor(px * inv_res)) - origin[0]
        y = int(math.floor(py * inv_res)) - origin[1]
        z = gz - origin[2]
        if x < 0 or x >= nx or y < 0 or y >= ny or z < 0 or z >= nz:
            out[i] = 0
        elif kind == 0:
            out[i] = 1 if logodds3[x, y, z] > l_occ else 0
        elif kind == 1:
            out[i] = 1 if infl3[x, y, z] > 0 else 0
        elif kind == 2:
            out[i] = 1 if logodds3[x, y, z] >= l_known else 0
        else:
            out[i] = 1
    return bad


@njit(cache=True)
def _query_lattice(xs, ys, zs, inv_res, origin, infl3, k_floor, k_ceil, out3):
    """Planning occupancy (``_query`` kind 1) at every point ``(xs[a], ys[b], zs[c])`` of
    a lattice, into ``out3[a, b, c]``: the same per-point test, the axes done once."""
    nx, ny, nz = infl3.shape
    ix = np.empty(xs.shape[0], np.int64)
    iy = np.empty(ys.shape[0], np.int64)
    iz = np.empty(zs.shape[0], np.int64)
    for a in range(xs.shape[0]):
        x = int(math.floor(xs[a] * inv_res)) - origin[0]
        ix[a] = x if 0 <= x < nx else -1
    for b in range(ys.shape[0]):
        y = int(math.floor(ys[b] * inv_res)) - origin[1]
        iy[b] = y if 0 <= y < ny else -1
    for c in range(zs.shape[0]):
        gz = int(math.floor(zs[c] * inv_res))
        if gz < k_floor or gz >= k_ceil:
            iz[c] = -2  # floor or ceiling: occupied everywhere
        else:
            z = gz - origin[2]
            iz[c] = z if 0 <= z < nz else -1
    for a in range(xs.shape[0]):
        x = ix[a]
        for b in range(ys.shape[0]):
            y = iy[b]
            for c in range(zs.shape[0]):
                z = iz[c]
                if z == -2:
                    out3[a, b, c] = 1
                elif x < 0 or y < 0 or z < 0:
                    out3[a, b, c] = 0
                else:
                    out3[a, b, c] = 1 if infl3[x, y, z] > 0 else 0


@njit(cache=True)
def _march(position, dirs, dists, max_range, inv_res, origin, infl3, k_floor, k_ceil, out):
    """Per ray: the first of ``dists`` along it whose point is planning-occupied (as
    ``_query`` kind 1), else ``max_range``."""
    nx, ny, nz = infl3.shape
    for r in range(dirs.shape[0]):
        out[r] = max_range
        for i in range(dists.shape[0]):
            px = position[0] + dirs[r, 0] * dists[i]
            py = position[1] + dirs[r, 1] * dists[i]
            pz = position[2] + dirs[r, 2] * dists[i]
            gz = int(math.floor(pz * inv_res))
            if gz < k_floor or gz >= k_ceil:
                out[r] = dists[i]
                break
            x = int(math.floor(px * inv_res)) - origin[0]
            y = int(math.floor(py * inv_res)) - origin[1]
            z = gz - origin[2]
            if 0 <= x < nx and 0 <= y < ny and 0 <= z < nz and infl3[x, y, z] > 0:
                out[r] = dists[i]
                break


@njit(cache=True)
def _query_log_odds(points, inv_res, origin, logodds3, l_unknown, out):
    nx, ny, nz = logodds3.shape
    bad = 0
    for i in range(points.shape[0]):
        px, py, pz = points[i, 0], points[i, 1], points[i, 2]
        if not (np.isfinite(px) and np.isfinite(py) and np.isfinite(pz)):
            bad += 1
            out[i] = np.nan
            continue
        x = int(math.floor(px * inv_res)) - origin[0]
        y = int(math.floor(py * inv_res)) - origin[1]
        z = int(math.floor(pz * inv_res)) - origin[2]
        if x < 0 or x >= nx or y < 0 or y >= ny or z < 0 or z >= nz:
            out[i] = l_unknown
        else:
            out[i] = logodds3[x, y, z]
    return bad


# --- the map ----------------------------------------------------------------------------------
def _as_points(points) -> tuple[np.ndarray, tuple]:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim == 0 or p.shape[-1] != 3:
        raise ValueError(f"points must have shape (..., 3), got {p.shape}")
    return np.ascontiguousarray(p.reshape(-1, 3)), p.shape[:-1]


def _shaped(out: np.ndarray, shape: tuple):
    out = out.reshape(shape)
    return out[()] if shape == () else out


def _frame_arrays(frame: DepthFrame,
                  camera: CameraConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A depth frame's depth image, camera position and rotation, checked against the
    map's ``camera``."""
    if not isinstance(frame, DepthFrame):
        raise TypeError(f"frame must be a DepthFrame, got {type(frame).__name__}")
    depth = np.asarray(frame.depth)
    cam = camera
    if depth.shape != (cam.height, cam.width):
        raise ValueError(f"frame.depth has shape {depth.shape}, the map's camera is "
                         f"{cam.height} x {cam.width} (pass camera= to LocalMap)")
    p = np.asarray(frame.p_world_camera, dtype=np.float64).reshape(-1)
    r = np.ascontiguousarray(frame.r_world_optical, dtype=np.float64)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"frame.p_world_camera must be 3 finite numbers, got {p}")
    if r.shape != (3, 3) or not np.all(np.isfinite(r)):
        raise ValueError("frame.r_world_optical must be a finite 3x3 rotation")
    return depth, p, r


def _as_boxes(boxes) -> tuple[np.ndarray, np.ndarray]:
    """Boxes given as a pair (lower corners, upper corners) of (K, 3) arrays, checked."""
    try:
        lo, hi = (np.ascontiguousarray(np.asarray(b, dtype=np.float64).reshape(-1, 3))
                  for b in boxes)
    except (TypeError, ValueError):
        raise ValueError("boxes must be a pair (lower corners, upper corners) of (K, 3) "
                         "arrays") from None
    if lo.shape != hi.shape or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ValueError("boxes: lower and upper corners must be finite and as many")
    return lo, hi


def _shift_window(logodds, infl, new_l, new_i, dx: int, dy: int, radius: int,
                  l_unknown: float, l_occ: float) -> None:
    """Fill ``new_l`` / ``new_i`` with the log-odds and dilation counts of a window moved
    by (dx, dy) voxels: what stays inside keeps its world position, the rest is unknown,
    and the dilation counts along the cut edges and the new strips (``radius`` voxels wide)
    are recounted."""
    nx, ny, _ = logodds.shape
    r = radius
    new_l.fill(l_unknown)
    new_i.fill(0)
    if abs(dx) < nx and abs(dy) < ny:
        xs, xe = max(0, -dx), nx - max(0, dx)
        ys, ye = max(0, -dy), ny - max(0, dy)
        new_l[xs:xe, ys:ye] = logodds[xs + dx:xe + dx, ys + dy:ye + dy]
        new_i[xs:xe, ys:ye] = infl[xs + dx:xe + dx, ys + dy:ye + dy]
        # dilation counts that lost neighbours (the cut edge) or have none yet (the new
        # strip next to the kept content) are recounted
        if dx != 0:
            for lo, hi in ((0, xs + r), (xe - r, nx)):
                _recount_box(new_l, l_occ, r, new_i, lo, hi, 0, ny)
        if dy != 0:
            for lo, hi in ((0, ys + r), (ye - r, ny)):
                _recount_box(new_l, l_occ, r, new_i, 0, nx, lo, hi)


class LocalMap:
    """The rolling local occupancy map of one vehicle (see the module docstring).

    ``ceiling_m`` / ``floor_m``: the virtual ceiling and floor heights (world z, m), both
    planning-occupied. ``camera``: the intrinsics of the frames :meth:`fuse` will get
    (default: the default :class:`~ft_sitl.scenarios.camera.CameraConfig`, 640 x 480).
    ``center_m``: where the window starts (x, y); the first frame re-centres it anyway when
    it is more than ``recentre_distance_m`` away.
    """

    def __init__(self, config: MapConfig | None, ceiling_m: float, floor_m: float = 0.0, *,
                 camera: CameraConfig | None = None, center_m=(0.0, 0.0)):
        self.config = cfg = MapConfig() if config is None else config
        if not isinstance(cfg, MapConfig):
            raise TypeError(f"config must be a MapConfig, got {type(cfg).__name__}")
        cfg.validate()
        self.camera = CameraConfig() if camera is None else camera
        if not isinstance(self.camera, CameraConfig):
            raise TypeError(f"camera must be a CameraConfig, got {type(self.camera).__name__}")
        for name, v in (("ceiling_m", ceiling_m), ("floor_m", floor_m)):
            if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v):
                raise ValueError(f"LocalMap.{name} must be a finite number (m), got {v!r}")
        self.ceiling_m, self.floor_m = float(ceiling_m), float(floor_m)
        res = cfg.resolution_m
        self.resolution_m = res
        self._inv_res = 1.0 / res
        self.k_floor = math.floor(self.floor_m * self._inv_res + 1e-6)
        self.k_ceil = math.floor(self.ceiling_m * self._inv_res + 1e-6)
        if self.k_ceil - self.k_floor < 2:
            raise ValueError(f"LocalMap.ceiling_m must be at least two voxels above floor_m "
                             f"({self.floor_m}), got {self.ceiling_m!r}")
        m = math.ceil(cfg.z_margin_m * self._inv_res - 1e-6)
        nxy = int(round(cfg.window_xy_m * self._inv_res))
        nz = self.k_ceil - self.k_floor + 1 + 2 * m
        if nxy * nxy * nz > _MAX_VOXELS:
            raise ValueError(f"the window holds {nxy * nxy * nz} voxels (> {_MAX_VOXELS}): "
                             "raise resolution_m or lower window_xy_m / the ceiling")
        self.shape = (nxy, nxy, nz)
        self._origin = np.zeros(3, np.int64)  # global index of local voxel (0, 0, 0)
        self._origin[2] = self.k_floor - m
        c = np.asarray(center_m, dtype=np.float64).reshape(-1)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise ValueError(f"center_m must be 2 finite numbers (x, y), got {center_m!r}")
        self._origin[0] = math.floor(c[0] * self._inv_res) - nxy // 2
        self._origin[1] = math.floor(c[1] * self._inv_res) - nxy // 2

        n = nxy * nxy * nz
        self._logodds = np.full(self.shape, cfg.l_unknown, dtype=np.float32)
        self._infl = np.zeros(self.shape, dtype=np.uint16)
        self._spare_logodds = np.empty_like(self._logodds)
        self._spare_infl = np.empty_like(self._infl)
        self._flags = np.zeros(n, dtype=np.uint8)
        self._touched = np.empty(n, dtype=np.int64)
        self._range = np.array(cfg.local_update_range_m)
        # thresholds as float32 values, the precision the log-odds are stored in
        self._l = {k: float(np.float32(getattr(cfg, k)))
                   for k in ("l_hit", "l_miss", "l_min", "l_max", "l_occ", "l_unknown")}
        self._l_known = float(np.float32(cfg.l_min - 1e-3))

        cam = self.camera
        rows = len(range(cfg.depth_margin_px, cam.height - cfg.depth_margin_px, cfg.skip_pixel))
        cols = len(range(cfg.depth_margin_px, cam.width - cfg.depth_margin_px, cfg.skip_pixel))
        self.max_rays = rows * cols
        self._pts = np.empty((max(self.max_rays, 1), 3))
        self._hit = np.empty(max(self.max_rays, 1), dtype=np.uint8)

        self._occupied_count = 0
        self._revision = 0
        self._frames = 0
        self.last_t_us: int | None = None
        self.last_camera_m: np.ndarray | None = None
        self._esdf = MapEsdf()

    # -- properties ----------------------------------------------------------------------------
    @property
    def occupied_count(self) -> int:
        """Occupied voxels (raw, not inflated) in the window."""
        return self._occupied_count

    @property
    def revision(self) -> int:
        """A counter that changes whenever the planning occupancy
        (:meth:`occupied_inflated`) may have changed anywhere: a voxel became occupied or
        free, the window moved, the map was cleared. Equal revisions of one map mean the
        same planning occupancy (what planners may cache results on)."""
        return self._revision

    @property
    def frames_fused(self) -> int:
        return self._frames

    @property
    def origin_index(self) -> np.ndarray:
        """Global voxel index of the window's first voxel (copy)."""
        return self._origin.copy()

    @property
    def window_min_m(self) -> np.ndarray:
        """Lower corner of the window (m, world)."""
        return self._origin * self.resolution_m

    @property
    def window_max_m(self) -> np.ndarray:
        """Upper corner of the window (m, world)."""
        return (self._origin + np.array(self.shape)) * self.resolution_m

    @property
    def window_center_m(self) -> np.ndarray:
        return (self._origin + np.array(self.shape) / 2.0) * self.resolution_m

    # -- index helpers -------------------------------------------------------------------------
    def voxel_index(self, points) -> np.ndarray:
        """Global voxel indices (..., 3) int64 of points (..., 3)."""
        p = np.asarray(points, dtype=np.float64)
        if p.shape[-1:] != (3,):
            raise ValueError(f"points must have shape (..., 3), got {p.shape}")
        return np.floor(p * self._inv_res).astype(np.int64)

    def voxel_center(self, index) -> np.ndarray:
        """World centres (..., 3) of global voxel indices (..., 3)."""
        i = np.asarray(index)
        if i.shape[-1:] != (3,):
            raise ValueError(f"index must have shape (..., 3), got {i.shape}")
        return (i + 0.5) * self.resolution_m

    def local_index(self, points) -> np.ndarray:
        """Window array indices (..., 3) of points (may be outside ``[0, shape)``)."""
        return self.voxel_index(points) - self._origin

    # -- fusion --------------------------------------------------------------------------------
    def _recentre(self, cam: np.ndarray) -> bool:
        nxy = self.shape[0]
        want = np.floor(cam[:2] * self._inv_res).astype(np.int64) - nxy // 2
        centre = self.window_center_m[:2]
        if self._frames > 0 and np.max(np.abs(cam[:2] - centre)) <= \
                self.config.recentre_distance_m:
            return False
        if np.array_equal(want, self._origin[:2]):
            return False
        self.shift_to(want)
        return True

    def shift_to(self, origin_xy) -> None:
        """Move the window so its first voxel is global index ``(origin_xy, z0)``; content
        keeps its world position, what leaves the window is forgotten."""
        ox, oy = (int(v) for v in origin_xy)
        dx, dy = ox - int(self._origin[0]), oy - int(self._origin[1])
        if dx == 0 and dy == 0:
            return
        new_l, new_i = self._spare_logodds, self._spare_infl
        _shift_window(self._logodds, self._infl, new_l, new_i, dx, dy,
                      self.config.inflation_voxels, self._l["l_unknown"], self._l["l_occ"])
        self._spare_logodds, self._logodds = self._logodds, new_l
        self._spare_infl, self._infl = self._infl, new_i
        self._origin[0], self._origin[1] = ox, oy
        self._revision += 1
        self._occupied_count = int(np.count_nonzero(self._logodds > self._l["l_occ"]))

    def project(self, frame: DepthFrame) -> tuple[np.ndarray, np.ndarray]:
        """The rays :meth:`fuse` casts for ``frame``: world end points (N, 3) and whether
        each is a hit (N,) bool (before clipping to the update box)."""
        n = self._project(frame)
        return self._pts[:n].copy(), self._hit[:n].astype(bool)

    def _project(self, frame: DepthFrame) -> int:
        depth, p, r = _frame_arrays(frame, self.camera)
        cfg, cam = self.config, self.camera
        return _project(depth, float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy), r,
                        p, cfg.skip_pixel, cfg.depth_margin_px, cfg.min_depth_m,
                        cfg.max_depth_m, cfg.max_ray_length_m, cfg.free_ray_depth_m,
                        self._pts, self._hit)

    def fuse(self, frame: DepthFrame, *, early_stop: bool = True,
             exclude_boxes=None) -> FuseStats:
        """Integrate one depth frame (re-centring the window first if the camera moved
        more than ``recentre_distance_m`` from the window centre, per axis).
        ``early_stop=False`` traces every ray in full: the same hits, more free voxels
        observed, ~40x slower (see the module docstring). ``exclude_boxes`` (a pair of
        (K, 3) arrays of lower and upper corners, world m): end points inside any of these
        boxes are left out, neither hits nor rays (NavRL's map does this in the boxes of
        the moving obstacles its detector tracks)."""
        depth, p, r = _frame_arrays(frame, self.camera)
        boxes = None if exclude_boxes is None else _as_boxes(exclude_boxes)
        shifted = self._recentre(p)
        n = self._project(frame)
        if boxes is not None and len(boxes[0]):
            n = _drop_in_boxes(self._pts, self._hit, n, boxes[0], boxes[1])
        dims = np.array(self.shape, np.int64)
        lo = np.maximum((p - self._range) * self._inv_res - self._origin, 0.0)
        hi = np.minimum((p + self._range) * self._inv_res - self._origin,
                        dims.astype(np.float64))
        L = self._l
        nt, d_occ, n_hit, n_flip = _integrate(
            self._pts, self._hit, n, p, self._inv_res, self._origin, lo, hi, dims,
            self._logodds.reshape(-1), self._flags, self._touched, self._infl.reshape(-1),
            bool(early_stop), L["l_hit"], L["l_miss"], L["l_min"], L["l_max"], L["l_occ"],
            self.config.inflation_voxels)
        self._occupied_count += int(d_occ)
        if n_flip:
            self._revision += 1
        self._frames += 1
        self.last_t_us = int(frame.t_us)
        self.last_camera_m = p.copy()
        return FuseStats(rays=int(n), hit_rays=int(n_hit), voxels_updated=int(nt),
                         shifted=shifted)

    def set_free(self, boxes) -> int:
        """Make every voxel of the window from the one holding a box's lower corner to the
        one holding its upper corner known free (log-odds at the lower clamp), for each of
        ``boxes`` (a pair of (K, 3) arrays of lower and upper corners, world m), as the
        original NavRL map's ``freeRegions`` does for the moving obstacles its detector
        reports. Returns how many occupied voxels it freed."""
        lo, hi = _as_boxes(boxes)
        if not len(lo):
            return 0
        d_occ, freed = _set_free(lo, hi, self._inv_res, self._origin, self._logodds.reshape(-1),
                                 self._infl.reshape(-1), np.array(self.shape, np.int64),
                                 self._l["l_min"], self._l["l_occ"],
                                 self.config.inflation_voxels)
        self._occupied_count += int(d_occ)
        if freed:
            self._revision += 1
        return int(freed)

    def clear(self) -> None:
        """Forget everything (all voxels unknown); the window stays where it is."""
        self._logodds.fill(self._l["l_unknown"])
        self._infl.fill(0)
        self._occupied_count = 0
        self._revision += 1
        self._esdf.forget()

    # -- queries -------------------------------------------------------------------------------
    def _ask(self, points, kind: int):
        p, shape = _as_points(points)
        out = np.empty(len(p), dtype=np.uint8)
        L = self._l
        bad = _query(p, self._inv_res, self._origin, self._logodds, self._infl, kind,
                     L["l_occ"], self._l_known, self.k_floor, self.k_ceil, out)
        if bad:
            raise ValueError(f"points must be finite ({bad} are not)")
        return _shaped(out.view(np.bool_), shape)

    def occupied(self, points):
        """Raw occupancy (log-odds above p_occ) of points (..., 3); False outside the
        window."""
        return self._ask(points, _Q_OCC)

    def occupied_inflated(self, points):
        """Planning occupancy of points (..., 3): inflated occupancy, the ceiling (z at or
        above the ceiling voxel) and the floor (z below floor_m); unknown is free, and so is
        everything outside the window between floor and ceiling."""
        return self._ask(points, _Q_PLAN)

    def occupied_inflated_lattice(self, xs, ys, zs) -> np.ndarray:
        """:meth:`occupied_inflated` at every point ``(xs[a], ys[b], zs[c])`` of the lattice
        of the coordinate vectors ``xs``, ``ys``, ``zs`` (finite, m): bool array
        ``(len(xs), len(ys), len(zs))``, the same answer point by point, without building
        the points (A* reads boxes of voxel centres this way)."""
        axes = [np.ascontiguousarray(np.asarray(v, dtype=np.float64).reshape(-1))
                for v in (xs, ys, zs)]
        if not all(np.all(np.isfinite(a)) for a in axes):
            raise ValueError("lattice coordinates must be finite")
        out = np.empty(tuple(len(a) for a in axes), dtype=np.uint8)
        _query_lattice(axes[0], axes[1], axes[2], self._inv_res, self._origin, self._infl,
                       self.k_floor, self.k_ceil, out)
        return out.view(np.bool_)

    def first_occupied(self, position, directions, step_m: float, max_range_m: float):
        """Per ray from ``position`` (3,) along unit ``directions`` (..., 3): the first
        distance ``step_m, 2 step_m, ... <= max_range_m`` whose point is planning-occupied
        (:meth:`occupied_inflated`), else ``max_range_m``. Shape ``directions.shape[:-1]``."""
        pos = np.asarray(position, dtype=np.float64).reshape(3)
        dirs, shape = _as_points(directions)
        if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(dirs))):
            raise ValueError("position and directions must be finite")
        if not (math.isfinite(step_m) and math.isfinite(max_range_m) and 0 < step_m
                <= max_range_m):
            raise ValueError(f"need 0 < step_m <= max_range_m, got {step_m}, {max_range_m}")
        dists = np.arange(step_m, max_range_m + 1e-9, step_m)
        out = np.empty(len(dirs))
        _march(pos, dirs, dists, float(max_range_m), self._inv_res, self._origin, self._infl,
               self.k_floor, self.k_ceil, out)
        return _shaped(out, shape)

    def is_known(self, points):
        """Whether points (..., 3) lie in voxels that have been observed (and not
        forgotten); False outside the window."""
        return self._ask(points, _Q_KNOWN)

    def in_window(self, points):
        """Whether points (..., 3) lie inside the window's voxels."""
        return self._ask(points, _Q_WINDOW)

    def log_odds(self, points):
        """Stored log-odds at points (..., 3) (float32 precision); the unknown value
        outside the window."""
        p, shape = _as_points(points)
        out = np.empty(len(p))
        bad = _query_log_odds(p, self._inv_res, self._origin, self._logodds,
                              self._l["l_unknown"], out)
        if bad:
            raise ValueError(f"points must be finite ({bad} are not)")
        return _shaped(out, shape)

    def occupied_centers(self, inflated: bool = False) -> np.ndarray:
        """World centres (M, 3) of the occupied voxels in the window (``inflated``: of the
        dilated occupancy, without the virtual floor and ceiling), for plots and debugging."""
        mask = self._infl > 0 if inflated else self._logodds > self._l["l_occ"]
        idx = np.argwhere(mask)
        return (idx + self._origin + 0.5) * self.resolution_m

    def planning_grid(self) -> np.ndarray:
        """(nx, ny, nz) uint8: 1 where planning-occupied (inflation, floor, ceiling); local
        array indices (add ``origin_index`` for global ones)."""
        out = np.empty(self.shape, dtype=np.uint8)
        _planning_grid(self._infl, int(self._origin[2]), self.k_floor, self.k_ceil, out)
        return out

    # -- ESDF (maps.map_esdf) -----------------------------------------------------------------
    def update_esdf(self, center_m=None, half_extent_m: float | None = None,
                    half_extent_z_m: float | None = None) -> np.ndarray:
        """Recompute the signed ESDF from the planning occupancy; returns the field
        (float64, metres, at voxel centres; global index of its first voxel in
        ``esdf_origin_index``).

        By default over the whole window: exact. With ``half_extent_m`` only over the
        horizontal box of ``2 round(half_extent_m / res) + 1`` voxels per side centred on the
        voxel of ``center_m (x, y)`` (clipped to the window; default centre: the last camera
        position), full height: faster, and exact only with respect
        to what lies inside the box (as Fast-Planner's local ESDF box); queries outside it
        are clamped onto it. ``half_extent_z_m`` limits the height the same way around the
        centre's z (``center_m`` given as (x, y, z), else the last camera position): the
        originals' local update box is +-4.5 m high; a 10 m ceiling otherwise doubles the
        cost.

        Asked again for the same box with the planning occupancy unchanged (the same
        ``revision``), it returns the field it computed then, the same array: callers must
        not modify it.
        """
        return self._esdf.update(self, center_m, half_extent_m, half_extent_z_m)

    def esdf_box_overlaps(self, center_m, half_extent_m: float) -> bool:
        """Whether :meth:`update_esdf` can take the box ``center_m (x, y) +-
        half_extent_m``: it overlaps the window by at least 2 voxels each way."""
        x0, x1, y0, y1 = box_xy(self.shape, self._origin, self._inv_res, center_m,
                                float(half_extent_m))
        return x1 - x0 >= 2 and y1 - y0 >= 2

    @property
    def esdf_origin_index(self) -> np.ndarray | None:
        """Global voxel index of the ESDF field's first voxel (None before the first
        :meth:`update_esdf`)."""
        return None if self._esdf.origin is None else self._esdf.origin.copy()

    @property
    def esdf_frame(self) -> int:
        """``frames_fused`` when the ESDF was last computed (-1: never)."""
        return self._esdf.frame

    def esdf(self, points) -> tuple:
        """(distance, gradient) at points (..., 3): trilinear interpolation of the last
        :meth:`update_esdf` field between voxel centres and its analytic gradient
        (shapes (...) and (..., 3)). Raises RuntimeError before the first update."""
        if self._esdf.field is None:
            raise RuntimeError("call update_esdf() before querying the ESDF")
        p, shape = _as_points(points)
        dist = np.empty(len(p))
        grad = np.empty((len(p), 3))
        bad = esdf_eval(self._esdf.field, self._esdf.origin, self._inv_res, p, dist, grad)
        if bad:
            raise ValueError(f"points must be finite ({bad} are not)")
        return _shaped(dist, shape), grad.reshape(shape + (3,))


def local_map_for(task: Task, camera):
    """The planners' local map for a task: the scenario ceiling and floor, frames of
    ``camera`` taken at full resolution (the benchmark camera is already subsampled)."""

    return LocalMap(MapConfig(skip_pixel=1, inflation_voxels=inflation_voxels(task)),
                    task.ceiling, float(task.bounds_min[2]), camera=camera,
                    center_m=tuple(task.start[:2]))


def inflation_voxels(task: Task, resolution_m: float = MapConfig.resolution_m) -> int:
    """The map's dilation radius (voxels) for a task: the footprint rounded up to whole
    voxels, as the originals turn ``obstacles_inflation`` into their ``inflate_step``
    (protocol 4 on); one voxel (the originals' default 0.099 m) without a footprint."""
    if task.footprint_m is None:
        return MapConfig.inflation_voxels
    return max(1, math.ceil(task.footprint_m / resolution_m - 1e-9))
