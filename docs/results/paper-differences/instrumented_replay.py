"""Instrumented re-flight of one stored trial: logs EGO's / PGO's plan attempts.

usage (from the repository root):
    .venv/bin/python docs/results/paper-differences/instrumented_replay.py TRIAL_ID OUT.json [RUN_DIR]

Caveat (README.md): with these hooks the flight is NOT bit-identical to the stored row
(PGO 1e-4..2e-3 in path/speed, same outcome; EGO the same stuck point and failure status,
but a 90-s hover instead of the give-up). The same in-process runner without the hooks
reproduces the row exactly; which hook perturbs it was not found. (The logs were made
with numpy imported before ft_sitl; the script now imports ft_sitl first, as
docs/architecture.md, "Determinism", asks.)
"""

import json
import os
import sys

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import numpy as np

import ft_sitl.navigation.planners.pgo as pgo_mod
from ft_sitl.cli.missions import differences
from ft_sitl.missions.protocol import navigator_params
from ft_sitl.missions.results import rows_from_parquet
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import run_trial
from ft_sitl.navigation.registry import create

tid, out = sys.argv[1], sys.argv[2]
run = sys.argv[3] if len(sys.argv) > 3 else "docs/results/paper"
rows = (
    [json.loads(line) for line in open(run + "/trials.jsonl") if line.strip()]
    if os.path.exists(run + "/trials.jsonl")
    else rows_from_parquet(run + "/trials.parquet")
)
stored = next(r for r in rows if r["trial_id"].startswith(tid))
spec = TrialSpec.from_dict(json.loads(stored["spec"]))
nav = create(spec.algorithm, navigator_params(spec))
log = []
cur = {}


def L(**kw):
    log.append(
        {
            k: (
                np.round(np.asarray(v, float), 3).tolist()
                if isinstance(v, (np.ndarray, list, tuple))
                else v
            )
            for k, v in kw.items()
        }
    )


orig_plan = nav._plan


def plan(obs):
    cur.clear()
    cur["t"] = round(float(obs.time_s), 3)
    cur["pos"] = obs.position
    orig_plan(obs)
    L(ev="plan", **cur)


nav._plan = plan

orig_failed = nav._failed


def failed(obs, p0, why, t_start):
    cur["fail"] = str(why)
    return orig_failed(obs, p0, why, t_start)


nav._failed = failed

if spec.algorithm == "pgo":
    orig_ps = pgo_mod.plan_segment

    def ps(init, resample, derivs, grid, rng, params=None, topo_params=None):
        res = orig_ps(init, resample, derivs, grid, rng, params, topo_params)
        cur["status"] = res.status
        cur["seg_start"] = init.position(0.0)
        cur["seg_end"] = init.position(init.duration)
        cur["npaths"] = len(res.search.paths) if res.search is not None else None
        if res.spline is not None:
            cur["plan_end"] = res.spline.position(res.spline.duration)
        return res

    pgo_mod.plan_segment = ps
    orig_cd = nav._collision_distance

    def cd(t):
        d = orig_cd(t)
        if d is not None:
            L(
                ev="unsafe",
                t=round(float(t), 3),
                dist=round(d, 3),
                stop=bool(d <= nav.stop_distance),
            )
        return d

    nav._collision_distance = cd
if spec.algorithm in ("ego", "fast"):

    def hook_reset():
        pass

    orig_reset = nav.reset

    def reset(task):
        orig_reset(task)
        if hasattr(nav, "reference") and hasattr(nav.reference, "local_target"):
            olt = nav.reference.local_target

            def lt(*a, **k):
                tg = olt(*a, **k)
                cur["target"] = tg.point
                return tg

            nav.reference.local_target = lt
        if hasattr(nav, "optimizer") and hasattr(nav.optimizer, "optimize"):
            oo = nav.optimizer.optimize

            def op(*a, **k):
                res = oo(*a, **k)
                cur["opt"] = getattr(res.status, "value", str(res.status))
                return res

            nav.optimizer.optimize = op

    nav.reset = reset

outc = run_trial(spec, navigator=nav, record=True)
diff = differences(outc.row, stored)
print("reproduced:", "yes" if not diff else "NO " + ", ".join(diff[:6]))
print(outc.row["reason"], outc.row["detail"])
print("stats", getattr(nav, "stats", None))
json.dump(
    {
        "trial_id": stored["trial_id"],
        "diff": diff,
        "log": log,
        "stats": getattr(nav, "stats", None),
    },
    open(out, "w"),
    default=str,
)
