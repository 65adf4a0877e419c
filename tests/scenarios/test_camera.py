"""The depth camera against analytic answers: walls, a cylinder, a floor seen from a tilt."""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import pytest
import trimesh

from ft_sitl.scenarios import camera as cam_mod
from ft_sitl.scenarios.camera import CameraConfig, DepthCamera, DepthFrame, camera_config

IDENTITY = np.array([1.0, 0.0, 0.0, 0.0])


def q_yaw(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def rotmat(q) -> np.ndarray:
    w, x, y, z = np.asarray(q, float) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def wall_x(d: float, half: float = 3.0, thick: float = 0.2) -> trimesh.Trimesh:
    """A wall whose face towards the origin is the plane x = d, |y|, |z| <= half."""
    box = trimesh.creation.box(extents=[thick, 2 * half, 2 * half])
    box.apply_translation([d + thick / 2, 0.0, 0.0])
    return box


def floor(half: float = 50.0) -> trimesh.Trimesh:
    box = trimesh.creation.box(extents=[2 * half, 2 * half, 0.1])
    box.apply_translation([0.0, 0.0, -0.05])
    return box


@pytest.fixture(scope="module")
def wall_cam():
    return DepthCamera(CameraConfig(), wall_x(3.0))


# --- geometry -------------------------------------------------------------------------------
def test_wall_z_depth_is_constant_and_exact(wall_cam):
    f = wall_cam.capture(1000, [0.0, 0.0, 0.0], IDENTITY)
    assert isinstance(f, DepthFrame)
    assert f.t_us == 1000
    assert f.depth.shape == (480, 640) and f.depth.dtype == np.float32
    assert abs(float(f.depth[240, 320]) - 3.0) < 1e-4
    assert np.all(np.isfinite(f.depth))  # the wall fills the field of view
    np.testing.assert_allclose(f.depth, 3.0, atol=1e-4)
    assert len(f.points_body) == len(f.points_world) == f.depth.size


def test_wall_points_lie_on_the_wall_plane_for_a_moved_vehicle():
    # vehicle at p, yaw 30 deg; wall 4 m ahead along the heading, facing the vehicle
    yaw, d = math.radians(30.0), 4.0
    p = np.array([1.0, 2.0, 0.5])
    heading = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    wall = wall_x(d, half=5.0)
    wall.apply_transform(trimesh.transformations.rotation_matrix(yaw, [0, 0, 1]))
    wall.apply_translation(p)
    cam = DepthCamera(CameraConfig().subsampled(4), wall)
    f = cam.capture(0, p, q_yaw(yaw))
    assert np.all(f.valid)
    np.testing.assert_allclose(f.depth, d, atol=1e-4)
    np.testing.assert_allclose((f.points_world - p) @ heading, d, atol=1e-9)
    # body and world clouds are the same points
    np.testing.assert_allclose(f.points_body @ rotmat(q_yaw(yaw)).T + p, f.points_world,
                               atol=1e-12)
    np.testing.assert_allclose(f.points_body[:, 0], d, atol=1e-9)  # forward = wall distance
    # pixels are row-major and match the depth image
    r, c = f.pixels.T
    np.testing.assert_allclose(f.depth[r, c], f.points_body[:, 0], atol=1e-5)


def test_image_orientation_left_is_low_columns_up_is_low_rows():
    # a small box up-left of the axis shows in the top-left quadrant of the image
    box = trimesh.creation.box(extents=[0.2, 0.5, 0.5])
    box.apply_translation([5.0, 1.0, 1.0])  # forward, left, up
    f = DepthCamera(CameraConfig().subsampled(4), box).capture(0, [0, 0, 0], IDENTITY)
    rows, cols = np.nonzero(f.valid)
    assert len(rows) > 0
    assert cols.max() < 80 and rows.max() < 60  # 160 x 120 image


def test_yaw_90_does_not_see_the_wall_ahead_then_sees_it_on_plus_y(wall_cam):
    f = wall_cam.capture(0, [0.0, 0.0, 0.0], q_yaw(math.pi / 2))
    assert np.all(np.isnan(f.depth))
    assert f.points_world.shape == (0, 3) and f.points_body.shape == (0, 3)

    side = trimesh.creation.box(extents=[6.0, 0.2, 6.0])
    side.apply_translation([0.0, 3.1, 0.0])  # face on y = 3
    f = DepthCamera(CameraConfig(), side).capture(0, [0.0, 0.0, 0.0], q_yaw(math.pi / 2))
    assert np.all(f.valid)
    np.testing.assert_allclose(f.depth, 3.0, atol=1e-4)
    np.testing.assert_allclose(f.points_world[:, 1], 3.0, atol=1e-9)


def test_mount_offset_shifts_the_depth_and_the_camera_pose():
    cfg = CameraConfig(mount_position_body=(0.1, 0.0, 0.05)).subsampled(4)
    f = DepthCamera(cfg, wall_x(3.0)).capture(0, [0.0, 0.0, 0.0], IDENTITY)
    np.testing.assert_allclose(f.depth, 2.9, atol=1e-4)
    np.testing.assert_allclose(f.p_world_camera, [0.1, 0.0, 0.05])
    np.testing.assert_allclose(f.points_body[:, 0], 3.0, atol=1e-9)  # body origin relative


@pytest.mark.parametrize("column", [180, 500, 320])
def test_cylinder_at_known_bearing(column):
    # bearing chosen so the cylinder's centre falls exactly on an integer column
    cfg = CameraConfig()
    d, r, sections = 5.0, 0.4, 512
    b = math.atan((cfg.cx - column) / cfg.fx)  # > 0 (left, +y) for columns left of centre
    c = np.array([d * math.cos(b), d * math.sin(b)])
    cyl = trimesh.creation.cylinder(radius=r, height=40.0, sections=sections)
    cyl.apply_translation([c[0], c[1], 0.0])
    f = DepthCamera(cfg, cyl).capture(0, [0.0, 0.0, 0.0], IDENTITY)
    facet = r * (1 - math.cos(math.pi / sections))  # polygon vs. true circle

    # columns: bearing b lands at u = cx - fx tan(b) (left of the image is body +y)
    u_centre = cfg.cx - cfg.fx * math.tan(b)
    assert u_centre == pytest.approx(column, abs=1e-9)
    assert (c[1] > 0) == (column < cfg.cx)
    row = int(round(cfg.cy))
    hit_cols = np.flatnonzero(np.isfinite(f.depth[row]))
    half = math.asin(r / d)
    u_left = cfg.cx - cfg.fx * math.tan(b + half)
    u_right = cfg.cx - cfg.fx * math.tan(b - half)
    assert abs(hit_cols.min() - u_left) <= 1.0 and abs(hit_cols.max() - u_right) <= 1.0
    assert np.all(np.diff(hit_cols) == 1)
    # the nearest surface point (shortest ray, not smallest z-depth) is on the bearing
    xn_row = (np.arange(cfg.width) - cfg.cx) / cfg.fx
    yn_row = (row - cfg.cy) / cfg.fy
    ray_len_row = f.depth[row] * np.sqrt(1 + xn_row**2 + yn_row**2)
    assert abs(int(np.nanargmin(ray_len_row)) - u_centre) <= 1.0

    # at the bearing column: ray length d - r, z-depth (d - r) cos(b)
    uc = column
    z = float(f.depth[row, uc])
    ray_len = z * math.sqrt(1 + ((uc - cfg.cx) / cfg.fx) ** 2 + ((row - cfg.cy) / cfg.fy) ** 2)
    assert abs(ray_len - (d - r)) < 1e-3 + facet
    assert abs(z - (d - r) * math.cos(b)) < 1e-3 + facet

    # every pixel: ray (x_n, y_n, 1) in optical = (1, -x_n, -y_n) in body, parameter s is
    # the z-depth; solve |s h - c| = r in the horizontal plane, h = (1, -x_n)
    xn = (np.arange(cfg.width) - cfg.cx) / cfg.fx
    hx, hy = np.ones_like(xn), -xn
    hh = hx * hx + hy * hy
    hc = hx * c[0] + hy * c[1]
    disc = hc * hc - hh * (c @ c - r * r)
    inside = disc > 0
    s = (hc - np.sqrt(np.where(inside, disc, 0.0))) / hh
    # away from the silhouette the hit pattern is analytic, and the same in every row
    edge = np.abs(disc) < 1e-3 * hh * r * r
    assert not np.any(edge[hit_cols.min() + 2:hit_cols.max() - 1])
    np.testing.assert_array_equal(f.valid[:, ~edge],
                                  np.broadcast_to(inside[~edge], (cfg.height, (~edge).sum())))
    # depth everywhere on the cylinder; the polygon's radial error `facet` grows as
    # 1 / cos(incidence) towards the silhouette, cos(incidence) = sqrt(disc / hh) / r
    clear = disc > 1e-3 * hh * r * r
    cos_inc = np.sqrt(disc[clear] / hh[clear]) / r
    err = np.abs(f.depth[:, clear] - s[clear])
    assert np.all(err <= 2 * facet / cos_inc + 1e-5)


def test_pitched_mount_sees_the_floor_analytically():
    h, pitch = 1.5, math.radians(30.0)
    cfg = CameraConfig(width=65, height=49, fx=40.0, fy=40.0, max_range_m=100.0,
                       mount_pitch_rad=pitch)
    assert cfg.cx == 32.0 and cfg.cy == 24.0
    f = DepthCamera(cfg, floor(half=500.0)).capture(0, [0.0, 0.0, h], IDENTITY)
    # the optical axis hits the floor at range h / sin(pitch)
    assert abs(float(f.depth[24, 32]) - h / math.sin(pitch)) < 1e-4
    yn = ((np.arange(cfg.height) - cfg.cy) / cfg.fy)[:, None]
    denom = math.sin(pitch) + yn * math.cos(pitch)  # downward rate of the z=1 ray
    expected = np.where(denom > 0, h / np.where(denom > 0, denom, 1.0), np.nan)
    expected[expected > cfg.max_range_m] = np.nan
    assert np.isnan(expected).any() and np.isfinite(expected).any()
    expected = np.broadcast_to(expected, f.depth.shape)
    assert np.array_equal(np.isfinite(f.depth), np.isfinite(expected))
    np.testing.assert_allclose(f.depth, expected, atol=1e-4)
    np.testing.assert_allclose(f.points_world[:, 2], 0.0, atol=1e-9)
    # negative pitch looks up: the floor is out of sight
    up = DepthCamera(CameraConfig(width=65, height=49, fx=40.0, fy=40.0,
                                  mount_pitch_rad=-pitch), floor())
    assert not np.any(up.capture(0, [0.0, 0.0, h], IDENTITY).valid)


def test_min_and_max_range_cut():
    wall = wall_x(3.0)
    base = CameraConfig().subsampled(8)
    for lo, hi, seen in [(0.2, 2.5, False), (3.5, 10.0, False), (0.2, 3.5, True),
                         (2.9, 3.1, True)]:
        cfg = dataclasses.replace(base, min_range_m=lo, max_range_m=hi)
        f = DepthCamera(cfg, wall).capture(0, [0, 0, 0], IDENTITY)
        assert np.all(f.valid) if seen else not np.any(f.valid), (lo, hi)
    # a tilted floor spans many depths: valid exactly where the analytic depth is in range
    h, pitch = 1.5, math.radians(30.0)
    cfg = CameraConfig(width=65, height=49, fx=40.0, fy=40.0, min_range_m=2.0,
                       max_range_m=6.0, mount_pitch_rad=pitch)
    f = DepthCamera(cfg, floor()).capture(0, [0.0, 0.0, h], IDENTITY)
    yn = ((np.arange(cfg.height) - cfg.cy) / cfg.fy)
    denom = math.sin(pitch) + yn * math.cos(pitch)
    z = np.where(denom > 0, h / np.where(denom > 0, denom, 1.0), np.inf)
    in_range = (z >= 2.0) & (z <= 6.0)
    assert in_range.any() and (~in_range).any()
    np.testing.assert_array_equal(f.valid.all(axis=1), in_range)
    np.testing.assert_array_equal(f.valid.any(axis=1), in_range)
    d = f.depth[f.valid]
    assert d.min() >= 2.0 and d.max() <= 6.0


# --- noise ---------------------------------------------------------------------------------
def test_noise_statistics_and_dropout():
    z0, k, p = 4.0, 0.01, 0.2
    cfg = CameraConfig(noise_k=k, dropout=p, max_range_m=20.0)
    f = DepthCamera(cfg, wall_x(z0, half=10.0)).capture(0, [0, 0, 0], IDENTITY,
                                                          rng=np.random.default_rng(7))
    d = f.depth[f.valid].astype(np.float64)
    n = f.depth.size
    assert abs(1.0 - len(d) / n - p) < 5 * math.sqrt(p * (1 - p) / n)
    sigma = k * z0 * z0
    assert abs(d.mean() - z0) < 5 * sigma / math.sqrt(len(d))  # unbiased
    assert abs(d.std() / sigma - 1.0) < 0.10
    # the cloud carries the noisy depth
    np.testing.assert_allclose(f.points_body[:, 0], d, atol=1e-5)


def test_noise_grows_with_depth_squared():
    k = 0.01
    sig = []
    for z0 in (2.0, 4.0):
        cfg = CameraConfig(noise_k=k).subsampled(2)
        f = DepthCamera(cfg, wall_x(z0, half=10.0)).capture(0, [0, 0, 0], IDENTITY,
                                                              rng=np.random.default_rng(1))
        sig.append(float(np.std(f.depth)))
    assert abs(sig[1] / sig[0] - 4.0) < 0.4


def test_same_seed_same_frame_other_seed_other_frame():
    cfg = CameraConfig(noise_k=0.005, dropout=0.1).subsampled(4)
    cam = DepthCamera(cfg, wall_x(3.0))
    a = cam.capture(0, [0, 0, 0], IDENTITY, rng=np.random.default_rng(42))
    b = cam.capture(0, [0, 0, 0], IDENTITY, rng=np.random.default_rng(42))
    c = cam.capture(0, [0, 0, 0], IDENTITY, rng=np.random.default_rng(43))
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.points_world, b.points_world)
    assert not np.array_equal(a.depth, c.depth, equal_nan=True)


def test_noise_needs_a_generator_and_noise_free_ignores_it(wall_cam):
    cam = DepthCamera(CameraConfig(noise_k=0.001).subsampled(8), wall_x(3.0))
    with pytest.raises(ValueError, match="Generator"):
        cam.capture(0, [0, 0, 0], IDENTITY)
    a = wall_cam.capture(0, [0, 0, 0], IDENTITY, rng=np.random.default_rng(0))
    b = wall_cam.capture(0, [0, 0, 0], IDENTITY)
    np.testing.assert_array_equal(a.depth, b.depth)


# --- config, rate, fallback ----------------------------------------------------------------
def test_defaults_match_the_planners_camera():
    cfg = CameraConfig()
    assert (cfg.width, cfg.height, cfg.rate_hz) == (640, 480, 30.0)
    assert cfg.fx == cfg.fy == pytest.approx(387.229, abs=1e-3)
    assert (cfg.cx, cfg.cy) == (319.5, 239.5)
    assert (cfg.min_range_m, cfg.max_range_m, cfg.noise_k, cfg.dropout) == (0.2, 10.0, 0, 0)
    h, v = cfg.fov_deg
    assert h == pytest.approx(79.1, abs=0.2) and v == pytest.approx(63.6, abs=0.2)
    assert cam_mod.stereo_noise_k(387.229, 0.05) == pytest.approx(0.00413, abs=1e-4)


def test_subsampled_keeps_the_field_of_view():
    cfg = CameraConfig()
    for step in (2, 4):
        s = cfg.subsampled(step)
        assert (s.width, s.height) == (640 // step, 480 // step)
        assert s.fov_deg == pytest.approx(cfg.fov_deg, abs=1e-9)
        assert s.cx == (s.width - 1) / 2 and s.cy == (s.height - 1) / 2
        assert (s.rate_hz, s.max_range_m) == (cfg.rate_hz, cfg.max_range_m)
    with pytest.raises(ValueError, match="step"):
        cfg.subsampled(0)


@pytest.mark.parametrize("kwargs, field_name", [
    ({"width": 0}, "width"),
    ({"height": 2.5}, "height"),
    ({"fx": 0.0}, "fx"),
    ({"fy": -1.0}, "fy"),
    ({"cx": 700.0}, "cx"),
    ({"cy": float("nan")}, "cy"),
    ({"min_range_m": -0.1}, "min_range_m"),
    ({"max_range_m": 0.1}, "max_range_m"),
    ({"max_range_m": float("inf")}, "max_range_m"),
    ({"rate_hz": 0.0}, "rate_hz"),
    ({"mount_position_body": (0.0, 0.0)}, "mount_position_body"),
    ({"mount_pitch_rad": 2.0}, "mount_pitch_rad"),
    ({"noise_k": -0.001}, "noise_k"),
    ({"dropout": 1.0}, "dropout"),
])
def test_config_validation_names_the_field(kwargs, field_name):
    with pytest.raises(ValueError, match=rf"CameraConfig\.{field_name} must be"):
        CameraConfig(**kwargs)


def test_rate_schedule_has_no_drift(wall_cam):
    cam = DepthCamera(CameraConfig(width=8, height=6, fx=5.0, fy=5.0), wall_x(3.0))
    assert cam.due(0)
    frames = []
    for t in range(5_000, 2_005_000, 1_000):  # 1 kHz lockstep, 2 s
        if cam.due(t):
            frames.append(cam.capture(t, [0, 0, 0], IDENTITY).t_us)
    assert len(frames) == 60
    assert frames[:3] == [5_000, 39_000, 72_000]  # 5000 + ceil(k * 33333.3)
    assert frames[-1] == 1_972_000  # slot 59 at 5000 + ceil(59 * 33333.3) = 1_971_667
    assert not cam.due(2_004_999) and cam.due(2_005_000)  # slot 60, exactly 2 s after t0
    cam.reset()
    assert cam.due(0)


def test_fallback_without_embree_warns_and_agrees(monkeypatch):
    mesh = trimesh.util.concatenate([wall_x(4.0), floor(10.0)])
    cfg = CameraConfig(width=16, height=12, fx=9.68, fy=9.68, mount_pitch_rad=0.2)
    ref = DepthCamera(cfg, mesh)
    monkeypatch.setattr(cam_mod, "embree_available", lambda: False)
    with pytest.warns(RuntimeWarning, match="embreex"):
        slow = DepthCamera(cfg, mesh)
    assert ref.uses_embree and not slow.uses_embree
    p = [0.0, 0.5, 1.2]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        a = ref.capture(0, p, q_yaw(0.1))
        b = slow.capture(0, p, q_yaw(0.1))
    assert a.valid.sum() > 100
    np.testing.assert_allclose(a.depth, b.depth, atol=1e-6)


@pytest.mark.parametrize("family", ["forest", "maze", "random_angle_cylinder"])
def test_packet_queries_hit_the_same_triangles_as_single_rays(family):
    """Embree's 16-ray packets (embree_packets) against embreex's one-ray query: the same
    first-hit triangle for every pixel of frames from random poses and attitudes, hence
    bit-identical depth images and point clouds."""
    from ft_sitl.scenarios.families import build_scenario

    sc = build_scenario(family, 3)
    cfg = camera_config("benchmark", None, None, None)
    packets = DepthCamera(cfg, sc.mesh, instances=False)
    single = DepthCamera(cfg, sc.mesh, packets=False)
    if packets._packets is None:
        pytest.fail("Embree's C API did not load from the embreex wheel")
    assert single._packets is None
    rng = np.random.default_rng(7)
    hits = 0
    for k in range(12):
        p = sc.start + (k / 11) * (sc.goal - sc.start) + rng.normal(0.0, 0.5, 3)
        q = rng.normal(0.0, 0.3, 4)
        q[0] += 1.0
        a, b = single.capture(k, p, q), packets.capture(k, p, q)
        np.testing.assert_array_equal(a.depth, b.depth)
        np.testing.assert_array_equal(a.points_world, b.points_world)
        hits += int(a.valid.sum())
    # unbounded rays (cast) too, in a ray count that is not a multiple of 16
    dirs = rng.normal(size=(1001, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    np.testing.assert_array_equal(single.cast(sc.start, dirs), packets.cast(sc.start, dirs))
    assert hits > 10_000  # the frames saw the scene (~5 % of their pixels at least)


@pytest.mark.parametrize("family,version", [("forest", None), ("random_angle_cylinder", None),
                                            ("perlin", 1)])
def test_one_instance_per_piece_sees_the_same_surfaces(family, version):
    """The default packet scene (each connected piece an Embree instance in its own
    principal-axes frame) against the one-scene query: every piece is its own instance, and
    all but a handful of pixels in a million (rays through an edge or grazing a silhouette,
    tested in the piece's frame) are bit-identical. (Perlin version 2's ~40,000 boxes are
    more pieces than MAX_INSTANCES: one scene, next test.)"""
    from ft_sitl.scenarios.families import build_scenario

    sc = build_scenario(family, 3, version=version)
    cfg = camera_config("benchmark", None, None, None)
    inst = DepthCamera(cfg, sc.mesh)
    plain = DepthCamera(cfg, sc.mesh, instances=False)
    if inst._packets is None:
        pytest.fail("Embree's C API did not load from the embreex wheel")
    assert len(inst._packets.offset) == len(sc.piece_names) > 1
    assert len(plain._packets.offset) == 1
    rng = np.random.default_rng(3)
    lo, hi = np.asarray(sc.bounds_min), np.asarray(sc.bounds_max)
    differ = seen = 0
    for k in range(60):
        p = lo + rng.random(3) * (hi - lo)
        q = rng.normal(0.0, 0.3, 4)
        q[0] += 1.0
        a, b = plain.capture(k, p, q).depth, inst.capture(k, p, q).depth
        differ += int(np.sum(~((a == b) | (np.isnan(a) & np.isnan(b)))))
        seen += int(np.isfinite(a).sum())
    assert seen > 20_000
    assert differ <= 60 * a.size * 1e-5  # at most 10 in a million
    dirs = rng.normal(size=(1001, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    la, lb = plain.cast(sc.start, dirs), inst.cast(sc.start, dirs)
    assert np.isfinite(la).sum() > 10
    assert np.sum(~((la == lb) | (np.isinf(la) & np.isinf(lb)))) <= 1


@pytest.mark.slow
def test_a_mesh_of_more_pieces_than_max_instances_is_one_scene():
    """Perlin version 2 (~40,000 boxes) is built as one Embree scene, not as one instance
    per box, and its frames are the one-scene camera's, pixel for pixel."""
    from ft_sitl.scenarios.embree_packets import MAX_INSTANCES
    from ft_sitl.scenarios.families import build_scenario

    sc = build_scenario("perlin", 2)
    assert len(sc.piece_names) > MAX_INSTANCES
    cfg = camera_config("benchmark", None, None, None)
    cam, plain = DepthCamera(cfg, sc.mesh), DepthCamera(cfg, sc.mesh, instances=False)
    if cam._packets is None:
        pytest.fail("Embree's C API did not load from the embreex wheel")
    assert len(cam._packets.offset) == 1
    q = np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])  # facing the goal
    a, b = cam.capture(0, sc.start, q).depth, plain.capture(0, sc.start, q).depth
    np.testing.assert_array_equal(a, b)
    assert np.isfinite(a).mean() > 0.2  # the clutter fills the view


def test_a_triangle_soup_is_one_scene():
    """A mesh whose triangles share no vertices would make one instance per triangle: it is
    built as one scene, and renders as the one-scene camera does."""
    box = trimesh.creation.box(bounds=[[2.0, -1.0, -1.0], [3.0, 1.0, 1.0]])
    soup = trimesh.Trimesh(box.triangles.reshape(-1, 3),
                           np.arange(3 * len(box.faces)).reshape(-1, 3), process=False)
    cfg = CameraConfig(width=64, height=48, fx=40.0, fy=40.0)
    cam, plain = DepthCamera(cfg, soup), DepthCamera(cfg, soup, instances=False)
    if cam._packets is None:
        pytest.fail("Embree's C API did not load from the embreex wheel")
    assert len(cam._packets.offset) == 1 and len(cam._packets.face_of) == 0
    a, b = cam.capture(0, [0.0, 0.0, 0.0], q_yaw(0.1)), plain.capture(0, [0.0, 0.0, 0.0],
                                                                       q_yaw(0.1))
    assert a.valid.sum() > 500
    np.testing.assert_array_equal(a.depth, b.depth)
    solid = DepthCamera(cfg, box)  # the same box with shared vertices: one instance
    assert len(solid._packets.offset) == 1 and len(solid._packets.face_of) == 12
    np.testing.assert_allclose(solid.capture(0, [0.0, 0.0, 0.0], q_yaw(0.1)).depth, a.depth,
                               atol=1e-5)


def test_point_clouds_are_made_on_first_access_and_survive_copies(wall_cam):
    """capture() leaves the clouds to their first reader: the same points as computed from
    the image, and a pickled or copied frame carries them, not the function making them."""
    import copy
    import pickle

    f = wall_cam.capture(0, [0.0, 0.0, 0.0], q_yaw(0.2))
    assert "points_world" not in f.__dict__  # not made yet
    v, u = np.nonzero(f.valid)
    assert np.array_equal(f.pixels, np.stack([v, u], axis=1))
    z = f.depth[v, u].astype(np.float64)
    assert np.allclose(f.points_world[:, 0], 3.0, atol=1e-9)  # the wall's face
    assert len(f.points_body) == len(z) > 1000
    g = pickle.loads(pickle.dumps(wall_cam.capture(1, [0.0, 0.0, 0.0], q_yaw(0.2))))
    np.testing.assert_array_equal(g.points_world, f.points_world)
    h = copy.deepcopy(wall_cam.capture(2, [0.0, 0.0, 0.0], q_yaw(0.2)))
    np.testing.assert_array_equal(h.points_body, f.points_body)
    assert "_make_cloud" not in h.__dict__
