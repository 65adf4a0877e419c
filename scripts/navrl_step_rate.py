"""Issue 43, point 2: what stepping NavRL at its deployment's 20 Hz instead of the trial
driver's 100 Hz would save. Flies the first three NavRL timeouts (one per family) of
docs/results/paper-pinned-sample in-process with ``NavRL.rate_hz`` set to the rate given
(a warm-up flight, then a timed one) and prints each flight's wall time and simulated
time. At 100 Hz the rows are the stored ones; at 20 Hz they are not (see
docs/benchmarks.md, "NavRL at its deployment's rate"), so this is a measurement, not a
protocol. Run it A B A B, pinned to one CPU::

    for r in 100 20 100 20; do
        taskset -c 1 .venv/bin/python scripts/navrl_step_rate.py $r | tail -1
    done
"""

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import pandas as pd  # noqa: E402

from ft_sitl.missions.spec import TrialSpec  # noqa: E402
from ft_sitl.missions.trial import run_trial  # noqa: E402
from ft_sitl.navigation.learned import navrl  # noqa: E402

SAMPLE = Path(__file__).resolve().parents[1] / "docs/results/paper-pinned-sample/trials.parquet"


def main(rate: float) -> None:
    df = pd.read_parquet(SAMPLE)
    df = df[(df.algorithm == "navrl") & (df.reason == "timeout")]
    rows = df.groupby("family").head(1).head(3)
    navrl.NavRL.rate_hz = rate
    wall = sim = 0.0
    for _, r in rows.iterrows():
        spec = TrialSpec.from_dict(json.loads(r["spec"]))
        run_trial(spec)  # warm-up: scene, distance grid, camera, JIT
        t0 = time.perf_counter()
        out = run_trial(spec)
        w = time.perf_counter() - t0
        wall += w
        sim += out.row["sim_time_s"]
        print(r.family, out.row["reason"], f"{w:.2f} s wall", f"{out.row['sim_time_s']:.1f} s sim",
              flush=True)
    print(f"rate {rate:g} Hz: {wall:.2f} s wall for {sim:.1f} s simulated")


if __name__ == "__main__":
    main(float(sys.argv[1]) if len(sys.argv) > 1 else 100.0)
