"""Replay a stored NavRL trial with its safety shield instrumented (navrl-rac.md).

    python scripts/navrl_replay.py RESULT_DIR TRIAL_ID [--protocol N] [--platform NAME]
        [--agent-radius M] [--map-footprint M] [--timeout S] [--dump-at T]
        [--log CSV] [--render PNG]

(docs/results/accel-sweep/navrl-rac.md.) Needs the checkpoint ($FT_SITL_NAVRL_CHECKPOINT).

Flies the stored trial's spec (optionally under another protocol or platform) with the
registry's NavRL whose shield calls are recorded: per 20 Hz control step the position,
the preferred velocity (policy or straight-to-goal), the shield's velocity, the number
of obstacle spheres (ORCA planes), how many of them put the preferred velocity in a
velocity obstacle, the nearest horizontal lidar hit and whether the policy ran.
``--agent-radius`` overrides the shield's ORCA agent radius (default: the protocol's,
= the footprint from protocol 4 on, else 0); ``--map-footprint`` the footprint the map
is inflated for (ceil(f / 0.1 m) voxels; 0: one voxel as before protocol 4).
``--dump-at T`` prints the lidar's 0 deg row, the shield's spheres and ORCA planes at the
first control step after T s. After a timeout it prints where the vehicle was in the last
20 s, what the policy and the shield commanded there, and the nearest cylinders (named as
the scenario's mesh pieces, as in a collision's detail).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import numpy as np
import pandas as pd

from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import run_trial
from ft_sitl.navigation.learned import navrl as nr


class LoggedNavRL(nr.NavRL):
    """NavRL whose shield calls are logged; optional agent radius / map footprint."""

    def __init__(self, agent_radius=None, map_footprint=None, **params):
        super().__init__(**params)
        self._agent_override = agent_radius
        self._map_footprint = map_footprint
        self.log: list[tuple] = []
        self.dump_at = None
        self.dumped = False

    def reset(self, task):
        if self._map_footprint is not None:
            fp = None if self._map_footprint <= 0 else self._map_footprint
            keep = task.footprint_m
            super().reset(dataclasses.replace(task, footprint_m=fp))
            self.agent_radius = keep if keep is not None else 0.0
        else:
            super().reset(task)
        if self._agent_override is not None:
            self.agent_radius = self._agent_override
        self.log = []
        self._t = 0.0

    def step(self, obs):
        self._t = obs.time_s
        return super().step(obs)

    def command(self, obs):
        nav = self
        calls = self.policy_calls
        original = nr.shield

        def logged(position, preferred, ray_points, max_speed, agent_radius=0.0):
            out, solved = original(position, preferred, ray_points, max_speed, agent_radius)
            planes = [nr.orca_plane(position, preferred, agent_radius, c, np.zeros(3), r)
                      for c, r in nr.cluster_spheres(ray_points, position)]
            planes = [p for p in planes if p is not None]
            in_vo = sum(bool(p[2]) for p in planes)
            viol = max([float(-(out - p) @ n) for p, n, _ in planes] or [0.0])
            hor = np.linalg.norm((ray_points - position)[:, :2], axis=1).reshape(36, 4)[:, 1]
            if nav.dump_at is not None and nav._t >= nav.dump_at and not nav.dumped:
                nav.dumped = True
                dist = np.linalg.norm((ray_points - position)[:, :2], axis=1).reshape(36, 4)
                print(f"  t = {nav._t:.2f} s at {position.round(2).tolist()}: preferred "
                      f"{preferred.round(2).tolist()} -> shield {np.asarray(out).round(3).tolist()}"
                      f" (agent radius {agent_radius:.3f} m)")
                print("  horizontal hit distance per beam (0 deg row; beam k at goal "
                      "direction + 10k deg): " + " ".join(f"{d:.2f}" for d in dist[:, 1]))
                for (c, r), pl in zip(nr.cluster_spheres(ray_points, position),
                                      [nr.orca_plane(position, preferred, agent_radius, c,
                                                     np.zeros(3), r)
                                       for c, r in nr.cluster_spheres(ray_points, position)]):
                    gap = float(np.linalg.norm(c - position)) - r - agent_radius
                    desc = "none" if pl is None else (
                        f"normal {pl[1].round(2).tolist()} point {pl[0].round(2).tolist()} "
                        f"in VO {pl[2]}")
                    print(f"    sphere centre {c.round(2).tolist()} r {r:.2f}: vehicle "
                          f"{gap:.2f} m outside r + agent radius; {desc}")
            nav._pending_log = (position.copy(), preferred.copy(), np.asarray(out).copy(),
                                len(planes), in_vo, bool(solved), viol, float(hor.min()))
            return out, solved

        self._pending_log = None
        nr.shield = logged
        try:
            sp = super().command(obs)
        finally:
            nr.shield = original
        if self._pending_log is not None:
            p, pref, out, npl, invo, solved, viol, hmin = self._pending_log
            self.log.append((self._t, *p[:2], *pref[:2], *out[:2], npl, invo, int(solved), viol,
                             hmin, int(self.policy_calls > calls)))
        return sp


COLS = ["t", "x", "y", "pref_x", "pref_y", "out_x", "out_y", "planes", "in_vo", "solved",
        "max_violation", "lidar_min_h", "policy"]


def point_segment(p, a, b):
    ab = b - a
    t = np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
    return float(np.linalg.norm(a + t * ab - p))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("trial_id")
    ap.add_argument("--protocol", type=int)
    ap.add_argument("--platform")
    ap.add_argument("--agent-radius", type=float)
    ap.add_argument("--map-footprint", type=float)
    ap.add_argument("--timeout", type=float, help="override the trial's timeout (s)")
    ap.add_argument("--log", type=Path)
    ap.add_argument("--dump-at", type=float, help="print the shield's spheres and planes at "
                    "the first shielded step after this time (s)")
    ap.add_argument("--render", type=Path)
    a = ap.parse_args(argv)
    rows = pd.read_parquet(a.dir / "trials.parquet")
    row = rows[rows.trial_id == a.trial_id].iloc[0]
    spec = TrialSpec.from_dict(json.loads(row["spec"]))
    changes = {}
    if a.protocol is not None:
        changes["protocol"] = a.protocol
    if a.platform is not None:
        changes["platform"] = a.platform
    if a.timeout is not None:
        changes["limits"] = dataclasses.replace(spec.limits, timeout_s=a.timeout)
    spec = dataclasses.replace(spec, **changes)
    nav = LoggedNavRL(agent_radius=a.agent_radius, map_footprint=a.map_footprint,
                      **spec.algorithm_params)
    nav.dump_at = a.dump_at
    out = run_trial(spec, record=True, navigator=nav, wall_budget_s=None)
    r = out.row
    print(f"{spec.platform} protocol {spec.protocol} agent radius {nav.agent_radius:.3f} m "
          f"map inflation {nav.map.config.inflation_voxels} voxels: {r['reason']} {r['detail']} "
          f"t_goal {r['time_to_goal_s']} path {r['path_length_m']:.1f} m "
          f"min clearance {r['min_clearance_m']:.3f} m")
    log = pd.DataFrame(nav.log, columns=COLS)
    if a.log:
        log.to_csv(a.log, index=False, float_format="%.4f")
    if a.render:
        from ft_sitl.scenarios.render import render_scenario
        render_scenario(out.scenario, a.render, trajectory=out.trajectory[:, 1:4],
                        title=f"navrl on {spec.platform}, protocol {spec.protocol}, "
                              f"agent radius {nav.agent_radius:.2f} m: {r['reason']}")
    # the stall: the last 20 s of a timeout
    if r["reason"] == "timeout" and len(log):
        tail = log[log.t > log.t.max() - 20.0]
        p = np.array([tail.x.median(), tail.y.median()])
        moved = float(np.ptp(tail.x) + np.ptp(tail.y))
        pref = np.hypot(tail.pref_x, tail.pref_y).mean()
        outs = np.hypot(tail.out_x, tail.out_y).mean()
        print(f"  stall (last 20 s) at ({p[0]:.2f}, {p[1]:.2f}), moved {moved:.2f} m: |pref| "
              f"{pref:.2f} m/s, |shield| {outs:.2f} m/s, planes {tail.planes.mean():.1f}, "
              f"in VO {tail.in_vo.mean():.1f}, solved {tail.solved.mean():.2f}, policy "
              f"{tail.policy.mean():.2f}, max violation {tail.max_violation.mean():.3f} m/s, "
              f"nearest lidar hit {tail.lidar_min_h.mean():.2f} m")
        z = float(out.scenario.start[2])
        cyls = out.scenario.provenance["layout"]["cylinders"]
        near = []
        for i, c in enumerate(cyls):
            p0, p1 = np.array(c["p0"]), np.array(c["p1"])
            d = point_segment(np.array([p[0], p[1], z]), p0, p1) - c["r"]
            near.append((d, i, c["r"], c["tilt_deg"]))
        near.sort()
        for d, i, rad, tilt in near[:4]:  # named as the mesh pieces ("cylinder 1" first)
            print(f"    cylinder {i + 1}: surface {d:.2f} m away (r {rad:.2f}, "
                  f"tilt {tilt:.0f} deg)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
