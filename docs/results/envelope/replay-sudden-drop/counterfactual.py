"""Counterfactual re-flights of stored EGO Sudden-Drop rows of
docs/results/envelope/series-acc: the same spec with one of our choices changed, by
wrapping the navigator's or the map's code in this process only (ft_sitl is unchanged).

    python counterfactual.py MODE ID [ID ...]   > counterfactual-MODE.csv

MODE letters (combine them):

A  EGO's emergency rule as in the original FSM (ego_replan_fsm.cpp, checkCollisionCallback):
   on a collision less than emergency_time_s ahead, replan from the current trajectory at
   once and stop only if that replan fails. Ours (EgoPlanner._emergency) stops whenever
   the collision is that close.
B  after a stop, plan only once the vehicle is slower than 0.1 m/s, from where it is then
   (the original's EMERGENCY_STOP -> GEN_NEW_TRAJ). Ours plans from rest at the stop point
   at once, while the vehicle still moves.
T  emergency_time_s 1.0 (the original's fsm/emergency_time) instead of our 0.8.
C  the planner's map ceiling (its virtual ceiling layer) at 3.0 m instead of the
   scenario's 4 m: a map that ends 0.5 m above the start altitude.
I  the planner's map inflated by one voxel (the originals' obstacles_inflation 0.099 m)
   instead of the body's half span (protocol 4 on).
"""

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import run_trial
from ft_sitl.navigation.maps import mapping
from ft_sitl.navigation.planners import skeleton
from ft_sitl.navigation.planners.ego import EgoPlanner

ROOT = Path(__file__).resolve().parents[4]
ROWS = pd.read_parquet(ROOT / "docs/results/envelope/series-acc/trials.parquet")
mode = sys.argv[1]

if "A" in mode:
    _failed, _succeeded = EgoPlanner._failed, EgoPlanner._succeeded

    def emergency(self, obs, ahead):
        if ahead < self.emergency_time:
            self.cf_emergency = True
            self.retry_at = obs.time_s  # plan at once (the check already asked for a plan)

    def failed(self, obs, p0, why, t_start):
        if getattr(self, "cf_emergency", False) and self.traj is not None:
            self._stop(np.array(obs.position))
        self.cf_emergency = False
        return _failed(self, obs, p0, why, t_start)

    def succeeded(self):
        self.cf_emergency = False
        return _succeeded(self)

    EgoPlanner._emergency, EgoPlanner._failed, EgoPlanner._succeeded = (emergency, failed,
                                                                        succeeded)

if "B" in mode:
    _plan = EgoPlanner._plan

    def plan(self, obs):
        if self.stop_at is not None and self.traj is None:
            if float(np.linalg.norm(obs.velocity)) >= 0.1:
                return  # still braking toward the stop point; plan_now stays set
            self.stop_at = np.array(obs.position)
        return _plan(self, obs)

    EgoPlanner._plan = plan

if "C" in mode or "I" in mode:
    _map_for = mapping.local_map_for

    def map_for(task, camera):
        if "C" in mode:
            top = np.array(task.bounds_max, dtype=float)
            top[2] = min(top[2], 3.0)
            task = dataclasses.replace(task, bounds_max=top)
        if "I" in mode:
            task = dataclasses.replace(task, footprint_m=None)
        return _map_for(task, camera)

    skeleton.local_map_for = map_for

print("trial_id,platform,scenario,acc,stored_reason,stored_detail,mode,reason,detail,"
      "nav_time_s,min_clearance_m", flush=True)
for prefix in sys.argv[2:]:
    r = ROWS[ROWS.trial_id.str.startswith(prefix)].iloc[0]
    spec = TrialSpec.from_dict(json.loads(r.spec))
    if "T" in mode:
        spec = dataclasses.replace(spec, algorithm_params={**(spec.algorithm_params or {}),
                                                           "emergency_time_s": 1.0})
    row = run_trial(spec, wall_budget_s=None).row
    print(f"{r.trial_id},{r.platform},{int(r.scenario_index)},{r.acc_limit_m_s2:g},"
          f"{r.reason},\"{r.detail}\",{mode},{row['reason']},\"{row['detail']}\","
          f"{row['nav_time_s']:.2f},{row['min_clearance_m']:.3f}", flush=True)
