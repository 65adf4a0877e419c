"""The local perception map against real depth frames (ray-cast camera, trimesh scenes).

Log-odds timing of a wall, free space, the range rules, the traversal early stop against a
slow reference, inflation, the virtual floor and ceiling, window shifts, the ESDF against
brute force, and configuration errors.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import trimesh
from scipy import ndimage

from ft_sitl.navigation.maps.mapping import FuseStats, LocalMap, MapConfig
from ft_sitl.scenarios.camera import CameraConfig, DepthCamera
from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.movers import movers_from_list

RES = 0.1
CEILING = 3.0
IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])
P0 = np.array([0.05, 0.05, 1.55])  # a voxel centre; the camera looks along +x from here
SMALL = CameraConfig().subsampled(2)  # 320 x 240, same field of view (fast captures)
DT_US = 50_000  # 20 Hz map updates


def q_yaw(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def box(lo, hi) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    b = trimesh.creation.box(extents=hi - lo)
    b.apply_translation((lo + hi) / 2)
    return b


def wall(x_face: float, half: float = 4.0) -> trimesh.Trimesh:
    """A wall facing the camera: its near face is the plane x = x_face."""
    return box([x_face, P0[1] - half, P0[2] - half], [x_face + 0.2, P0[1] + half, P0[2] + half])


def nothing() -> trimesh.Trimesh:
    """A scene the camera never sees (a small box far behind it)."""
    return box([-60.0, -0.1, 1.0], [-59.9, 0.1, 1.1])


def fuse_frames(m: LocalMap, cam: DepthCamera, n: int, p=P0, q=IDENTITY, t0: int = 0,
                early_stop: bool = True) -> list[FuseStats]:
    return [m.fuse(cam.capture(t0 + k * DT_US, p, q), early_stop=early_stop) for k in range(n)]


def grid(xs, ys, zs) -> np.ndarray:
    return np.stack(np.meshgrid(xs, ys, zs, indexing="ij"), axis=-1).reshape(-1, 3)


def centres(lo_idx: int, hi_idx: int) -> np.ndarray:
    """Voxel centres of global indices lo_idx..hi_idx-1 on one axis."""
    return (np.arange(lo_idx, hi_idx) + 0.5) * RES


def in_frustum(points: np.ndarray, cam_p=P0, shrink: float = 0.85, pad: float = 0.15):
    """Points comfortably inside the default camera's field of view looking along +x."""
    rel = points - cam_p
    th = math.tan(math.radians(79.2 / 2)) * shrink
    tv = math.tan(math.radians(63.6 / 2)) * shrink
    return ((rel[:, 0] > 0.3) & (np.abs(rel[:, 1]) < rel[:, 0] * th - pad)
            & (np.abs(rel[:, 2]) < rel[:, 0] * tv - pad))


# --- occupancy latency and decay ----------------------------------------------------------------
def test_defaults_follow_the_originals():
    cfg = MapConfig()
    assert cfg.resolution_m == 0.1 and cfg.skip_pixel == 2 and cfg.inflation_voxels == 1
    assert (cfg.p_hit, cfg.p_miss, cfg.p_min, cfg.p_max, cfg.p_occ) == (0.65, 0.35, 0.12,
                                                                          0.90, 0.80)
    assert cfg.local_update_range_m == (5.5, 5.5, 4.5)
    assert cfg.l_unknown == pytest.approx(math.log(0.12 / 0.88) - 0.01)
    assert cfg.hits_to_occupy() == 6  # 0.3 s at 20 Hz
    assert cfg.misses_to_free() == 2
    assert cfg.free_ray_depth_m == pytest.approx(4.6)


def test_wall_becomes_occupied_after_the_hits_the_log_odds_imply_and_not_before():
    cfg = MapConfig()
    n = cfg.hits_to_occupy()
    cam = DepthCamera(SMALL, wall(3.05))  # the face lies mid-voxel (voxel x = 30)
    m = LocalMap(cfg, CEILING, camera=SMALL)
    face = grid([3.05], centres(-5, 6), centres(10, 21))  # 11 x 11 voxels straight ahead
    expect = cfg.l_unknown
    for k in range(1, n + 2):
        fuse_frames(m, cam, 1, t0=k * DT_US)
        expect = min(max(expect + cfg.l_hit, cfg.l_min), cfg.l_max)
        np.testing.assert_allclose(m.log_odds(face), expect, rtol=0, atol=1e-6)
        if k < n:
            assert not m.occupied(face).any() and m.occupied_count == 0, k
        else:
            assert m.occupied(face).all(), k
    assert m.frames_fused == n + 1
    assert n * DT_US * 1e-6 == pytest.approx(0.3)
    # only the wall's face layer is occupied, and it fills the view
    occ = m.occupied_centers()
    np.testing.assert_allclose(occ[:, 0], 3.05, atol=1e-9)
    assert len(occ) > 1000
    # nothing behind the face was observed
    behind = grid([3.15, 3.55, 4.05], centres(-5, 6), centres(10, 21))
    assert not m.is_known(behind).any()


def test_free_space_in_front_of_the_wall_becomes_known_free():
    cam = DepthCamera(SMALL, wall(3.05))
    frame = cam.capture(0, P0, IDENTITY)
    front = grid(centres(2, 30), centres(-30, 31), centres(-15, 46))
    front = front[in_frustum(front)]
    axis = grid(centres(1, 30), [0.05], [1.55])
    full = LocalMap(None, CEILING, camera=SMALL)
    full.fuse(frame, early_stop=False)
    fast = LocalMap(None, CEILING, camera=SMALL)
    fast.fuse(frame)
    l_min = float(np.float32(MapConfig().l_min))
    # full ray casting: every voxel in the field of view in front of the wall is known free
    assert full.is_known(front).all() and not full.occupied(front).any()
    np.testing.assert_allclose(full.log_odds(front), l_min, atol=1e-6)
    # the originals' early stop marks a subset of them (the same free value), never more;
    # the optical axis is covered
    known = fast.is_known(front)
    assert known.any() and not fast.occupied(front).any()
    np.testing.assert_allclose(fast.log_odds(front[known]), l_min, atol=1e-6)
    assert fast.is_known(axis).all()
    assert not (fast.is_known(front) & ~full.is_known(front)).any()


def test_a_removed_wall_decays_back_to_free():
    cfg = MapConfig()
    k_free = cfg.misses_to_free()
    walled, empty = DepthCamera(SMALL, wall(3.05)), DepthCamera(SMALL, nothing())
    face = grid([3.05], centres(-5, 6), centres(10, 21))
    # full ray casting: every face voxel follows the miss schedule exactly
    m = LocalMap(cfg, CEILING, camera=SMALL)
    fuse_frames(m, walled, 10, early_stop=False)  # saturated at p_max
    np.testing.assert_allclose(m.log_odds(face), cfg.l_max, atol=1e-6)
    for k in range(1, k_free + 1):
        fuse_frames(m, empty, 1, t0=(10 + k) * DT_US, early_stop=False)
        assert m.occupied(face).all() == (k < k_free) and m.occupied(face).any() == (k < k_free)
    assert m.occupied_count == 0
    assert m.is_known(face).all()
    # with the early stop a static camera only clears the face voxels its truncated traces
    # reach (those get exactly the same schedule); the others keep their value
    m = LocalMap(cfg, CEILING, camera=SMALL)
    fuse_frames(m, walled, 10)
    before = m.occupied_count
    fuse_frames(m, empty, k_free, t0=20 * DT_US)
    lo = m.log_odds(face)
    cleared = np.isclose(lo, cfg.l_max + k_free * cfg.l_miss, atol=1e-5)
    untouched = np.isclose(lo, cfg.l_max, atol=1e-6)
    assert np.all(cleared | untouched) and cleared.any()
    assert 0 < m.occupied_count < before


def _person_leaving(early_stop: bool):
    """A person (rendered by the camera) stands 3 m in front of a hovering camera long
    enough to saturate its voxels (12 frames), then walks out of the view at 1.5 m/s; the
    scene is otherwise empty. Returns the map, the voxels the standing person occupied
    (centres) and their log-odds at every frame after it started walking."""
    cam_cfg = CameraConfig().subsampled(4)  # the benchmark camera, 160 x 120
    cam = DepthCamera(cam_cfg, nothing())
    size = {"shape": "person", "radius_m": 0.3, "height_m": 1.8}
    standing = movers_from_list([{**size, "points": [[3.0, 0.0]], "speed_m_s": 0.0}])
    walking = movers_from_list([{**size, "points": [[3.0, 0.0], [3.0, 6.0]],
                                 "speed_m_s": 1.5}])
    m = LocalMap(MapConfig(skip_pixel=1), CEILING, camera=cam_cfg)
    period = round(cam_cfg.period_us)
    for k in range(12):
        m.fuse(cam.capture(k * period, P0, IDENTITY, movers=standing, movers_time_us=0),
               early_stop=early_stop)
    occupied = m.occupied_centers()
    trace = []
    for k in range(12, 12 + 60):  # 2 s: it is out of the view after ~1.6 s
        frame = cam.capture(k * period, P0, IDENTITY, movers=walking,
                            movers_time_us=(k - 12) * period)
        m.fuse(frame, early_stop=early_stop)
        trace.append(m.log_odds(occupied))
    assert not np.isfinite(frame.depth).any()  # gone (the empty scene is never seen)
    return m, occupied, np.array(trace)


@pytest.mark.slow
def test_a_person_walking_out_of_the_view_is_cleared_by_the_misses_the_map_predicts():
    """With every ray traced in full, each voxel the standing person saturated is free
    misses_to_free() frames (2) after its first miss, and all get their misses once it has
    gone; the originals' early stop leaves part of them occupied for a hovering camera (no
    trace reaches them again): the ghosts NavRL's free regions remove (docs/planners.md,
    "Moving obstacles")."""
    cfg = MapConfig()
    n = cfg.misses_to_free()
    l_max, l_occ = float(np.float32(cfg.l_max)), float(np.float32(cfg.l_occ))
    m, occupied, trace = _person_leaving(early_stop=False)
    assert len(occupied) > 40 and np.allclose(trace[0][trace[0] > l_occ], l_max)
    first_miss = np.argmax(trace < l_max - 1e-5, axis=0)
    assert np.all(trace[-1] < l_occ) and np.all(first_miss > 0)  # all left behind, freed
    k = np.arange(len(occupied))
    assert np.all(trace[first_miss + n - 1, k] < l_occ)  # free after n misses ...
    assert np.all(trace[first_miss + n - 2, k] > l_occ)  # ... and not before
    assert m.occupied_count == 0
    ghosts, occupied, trace = _person_leaving(early_stop=True)
    stuck = trace[-1] > l_occ
    assert 0.2 * len(occupied) < stuck.sum() < len(occupied)
    assert ghosts.occupied_count > stuck.sum()  # and more of the trail it walked
    walked = (np.array([2.6, -0.4, 0.0]), np.array([3.4, 6.4, 1.9]))  # its path's box
    before = ghosts.occupied_count
    assert ghosts.set_free(walked) == before and ghosts.occupied_count == 0
    assert ghosts.is_known(occupied).all() and ghosts.set_free(walked) == 0
    assert len(ghosts.occupied_centers(inflated=True)) == 0  # the inflation went with them


def test_points_in_excluded_boxes_are_neither_hits_nor_rays():
    """``fuse(exclude_boxes=...)`` leaves out the end points inside the boxes (NavRL's map
    in the boxes of the moving obstacles it tracks): a wall behind such a box keeps its
    voxels outside the box only, and the rays to the left-out points carve nothing."""
    cam = DepthCamera(SMALL, wall(3.05))
    frame = cam.capture(0, P0, IDENTITY)
    box = (np.array([2.9, -0.5, 1.0]), np.array([3.5, 0.5, 2.0]))
    inside = grid([3.05], centres(-3, 4), centres(12, 19))  # one voxel in from its sides
    outside = grid([3.05], centres(8, 14), centres(11, 20))
    m = LocalMap(None, CEILING, camera=SMALL)
    for k in range(8):
        m.fuse(cam.capture(k * DT_US, P0, IDENTITY), exclude_boxes=box, early_stop=False)
    assert m.occupied(outside).all() and not m.is_known(inside).any()
    axis = grid(centres(5, 28), [0.05], [1.55])  # the ray to the box's centre
    assert not m.is_known(axis).any()
    with pytest.raises(ValueError, match="boxes"):
        m.fuse(frame, exclude_boxes=(np.zeros(3), np.zeros((2, 3))))
    assert m.set_free((np.zeros((0, 3)), np.zeros((0, 3)))) == 0


# --- range rules ------------------------------------------------------------------------------
def test_pixels_without_a_return_become_free_rays_of_max_ray_length():
    cfg = MapConfig()
    m = LocalMap(cfg, CEILING, camera=SMALL)
    frame = DepthCamera(SMALL, nothing()).capture(0, P0, IDENTITY)
    assert np.isnan(frame.depth).all()
    pts, hit = m.project(frame)
    rows = len(range(2, SMALL.height - 2, 2))
    cols = len(range(2, SMALL.width - 2, 2))
    assert len(pts) == rows * cols == 118 * 158 and not hit.any()
    np.testing.assert_allclose(np.linalg.norm(pts - P0, axis=1), cfg.max_ray_length_m,
                               atol=1e-9)
    m.fuse(frame, early_stop=False)
    assert m.occupied_count == 0
    # free up to the 4.5 m end point's voxel (x in [4.5, 4.6)), unknown beyond
    assert m.is_known([4.55, 0.05, 1.55]) and not m.occupied([4.55, 0.05, 1.55])
    assert not m.is_known([4.65, 0.05, 1.55])
    ahead = grid(centres(0, 50), centres(-40, 41), centres(-15, 46))
    dist = np.linalg.norm(ahead - P0, axis=1)
    known = m.is_known(ahead)
    assert dist[known].max() <= cfg.max_ray_length_m + math.sqrt(3) * RES / 2 + 1e-9
    inside = in_frustum(ahead) & (dist < cfg.max_ray_length_m - 0.1)
    inside &= (ahead[:, 2] > 0.0) & (ahead[:, 2] < CEILING + 0.5)  # within the window
    assert known[inside].all()
    # the full-resolution default camera gives the originals' 318 x 238 rays
    assert LocalMap(cfg, CEILING).max_rays == 318 * 238


@pytest.mark.parametrize("x_face", [4.75, 5.55])
def test_surfaces_beyond_the_ray_length_are_not_marked(x_face):
    # 4.75 m: measured (<= 5 m) but farther than 4.5 m -> cut to a miss; 5.55 m: beyond the
    # 5 m depth cut -> a free ray. Either way free space up to 4.5 m and no obstacle.
    m = LocalMap(None, CEILING, camera=SMALL)
    fuse_frames(m, DepthCamera(SMALL, wall(x_face)), 8)
    pts, hit = m.project(DepthCamera(SMALL, wall(x_face)).capture(0, P0, IDENTITY))
    assert not hit.any()
    assert m.occupied_count == 0
    assert m.is_known([4.55, 0.05, 1.55]) and not m.is_known([x_face + 0.05, 0.05, 1.55])


def test_depth_closer_than_min_depth_is_skipped_but_nan_is_a_free_ray():
    near = wall(0.15)
    # a camera that reports 0.15 m: the map skips those pixels (no rays at all)
    close_cam = CameraConfig(min_range_m=0.05).subsampled(2)
    m = LocalMap(None, CEILING, camera=close_cam)
    pts, _ = m.project(DepthCamera(close_cam, near).capture(0, P0, IDENTITY))
    assert len(pts) == 0
    # the default camera reports nothing (NaN) below 0.2 m: free rays, as a RealSense's 0
    # is in the originals
    m = LocalMap(None, CEILING, camera=SMALL)
    pts, hit = m.project(DepthCamera(SMALL, near).capture(0, P0, IDENTITY))
    assert len(pts) == 118 * 158 and not hit.any()


def test_projection_matches_the_cameras_point_cloud():
    sc = build_scenario("forest", 5)
    cam = DepthCamera(SMALL, sc.mesh)
    frame = cam.capture(0, sc.start, q_yaw(sc.start_yaw))
    m = LocalMap(None, sc.ceiling, camera=SMALL)
    pts, hit = m.project(frame)
    r, c = frame.pixels.T
    sel = (r >= 2) & (r < SMALL.height - 2) & (c >= 2) & (c < SMALL.width - 2) & \
        (r % 2 == 0) & (c % 2 == 0)
    near = np.linalg.norm(frame.points_world - frame.p_world_camera, axis=1) <= 4.5
    near &= frame.depth[r, c] <= 5.0
    expect = frame.points_world[sel & near]
    assert hit.sum() == len(expect) > 100
    # the map reads the float32 depth image, the camera used float64 depths
    np.testing.assert_allclose(pts[hit], expect, atol=1e-6)


# --- the early stop against a slow reference ------------------------------------------------------
def reference_cast(m: LocalMap, pts: np.ndarray, hit: np.ndarray, cam: np.ndarray,
                   early_stop: bool) -> tuple[set, set]:
    """Slow reference: clip each ray to the update box, trace its end voxel back to the
    camera voxel (Amanatides-Woo, ties to the lowest axis), optionally with the originals'
    early stops. Returns (hit voxels, traversed voxels), local indices."""
    inv = 1.0 / m.resolution_m
    origin = m.origin_index
    dims = np.array(m.shape)
    rng = np.array(m.config.local_update_range_m)
    lo = np.maximum((cam - rng) * inv - origin, 0.0)
    hi = np.minimum((cam + rng) * inv - origin, dims.astype(float))
    c = [cam[a] * inv - origin[a] for a in range(3)]
    hits, trav, ends = set(), set(), set()

    def vox(g, n):
        return min(max(math.floor(g), 0), n - 1)

    for k in range(len(pts)):
        e = [pts[k, a] * inv - origin[a] for a in range(3)]
        d = [e[a] - c[a] for a in range(3)]
        t0, t1, empty = 0.0, 1.0, False
        for a in range(3):
            if d[a] == 0.0:
                empty |= c[a] < lo[a] or c[a] > hi[a]
            else:
                ta, tb = (lo[a] - c[a]) / d[a], (hi[a] - c[a]) / d[a]
                ta, tb = min(ta, tb), max(ta, tb)
                t0, t1 = max(t0, ta), min(t1, tb)
        if empty or t0 > t1:
            continue
        is_hit = bool(hit[k]) and t1 >= 1.0
        if t1 < 1.0:
            e = [c[a] + t1 * d[a] for a in range(3)]
        s = [c[a] + t0 * d[a] for a in range(3)]
        i = [vox(e[a], dims[a]) for a in range(3)]
        j = [vox(s[a], dims[a]) for a in range(3)]
        if is_hit:
            hits.add(tuple(i))
        if early_stop and tuple(i) in ends:
            continue
        ends.add(tuple(i))
        step, tmax, tdel = [0] * 3, [math.inf] * 3, [math.inf] * 3
        for a in range(3):
            dd = s[a] - e[a]
            if j[a] > i[a]:
                step[a] = 1
                if dd > 0.0:
                    tmax[a], tdel[a] = (i[a] + 1.0 - e[a]) / dd, 1.0 / dd
            elif j[a] < i[a]:
                step[a] = -1
                if dd < 0.0:
                    tmax[a], tdel[a] = (e[a] - i[a]) / (-dd), -1.0 / dd
        path = [tuple(i)]
        while tuple(i) != tuple(j):
            cand = [a for a in range(3) if step[a] != 0]
            a = min(cand, key=lambda b: (tmax[b], b))
            i[a] += step[a]
            tmax[a] += tdel[a]
            if i[a] == j[a]:
                step[a] = 0
            path.append(tuple(i))
        for v in path:
            if early_stop and v in trav:
                break
            trav.add(v)
    return hits, trav


def map_sets(m: LocalMap) -> tuple[set, set]:
    cfg = m.config
    lo = m._logodds  # one fused frame from unknown: hit, miss or unknown
    hit = lo > np.float32(cfg.l_min) + 1e-4
    miss = np.isclose(lo, np.float32(cfg.l_min), atol=1e-6)
    return set(map(tuple, np.argwhere(hit))), set(map(tuple, np.argwhere(miss)))


def test_early_stop_equals_the_reference_and_only_drops_free_voxels():
    sc = build_scenario("forest", 5)
    cfg_cam = CameraConfig().subsampled(4)  # 160 x 120: a pure-Python reference stays fast
    cam = DepthCamera(cfg_cam, sc.mesh)
    frame = cam.capture(0, sc.start + [0.3, 1.0, 0.1], q_yaw(sc.start_yaw + 0.3))
    result = {}
    for early in (True, False):
        m = LocalMap(None, sc.ceiling, camera=cfg_cam)
        m.fuse(frame, early_stop=early)
        pts, hit = m.project(frame)
        ref_hits, ref_trav = reference_cast(m, pts, hit, frame.p_world_camera, early)
        hits, misses = map_sets(m)
        assert hits == ref_hits  # hits win over traversals
        assert misses == ref_trav - ref_hits
        result[early] = (hits, misses)
    (h_fast, m_fast), (h_full, m_full) = result[True], result[False]
    assert h_fast == h_full and len(h_fast) > 50  # the same obstacles
    assert m_fast <= m_full  # the early stop only leaves some free voxels unobserved
    assert len(m_fast) > 0.3 * len(m_full)


# --- inflation, floor and ceiling -------------------------------------------------------------
def test_inflation_grows_an_occupied_voxel_to_its_26_neighbours():
    c = np.array([2.05, 0.05, 1.55])  # a voxel centre
    cam = DepthCamera(SMALL, box(c - 0.02, c + 0.02))
    m = LocalMap(None, CEILING, camera=SMALL)
    fuse_frames(m, cam, MapConfig().hits_to_occupy())
    np.testing.assert_allclose(m.occupied_centers(), [c], atol=1e-9)
    offsets = grid([-1, 0, 1], [-1, 0, 1], [-1, 0, 1]) * RES
    cube = c + offsets
    got = m.occupied_centers(inflated=True)
    assert len(got) == 27
    np.testing.assert_allclose(got[np.lexsort(got.T[::-1])], cube[np.lexsort(cube.T[::-1])],
                               atol=1e-9)
    assert m.occupied_inflated(cube).all()
    assert m.occupied(cube).sum() == 1
    shell = c + grid(*[np.arange(-2, 3)] * 3) * RES
    ring = np.abs(np.rint((shell - c) / RES)).max(axis=1) == 2
    assert not m.occupied_inflated(shell[ring]).any()
    # radius 0: no dilation
    m0 = LocalMap(MapConfig(inflation_voxels=0), CEILING, camera=SMALL)
    fuse_frames(m0, cam, 6)
    assert len(m0.occupied_centers(inflated=True)) == 1


def test_ceiling_and_floor_are_occupied_for_planning_everywhere():
    m = LocalMap(None, CEILING, camera=SMALL)
    far = 1000.0  # outside the window: unknown is free, the virtual layers still hold
    for x in (0.05, far):
        pts = np.array([[x, 0.05, z] for z in (3.0, 3.05, 50.0, -0.01, -7.0, 2.99, 0.0, 1.5)])
        np.testing.assert_array_equal(m.occupied_inflated(pts),
                                      [True, True, True, True, True, False, False, False])
        assert not m.occupied(pts).any() and not m.is_known(pts).any()
    # a ceiling between voxel boundaries: its voxel (2.9 .. 3.0) and up are occupied
    m2 = LocalMap(None, 2.95, camera=SMALL)
    assert m2.occupied_inflated([0.0, 0.0, 2.91]) and not m2.occupied_inflated([0, 0, 2.89])
    # the ESDF sees them: mid-height, 1.5 m to the ceiling voxel, 1.6 m to the floor voxel
    m.update_esdf()
    d, g = m.esdf([[0.05, 0.05, 1.55], [0.05, 0.05, 1.45]])
    np.testing.assert_allclose(d, [1.5, 1.5], atol=1e-9)
    np.testing.assert_allclose(g[0], [0, 0, -1.0], atol=1e-9)


# --- window shifts ----------------------------------------------------------------------------
def dilation_centres(m: LocalMap) -> np.ndarray:
    occ = m.occupied(m.voxel_center(np.argwhere(np.ones(m.shape, bool)) + m.origin_index))
    occ = occ.reshape(m.shape)
    dil = ndimage.binary_dilation(occ, np.ones((3, 3, 3), bool))
    return (np.argwhere(dil) + m.origin_index + 0.5) * RES


def sort_rows(a: np.ndarray) -> np.ndarray:
    return a[np.lexsort(a.T[::-1])]


def test_window_shift_keeps_world_content_at_its_world_position():
    cfg = MapConfig()
    m = LocalMap(cfg, CEILING, camera=SMALL)
    fuse_frames(m, DepthCamera(SMALL, wall(3.05)), 8)
    origin0 = m.origin_index
    occ0 = m.occupied_centers()
    # east of where the camera will be, so the next frame (looking west) cannot touch it
    probe = grid(centres(25, 40), centres(-30, 31), centres(5, 26))
    lo0, known0 = m.log_odds(probe), m.is_known(probe)
    # fly 2.3 m east, 5.2 m south, looking west (away from the wall): the window re-centres
    # and part of the wall leaves it
    p1 = P0 + [2.3, -5.2, 0.0]
    (st,) = fuse_frames(m, DepthCamera(SMALL, nothing()), 1, p=p1, q=q_yaw(math.pi),
                        t0=10 * DT_US)
    assert st.shifted
    np.testing.assert_array_equal(m.origin_index - origin0, [23, -52, 0])
    np.testing.assert_allclose(m.window_center_m[:2], p1[:2], atol=RES)
    keep = m.in_window(occ0)
    assert keep.any() and not keep.all()
    np.testing.assert_allclose(sort_rows(m.occupied_centers()), sort_rows(occ0[keep]),
                               atol=1e-9)
    assert m.occupied_count == keep.sum()
    # the dilation counts stay exact across the cut and new edges
    np.testing.assert_allclose(sort_rows(m.occupied_centers(inflated=True)),
                               sort_rows(dilation_centres(m)), atol=1e-9)
    # voxels keep their log-odds at the same world points; what left is unknown
    both = m.in_window(probe)
    assert both.any() and not both.all() and known0[both].any() and known0[~both].any()
    np.testing.assert_array_equal(m.log_odds(probe)[both], lo0[both])
    assert not m.is_known(probe[~both]).any()
    # small moves do not shift
    (st,) = fuse_frames(m, DepthCamera(SMALL, nothing()), 1, p=p1 + [0.5, 0.5, 0],
                        q=q_yaw(math.pi), t0=11 * DT_US)
    assert not st.shifted
    # a long trip forgets everything
    fuse_frames(m, DepthCamera(SMALL, nothing()), 1, p=P0 + [30.0, 0, 0], q=q_yaw(math.pi),
                t0=12 * DT_US)
    fuse_frames(m, DepthCamera(SMALL, nothing()), 1, p=P0 + [-1.0, 0, 0], q=q_yaw(math.pi),
                t0=13 * DT_US)
    assert m.in_window(occ0).all()
    assert m.occupied_count == 0 and not m.is_known(occ0).any()
    assert len(m.occupied_centers(inflated=True)) == 0


# --- ESDF -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def forest_map():
    sc = build_scenario("forest", 5)
    cam = DepthCamera(SMALL, sc.mesh)
    m = LocalMap(None, sc.ceiling, camera=SMALL)
    q = q_yaw(sc.start_yaw)
    for k in range(8):
        m.fuse(cam.capture(k * DT_US, sc.start + [0.0, 0.3 * k, 0.0], q))
    assert m.occupied_count > 50
    m.update_esdf()
    return m


def test_first_occupied_is_the_sampled_march_over_planning_occupancy(forest_map):
    from ft_sitl.navigation.learned.navrl import cast_lidar, lidar_directions

    m = forest_map
    rng = np.random.default_rng(2)
    dirs = rng.normal(size=(300, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)  # some rays reach floor or ceiling
    dirs = dirs.reshape(100, 3, 3)  # cast_lidar takes (beams, elevations, 3)
    for pos in (m.window_center_m, m.window_center_m + [1.0, 2.5, -0.3]):
        for rays in (dirs, lidar_directions(0.3)):
            got = m.first_occupied(pos, rays, 0.05, 4.0)
            want = cast_lidar(m.occupied_inflated, pos, rays, max_range=4.0, step=0.05)
            assert got.shape == rays.shape[:-1]
            np.testing.assert_array_equal(got, want)
            assert (got < 4.0).any() and (got == 4.0).any()
    with pytest.raises(ValueError, match="step_m"):
        m.first_occupied(m.window_center_m, dirs, 0.0, 4.0)
    with pytest.raises(ValueError, match="finite"):
        m.first_occupied([np.nan, 0, 0], dirs, 0.05, 4.0)


def brute_distance(points: np.ndarray, sites: np.ndarray) -> np.ndarray:
    """Distance from each point to the nearest site, by trying them all."""
    out = np.empty(len(points))
    chunk = max(1, 3_000_000 // max(len(sites), 1))
    for i in range(0, len(points), chunk):
        d2 = ((points[i:i + chunk, None, :] - sites[None, :, :]) ** 2).sum(-1)
        out[i:i + chunk] = np.sqrt(d2.min(axis=1))
    return out


def test_esdf_matches_brute_force_distances(forest_map):
    m = forest_map
    plan = m.planning_grid().astype(bool)
    all_idx = np.argwhere(np.ones(m.shape, bool))
    occ_c = (np.argwhere(plan) + m.origin_index + 0.5) * RES
    free_c = (np.argwhere(~plan) + m.origin_index + 0.5) * RES
    rng = np.random.default_rng(7)
    field = m.update_esdf()
    assert field.shape == m.shape
    # voxel centres near the obstacles, free and occupied: exact (Fast-Planner's sign rule)
    obst = m.local_index(m.occupied_centers(inflated=True))
    near = obst[rng.choice(len(obst), 150)] + rng.integers(-4, 5, (150, 3))
    near = near[np.all((near >= 0) & (near < m.shape), axis=1)]
    pts = (near + m.origin_index + 0.5) * RES
    occupied = plan[tuple(near.T)]
    expect = np.empty(len(pts))
    expect[occupied] = RES - brute_distance(pts[occupied], free_c)
    expect[~occupied] = brute_distance(pts[~occupied], occ_c)
    d, _ = m.esdf(pts)
    assert occupied.any() and (~occupied).any()
    np.testing.assert_allclose(d, expect, atol=1e-9)
    np.testing.assert_allclose(field[tuple(near.T)], expect, atol=1e-9)
    # random points between centres vs the true distance to the nearest occupied voxel
    # centre: trilinear interpolation of a 1-Lipschitz field is off by at most the distance
    # to the farthest of the 8 centres (half a voxel diagonal); in practice within half a
    # voxel (99 %; the worst seen in 15k points, next to obstacle corners: 0.506 voxel)
    sample = all_idx[rng.choice(len(all_idx), 400)]
    p = (sample + m.origin_index + rng.random((400, 3))) * RES
    free = ~m.occupied_inflated(p)
    d, _ = m.esdf(p[free])
    err = np.abs(d - brute_distance(p[free], occ_c))
    assert err.max() <= math.sqrt(3) / 2 * RES
    assert np.percentile(err, 99) <= RES / 2


def test_esdf_gradient_matches_finite_differences(forest_map):
    m = forest_map
    rng = np.random.default_rng(3)
    lo, hi = m.window_min_m + 0.2, m.window_max_m - 0.2
    p = lo + rng.random((300, 3)) * (hi - lo)
    # keep away from cell faces (between voxel centres) where the gradient jumps
    frac = (p / RES - 0.5) % 1.0
    p = p[np.all((frac > 0.01) & (frac < 0.99), axis=1)]
    h = 1e-6
    _, g = m.esdf(p)
    fd = np.empty_like(g)
    for a in range(3):
        e = np.zeros(3)
        e[a] = h
        fd[:, a] = (m.esdf(p + e)[0] - m.esdf(p - e)[0]) / (2 * h)
    np.testing.assert_allclose(g, fd, atol=1e-6)
    assert np.abs(g).max() > 0.5
    # beyond the window: clamped, no gradient along the clamped axis
    d, g = m.esdf([m.window_max_m[0] + 5.0, m.window_center_m[1], 1.5])
    assert math.isfinite(d) and g[0] == 0.0


def test_esdf_sub_box_and_query_shapes(forest_map):
    m = forest_map
    whole = m.update_esdf()
    pts = np.stack([m.last_camera_m + [dx, 2.0, 0.0] for dx in np.linspace(-2, 2, 9)])
    box_field = m.update_esdf(half_extent_m=3.0)
    assert box_field.shape[:2] == (61, 61) and box_field.shape[2] == m.shape[2]
    x0, y0, _ = m.esdf_origin_index - m.origin_index
    sub = whole[x0:x0 + 61, y0:y0 + 61]
    # the box ignores what lies outside it: free voxels can only be farther from obstacles,
    # and agree where the nearest obstacle is inside
    free = sub > 0
    assert np.all(box_field[free] >= sub[free] - 1e-12)
    assert np.mean(np.isclose(box_field[free], sub[free])) > 0.5
    m.update_esdf()
    # shapes: (3,) -> scalar, (a, b, 3) -> (a, b)
    d, g = m.esdf(pts.reshape(3, 3, 3))
    assert d.shape == (3, 3) and g.shape == (3, 3, 3)
    d, g = m.esdf(pts[0])
    assert np.ndim(d) == 0 and g.shape == (3,)
    assert m.occupied(pts.reshape(3, 3, 3)).shape == (3, 3)
    assert isinstance(m.occupied_inflated(pts[0]), np.bool_)
    with pytest.raises(ValueError, match="finite"):
        m.occupied_inflated([np.nan, 0.0, 1.0])
    with pytest.raises(ValueError, match="finite"):
        m.esdf([0.0, np.inf, 1.0])


def test_esdf_before_update_raises():
    with pytest.raises(RuntimeError, match="update_esdf"):
        LocalMap(None, CEILING).esdf([0.0, 0.0, 1.0])


# --- configuration ----------------------------------------------------------------------------
@pytest.mark.parametrize("field, value", [
    ("resolution_m", 0.0), ("resolution_m", float("nan")), ("resolution_m", "0.1"),
    ("local_update_range_m", (5.5, 5.5)), ("local_update_range_m", (5.5, -1.0, 4.5)),
    ("window_xy_m", 8.0), ("recentre_distance_m", -1.0), ("z_margin_m", 0.01),
    ("p_hit", 0.4), ("p_hit", 1.0), ("p_miss", 0.6), ("p_min", 0.85), ("p_max", 0.7),
    ("p_occ", 0.0), ("unknown_offset", 0.0), ("skip_pixel", 0), ("skip_pixel", 1.5),
    ("skip_pixel", True), ("depth_margin_px", -1), ("min_depth_m", -0.1),
    ("max_depth_m", 0.1), ("max_ray_length_m", 0.0), ("inflation_voxels", 9),
])
def test_bad_config_values_raise_naming_the_field(field, value):
    with pytest.raises(ValueError, match=f"MapConfig.{field}"):
        MapConfig(**{field: value})


def test_bad_map_arguments_raise():
    with pytest.raises(ValueError, match="ceiling_m"):
        LocalMap(None, 0.1)
    with pytest.raises(ValueError, match="ceiling_m"):
        LocalMap(None, float("inf"))
    m = LocalMap(None, CEILING)  # expects 640 x 480 frames
    frame = DepthCamera(SMALL, nothing()).capture(0, P0, IDENTITY)
    with pytest.raises(ValueError, match="480 x 640"):
        m.fuse(frame)


def test_esdf_box_limited_in_height_matches_the_full_field_inside_it():
    m = LocalMap(MapConfig(), ceiling_m=10.0, floor_m=0.0, center_m=(0.0, 0.0))
    pts = np.array([[0.3, 0.2, 0.95], [1.0, -2.0, 2.05], [-1.5, 1.5, 3.55]])
    full = m.update_esdf(center_m=(0.0, 0.0, 2.0), half_extent_m=3.0)
    d_full, g_full = m.esdf(pts)
    low = m.update_esdf(center_m=(0.0, 0.0, 2.0), half_extent_m=3.0, half_extent_z_m=4.5)
    assert low.shape[2] < full.shape[2]  # cheaper: fewer layers
    d_low, g_low = m.esdf(pts)
    # the floor is inside the box: the distances to it agree (the ceiling is far above)
    assert d_low == pytest.approx(d_full, abs=1e-9)
    assert g_low == pytest.approx(g_full, abs=1e-9)
    assert d_full == pytest.approx(pts[:, 2], abs=0.11)  # the floor, to within a voxel
    with pytest.raises(ValueError, match="half_extent_z_m"):
        m.update_esdf(half_extent_z_m=-1.0)


def test_lattice_query_and_revision_follow_the_planning_occupancy():
    c = np.array([2.05, 0.05, 1.55])
    cam = DepthCamera(SMALL, box(c - 0.02, c + 0.02))
    m = LocalMap(None, CEILING, camera=SMALL)
    r0 = m.revision
    fuse_frames(m, cam, MapConfig().hits_to_occupy() - 1)
    assert m.revision == r0  # nothing occupied yet: the planning occupancy is unchanged
    fuse_frames(m, cam, 1)
    assert m.revision != r0
    r1 = m.revision
    fuse_frames(m, cam, 3)  # saturating hits flip nothing
    assert m.revision == r1
    # the lattice answer is the point answer, inside and outside the window, floor, ceiling
    xs = np.arange(-80, 90) * 0.1 + 0.05
    ys = np.concatenate([np.arange(-5, 5) * 0.1 + 0.05, [700.05]])
    zs = np.arange(-3, 33) * 0.1 + 0.05
    got = m.occupied_inflated_lattice(xs, ys, zs)
    assert got.shape == (len(xs), len(ys), len(zs)) and got.dtype == bool
    np.testing.assert_array_equal(got.reshape(-1), m.occupied_inflated(grid(xs, ys, zs)))
    assert got.sum() > 27
    m.shift_to(m.origin_index[:2] + 3)
    assert m.revision != r1


def test_esdf_is_recomputed_only_when_the_planning_occupancy_or_box_changes():
    c = np.array([2.05, 0.05, 1.55])
    cam = DepthCamera(SMALL, box(c - 0.3, c + 0.3))
    m = LocalMap(None, CEILING, camera=SMALL)
    fuse_frames(m, cam, MapConfig().hits_to_occupy())
    first = m.update_esdf(P0, 2.0, 1.5)
    again = m.update_esdf(P0, 2.0, 1.5)
    assert again is first  # same revision, same box: the stored field
    other = m.update_esdf(P0, 2.5, 1.5)
    assert other is not first
    fresh = LocalMap(None, CEILING, camera=SMALL)
    fuse_frames(fresh, cam, MapConfig().hits_to_occupy())
    np.testing.assert_array_equal(fresh.update_esdf(P0, 2.5, 1.5), other)
    m.clear()
    cleared = m.update_esdf(P0, 2.5, 1.5)
    assert cleared is not other and not np.array_equal(cleared, other)
