"""Benchmark: NavRL's dynamic-obstacle detector and tracker (navigation.learned.navrl_detector), and
NavRL's perception per frame with it, one core.

Scenes: the Maze (configuration 1) and Forest (configuration 5), each with 20 people
walking back and forth on 4-8 m lines (``movers`` count 20, keep-out 2 m, 1 m/s). The
camera flies the start->goal line at NavRL's 1 m/s with a +-0.3 rad yaw sway; frames at the
20 Hz the navigator's map takes them (protocol 6 on), captured first (capture time
excluded), at the benchmark camera's 160 x 120 and the originals' 320 x 240 ("d435").

Reported per scene and camera, medians over repeats of the whole sequence: ms per frame
(median, p90, max) of ``DynamicObstacleTracker.update`` and of its two halves (points and
DBSCAN; association, Kalman filters and classification), points and clusters per frame,
tracks, frames with a dynamic obstacle; and NavRL's whole perception of a frame
(``NavRL._perceive``: tracker, free regions, map fusion) against the plain map fusion
("off"). Times are the thread's CPU time (``time.thread_time``), so other load on the
machine inflates them less than wall time would. The process is pinned to one CPU
(``--no-pin`` to leave it free) and numba/BLAS to one thread. Timings are never asserted.

    FT_SITL_NAVRL_CHECKPOINT=... .venv/bin/python bench/bench_navrl_detector.py   # ~1 min
    .venv/bin/python bench/bench_navrl_detector.py --quick --json
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS",
             "TBB_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import gc  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from benchutil import machine_info, pin_to_one_cpu  # noqa: E402

from ft_sitl.navigation.base import Limits, Observation, Task  # noqa: E402
from ft_sitl.navigation.learned.navrl import NavRL, find_checkpoint  # noqa: E402
from ft_sitl.navigation.learned.navrl_detector import DynamicObstacleTracker  # noqa: E402
from ft_sitl.scenarios.camera import DepthCamera, camera_config  # noqa: E402
from ft_sitl.scenarios.families import build_scenario  # noqa: E402
from ft_sitl.scenarios.movers import place_movers  # noqa: E402

SCENES = (("maze", 1), ("forest", 5))
MOVERS = {"count": 20, "keep_out_m": 2.0, "speed_m_s": 1.0, "path": "line",
          "path_length_m": [4, 8]}
SPEED_M_S = 1.0
RATE_HZ = 20.0


def capture_sequence(sc, movers, cam_cfg, n_frames: int):
    cam = DepthCamera(cam_cfg, sc.mesh)
    d = np.asarray(sc.goal - sc.start, float)
    d[2] = 0.0
    d /= np.linalg.norm(d)
    dt_us = int(1e6 / RATE_HZ)
    frames = []
    for k in range(n_frames):
        t = k * dt_us * 1e-6
        yaw = math.atan2(d[1], d[0]) + 0.3 * math.sin(2.0 * t)
        q = np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])
        frames.append(cam.capture(k * dt_us, sc.start + d * SPEED_M_S * t, q, movers=movers,
                                  movers_time_us=k * dt_us))
    return frames


def stats_ms(t) -> dict:
    t = np.asarray(t) * 1e3
    return {"median": float(np.median(t)), "p90": float(np.percentile(t, 90)),
            "max": float(t.max())}


def bench_tracker(frames, cam_cfg, repeats: int) -> dict:
    runs = []
    for _ in range(repeats):
        tr = DynamicObstacleTracker(cam_cfg)
        whole, detect, rest, points, clusters, tracks, dyn = [], [], [], [], [], [], 0
        gc.collect()
        gc.disable()
        try:
            for f in frames:
                t0 = time.thread_time()
                tr.update(f)
                whole.append(time.thread_time() - t0)
                # the halves, timed again on a copy of the state: detection alone
                t1 = time.thread_time()
                boxes, _ = tr._detect(f, np.asarray(f.p_world_camera),
                                      np.asarray(f.r_world_optical), int(f.t_us))
                detect.append(time.thread_time() - t1)
                rest.append(max(whole[-1] - detect[-1], 0.0))
                clusters.append(len(boxes))
                points.append(sum(b.n_points for b in boxes))
                tracks.append(len(tr.tracks))
                dyn += tr.obstacles().count > 0
        finally:
            gc.enable()
        runs.append((whole, detect, rest))
    med = [np.median(np.array([r[i] for r in runs]), axis=0) for i in range(3)]
    return {"update_ms": stats_ms(med[0]), "points_dbscan_ms": stats_ms(med[1]),
            "track_classify_ms": stats_ms(med[2]),
            "clustered_points_per_frame": float(np.mean(points)),
            "clusters_per_frame": float(np.mean(clusters)),
            "tracks_per_frame": float(np.mean(tracks)), "frames_with_dynamic": dyn,
            "frames": len(frames)}


def bench_perceive(sc, frames, mode: str, camera: str, repeats: int) -> dict:
    runs = []
    for _ in range(repeats):
        nav = NavRL(dynamic_obstacles=mode, camera=camera)
        nav.reset(Task(start=sc.start, start_yaw=sc.start_yaw, goal=sc.goal, limits=Limits(),
                       bounds_min=sc.bounds_min, bounds_max=sc.bounds_max,
                       collision_radius_m=0.3, twr_max=3.0, alpha_xy_max=100.0,
                       alpha_z_max=10.0))
        times = []
        for f in frames:
            obs = Observation(time_s=f.t_us * 1e-6, position=f.p_world_body,
                              velocity=np.zeros(3), yaw=0.0, attitude=f.q_world_body,
                              angular_velocity=np.zeros(3), depth=f)
            t0 = time.thread_time()
            nav._perceive(obs)
            times.append(time.thread_time() - t0)
        runs.append(times)
    return stats_ms(np.median(np.array(runs), axis=0))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a smoke run")
    ap.add_argument("--json", action="store_true", help="results as JSON on stdout")
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU")
    args = ap.parse_args()
    cpu = None if args.no_pin else pin_to_one_cpu(None)
    n_frames, repeats = (40, 1) if args.quick else (200, 3)
    have_policy = find_checkpoint() is not None
    out = {"machine": machine_info(cpu), "frames": n_frames, "repeats": repeats,
           "scenes": {}}
    for family, index in SCENES:
        sc = build_scenario(family, index)
        movers = place_movers(sc, MOVERS, seed=0)
        movers.start(0)
        for camera in ("benchmark", "d435"):
            cam_cfg = camera_config(camera, None, None, None)
            frames = capture_sequence(sc, movers, cam_cfg, n_frames)
            DynamicObstacleTracker(cam_cfg).update(frames[0])  # JIT
            res = {"tracker": bench_tracker(frames, cam_cfg, repeats)}
            if have_policy:  # NavRL needs the checkpoint to be built
                res["perceive_tracked_ms"] = bench_perceive(sc, frames, "tracked", camera,
                                                            repeats)
                res["perceive_off_ms"] = bench_perceive(sc, frames, "off", camera, repeats)
            out["scenes"][f"{family} {index}, {camera}"] = res
            if not args.json:
                t = res["tracker"]
                line = (f"{family} {index} {camera:9s} tracker {t['update_ms']['median']:.2f} "
                        f"ms (p90 {t['update_ms']['p90']:.2f}, max {t['update_ms']['max']:.1f}"
                        f"; points+DBSCAN {t['points_dbscan_ms']['median']:.2f}, tracking "
                        f"{t['track_classify_ms']['median']:.2f}), {t['clusters_per_frame']:.1f}"
                        f" clusters, {t['tracks_per_frame']:.1f} tracks, "
                        f"{t['frames_with_dynamic']}/{t['frames']} frames with a dynamic one")
                if have_policy:
                    line += (f"; NavRL perception {res['perceive_tracked_ms']['median']:.2f} "
                             f"ms vs {res['perceive_off_ms']['median']:.2f} ms off")
                print(line, flush=True)
    if args.json:
        print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
