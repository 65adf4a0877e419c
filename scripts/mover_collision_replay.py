"""Replays of a campaign's mover collisions: who ran into whom (docs/results/dynamic).

    python scripts/mover_collision_replay.py runs/dynamic --out docs/results/dynamic/replays.md

Re-flies every ``mover_collision`` row of a result directory (or ``--sample N`` of them,
stratified by algorithm) from its stored spec with ``run_trial(..., monitor=...)``, which
records after every advance of the simulation the vehicle's position and velocity and
every mover's pose. At the contact it splits the closing speed along the line from the
mover's centre to the vehicle into the vehicle's share (its velocity one advance, 50 ms at
the benchmark's 20 Hz, before the contact: the contact response has removed it after) and
the mover's share, and looks
back over the flight for when the mover first came within the camera's range (10 m) in
front of the vehicle (inside the camera's horizontal field of view) and how far the
vehicle then still was from it. A rerun whose outcome differs from the stored row is
reported as such (it would mean the row does not reproduce).
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import numpy as np
import pandas as pd

from ft_sitl import markdown as md
from ft_sitl.missions.results import rows_from_parquet
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import run_trial
from ft_sitl.physics import dynamics as d

HALF_FOV_RAD = math.radians(79.2 / 2)  # the benchmark camera's horizontal half angle
RANGE_M = 10.0


def _markdown(df: pd.DataFrame, index: bool = True) -> str:
    """A pipe table of df (NaN cells empty)."""
    if index:
        df = df.reset_index()
    return md.table(list(df.columns), [
        ["" if (isinstance(v, float) and math.isnan(v)) else v for v in row]
        for row in df.itertuples(index=False)])


def _rows(directory: Path) -> list[dict]:
    jsonl = directory / "trials.jsonl"
    if jsonl.exists():
        return [json.loads(line) for line in jsonl.read_text().splitlines() if line]
    return rows_from_parquet(directory / "trials.parquet")


def replay(row: dict) -> dict:
    spec = TrialSpec.from_dict(json.loads(row["spec"]))
    log: list = []

    def monitor(fleet, t_nav_us: int) -> None:
        m = fleet.sim.guard.movers
        x = fleet.sim.x[0]
        log.append((t_nav_us * 1e-6, x[d.X_POS:d.X_POS + 3].copy(),
                    x[d.X_VEL:d.X_VEL + 3].copy(), m.poses(fleet.time_us),
                    m.velocities(fleet.time_us)))

    out = run_trial(spec, monitor=monitor)
    got = out.row
    res = {"trial_id": row["trial_id"], "algorithm": row["algorithm"],
           "platform": row["platform"], "scenario": row["scenario"],
           "movers": row["movers"], "reason": got["reason"], "detail": got["detail"],
           "reproduced": (got["reason"], got["detail"]) == (row["reason"], row["detail"])}
    if got["reason"] != "mover_collision" or not log:
        return res
    m = out.scenario.movers if out.scenario is not None else None
    name = got["detail"].split("hit ", 1)[1].split(" (moving)")[0]
    j = list(m.names).index(name) if m is not None and name in m.names else None
    if j is None:
        return res
    t, p, _, poses, mv = log[-1]
    # the vehicle's velocity one advance before: the contact response has taken away its
    # velocity towards the mover by the time the monitor sees the contact
    v = log[-2][2] if len(log) > 1 else log[-1][2]
    n = p - poses[j, :3]
    if m.kind[j] != 2:
        n[2] = 0.0
    n /= max(np.linalg.norm(n), 1e-9)
    vehicle_in = float(-(v @ n))  # the vehicle's speed towards the mover
    mover_in = float(mv[j] @ n)   # the mover's speed towards the vehicle
    first_seen = None
    for t_k, p_k, v_k, poses_k, _ in log:
        rel = poses_k[j, :2] - p_k[:2]
        dist = float(np.linalg.norm(rel))
        heading = math.atan2(v_k[1], v_k[0]) if np.hypot(v_k[0], v_k[1]) > 0.3 else None
        if dist <= RANGE_M and heading is not None:
            off = abs((math.atan2(rel[1], rel[0]) - heading + math.pi) % (2 * math.pi) - math.pi)
            if off <= HALF_FOV_RAD:
                first_seen = (t_k, dist)
                break
    res.update({"t_s": round(t, 2), "vehicle_speed": round(float(np.linalg.norm(v)), 2),
                "vehicle_closing": round(vehicle_in, 2), "mover_closing": round(mover_in, 2),
                "mover_path": m.paths[j], "mover_shape": ("person", "box", "sphere")[
                    int(m.kind[j])],
                "seen_s_before": None if first_seen is None else round(t - first_seen[0], 2),
                "seen_at_m": None if first_seen is None else round(first_seen[1], 1)})
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--sample", type=int, default=0, help="N collisions (0: all)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path)
    a = ap.parse_args()
    rows = [r for r in _rows(a.dir) if r["reason"] == "mover_collision"]
    if a.sample:
        rng = np.random.default_rng(a.seed)
        algos = sorted({r["algorithm"] for r in rows})
        per = max(1, a.sample // len(algos))
        picked = []
        for algo in algos:
            mine = [r for r in rows if r["algorithm"] == algo]
            picked += [mine[k] for k in sorted(rng.choice(len(mine), min(per, len(mine)),
                                                          replace=False))]
        rows = picked
    out = [replay(r) for r in rows]
    df = pd.DataFrame(out)
    lines = [f"# Mover collisions replayed ({len(df)} of the directory's mover_collision "
             f"rows)", "", "`python scripts/mover_collision_replay.py " +
             " ".join(f"{k}" for k in [a.dir] + ([f"--sample {a.sample}"] if a.sample else []))
             + "`", ""]
    hit = df.dropna(subset=["vehicle_closing"]) if "vehicle_closing" in df else df.iloc[:0]
    if len(hit):
        flew_in = hit["vehicle_closing"] > hit["mover_closing"]
        lines += [f"- reproduced: {int(df['reproduced'].sum())} of {len(df)}",
                  f"- the vehicle's share of the closing speed larger than the mover's: "
                  f"{int(flew_in.sum())} of {len(hit)} (the vehicle flew into the mover); "
                  f"the mover's larger: {int((~flew_in).sum())} (the mover ran into it)",
                  f"- median vehicle speed at contact {hit['vehicle_speed'].median():.2f} m/s; "
                  f"median closing speeds: vehicle {hit['vehicle_closing'].median():.2f}, "
                  f"mover {hit['mover_closing'].median():.2f} m/s",
                  f"- seen in front within 10 m before the contact: "
                  f"{int(hit['seen_s_before'].notna().sum())} of {len(hit)}; median "
                  f"{hit['seen_s_before'].median():.1f} s before, at "
                  f"{hit['seen_at_m'].median():.1f} m",
                  "", "By path of the mover hit:", "",
                  _markdown(hit.groupby("mover_path").size().to_frame("contacts")), "",
                  "By algorithm (median closing speeds, m/s):", "",
                  _markdown(hit.groupby("algorithm")[["vehicle_closing", "mover_closing",
                                                      "seen_s_before"]].median().round(2)),
                  ""]
    lines += ["## Every replay", "", _markdown(df, index=False), ""]
    text = "\n".join(lines)
    if a.out:
        a.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
