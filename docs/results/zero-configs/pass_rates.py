"""Narrow-Gap: per-wall pass rates of Fast-Planner on small platforms, and the product
model (docs/results/zero-configs/README.md).

    python docs/results/zero-configs/pass_rates.py [RUN_DIR]   (default docs/results/paper)

A platform is small when its map inflation (ceil(half span / 0.1 m)) is at most 3 voxels.
A flight reaches walls 1..k and passes 1..k-1 when it hits wall k (mesh pieces 2k-1, 2k);
a success passes every wall; other failures (no wall named) are left out. A wall's
sidestep is the lateral distance from the previous gap's centre (from the line for wall 1).
"""

import collections
import json
import math
import os
import re
import sys

import ft_sitl  # noqa: F401
from ft_sitl.missions.results import rows_from_parquet
from ft_sitl.missions.spec import vehicle_half_span_m
from ft_sitl.physics.catalog import catalog
from ft_sitl.scenarios.families import build_scenario

run = sys.argv[1] if len(sys.argv) > 1 else "docs/results/paper"
infl = {n: max(1, math.ceil(vehicle_half_span_m(6, p) / 0.1 - 1e-9)) for n, p in catalog().items()}
rows = (
    [json.loads(line) for line in open(run + "/trials.jsonl") if line.strip()]
    if os.path.exists(run + "/trials.jsonl")
    else rows_from_parquet(run + "/trials.parquet")
)
walls = {i: build_scenario("narrow_gap", i, 0).provenance["layout"]["walls"] for i in range(1, 11)}


def kind(w, shift):
    if shift >= 2.5:
        return "sidestep > 2.5 m"
    if shift >= 1.0:
        return "sidestep 1-2.5 m"
    return "straight ahead, " + ("on the line" if w["on_line"] else "off the line")


stats = collections.defaultdict(lambda: [0, 0])
left_out = 0
for r in rows:
    if r["family"] != "narrow_gap" or r["algorithm"] != "fast" or infl[r["platform"]] > 3:
        continue
    W = walls[r["scenario_index"]]
    if r["success"]:
        stop = len(W) + 1
    else:
        m = re.match(r"hit wall (\d+)", r["detail"])
        if not m:
            left_out += 1
            continue
        stop = (int(m.group(1)) + 1) // 2
    prev = 25.0
    for k, w in enumerate(W, 1):
        if k > stop:
            break
        key = kind(w, abs(w["gap_centre_x_m"] - prev))
        stats[key][0] += 1
        stats[key][1] += k < stop
        prev = w["gap_centre_x_m"]
print(f"left out (no wall named): {left_out}")
rate = {}
for key, (reached, passed) in sorted(stats.items()):
    rate[key] = passed / reached
    print(f"{key:36s} reached {reached:4d} passed {passed:4d} {100 * passed / reached:4.0f} %")
print("\ncfg  predicted/14  observed/14")
for i in range(1, 11):
    p, prev = 1.0, 25.0
    for w in walls[i]:
        p *= rate[kind(w, abs(w["gap_centre_x_m"] - prev))]
        prev = w["gap_centre_x_m"]
    obs = sum(
        1
        for r in rows
        if r["family"] == "narrow_gap"
        and r["scenario_index"] == i
        and r["algorithm"] == "fast"
        and infl[r["platform"]] <= 3
        and r["success"]
    )
    print(f"{i:3d}  {14 * p:12.1f}  {obs:11d}")
