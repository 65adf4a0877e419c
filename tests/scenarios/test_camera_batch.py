"""The depth camera for many vehicles at once (one compiled call): image v is exactly what
capture() gives for that pose alone, fan v what cast() gives for its rays, movers
included."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from ft_sitl.physics.quaternion import qfrom_euler
from ft_sitl.scenarios.camera import CameraConfig, DepthCamera
from ft_sitl.scenarios.movers import movers_from_list

RNG = np.random.default_rng(11)


def scene() -> trimesh.Trimesh:
    parts = []
    for _ in range(12):
        p = trimesh.creation.cylinder(radius=RNG.uniform(0.2, 0.5), height=6.0, sections=12)
        p.apply_translation([RNG.uniform(0, 20), RNG.uniform(0, 20), 3.0])
        parts.append(p)
    wall = trimesh.creation.box(extents=[20.0, 0.3, 4.0])
    wall.apply_translation([10.0, 21.0, 2.0])
    return trimesh.util.concatenate([*parts, wall])


MESH = scene()
POSES = np.column_stack([RNG.uniform(2, 18, 6), RNG.uniform(2, 18, 6), RNG.uniform(1, 3, 6)])
QUATS = np.array([qfrom_euler(RNG.normal(0, 0.2), RNG.normal(0, 0.2), RNG.uniform(-3, 3))
                  for _ in range(6)])
MOVERS = movers_from_list([{"shape": "person", "radius_m": 0.4, "height_m": 1.8,
                            "points": [[5.0, 5.0], [15.0, 15.0]],
                            "speed_m_s": 1.0}])


@pytest.mark.parametrize("packets", [True, False])
def test_capture_depths_are_the_captures(packets):
    cam = DepthCamera(CameraConfig(max_range_m=10.0).subsampled(16), MESH, packets=packets)
    depth = cam.capture_depths(POSES, QUATS, movers=MOVERS, movers_time_us=3_000_000)
    assert depth.shape == (6, 30, 40) and depth.dtype == np.float32
    assert np.isfinite(depth).any()
    for v in range(6):
        f = cam.capture(0, POSES[v], QUATS[v], movers=MOVERS, movers_time_us=3_000_000)
        assert np.array_equal(depth[v], f.depth, equal_nan=True)


@pytest.mark.parametrize("packets", [True, False])
def test_cast_fans_are_the_casts(packets):
    cam = DepthCamera(CameraConfig().subsampled(40), MESH, packets=packets)
    dirs = RNG.normal(size=(50, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    rots = np.stack([qrot for qrot in (np.linalg.qr(RNG.normal(size=(3, 3)))[0]
                                       for _ in range(6))])
    out = cam.cast_fans(POSES, rots, dirs, movers=MOVERS, movers_time_us=0)
    assert np.isfinite(out).any() and np.isinf(out).any()
    for v in range(6):  # (the kernel rotates the rays component by component: a matmul's
        # directions may differ in the last bit)
        ref = cam.cast(POSES[v], dirs @ rots[v].T, movers=MOVERS, movers_time_us=0)
        assert np.array_equal(np.isinf(out[v]), np.isinf(ref))
        np.testing.assert_allclose(out[v], ref, rtol=1e-12)
    near = cam.cast_fans(POSES, rots, dirs, max_range_m=4.0)  # (the movers left out)
    far = cam.cast_fans(POSES, rots, dirs)
    assert np.array_equal(near[far <= 4.0], far[far <= 4.0]) and np.all(near[far > 4.0] > 4.0)


def test_what_the_batch_refuses():
    cam = DepthCamera(CameraConfig().subsampled(40), MESH)
    with pytest.raises(ValueError, match=r"origins_world \(V, 3\) and rots \(V, 3, 3\)"):
        cam.cast_fans(POSES, np.eye(3), np.array([[1.0, 0.0, 0.0]]))
    with pytest.raises(ValueError, match="movers_time_us"):
        cam.capture_depths(POSES, QUATS, movers=MOVERS)
    noisy = DepthCamera(CameraConfig(noise_k=0.001).subsampled(40), MESH)
    with pytest.raises(ValueError, match="noise-free frames"):
        noisy.capture_depths(POSES, QUATS)
