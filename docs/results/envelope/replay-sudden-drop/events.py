"""Re-fly stored Sudden-Drop rows of docs/results/envelope/series-acc with the planner's
events recorded; one JSON line per row on stdout.

    python events.py ID [ID ...]        (trial ids or unique prefixes; run from anywhere)

Per row: whether the re-flown row equals the stored one (``identical``), the outcome,
where the vehicle ended (and against which block face), the first plan that leaves the
straight 2.5 m line within 1 m before the first block face (when, how far from the face,
its lowest and highest point and largest sideways offset there), every emergency stop
(time, position, speed) and the failed plans by reason. The hooks only read the
navigator: they wrap ReplanningPlanner._stop, _failed and _adopt_at.
"""

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from ft_sitl.cli.missions import differences
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import run_trial
from ft_sitl.navigation.planners import skeleton as sk
from ft_sitl.physics.dynamics import X_POS
from ft_sitl.scenarios.families import build_scenario

ROOT = Path(__file__).resolve().parents[4]
ROWS = pd.read_parquet(ROOT / "docs/results/envelope/series-acc/trials.parquet")
events: list[tuple] = []
current: dict = {}

_step, _stop, _failed, _adopt_at = (sk.ReplanningPlanner.step, sk.ReplanningPlanner._stop,
                                    sk.ReplanningPlanner._failed, sk.ReplanningPlanner._adopt_at)


def step(self, obs):
    current["obs"] = obs
    return _step(self, obs)


def stop(self, point):
    o = current["obs"]
    events.append(("STOP", o.time_s, np.array(o.position), np.array(o.velocity)))
    return _stop(self, point)


def failed(self, obs, p0, why, t_start):
    events.append(("FAIL", obs.time_s, np.array(obs.position), why))
    return _failed(self, obs, p0, why, t_start)


def adopt_at(self, traj, obs, latency):
    if traj is not None:
        pts = traj.spline.position(np.linspace(0.0, traj.spline.duration, 80))
        events.append(("PLAN", obs.time_s, np.array(obs.position), pts))
    return _adopt_at(self, traj, obs, latency)


sk.ReplanningPlanner.step, sk.ReplanningPlanner._stop = step, stop
sk.ReplanningPlanner._failed, sk.ReplanningPlanner._adopt_at = failed, adopt_at


def first_reaction(face_y: float) -> dict | None:
    for kind, t, pos, pts in events:
        if kind != "PLAN":
            continue
        near = (pts[:, 1] > face_y - 1.0) & (pts[:, 1] < face_y + 0.5)
        if not near.any():
            continue
        zmin, zmax = float(pts[near, 2].min()), float(pts[near, 2].max())
        xdev = float(np.abs(pts[near, 0] - 25.0).max())
        if zmin < 2.2 or zmax > 2.8 or xdev > 0.5:
            return {"t": round(t, 2), "y": round(float(pos[1]), 2),
                    "to_face": round(face_y - float(pos[1]), 2), "zmin": round(zmin, 2),
                    "zmax": round(zmax, 2), "xdev": round(xdev, 2)}
    return None


for prefix in sys.argv[1:]:
    r = ROWS[ROWS.trial_id.str.startswith(prefix)].iloc[0]
    spec = TrialSpec.from_dict(json.loads(r.spec))
    blocks = build_scenario("sudden_drop", int(r.scenario_index),
                            int(r.scenario_seed)).provenance["layout"]["blocks_y_m"]
    faces, backs = [b[0] for b in blocks], [b[1] for b in blocks]
    events.clear()
    trace = []
    row = run_trial(spec, wall_budget_s=None, monitor=lambda fleet, t_us: trace.append(
        tuple(fleet.sim.x[0][X_POS:X_POS + 3]))).row
    path = np.array(trace)
    end = path[-1]
    at = [k for k, (a, b) in enumerate(zip(faces, backs)) if a - 0.6 <= end[1] <= b + 0.3]
    fails: dict = {}
    for e in events:
        if e[0] == "FAIL":
            fails[e[3]] = fails.get(e[3], 0) + 1
    print(json.dumps({
        "trial_id": r.trial_id, "algorithm": r.algorithm, "platform": r.platform,
        "scenario": int(r.scenario_index), "acc": float(r.acc_limit_m_s2),
        "identical": not differences(row, r.to_dict()), "reason": row["reason"],
        "detail": row["detail"], "nav_time_s": row["nav_time_s"],
        "first_face_y": round(faces[0], 2),
        "end_x": round(float(end[0]), 2), "end_y": round(float(end[1]), 2),
        "end_z": round(float(end[2]), 2), "end_block": at[0] + 1 if at else None,
        "end_to_face": round(float(faces[at[0]] - end[1]), 2) if at else None,
        "max_z": round(float(path[:, 2].max()), 2),
        "max_xdev": round(float(np.abs(path[:, 0] - 25.0).max()), 2),
        "first_reaction": first_reaction(faces[0]),
        "stops": [{"t": round(t, 2), "x": round(float(p[0]), 2), "y": round(float(p[1]), 2),
                   "z": round(float(p[2]), 2), "speed": round(float(np.linalg.norm(v)), 2)}
                  for kind, t, p, v in events if kind == "STOP"],
        "fails": fails, "n_plans": sum(e[0] == "PLAN" for e in events)}), flush=True)
