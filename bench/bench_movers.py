"""Benchmark: what moving obstacles cost (issue 24's target: at most 20 % more wall time
per trial in Forest with 10 movers).

Three measurements, each timed in turn static / with movers, ``--repeats`` times, medians
compared (ratios measured in one run: this machine is shared):

* **trials**: the same Forest trials (configurations 1-4, two trial numbers, the baseline,
  EGO and Fast-Planner on one platform) flown in the static world and with 10 movers
  (``{"count": 10}``: mixed paths, people at 1.5 m/s). The flights differ (movers block
  and crash vehicles), so the comparison is wall time per simulated second of the trial
  as well as per trial; the movers' placement (cached per process after the first trial
  of each seed) is included.
* **physics**: a vehicle hovering 1 m from a mover's path versus in an empty world: the
  guard's chunked stepping near movers, the worst case per simulated second.
* **camera**: a 640 x 480 frame with 10 movers in view versus none.

    .venv/bin/python bench/bench_movers.py              # ~4 min
    .venv/bin/python bench/bench_movers.py --json
"""

from __future__ import annotations

# isort: off
import ft_sitl  # noqa: F401  (its BLAS settings before numpy loads)
# isort: on

import argparse  # noqa: E402
import json  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import trimesh  # noqa: E402
from benchutil import machine_info  # noqa: E402

from ft_sitl.missions.spec import TrialSpec  # noqa: E402
from ft_sitl.missions.trial import run_trial  # noqa: E402
from ft_sitl.physics.catalog import get_platform  # noqa: E402
from ft_sitl.scenarios import movers as mv  # noqa: E402
from ft_sitl.scenarios.camera import DepthCamera  # noqa: E402
from ft_sitl.scenarios.collision import CollisionWorld  # noqa: E402
from ft_sitl.scenarios.families import build_scenario  # noqa: E402
from ft_sitl.sim.guard import CollisionGuard  # noqa: E402
from ft_sitl.sim.lockstep import Simulation  # noqa: E402

PLATFORM = "0.98kg-EGO Planner DIY"
MOVERS = {"count": 10}


def trials(repeats: int, algorithms) -> dict:
    specs = [TrialSpec(algorithm=a, platform=PLATFORM, family="forest", scenario_index=k,
                       trial=t, seed=11)
             for a in algorithms for k in (1, 2, 3, 4) for t in (0, 1)]
    for s in specs:  # compile, build every scenario's grid and place its movers once
        run_trial(s)
        run_trial(TrialSpec(**{**s.__dict__, "movers": MOVERS}))
    wall = {"static": [], "movers": []}
    per_s = {"static": [], "movers": []}
    outcomes = {}
    for _ in range(repeats):
        for case in ("static", "movers"):
            w = sim = 0.0
            for s in specs:
                spec = s if case == "static" else TrialSpec(**{**s.__dict__,
                                                               "movers": MOVERS})
                t0 = time.perf_counter()
                row = run_trial(spec).row
                w += time.perf_counter() - t0
                sim += row["sim_time_s"]
                outcomes.setdefault(case, {}).setdefault(row["reason"], 0)
                outcomes[case][row["reason"]] += 1
            wall[case].append(w / len(specs))
            per_s[case].append(w / sim)
    out = {k: statistics.median(v) for k, v in wall.items()}
    ps = {k: statistics.median(v) for k, v in per_s.items()}
    return {"trials": len(specs), "algorithms": list(algorithms),
            "wall_per_trial_s": out, "wall_per_sim_s": ps,
            "ratio_per_trial": out["movers"] / out["static"],
            "ratio_per_sim_s": ps["movers"] / ps["static"],
            "outcomes_per_repeat": {c: {r: n // repeats for r, n in o.items()}
                                    for c, o in outcomes.items()}}


def physics(repeats: int, seconds: float = 10.0) -> dict:
    p = get_platform(PLATFORM)
    world = CollisionWorld(trimesh.Trimesh(), [-30.0, -30.0, 0.0], [30.0, 30.0, 6.0])
    near = mv.movers_from_list([{"shape": "person", "radius_m": 0.4, "height_m": 2.0,
                                 "points": [[-20, 1.0 + 0.4 + 0.25], [20, 1.65]],
                                 "speed_m_s": 1.5}])
    times = {"empty": [], "a mover passing 0.25 m away": []}
    for _ in range(repeats + 1):  # (the first round compiles: not counted)
        for case, movers in (("empty", None), ("a mover passing 0.25 m away", near)):
            sim = Simulation([p])
            sim.start_hovering(0, [0.0, 1.0, 1.0])
            guard = CollisionGuard(world, [p.body().bounding_radius_m], bodies=[p.body()])
            guard.set_movers(movers)
            sim.attach_guard(guard)
            sim.run(0.01)
            t0 = time.perf_counter()
            sim.run(seconds)
            times[case].append((time.perf_counter() - t0) / seconds)
    med = {k: statistics.median(v[1:]) for k, v in times.items()}
    return {"wall_per_sim_s": med,
            "ratio": med["a mover passing 0.25 m away"] / med["empty"]}


def camera(repeats: int, frames: int = 20) -> dict:
    sc = build_scenario("forest", 3)
    cam = DepthCamera(None, sc.mesh)
    p = np.array([sc.start[0], sc.start[1], sc.start[2]])
    # ten people in a fan 3-8 m ahead of the camera (looking along +y, north)
    items = [{"shape": "person", "radius_m": 0.4, "height_m": 2.0,
              "points": [[p[0] - 3.0 + 0.7 * k, p[1] + 3.0 + 0.5 * k]], "speed_m_s": 0.0}
             for k in range(10)]
    m = mv.movers_from_list(items)
    q = np.array([np.cos(np.pi / 4), 0.0, 0.0, np.sin(np.pi / 4)])  # yaw 90 deg: north
    times = {"static": [], "10 movers in view": []}
    cam.capture(0, p, q, movers=m, movers_time_us=0)  # compiled before timing
    for _ in range(repeats):
        for case, movers in (("static", None), ("10 movers in view", m)):
            t0 = time.perf_counter()
            for _f in range(frames):
                cam.capture(0, p, q, movers=movers, movers_time_us=0)
            times[case].append((time.perf_counter() - t0) / frames)
    med = {k: statistics.median(v) for k, v in times.items()}
    covered = np.isfinite(cam.capture(0, p, q, movers=m, movers_time_us=0).depth).mean()
    return {"ms_per_frame": {k: 1e3 * v for k, v in med.items()},
            "ratio": med["10 movers in view"] / med["static"],
            "valid_pixel_fraction_with_movers": float(covered)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--algorithms", default="straight,ego,fast")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    out = {"machine": machine_info(None), "camera": camera(a.repeats),
           "physics": physics(a.repeats),
           "trials": trials(a.repeats, a.algorithms.split(","))}
    if a.json:
        print(json.dumps(out, indent=1))
        return
    c, ph, tr = out["camera"], out["physics"], out["trials"]
    print(f"camera: {c['ms_per_frame']['static']:.1f} ms/frame static, "
          f"{c['ms_per_frame']['10 movers in view']:.1f} with 10 movers in view "
          f"(x{c['ratio']:.3f})")
    print(f"physics: x{ph['ratio']:.2f} per simulated second hovering beside a mover's path")
    print(f"trials ({tr['trials']}, {', '.join(tr['algorithms'])}): "
          f"{tr['wall_per_trial_s']['static']:.2f} s -> {tr['wall_per_trial_s']['movers']:.2f}"
          f" s per trial (x{tr['ratio_per_trial']:.3f}); per simulated second "
          f"x{tr['ratio_per_sim_s']:.3f}; outcomes {tr['outcomes_per_repeat']}")


if __name__ == "__main__":
    main()
