"""Re-fly a stored row of docs/results/envelope/series-acc and print the planner's map on
a vertical slice across the route (the plane y = Y, x 19.0-30.8 m every 0.2 m, z 0-4.2 m
every 0.1 m) at the given navigation times.

    python face_slice.py ID T1,T2,... Y    > face-patch.txt

o: occupied (6 or more hits); #: planning-occupied through inflation or the ceiling layer;
.: seen but not occupied (free, or fewer than 6 hits so far); blank: never seen.
"""

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import run_trial
from ft_sitl.navigation.planners import skeleton as sk

ROOT = Path(__file__).resolve().parents[4]
ROWS = pd.read_parquet(ROOT / "docs/results/envelope/series-acc/trials.parquet")
prefix, times, y_plane = sys.argv[1], [float(t) for t in sys.argv[2].split(",")], float(sys.argv[3])
_step = sk.ReplanningPlanner.step


def step(self, obs):
    while times and obs.time_s >= times[0] - 1e-9:
        times.pop(0)
        xs = np.arange(19.0, 31.0, 0.2) + 0.05
        print(f"--- t {obs.time_s:.2f} vehicle {np.round(obs.position, 2)}; slice y = {y_plane}")
        for z in (np.arange(0.0, 4.2, 0.1) + 0.05)[::-1]:
            pts = np.column_stack([xs, np.full_like(xs, y_plane), np.full_like(xs, z)])
            infl = np.asarray(self.map.occupied_inflated(pts))
            occ = np.asarray(self.map.occupied(pts))
            known = np.asarray(self.map.is_known(pts))
            print(f"{z:4.2f} |" + "".join("o" if o else "#" if i else "." if k else " "
                                         for i, o, k in zip(infl, occ, known)) + "|")
    return _step(self, obs)


sk.ReplanningPlanner.step = step
r = ROWS[ROWS.trial_id.str.startswith(prefix)].iloc[0]
print(run_trial(TrialSpec.from_dict(json.loads(r.spec)), wall_budget_s=None).row["detail"])
