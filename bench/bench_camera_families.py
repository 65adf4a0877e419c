"""Benchmark: the planners' depth camera (160 x 120) in each scenario family, one core.

For each family (configuration 2 unless ``--index``), the same random poses (uniform over
the flight volume, random yaw) are captured by two cameras built in the same process: one
Embree scene over all triangles (``DepthCamera(..., instances=False)``) and the default,
one Embree instance per connected mesh piece in its own principal-axes frame. The two
captures alternate frame by frame, so a change in the machine's speed hits both alike.

Reported per family: the mesh's triangles and pieces, ms per frame for each (whole
``capture``: rays, query, plane distances, depth image), their ratio, and the pixels whose
depth differs between the two (rays through an edge or grazing a silhouette). Timings are
never asserted.

    .venv/bin/python bench/bench_camera_families.py            # ~1 min
    .venv/bin/python bench/bench_camera_families.py --frames 50 --json
    .venv/bin/python bench/bench_camera_families.py --all-versions   # older generators too
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
import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
from benchutil import machine_info, pin_to_one_cpu  # noqa: E402

from ft_sitl.scenarios.camera import DepthCamera, camera_config  # noqa: E402
from ft_sitl.scenarios.families import FAMILIES, REGISTRY, build_scenario  # noqa: E402


def family_row(family: str, index: int, frames: int, seed: int,
               version: int | None = None) -> dict:
    sc = build_scenario(family, index, version=version)
    cfg = camera_config("benchmark", None, None, None)
    plain = DepthCamera(cfg, sc.mesh, instances=False)
    inst = DepthCamera(cfg, sc.mesh)
    rng = np.random.default_rng(seed)
    lo, hi = np.asarray(sc.bounds_min), np.asarray(sc.bounds_max)
    t_plain = t_inst = 0.0
    differ = 0
    for k in range(frames):
        p = lo + rng.random(3) * (hi - lo)
        yaw = rng.uniform(-np.pi, np.pi)
        q = np.array([np.cos(yaw / 2), 0.0, 0.0, np.sin(yaw / 2)])
        t0 = time.perf_counter()
        a = plain.capture(k * 1000, p, q).depth
        t1 = time.perf_counter()
        b = inst.capture(k * 1000, p, q).depth
        t2 = time.perf_counter()
        t_plain += t1 - t0
        t_inst += t2 - t1
        differ += int(np.sum(~((a == b) | (np.isnan(a) & np.isnan(b)))))
    pieces = len(inst._packets.offset) if inst._packets is not None else None
    return {"family": family, "version": sc.provenance["generator_version"], "index": index,
            "triangles": int(len(sc.mesh.faces)),
            "pieces": pieces, "ms_one_scene": 1000 * t_plain / frames,
            "ms_instances": 1000 * t_inst / frames, "ratio": t_inst / t_plain,
            "pixels_differing": differ, "pixels": frames * cfg.n_pixels}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=500, help="frames per family (500)")
    ap.add_argument("--index", type=int, default=2, help="configuration 1-10 (2)")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--json", action="store_true", help="results as JSON on stdout")
    ap.add_argument("--no-pin", action="store_true", help="do not pin to one CPU")
    ap.add_argument("--all-versions", action="store_true",
                    help="a row for every generator version of each family (default: the "
                         "newest)")
    args = ap.parse_args()
    if args.frames < 1:
        ap.error(f"--frames must be >= 1, got {args.frames}")
    if not 1 <= args.index <= 10:
        ap.error(f"--index must be within 1..10, got {args.index}")
    cpu = None if args.no_pin else pin_to_one_cpu(None)
    rows = [family_row(f, args.index, args.frames, args.seed, v) for f in FAMILIES
            for v in (sorted(REGISTRY[f].versions) if args.all_versions else [None])]
    if args.json:
        print(json.dumps({"machine": machine_info(cpu), "rows": rows}, indent=1))
        return
    print(f"planners' camera 160 x 120, configuration {args.index}, {args.frames} frames "
          f"per family, CPU {cpu}")
    print(f"{'family':<24}{'v':>3}{'triangles':>10}{'pieces':>8}{'one scene ms':>14}"
          f"{'instances ms':>14}{'ratio':>7}{'px differ':>11}")
    for r in rows:
        print(f"{r['family']:<24}{r['version']:>3}{r['triangles']:>10}{r['pieces']:>8}"
              f"{r['ms_one_scene']:>14.3f}{r['ms_instances']:>14.3f}{r['ratio']:>7.2f}"
              f"{r['pixels_differing']:>7} / {r['pixels'] // 1000}k")


if __name__ == "__main__":
    main()
