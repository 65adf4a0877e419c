"""One trial flown on a weak and a strong platform of the same size: tracking error and
motor saturation over time (docs/results/tracking-twr).

    python scripts/tracking_replay.py --out docs/results/tracking-twr

    python scripts/tracking_replay.py --out DIR --rows RESULTS WEAK_ID STRONG_ID

Flies the same spec (navigator, scenario, seed, protocol limits) on each platform, or with
``--rows`` two stored rows of a result directory (their specs; each re-flown row must
equal its stored one, else the script stops), with
``run_trial(..., monitor=...)`` recording, after every advance of the simulation, the
distance between the position setpoint the navigator's plan commands and the vehicle
(tracking error) and whether any rotor sat at a limit in that stretch.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import numpy as np

from ft_sitl.autopilot import cascade as c
from ft_sitl.cli.missions import differences
from ft_sitl.missions.spec import PROTOCOL_VERSION, TrialSpec
from ft_sitl.missions.store import load_rows
from ft_sitl.missions.trial import run_trial
from ft_sitl.navigation.base import Limits
from ft_sitl.physics import dynamics as d


def fly(spec: TrialSpec) -> tuple[dict, np.ndarray]:
    samples: list[tuple[float, float, float, float]] = []
    last = {"sat": 0.0, "steps": 0}

    def monitor(fleet, t_nav_us: int) -> None:
        sat, steps = float(fleet.sim.ctrl[0, c.C_SAT_STEPS]), fleet.sim.steps
        d_sat = (sat - last["sat"]) / max(1, steps - last["steps"])
        last["sat"], last["steps"] = sat, steps
        sp = fleet.sim.sp[0, c.SP_POS:c.SP_POS + 3]
        p = fleet.sim.x[0, d.X_POS:d.X_POS + 3]
        err = float(np.linalg.norm(sp - p)) if np.all(np.isfinite(sp)) else float("nan")
        speed = float(np.linalg.norm(fleet.sim.x[0, d.X_VEL:d.X_VEL + 3]))
        samples.append((t_nav_us * 1e-6, err, d_sat, speed))

    row = run_trial(spec, monitor=monitor, wall_budget_s=None).row
    return row, np.array(samples)


def _stored(rows_arg) -> dict:
    """The two stored rows ``--rows`` names, by role."""
    directory, weak, strong = rows_arg
    rows = load_rows(directory)[1]
    out = {}
    for role, prefix in (("weak", weak), ("strong", strong)):
        found = [r for r in rows if str(r["trial_id"]).startswith(prefix)]
        if len(found) != 1:
            raise SystemExit(f"--rows: {prefix!r} matches {len(found)} rows of {directory}")
        out[role] = found[0]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--algorithm", default="fast")
    ap.add_argument("--family", default="forest")
    ap.add_argument("--index", type=int, default=1)
    ap.add_argument("--max-acc", type=float, default=8.0,
                    help="the protocol acceleration limit the planner plans with (m/s^2)")
    ap.add_argument("--protocol", type=int, default=PROTOCOL_VERSION,
                    help="the trial protocol's version (default: the newest)")
    ap.add_argument("--weak", default="2.00kg-T-MOTOR", help="(TWR 1.4, arm 0.257 m)")
    ap.add_argument("--strong", default="2.00kg-UAV 8", help="(TWR 3.2, the same size)")
    ap.add_argument("--rows", nargs=3, metavar=("RESULTS", "WEAK_ID", "STRONG_ID"),
                    help="re-fly two stored rows (trial ids, or unique prefixes) instead")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    runs = {}
    stored = _stored(args.rows) if args.rows else {}
    for role, platform in (("weak", args.weak), ("strong", args.strong)):
        if stored:
            spec = TrialSpec.from_dict(json.loads(stored[role]["spec"]))
            platform = spec.platform
        else:
            spec = TrialSpec(args.algorithm, platform, args.family, scenario_index=args.index,
                             limits=Limits(max_acc_m_s2=args.max_acc),
                             campaign="tracking-twr", protocol=args.protocol)
        row, s = fly(spec)
        if stored and (diff := differences(row, stored[role])):
            raise SystemExit(f"{role}: the re-flown row differs from the stored one: {diff}")
        runs[role] = (platform, row, s)
        with open(args.out / f"{role}.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["t_s", "tracking_error_m", "saturated_fraction", "speed_m_s"])
            w.writerows(s.tolist())
        print(f"{role:6s} {platform:16s} twr {row['twr_max']:.1f}: {row['reason']} "
              f"{row['detail']} | saturation {row['saturation_fraction']:.3f}, max tilt "
              f"{row['max_tilt_deg']:.0f} deg, median tracking error "
              f"{np.nanmedian(s[:, 1]):.3f} m, p95 {np.nanpercentile(s[:, 1], 95):.3f} m")
    summary = {role: {"platform": p, "trial_id": r["trial_id"], "reason": r["reason"],
                      "detail": r["detail"], "twr_max": r["twr_max"],
                      "alpha_xy_max": r["alpha_xy_max"],
                      "saturation_fraction": r["saturation_fraction"],
                      "max_tilt_deg": r["max_tilt_deg"], "nav_time_s": r["nav_time_s"],
                      "median_tracking_error_m": float(np.nanmedian(s[:, 1])),
                      "p95_tracking_error_m": float(np.nanpercentile(s[:, 1], 95)),
                      "spec": json.loads(r["spec"])}
               for role, (p, r, s) in runs.items()}
    (args.out / "summary.json").write_text(json.dumps(summary, indent=2))
    plot(runs, args.out / "tracking.png")
    return 0


def plot(runs, path: Path) -> None:
    from matplotlib.figure import Figure  # matplotlib: only for the figure

    fig = Figure(figsize=(9, 6), dpi=110)
    ax1, ax2 = fig.subplots(2, 1, sharex=True)
    for (platform, row, s), colour in zip(runs.values(), ("tab:red", "tab:blue")):
        label = f"{platform} (TWR {row['twr_max']:.1f}): {row['reason']}"
        ax1.plot(s[:, 0], s[:, 1], color=colour, lw=1.0, label=label)
        # saturation as the fraction of physics steps over a 0.1 s window
        t, sat = s[:, 0], s[:, 2]
        bins = np.arange(0.0, t.max() + 0.1, 0.1)
        idx = np.digitize(t, bins)
        frac = [sat[idx == k].mean() if np.any(idx == k) else np.nan
                for k in range(1, len(bins))]
        ax2.step(bins[:-1], frac, where="post", color=colour, lw=1.0, label=label)
    ax1.set_ylabel("tracking error (m)\n|position setpoint - position|")
    ax2.set_ylabel("motor saturation\n(fraction of steps, 0.1 s bins)")
    ax2.set_xlabel("navigation time (s)")
    ax1.legend(loc="upper left", fontsize=8)
    ax1.grid(alpha=0.3)
    ax2.grid(alpha=0.3)
    fig.suptitle("Same plan request, same size: weak vs strong platform")
    fig.tight_layout()
    fig.savefig(path)


if __name__ == "__main__":
    raise SystemExit(main())
