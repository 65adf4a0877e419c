"""Benchmark: depth-camera rays per second (ft_sitl.scenarios.camera), one core.

Scene: 800 vertical cylinders (radius 0.15-0.5 m, height 2-6 m, 16-sided prisms) scattered
over 40 x 60 m with a fixed seed, plus a floor plane. Frames are captured from several
poses inside and around the forest (level, yawed, pitched, rolled), at 640 x 480 (the
default camera) and 320 x 240 (``subsampled(2)``), noise-free and with noise + dropout.

Reported, median of repeats (spread min..max): full-capture depth rays per second (every
pixel cast, depth image and body/world point clouds built) and ms per frame; the raw cast
alone: trimesh's ``intersects_location`` (``multiple_hits=False``) and ``intersects_first``
against the camera's own path (Embree's scene queried directly, one ray per call and 16 per
call, float64 plane distance); the 640 x 480 and the planners' 160 x 120 captures also with
one ray per call, in the same run;
and the CPU share (process CPU time / wall time) and OS thread count, to show whether
Embree ran on more than one thread. The process is pinned to one CPU (``--no-pin`` to
leave it free) and numpy's BLAS to one thread. Timings are never asserted.

    .venv/bin/python bench/bench_camera.py            # ~20 s
    .venv/bin/python bench/bench_camera.py --quick    # smoke run, a few seconds
    .venv/bin/python bench/bench_camera.py --json     # results as JSON on stdout
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import os

# One thread everywhere, set before numpy is imported (OpenBLAS idle threads otherwise spin
# and inflate the CPU share).
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
             "TBB_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import trimesh  # noqa: E402
from benchutil import machine_info, pin_to_one_cpu, timed  # noqa: E402

from ft_sitl.scenarios.camera import (  # noqa: E402
    CameraConfig,
    DepthCamera,
    _rotmat,
    embree_available,
)

SEED = 20240601
N_CYLINDERS = 800
FOREST_X = (0.0, 60.0)
FOREST_Y = (-20.0, 20.0)
TARGET_RAYS_PER_S = 1e6


# --- scene ---------------------------------------------------------------------------------
def forest_scene(n: int = N_CYLINDERS, seed: int = SEED):
    """n vertical cylinders in FOREST_X x FOREST_Y plus a floor; returns (mesh, centres, radii)."""
    rng = np.random.default_rng(seed)
    xs = rng.uniform(*FOREST_X, n)
    ys = rng.uniform(*FOREST_Y, n)
    radii = rng.uniform(0.15, 0.5, n)
    heights = rng.uniform(2.0, 6.0, n)
    parts = []
    for x, y, r, h in zip(xs, ys, radii, heights):
        c = trimesh.creation.cylinder(radius=r, height=h, sections=16)
        c.apply_translation([x, y, h / 2])
        parts.append(c)
    x0, x1 = FOREST_X[0] - 20.0, FOREST_X[1] + 20.0
    y0, y1 = FOREST_Y[0] - 20.0, FOREST_Y[1] + 20.0
    parts.append(trimesh.Trimesh(vertices=[[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]],
                                 faces=[[0, 1, 2], [0, 2, 3]], process=False))
    mesh = trimesh.util.concatenate(parts)
    return mesh, np.stack([xs, ys], axis=1), radii


def quat(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """q_world_body (w, x, y, z) from ZYX Euler angles (yaw about z up, FLU body)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def poses(centres, radii, n: int = 8, seed: int = SEED + 1):
    """n collision-free poses (1-2 m up) in and at the edge of the forest, varied attitude."""
    rng = np.random.default_rng(seed)
    out = [(np.array([-3.0, 0.0, 1.5]), quat(0.0, 0.0, 0.0))]  # at the edge, looking in
    while len(out) < n:
        p = np.array([rng.uniform(5.0, 55.0), rng.uniform(-15.0, 15.0), rng.uniform(1.0, 2.0)])
        if np.min(np.linalg.norm(centres - p[:2], axis=1) - radii) < 0.5:
            continue
        roll, pitch = rng.uniform(-0.2, 0.2, 2)
        out.append((p, quat(roll, pitch, rng.uniform(-math.pi, math.pi))))
    return out


# --- timing --------------------------------------------------------------------------------
def n_threads() -> int | None:
    try:
        return len(os.listdir("/proc/self/task"))
    except OSError:
        return None


def bench_capture(cam: DepthCamera, pose_list, repeats: int, noisy: bool) -> dict:
    rng = np.random.default_rng(SEED + 2) if noisy else None
    for p, q in pose_list[:2]:
        cam.capture(0, p, q, rng=rng)
    hits = []

    def run():
        for k, (p, q) in enumerate(pose_list):
            f = cam.capture(k * 33_333, p, q, rng=rng)
            hits.append(f.points_world.shape[0])

    t = timed(run, repeats)
    frames = len(pose_list)
    rays = frames * cam.config.n_pixels
    return {
        **t,
        "frames_per_repeat": frames,
        "rays_per_repeat": rays,
        "rays_per_s": rays / t["median_s"],
        "rays_per_s_min": rays / t["max_s"],
        "rays_per_s_max": rays / t["min_s"],
        "ms_per_frame": t["median_s"] / frames * 1e3,
        "valid_fraction": float(np.mean(hits)) / cam.config.n_pixels,
    }


def bench_cast_methods(cam: DepthCamera, pose_list, repeats: int,
                       single: DepthCamera) -> dict:
    """Raw cast, no image: the two trimesh queries the camera could be built on."""
    ray = cam._intersector
    jobs = []
    for p, q in pose_list:
        r_wb = _rotmat(q)
        dirs = cam.dirs_optical @ (r_wb @ cam.r_body_optical).T
        origin = p + r_wb @ cam.mount_body
        jobs.append((origin, dirs, np.ascontiguousarray(np.broadcast_to(origin, dirs.shape))))

    def location():
        for _, dirs, origins in jobs:
            ray.intersects_location(origins, dirs, multiple_hits=False)

    def first_only():
        for _, dirs, origins in jobs:
            ray.intersects_first(origins, dirs)

    def first_plane():
        for origin, dirs, _ in jobs:
            cam.cast(origin, dirs)

    def first_plane_single():
        for origin, dirs, _ in jobs:
            single.cast(origin, dirs)

    rays = len(jobs) * cam.config.n_pixels
    out = {}
    for name, fn in [("intersects_location(multiple_hits=False)", location),
                     ("intersects_first only (no distance)", first_only),
                     ("Embree scene, one ray per call (embreex) + float64 plane distance",
                      first_plane_single),
                     ("Embree scene, 16 rays per call + float64 plane distance (used)",
                      first_plane)]:
        fn()
        t = timed(fn, repeats)
        out[name] = {**t, "rays_per_s": rays / t["median_s"],
                     "ms_per_frame": t["median_s"] / len(jobs) * 1e3}
    # the two distance-returning methods agree
    origin, dirs, origins = jobs[0]
    loc, idx, _ = ray.intersects_location(origins, dirs, multiple_hits=False)
    ref = cam.cast(origin, dirs)[idx]
    out["max_abs_difference_m"] = float(np.max(np.abs(np.linalg.norm(loc - origin, axis=1)
                                                      - ref)))
    return out


# --- reporting -----------------------------------------------------------------------------
def print_markdown(res: dict, file=sys.stdout) -> None:
    m, s = res["machine"], res["scene"]
    print(f"# {m['cpu_model']}, {m['n_cpus']} CPUs (pinned to {m['pinned_cpu']}), "
          f"{m['date_utc']}, trimesh {m['trimesh']}, embree {m['embree']}", file=file)
    print(f"# scene: {s['n_cylinders']} cylinders in 40 x 60 m + floor, {s['n_faces']} "
          f"triangles; {s['n_poses']} poses; camera build (BVH) {s['build_s'] * 1e3:.0f} ms",
          file=file)
    print(file=file)
    print("| frame | Embree rays per call | noise | Mrays/s (median) | min..max | ms/frame "
          "| valid px | CPU share |", file=file)
    print("|---|---:|---|---:|---:|---:|---:|---:|", file=file)
    for r in res["capture"]:
        print(f"| {r['width']}x{r['height']} | {16 if r['packets'] else 1} "
              f"| {'k=0.001, 5% drop' if r['noisy'] else 'off'} "
              f"| {r['rays_per_s'] / 1e6:.2f} | {r['rays_per_s_min'] / 1e6:.2f}.."
              f"{r['rays_per_s_max'] / 1e6:.2f} | {r['ms_per_frame']:.1f} "
              f"| {r['valid_fraction']:.0%} | {r['cpu_share_median']:.2f} |", file=file)
    print(file=file)
    print("| raw cast, 640x480, no image | Mrays/s | ms/frame |", file=file)
    print("|---|---:|---:|", file=file)
    for name, r in res["cast_methods"].items():
        if isinstance(r, dict):
            print(f"| {name} | {r['rays_per_s'] / 1e6:.2f} | {r['ms_per_frame']:.1f} |",
                  file=file)
    th = res["threads"]
    print(file=file)
    print(f"target > {TARGET_RAYS_PER_S / 1e6:.0f} M rays/s on one core: "
          f"{'met' if res['capture'][0]['rays_per_s'] > TARGET_RAYS_PER_S else 'NOT met'} "
          f"at 640x480; intersects_location vs plane distance agree to "
          f"{res['cast_methods']['max_abs_difference_m']:.1e} m", file=file)
    pin = "pinned to one CPU" if m["pinned_cpu"] is not None else "not pinned"
    print(f"threads ({pin}): {th['os_threads_before']} OS thread(s) before the cameras, "
          f"{th['os_threads_after']} after; max CPU share {th['cpu_share_max']:.2f} -> ray "
          f"casting {'used more than one thread' if th['multithreaded'] else 'ran on one thread'}",
          file=file)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="few repeats, smoke run")
    ap.add_argument("--json", action="store_true", help="print JSON instead of markdown")
    ap.add_argument("--cpu", type=int, default=None, help="CPU to pin to (default: last)")
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU")
    args = ap.parse_args(argv)

    cpu = None if args.no_pin else pin_to_one_cpu(args.cpu)
    repeats = 3 if args.quick else 9
    threads_before = n_threads()

    mesh, centres, radii = forest_scene()
    pose_list = poses(centres, radii)
    t0 = time.perf_counter()
    cam_full = DepthCamera(CameraConfig(), mesh)
    build_s = time.perf_counter() - t0
    cam_half = DepthCamera(CameraConfig().subsampled(2), mesh)
    noisy_cfg = CameraConfig(noise_k=0.001, dropout=0.05)
    cam_noisy = DepthCamera(noisy_cfg, mesh)

    # the planners' 160 x 120 camera, Embree queried 16 rays per call (default) and one ray
    # per call (embreex), timed in the same run
    planners = CameraConfig().subsampled(4)
    cam_q = DepthCamera(planners, mesh)
    cam_q1 = DepthCamera(planners, mesh, packets=False)
    cam_full1 = DepthCamera(CameraConfig(), mesh, packets=False)

    capture = []
    for cam, noisy in [(cam_full, False), (cam_full1, False), (cam_half, False),
                       (cam_q, False), (cam_q1, False), (cam_noisy, True)]:
        r = bench_capture(cam, pose_list, repeats, noisy)
        capture.append({"width": cam.config.width, "height": cam.config.height,
                        "noisy": noisy, "packets": cam._packets is not None, **r})
    cast = bench_cast_methods(cam_full, pose_list, max(3, repeats // 3), cam_full1)
    threads_after = n_threads()
    share_max = max([r["cpu_share_max"] for r in capture]
                    + [v["cpu_share_max"] for v in cast.values() if isinstance(v, dict)])
    res = {
        "machine": machine_info(cpu, trimesh=trimesh.__version__, embree=embree_available()),
        "scene": {"n_cylinders": N_CYLINDERS, "n_faces": int(len(mesh.faces)),
                  "n_poses": len(pose_list), "seed": SEED, "build_s": build_s},
        "repeats": repeats,
        "capture": capture,
        "cast_methods": cast,
        "threads": {"os_threads_before": threads_before, "os_threads_after": threads_after,
                    "cpu_share_max": share_max,
                    "multithreaded": bool(share_max > 1.05)},
        "target_rays_per_s": TARGET_RAYS_PER_S,
    }
    if args.json:
        json.dump(res, sys.stdout, indent=2)
        print()
    else:
        print_markdown(res)
    return 0


if __name__ == "__main__":
    sys.exit(main())
