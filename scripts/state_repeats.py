"""Do the states of a flight that goes nowhere repeat exactly? (issue 43, point 1)

An exact fast-forward of a stalled flight would need the whole state of the trial at a
navigator step to equal, bit for bit, its state at an earlier step. This flies stored rows
again (they must re-run identically: the script checks) and digests, at every 10 ms of
navigation, the plant's state and the controller's rows (a necessary part of the whole
state), the vehicle's position alone, and the navigator's map arrays; it prints how many
steps were nearly still (< 0.05 m/s) and whether any digest was seen before.

    .venv/bin/python scripts/state_repeats.py docs/results/paper-pinned-sample TRIAL_ID ...
"""

# isort: off
import ft_sitl  # noqa: F401  (first: the numeric pins before numpy loads)
# isort: on

import hashlib  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from ft_sitl.missions.plan import navigator_params  # noqa: E402
from ft_sitl.missions.spec import TrialSpec  # noqa: E402
from ft_sitl.missions.trial import run_trial  # noqa: E402
from ft_sitl.navigation.registry import create  # noqa: E402

STILL_M_S = 0.05


def arrays(obj, depth: int = 0) -> list[bytes]:
    """The bytes of every numpy array an object (and the objects it holds) keeps."""
    out = []
    for _, v in sorted(vars(obj).items()):
        if isinstance(v, np.ndarray):
            out.append(v.tobytes())
        elif hasattr(v, "__dict__") and not isinstance(v, type) and depth < 2:
            out += arrays(v, depth + 1)
    return out


def study(row) -> str:
    spec = TrialSpec.from_dict(json.loads(row["spec"]))
    nav = create(spec.algorithm, navigator_params(spec))
    seen_state, seen_pos, seen_all = set(), set(), set()
    counts = {"steps": 0, "still": 0, "state": 0, "position": 0, "all": 0}
    last = [-10_000]

    def monitor(fleet, t_us):
        if t_us - last[0] < 10_000:
            return
        last[0] = t_us
        x, ctrl = fleet.sim.plant.x[0], fleet.sim.ctrl[0]
        state = hashlib.sha1(x.tobytes() + ctrl.tobytes()).digest()
        pos = hashlib.sha1(x[0:3].tobytes()).digest()
        m = getattr(nav, "map", None)
        whole = state + hashlib.sha1(b"".join(arrays(m)) if m is not None else b"").digest()
        counts["steps"] += 1
        counts["still"] += int(np.linalg.norm(fleet.sim.velocity(0)) < STILL_M_S)
        for key, digest, seen in (("state", state, seen_state), ("position", pos, seen_pos),
                                  ("all", whole, seen_all)):
            counts[key] += int(digest in seen)
            seen.add(digest)

    got = run_trial(spec, navigator=nav, wall_budget_s=None, monitor=monitor).row
    same = all(got[k] == row[k] for k in ("reason", "detail", "nav_time_s", "path_length_m"))
    flown = "re-flown identically" if same else "DIFFERENT from the stored row"
    return (f"{row['trial_id']} {spec.algorithm} {row['family']} {row['platform']}: "
            f"{row['reason']} after {row['nav_time_s']:.1f} s ({flown}); "
            f"{counts['steps']} steps, {counts['still']} nearly still; steps whose state was "
            f"seen before: plant+controller {counts['state']}, position {counts['position']}, "
            f"with the map {counts['all']}")


def main() -> None:
    rows = pd.read_parquet(Path(sys.argv[1]) / "trials.parquet")
    for tid in sys.argv[2:]:
        print(study(rows[rows.trial_id == tid].iloc[0]), flush=True)


if __name__ == "__main__":
    main()
