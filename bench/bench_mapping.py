"""Benchmark: the planners' local map (ft_sitl.navigation.maps.mapping), one core.

Scene: FLYINGTRUST Forest configuration 5 (``build_scenario("forest", 5)``, 3 m ceiling).
The camera flies the start->goal line at 4 m/s; frames at the map's 20 Hz (0.2 m apart) are
captured first (capture time excluded) at 640 x 480 (the default camera) and 320 x 240
(``subsampled(2)``), then fused in order into a fresh map, every fuse timed on its own.

Reported, medians over repeats of the whole sequence: ms per fused frame (median, p90, max;
the max includes the window re-centring shifts), rays and voxels updated per frame, the
same with the early stop off (every ray traced in full: the originals' speed-up measured)
and how much free space each leaves known; the window shift alone; the ESDF update over the
whole window (Forest: 130 x 130 x 41 voxels; a 10 m ceiling as in Urban: 130 x 130 x 111)
and over a +-4 m box; query throughput (planning occupancy and ESDF with gradient) in
batches and one point per call. The process is pinned to one CPU (``--no-pin`` to leave it
free) and numba/BLAS to one thread. Timings are never asserted.

    .venv/bin/python bench/bench_mapping.py            # ~30 s
    .venv/bin/python bench/bench_mapping.py --quick    # smoke run
    .venv/bin/python bench/bench_mapping.py --json     # results as JSON on stdout
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
import statistics  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from benchutil import machine_info, pin_to_one_cpu, timed  # noqa: E402

from ft_sitl.navigation.maps.mapping import LocalMap, MapConfig  # noqa: E402
from ft_sitl.scenarios.camera import CameraConfig, DepthCamera  # noqa: E402
from ft_sitl.scenarios.families import build_scenario  # noqa: E402

FAMILY, INDEX = "forest", 5
SPEED_M_S = 4.0
MAP_RATE_HZ = 20.0
TARGET_MS = 10.0


def q_yaw(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def capture_sequence(sc, cam_cfg: CameraConfig, n_frames: int):
    """Frames along the start->goal line at SPEED_M_S, MAP_RATE_HZ apart."""
    cam = DepthCamera(cam_cfg, sc.mesh)
    d = sc.goal - sc.start
    d /= np.linalg.norm(d)
    q = q_yaw(math.atan2(d[1], d[0]))
    step = SPEED_M_S / MAP_RATE_HZ
    dt_us = int(1e6 / MAP_RATE_HZ)
    return [cam.capture(k * dt_us, sc.start + d * step * k, q) for k in range(n_frames)]


def bench_fuse(sc, frames, cam_cfg, repeats: int, early_stop: bool = True) -> dict:
    per_frame, stats, known, occupied = [], [], [], []
    LocalMap(None, sc.ceiling, camera=cam_cfg).fuse(frames[0], early_stop=early_stop)  # JIT
    for _ in range(repeats):
        m = LocalMap(None, sc.ceiling, camera=cam_cfg)
        times = []
        gc.collect()
        gc.disable()
        try:
            for f in frames:
                t0 = time.perf_counter()
                st = m.fuse(f, early_stop=early_stop)
                times.append(time.perf_counter() - t0)
                stats.append(st)
        finally:
            gc.enable()
        per_frame.append(times)
        known.append(int(np.count_nonzero(m._logodds >= m._l_known)))
        occupied.append(m.occupied_count)
    t = np.array(per_frame)  # repeats x frames
    med = np.median(t, axis=0)  # per frame, over repeats
    shifted = np.array([s.shifted for s in stats[:len(frames)]])
    return {
        "frames": len(frames),
        "ms_median": float(np.median(med) * 1e3),
        "ms_p90": float(np.percentile(med, 90) * 1e3),
        "ms_max": float(med.max() * 1e3),
        "ms_median_no_shift": float(np.median(med[~shifted]) * 1e3),
        "ms_median_shift_frames": float(np.median(med[shifted]) * 1e3) if shifted.any()
        else None,
        "shifts": int(shifted.sum()),
        "rays_per_frame": float(np.mean([s.rays for s in stats])),
        "hit_rays_per_frame": float(np.mean([s.hit_rays for s in stats])),
        "voxels_updated_per_frame": float(np.mean([s.voxels_updated for s in stats])),
        "known_voxels_end": int(statistics.median(known)),
        "occupied_voxels_end": int(statistics.median(occupied)),
    }


def bench_shift(sc, frames, cam_cfg, repeats: int) -> dict:
    m = LocalMap(None, sc.ceiling, camera=cam_cfg)
    for f in frames[:10]:
        m.fuse(f)
    o = m.origin_index[:2]
    m.shift_to(o + [5, 5])
    m.shift_to(o)
    k = [0]

    def run():
        k[0] += 1
        m.shift_to(o + ([10, 3] if k[0] % 2 else [0, 0]))

    return timed(run, repeats)


def bench_esdf(sc, frames, cam_cfg, repeats: int) -> dict:
    out = {}
    for label, ceiling in (("forest window (3 m ceiling)", sc.ceiling),
                           ("10 m ceiling (Urban)", 10.0)):
        m = LocalMap(None, ceiling, camera=cam_cfg)
        for f in frames[:20]:
            m.fuse(f)
        m.update_esdf()
        for box in (None, 4.0):
            t = timed(lambda m=m, box=box: m.update_esdf(half_extent_m=box), repeats)
            shape = m.update_esdf(half_extent_m=box).shape  # the field just timed (cached)
            out[f"{label}, {'whole window' if box is None else f'+-{box:g} m box'}"] = {
                **t, "shape": list(shape), "voxels": int(np.prod(shape)),
                "ns_per_voxel": t["median_s"] / np.prod(shape) * 1e9}
    return out


def bench_queries(sc, frames, cam_cfg, repeats: int) -> dict:
    m = LocalMap(None, sc.ceiling, camera=cam_cfg)
    for f in frames[:20]:
        m.fuse(f)
    m.update_esdf()
    rng = np.random.default_rng(1)
    lo, hi = m.window_min_m, m.window_max_m
    pts = lo + rng.random((100_000, 3)) * (hi - lo)
    one = pts[0].copy()
    m.occupied_inflated(pts[:10])
    m.esdf(pts[:10])
    out = {}
    for name, fn, n in [
        ("occupied_inflated, 100k points per call", lambda: m.occupied_inflated(pts), len(pts)),
        ("esdf + gradient, 100k points per call", lambda: m.esdf(pts), len(pts)),
        ("occupied_inflated, 1 point per call", lambda: m.occupied_inflated(one), 1),
        ("esdf + gradient, 1 point per call", lambda: m.esdf(one), 1),
    ]:
        if n == 1:
            calls = 2000

            def loop(fn=fn, calls=calls):
                for _ in range(calls):
                    fn()

            t = timed(loop, repeats)
            out[name] = {"us_per_call": t["median_s"] / calls * 1e6,
                         "points_per_s": calls / t["median_s"]}
        else:
            t = timed(fn, repeats)
            out[name] = {"us_per_call": t["median_s"] * 1e6, "points_per_s": n / t["median_s"]}
    return out


# --- reporting -----------------------------------------------------------------------------
def print_markdown(res: dict, file=sys.stdout) -> None:
    m, s = res["machine"], res["scene"]
    print(f"# {m['cpu_model']}, {m['n_cpus']} CPUs (pinned to {m['pinned_cpu']}), "
          f"load {m['load_avg_1min']:.2f}, {m['date_utc']}", file=file)
    print(f"# scene: {s['family']} #{s['index']}, {s['n_faces']} triangles; {s['frames']} "
          f"frames at {MAP_RATE_HZ:g} Hz along the start->goal line at {SPEED_M_S:g} m/s; "
          f"map window {s['window_shape']}", file=file)
    print(file=file)
    print("| fuse | early stop | frames | ms/frame median | p90 | max | median w/o shift "
          "| rays/frame | voxels updated/frame | known voxels at end | occupied at end |",
          file=file)
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|", file=file)
    for r in res["fuse"]:
        print(f"| {r['camera']} | {'on' if r['early_stop'] else 'off'} | {r['frames']} "
              f"| {r['ms_median']:.2f} "
              f"| {r['ms_p90']:.2f} | {r['ms_max']:.2f} | {r['ms_median_no_shift']:.2f} "
              f"| {r['rays_per_frame']:.0f} | {r['voxels_updated_per_frame']:.0f} "
              f"| {r['known_voxels_end']} | {r['occupied_voxels_end']} |", file=file)
    sh = res["shift"]
    print(f"\nwindow shift (10 x 3 voxels, dilation edges recounted): "
          f"{sh['median_s'] * 1e3:.2f} ms median", file=file)
    print("\n| ESDF update | voxels | ms median | min | ns/voxel |", file=file)
    print("|---|---:|---:|---:|---:|", file=file)
    for name, r in res["esdf"].items():
        print(f"| {name} | {r['voxels']} | {r['median_s'] * 1e3:.1f} | {r['min_s'] * 1e3:.1f} "
              f"| {r['ns_per_voxel']:.1f} |", file=file)
    print("\n| query | us/call | points/s |", file=file)
    print("|---|---:|---:|", file=file)
    for name, r in res["queries"].items():
        print(f"| {name} | {r['us_per_call']:.1f} | {r['points_per_s']:.3g} |", file=file)
    f640 = next(r for r in res["fuse"] if r["camera"] == "640x480" and r["early_stop"])
    print(f"\ntarget: fuse a 640x480 frame in well under {TARGET_MS:g} ms on one core: "
          f"median {f640['ms_median']:.2f} ms, max {f640['ms_max']:.2f} ms", file=file)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="few frames and repeats, smoke run")
    ap.add_argument("--json", action="store_true", help="print JSON instead of markdown")
    ap.add_argument("--cpu", type=int, default=None, help="CPU to pin to (default: last)")
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU")
    args = ap.parse_args(argv)

    cpu = None if args.no_pin else pin_to_one_cpu(args.cpu)
    repeats = 3 if args.quick else 7
    n_frames = 20 if args.quick else 60

    sc = build_scenario(FAMILY, INDEX)
    full, half = CameraConfig(), CameraConfig().subsampled(2)
    seq = {"640x480": (full, capture_sequence(sc, full, n_frames)),
           "320x240": (half, capture_sequence(sc, half, n_frames))}

    fuse = []
    for label, (cfg, frames) in seq.items():
        fuse.append({"camera": label, "early_stop": True,
                     **bench_fuse(sc, frames, cfg, repeats)})
    # every ray traced in full (slow): fewer frames and repeats
    cfg, frames = seq["640x480"]
    fuse.append({"camera": "640x480", "early_stop": False,
                 **bench_fuse(sc, frames[:max(10, n_frames // 3)], cfg, max(1, repeats // 3),
                              early_stop=False)})
    short = {"camera": "640x480", "early_stop": True,
             **bench_fuse(sc, frames[:max(10, n_frames // 3)], cfg, max(1, repeats // 3))}
    res = {
        "machine": machine_info(cpu, numba=__import__("numba").__version__),
        "scene": {"family": FAMILY, "index": INDEX, "n_faces": int(len(sc.mesh.faces)),
                  "frames": n_frames,
                  "window_shape": list(LocalMap(None, sc.ceiling).shape)},
        "config": {k: getattr(MapConfig(), k) for k in MapConfig.__dataclass_fields__},
        "repeats": repeats,
        "fuse": fuse,
        "early_stop_same_frames": short,
        "shift": bench_shift(sc, seq["640x480"][1], full, repeats * 3),
        "esdf": bench_esdf(sc, seq["640x480"][1], full, repeats),
        "queries": bench_queries(sc, seq["640x480"][1], full, repeats),
        "target_ms_per_frame": TARGET_MS,
    }
    if args.json:
        json.dump(res, sys.stdout, indent=2, default=float)
        print()
    else:
        print_markdown(res)
        s = res["early_stop_same_frames"]
        off = fuse[-1]
        print(f"early stop vs full tracing over the same {off['frames']} frames: "
              f"{off['ms_median'] / s['ms_median']:.0f}x faster; known voxels at the end "
              f"{s['known_voxels_end']} vs {off['known_voxels_end']} "
              f"({s['known_voxels_end'] / off['known_voxels_end']:.0%}); occupied "
              f"{s['occupied_voxels_end']} vs {off['occupied_voxels_end']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
