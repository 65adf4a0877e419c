"""Re-fly stored Sudden-Drop configuration-1 rows of docs/results/envelope/series-acc with
the block 8 m wide (x 21-29 m, `sudden-drop-01-block-8m.toml`, `block-8m.stl`) instead of
the area's full 50 m; everything else as stored (same spec, seed, y extent 29.60-32.35 m,
underside 1.5 m, top 14 m, ceiling 4 m).

    python block_width.py ID [ID ...]   > counterfactual-block-8m.csv

The STL is one box: trimesh.creation.box(extents=(8, 2.7495, 12.5)) moved to its centre
(25, 30.9758, 7.75).
"""

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import json
import sys
from pathlib import Path

import pandas as pd

from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import run_trial

HERE = Path(__file__).resolve().parent
ROWS = pd.read_parquet(HERE.parents[3] / "docs/results/envelope/series-acc/trials.parquet")
print("trial_id,algorithm,platform,acc,stored_reason,stored_detail,reason,detail,nav_time_s,"
      "min_clearance_m", flush=True)
for prefix in sys.argv[1:]:
    r = ROWS[ROWS.trial_id.str.startswith(prefix)].iloc[0]
    spec = json.loads(r.spec)
    spec["scenario_file"] = str(HERE / "sudden-drop-01-block-8m.toml")
    row = run_trial(TrialSpec.from_dict(spec), wall_budget_s=None).row
    print(f"{r.trial_id},{r.algorithm},{r.platform},{r.acc_limit_m_s2:g},{r.reason},"
          f"\"{r.detail}\",{row['reason']},\"{row['detail']}\",{row['nav_time_s']:.2f},"
          f"{row['min_clearance_m']:.3f}", flush=True)
