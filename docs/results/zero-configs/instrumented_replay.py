"""Instrumented replay of one stored trial (docs/results/zero-configs/README.md).

    python docs/results/zero-configs/instrumented_replay.py RUN_DIR TRIAL_ID_PREFIX OUT.pkl \
        X0,X1,Y0,Y1 [SNAP_EVERY_S]

Flies the row's spec with its own navigator instance (``run_trial(..., navigator=nav,
monitor=...)``), logs the true pose and yaw after every advance, and every SNAP_EVERY_S
(default 0.5 s) stores a horizontal slice of the navigator's planning map at the vehicle's
altitude over the box X0..X1, Y0..Y1 (0.1 m voxels): inflated occupancy (what it plans
against; unknown counts as free), raw occupancy and the observed mask. It then compares the
new row with the stored one (all but wall-clock columns) and prints REPRODUCED or the
differences. The monitor only reads the simulation and the map.
"""

import json
import os
import pickle
import sys

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import numpy as np

from ft_sitl.cli.missions import differences
from ft_sitl.missions.results import rows_from_parquet
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import navigator_params, run_trial
from ft_sitl.navigation.registry import create

runs, tid, out = sys.argv[1], sys.argv[2], sys.argv[3]
box = [float(v) for v in sys.argv[4].split(",")]
snap_every = float(sys.argv[5]) if len(sys.argv) > 5 else 0.5
rows = (
    [json.loads(line) for line in open(runs + "/trials.jsonl") if line.strip()]
    if os.path.exists(runs + "/trials.jsonl")
    else rows_from_parquet(runs + "/trials.parquet")
)
row = [r for r in rows if r["trial_id"].startswith(tid)]
assert len(row) == 1, f"{len(row)} rows match {tid}"
row = row[0]
spec = TrialSpec.from_dict(json.loads(row["spec"]))
nav = create(spec.algorithm, navigator_params(spec))
log, snaps = [], []
state = {"next": 0.0}
xs = np.arange(box[0] + 0.05, box[1], 0.1)
ys = np.arange(box[2] + 0.05, box[3], 0.1)


def monitor(fleet, t_us):
    t = t_us * 1e-6
    s = fleet.true_state(0)
    log.append((t, *s.position.tolist(), float(s.yaw)))
    if t >= state["next"]:
        state["next"] += snap_every
        m = getattr(nav, "map", None)
        if m is None:
            return
        z = float(s.position[2])
        pts = np.stack(np.meshgrid(xs, ys, [z], indexing="ij"), -1).reshape(-1, 3)
        shape = (len(xs), len(ys))
        snaps.append(
            dict(
                t=t,
                pos=s.position.copy(),
                yaw=float(s.yaw),
                z=z,
                occ=m.occupied_inflated(pts).reshape(shape),
                raw=m.occupied(pts).reshape(shape),
                known=m.is_known(pts).reshape(shape),
            )
        )


res = run_trial(spec, record=True, navigator=nav, monitor=monitor)
diff = differences(res.row, row)
print(tid, res.row["reason"], res.row["detail"], "L={:.2f}".format(res.row["path_length_m"]))
print("REPRODUCED" if not diff else "DIFFERENT: " + "; ".join(diff[:6]))
infl = nav.map.config.inflation_voxels if getattr(nav, "map", None) is not None else None
with open(out, "wb") as fh:
    pickle.dump(
        dict(
            row=row, new=res.row, diff=diff, log=np.array(log), snaps=snaps, xs=xs, ys=ys, infl=infl
        ),
        fh,
    )
