"""Fly a result directory's trials in-process again with the PX4 parameters the ArduCopter
face's defaults would set (ANGLE_MAX, WPNAV_*, PSC_*, GUID_TIMEOUT, ... written through),
to show what a wire trial would fly if the face's defaults were kept instead of the
trial's parameters (docs/wire.md, "Autopilots"). Prints each trial's reason, navigation
time and largest tilt both ways.

    python docs/results/wire-agreement/ardupilot/face_defaults.py runs/a-inproc
"""

import json
import sys
from pathlib import Path

import ft_sitl  # noqa: F401  (numeric pins first)
from ft_sitl import frames
from ft_sitl.mavlink.ardupilot.server import ArduPilotServer
from ft_sitl.missions.plan import plan_trial
from ft_sitl.missions.protocol import trial_vehicle
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import run_trial


def face_params(spec: TrialSpec) -> dict:
    """The parameters the face changes on this trial's vehicle (the fence's GF_* left out:
    the protocol sets those)."""
    _, fleet = trial_vehicle(plan_trial(spec))
    before = fleet.params[0].as_dict()
    ArduPilotServer(fleet, frames.GeoReference(*frames.PX4_SITL_HOME)).close()
    return {k: v for k, v in fleet.params[0].as_dict().items()
            if before[k] != v and not k.startswith("GF_")}


def main(result_dir: str) -> int:
    same = n = 0
    for line in (Path(result_dir) / "trials.jsonl").read_text().splitlines():
        r = json.loads(line)
        spec = TrialSpec.from_dict(json.loads(r["spec"]))
        d = spec.to_dict()
        d["params"] = {**(spec.params or {}), **face_params(spec)}
        row = run_trial(TrialSpec.from_dict(d)).row
        n += 1
        same += row["reason"] == r["reason"]
        print(f"{r['trial_id'][:10]} {r['algorithm']:8} {r['platform']:22} {r['family']} "
              f"{r['scenario_index']}: {r['reason']} -> {row['reason']}, nav "
              f"{r['nav_time_s']:.2f} -> {row['nav_time_s']:.2f} s, tilt "
              f"{r['max_tilt_deg']:.1f} -> {row['max_tilt_deg']:.1f} deg", flush=True)
    print(f"same reason in {same} of {n}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
