"""Re-fly stored rows, as they were or with one thing changed, and record the vertical
channel, the attitude and the thrust limits over time (issue 44: why the TWR-6 members of
the controlled series climb out of Random-Angle Cylinder).

    python scripts/trace_replay.py --rows RESULTS ID [ID ...] --out DIR [--traces]
        [--set gains=bandwidth] [--set params.MPC_THR_MIN=0.06] [--set seed=FROM:ID]

Each ``ID`` (a trial id or a unique prefix) names a stored row of ``RESULTS``. Without
``--set`` every re-flown row must equal its stored one, else the script stops. Each
``--set`` changes every spec before it flies (a counterfactual; the row is then compared
with the stored one, not checked): ``gains=MODE`` (docs/missions.md, "Controller gains"),
``params.NAME=VALUE`` (a PX4 parameter of the trial's flight controller), ``seed=FROM:ID``
(the seed of another stored row, e.g. the same trial's TWR-3 twin: the navigator and camera
streams of that row). Writes ``flights.csv`` (one line per flight: the stored and the
re-flown outcome) and, with ``--traces``, ``<id>.csv`` per flight (after every navigation
advance: time, position, vertical setpoint and velocity, the vertical acceleration the
position controller commands after its limits, whether the collective sat at
MPC_THR_MIN's floor, tilt, body-rate magnitude, rotor saturation) and ``vertical.png``
(height, vertical acceleration against the floor, tilt and body rates, all flights).
One worker; run it niced beside a campaign.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import json
import math
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
import numpy as np

from ft_sitl import G
from ft_sitl.autopilot import cascade as c
from ft_sitl.cli.missions import differences
from ft_sitl.missions.results import rows_from_parquet
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.store import PARQUET_FILE, TRIALS_FILE, load_rows
from ft_sitl.missions.trial import run_trial
from ft_sitl.physics import dynamics as d

TRACE_COLUMNS = ("t_s", "x_m", "y_m", "z_m", "vz_m_s", "z_sp_m", "vz_sp_m_s",
                 "az_cmd_m_s2", "az_floor_m_s2", "at_floor", "tilt_deg", "rate_rad_s",
                 "saturated_fraction", "tracking_error_m")
ROW_COLUMNS = ("success", "reason", "detail", "nav_time_s", "max_tilt_deg",
               "tracking_rms_m", "saturation_fraction")


def fly(spec: TrialSpec) -> tuple[dict, np.ndarray, float]:
    """The row of ``spec``, its trace (one line per navigation advance) and the
    scenario's ceiling (m)."""
    out: list[tuple] = []
    last = {"sat": 0.0, "steps": 0}

    def monitor(fleet, t_nav_us: int) -> None:
        sim = fleet.sim
        cs, gn, x, sp = sim.ctrl[0], sim.gains[0], sim.x[0], sim.sp[0]
        sat, steps = float(cs[c.C_SAT_STEPS]), sim.steps
        d_sat = (sat - last["sat"]) / max(1, steps - last["steps"])
        last["sat"], last["steps"] = sat, steps
        q = x[d.X_QUAT:d.X_QUAT + 4]
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (q[1] ** 2 + q[2] ** 2)))))
        floor = gn[c.G_FMIN] / gn[c.G_MASS] - G  # the vertical acceleration at MPC_THR_MIN
        az = float(cs[c.C_ACC_SP + 2])
        p, sp_p = x[d.X_POS:d.X_POS + 3], sp[c.SP_POS:c.SP_POS + 3]
        err = float(np.linalg.norm(sp_p - p)) if np.all(np.isfinite(sp_p)) else math.nan
        out.append((t_nav_us * 1e-6, p[0], p[1], p[2], x[d.X_VEL + 2], sp[c.SP_POS + 2],
                    sp[c.SP_VEL + 2], az, floor, float(az <= floor + 1e-6), tilt,
                    float(np.linalg.norm(x[d.X_OMEGA:d.X_OMEGA + 3])), d_sat, err))

    outcome = run_trial(spec, monitor=monitor, wall_budget_s=None)
    return outcome.row, np.array(out, dtype=float), float(outcome.scenario.bounds_max[2])


def _find(rows: list[dict], prefix: str, directory) -> dict:
    found = [r for r in rows if str(r["trial_id"]).startswith(prefix)]
    if len(found) != 1:
        raise SystemExit(f"trace_replay: {prefix!r} matches {len(found)} rows of {directory}")
    return found[0]


def _changes(sets: list[str], rows: list[dict], directory) -> list[tuple[str, object]]:
    """``--set`` items as (field, value): gains, params.NAME, seed (from another row)."""
    out = []
    for item in sets:
        key, sep, value = item.partition("=")
        if not sep or not value:
            raise SystemExit(f"trace_replay: --set {item!r}: expected KEY=VALUE")
        if key == "gains":
            out.append(("gains", value))
        elif key.startswith("params.") and len(key) > len("params."):
            try:
                out.append((key, float(value)))
            except ValueError:
                raise SystemExit(f"trace_replay: --set {item!r}: the value must be a number "
                                 "(the parameter's range: ft-sitl params)") from None
        elif key == "seed" and value.startswith("FROM:"):
            other = json.loads(_find(rows, value[5:], directory)["spec"])
            out.append(("seed", int(other["seed"])))
        else:
            raise SystemExit(f"trace_replay: --set {item!r}: allowed keys are gains=MODE, "
                             "params.NAME=NUMBER and seed=FROM:ID")
    return out


def changed(spec: TrialSpec, changes: list[tuple[str, object]]) -> TrialSpec:
    for key, value in changes:
        if key.startswith("params."):
            params = dict(spec.params or {})
            params[key[len("params."):]] = value
            spec = dataclasses.replace(spec, params=dict(sorted(params.items())))
        else:
            spec = dataclasses.replace(spec, **{key: value})
    return spec


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", required=True, type=Path, help="a result directory")
    ap.add_argument("ids", nargs="+", help="trial ids (or unique prefixes) of its rows")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--set", action="append", default=[], dest="sets",
                    help="gains=MODE, params.NAME=NUMBER or seed=FROM:ID (repeatable)")
    ap.add_argument("--traces", action="store_true",
                    help="also write each flight's trace and the figure")
    args = ap.parse_args(argv)
    # a campaign's trials.jsonl, or a committed directory's trials.parquet (as trial rerun)
    if (args.rows / TRIALS_FILE).exists() or not (args.rows / PARQUET_FILE).is_file():
        rows = load_rows(args.rows)[1]
    else:
        rows = rows_from_parquet(args.rows / PARQUET_FILE)
    changes = _changes(args.sets, rows, args.rows)
    args.out.mkdir(parents=True, exist_ok=True)
    lines, traces = [], []
    for prefix in args.ids:
        stored = _find(rows, prefix, args.rows)
        spec = changed(TrialSpec.from_dict(json.loads(stored["spec"])), changes)
        row, trace, ceiling = fly(spec)
        if not changes and (diff := differences(row, stored)):
            raise SystemExit(f"{stored['trial_id']}: the re-flown row differs from the "
                             f"stored one: {diff}")
        line = {"trial_id": stored["trial_id"], "platform": stored["platform"],
                "algorithm": stored["algorithm"], "scenario": stored["scenario"],
                "aggressiveness": stored["aggressiveness"],
                "change": " ".join(args.sets) or "none (identical)"}
        line.update({f"stored_{k}": stored[k] for k in ROW_COLUMNS})
        line.update({k: row[k] for k in ROW_COLUMNS})
        at = trace[:, TRACE_COLUMNS.index("at_floor")]
        line["floor_fraction"] = float(at.mean()) if len(at) else math.nan
        line["max_z_m"] = float(np.nanmax(trace[:, 3])) if len(trace) else math.nan
        lines.append(line)
        print(f"{stored['trial_id'][:8]} {stored['platform']:28s} {stored['algorithm']:5s} "
              f"{stored['scenario']:32s} stored {stored['reason']:14s} -> {row['reason']:14s}"
              f" {row['detail']} | at the thrust floor {line['floor_fraction']:.1%}, "
              f"max z {line['max_z_m']:.2f} m", flush=True)
        if args.traces:
            with open(args.out / f"{stored['trial_id'][:8]}.csv", "w", newline="") as fh:
                w = csv.writer(fh)
                w.writerow(TRACE_COLUMNS)
                w.writerows(np.round(trace, 4).tolist())
            traces.append((stored, row, trace))
    ceiling_m = ceiling if traces else math.nan
    with open(args.out / "flights.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(lines[0]))
        w.writeheader()
        w.writerows(lines)
    if traces:
        plot(traces, ceiling_m, " ".join(args.sets), args.out / "vertical.png")
    return 0


def plot(traces, ceiling_m: float, change: str, path: Path) -> None:
    from matplotlib.figure import Figure  # matplotlib: only for the figure

    fig = Figure(figsize=(10, 9), dpi=110)
    axes = fig.subplots(4, 1, sharex=True)
    colours = ("tab:blue", "tab:red", "tab:green", "tab:purple", "tab:orange", "tab:brown")
    for (stored, row, s), colour in zip(traces, colours):
        twr = f"TWR {row['twr_max']:.1f}"
        label = f"{stored['platform']} ({twr}): {row['reason']}"
        t = s[:, 0]
        axes[0].plot(t, s[:, 3], color=colour, lw=1.0, label=label)
        axes[0].plot(t, s[:, 5], color=colour, lw=0.8, ls=":")
        axes[1].plot(t, s[:, 7], color=colour, lw=0.8)
        axes[1].axhline(s[0, 8], color=colour, lw=0.8, ls="--")
        axes[2].plot(t, s[:, 10], color=colour, lw=0.8)
        axes[3].plot(t, s[:, 11], color=colour, lw=0.8)
    axes[0].axhline(ceiling_m, color="k", lw=0.8, ls="--", label="ceiling")
    axes[0].set_ylabel("height (m)\nsolid flown, dotted setpoint")
    axes[1].set_ylabel("vertical acc. commanded\n(m/s², dashed: floor)")
    axes[2].set_ylabel("tilt (deg)")
    axes[3].set_ylabel("|body rate| (rad/s)")
    axes[3].set_xlabel("navigation time (s)")
    axes[0].legend(loc="lower left", fontsize=8)
    for ax in axes:
        ax.grid(alpha=0.3)
    scen = traces[0][0]["scenario"]
    what = f" (changed: {change})" if change else " (stored rows, re-flown identical)"
    fig.suptitle(f"{traces[0][0]['algorithm']} in {scen}, {traces[0][0]['aggressiveness']}{what}: "
                 "height, vertical command, attitude", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)


if __name__ == "__main__":
    raise SystemExit(main())
