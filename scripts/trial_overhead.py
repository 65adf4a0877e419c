"""Issue 43, point 3: what a trial costs beyond its flight once a worker is warm. Flies
the ``--rows`` shortest stored rows of one algorithm from docs/results/paper-pinned-sample
twice in one process (the first pass builds the scenes, grids, cameras and JIT code the
caches of missions/resources.py keep), the second under cProfile, and prints the
cumulative times of the trial's phases: set-up (run_trial minus approach and navigation),
the approach, the navigation, and inside it the camera, the map, the navigator and the
judges::

    .venv/bin/python scripts/trial_overhead.py ego --rows 8
"""

# isort: off
import ft_sitl  # noqa: F401  (first: its numeric pins before numpy loads)
# isort: on

import argparse  # noqa: E402
import cProfile  # noqa: E402
import json  # noqa: E402
import pstats  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import pandas as pd  # noqa: E402

from ft_sitl.missions.spec import TrialSpec  # noqa: E402
from ft_sitl.missions.trial import run_trial  # noqa: E402

SAMPLE = Path(__file__).resolve().parents[1] / "docs/results/paper-pinned-sample/trials.parquet"
#: phase -> (file suffix, function) whose cumulative time it is
PHASES = {
    "trial": ("missions/trial.py", "run_trial"),
    "approach": ("missions/trial.py", "_approach"),
    "navigation": ("missions/trial.py", "_navigate"),
    "camera": ("missions/trial.py", "frame"),
    "map fusion": ("navigation/maps/mapping.py", "fuse"),
    "navigator steps": ("missions/trial.py", "_ask"),
    "judges": ("missions/protocol.py", "after_step"),
    "physics + controller": ("sim/fleet.py", "run_us"),
}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("algorithm")
    ap.add_argument("--rows", type=int, default=8)
    args = ap.parse_args()
    df = pd.read_parquet(SAMPLE)
    df = df[df.algorithm == args.algorithm].sort_values("sim_time_s").head(args.rows)
    specs = [TrialSpec.from_dict(json.loads(s)) for s in df.spec]
    for spec in specs:
        run_trial(spec)
    prof = cProfile.Profile()
    t0 = time.perf_counter()
    prof.enable()
    sim = sum(run_trial(spec).row["sim_time_s"] for spec in specs)
    prof.disable()
    wall = time.perf_counter() - t0
    stats = pstats.Stats(prof).stats
    cum: dict[str, float] = {}
    for (path, _line, fn), (_cc, _nc, _tt, ct, _callers) in stats.items():
        for phase, (suffix, name) in PHASES.items():
            if fn == name and path.endswith(suffix):
                cum[phase] = cum.get(phase, 0.0) + ct
    total = cum.get("trial", wall)
    setup = total - cum.get("approach", 0.0) - cum.get("navigation", 0.0)
    print(f"{len(specs)} {args.algorithm} rows, {sim:.1f} simulated s, {wall:.2f} s wall "
          f"(profiled)")
    print(f"  set-up {setup:.3f} s ({setup / len(specs) * 1e3:.0f} ms per trial, "
          f"{setup / total:.1%})")
    for phase in PHASES:
        if phase != "trial" and phase in cum:
            print(f"  {phase}: {cum[phase]:.3f} s ({cum[phase] / total:.1%})")


if __name__ == "__main__":
    main()
