"""``ft-sitl campaign``, ``ft-sitl trial`` and ``ft-sitl navigators``: the benchmark itself.

Kept apart from ``cli.py`` (which registers these parsers through :func:`add_parsers`);
errors are :class:`~ft_sitl.cli.CliError` like everywhere else: one line, exit status 2.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path


def _cli_error():
    from ft_sitl.cli import CliError

    return CliError


def _campaign(source: str):
    from ft_sitl.missions.campaign import CampaignError, load_campaign

    try:
        return load_campaign(source)
    except CampaignError as exc:
        raise _cli_error()(str(exc)) from None


# --- campaign ------------------------------------------------------------------------------
def cmd_campaign_check(args) -> int:
    c = _campaign(args.campaign)
    specs = c.trial_specs()
    info = {"name": c.name, "trials": len(specs),
            "algorithms": [a.label for a in c.algorithms],
            "platforms": [p.name for p in c.platforms],
            "scenarios": [{"family": s.family, "indices": list(s.indices)}
                          for s in c.scenarios],
            "trials_per_combination": c.trials, "limits": c.limits.as_dict(),
            "notes": list(c.notes)}
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"campaign {c.name!r}: {len(specs)} trials = {len(c.algorithms)} algorithms x "
          f"{len(c.platforms)} platforms x {len(c.scenarios)} scenario families x "
          f"{c.trials} trials")
    print(f"  algorithms: {', '.join(info['algorithms'])}")
    print(f"  platforms:  {', '.join(info['platforms'])}")
    print("  scenarios:  " + ", ".join(
        f"{s.family} {list(s.indices)}" for s in c.scenarios))
    lim = c.limits
    print(f"  limits: {lim.max_speed_m_s:g} m/s, {lim.timeout_s:g} s, goal sphere "
          f"{lim.goal_radius_m:g} m held {lim.hold_s:g} s")
    for note in c.notes:
        print(f"  note: {note}")
    return 0


def cmd_campaign_run(args) -> int:
    from ft_sitl.missions.campaign import run_campaign
    from ft_sitl.missions.store import StoreError

    c = _campaign(args.campaign)
    if args.workers < 1:
        raise _cli_error()(f"--workers: {args.workers} must be at least 1")
    if args.limit is not None and args.limit < 1:
        raise _cli_error()(f"--limit: {args.limit} must be at least 1")
    out = Path(args.out)
    for note in c.notes:
        print(f"note: {note}", file=sys.stderr)
    from ft_sitl.missions.campaign import CampaignError, Transport

    try:
        transport = Transport(args.transport, args.speed_factor, args.mqtt)
    except CampaignError as exc:
        raise _cli_error()(str(exc)) from None
    if args.mqtt:
        from ft_sitl.bus.options import parse_broker_url as parse_url

        try:
            parse_url(args.mqtt)
        except ValueError as exc:
            raise _cli_error()(f"--mqtt: {exc}") from None
    try:
        summary = run_campaign(c, out, workers=args.workers, progress=not args.quiet,
                               limit=args.limit, transport=transport)
    except StoreError as exc:
        raise _cli_error()(str(exc)) from None
    except KeyboardInterrupt:
        print(f"interrupted: finished trials are in {out}; run the same command again to "
              f"resume", file=sys.stderr)
        return 130
    rate = summary.ran / summary.wall_s if summary.wall_s > 0 else math.nan
    print(f"{summary.ran} trials run, {summary.skipped} already done, {summary.total} in the "
          f"campaign; {summary.wall_s:.1f} s ({rate:.2f} trials/s) -> {out}")
    for tid, err in summary.errors[:10]:
        print(f"  trial {tid} could not run: {err}", file=sys.stderr)
    if summary.errors:
        print(f"{len(summary.errors)} trials could not run (not recorded; a rerun retries "
              f"them)", file=sys.stderr)
    if args.csv:
        from ft_sitl.missions.store import ResultStore

        store = ResultStore(out)
        store.done = store._load()
        if store.done:
            print(f"table: {store.write_tables(csv=True)[-1]}")
    if not args.no_report and (summary.ran or summary.skipped):
        _report(out, quiet=False)
    return 1 if summary.errors else 0


def _report(out: Path, quiet: bool = False) -> Path:
    from ft_sitl.missions.campaign import report_meta
    from ft_sitl.missions.report import write_report
    from ft_sitl.missions.results import to_frame
    from ft_sitl.missions.store import StoreError, load_rows

    try:
        campaign, rows = load_rows(out)
    except StoreError as exc:
        raise _cli_error()(str(exc)) from None
    if not rows:
        raise _cli_error()(f"{out}: no finished trials yet")
    paths = write_report(to_frame(rows), out, campaign_spec=campaign.get("spec", {}),
                         meta=report_meta(out, campaign))
    page = paths["report.html"]
    if not quiet:
        print(f"report: {page}  (summary: {paths['summary.md']})")
    return page


def cmd_campaign_report(args) -> int:
    out = Path(args.dir)
    if args.csv:
        from ft_sitl.missions.store import ResultStore, StoreError, load_rows

        try:
            load_rows(out)
        except StoreError as exc:
            raise _cli_error()(str(exc)) from None
        store = ResultStore(out)
        store.done = store._load()
        print(f"table: {store.write_tables(csv=True)[-1]}")
    _report(out)
    return 0


def compare_runs(a_rows: list[dict], b_rows: list[dict]) -> dict:
    """Outcome agreement of two result sets on their common trial ids (e.g. the same
    campaign in-process and over MAVLink): per algorithm and overall, with the trials that
    disagree."""
    a = {r["trial_id"]: r for r in a_rows}
    b = {r["trial_id"]: r for r in b_rows}
    common = sorted(set(a) & set(b))
    per: dict = {}
    diffs = []
    for tid in common:
        ra, rb = a[tid], b[tid]
        alg = per.setdefault(ra["algorithm"], {"trials": 0, "same_success": 0,
                                               "same_reason": 0})
        alg["trials"] += 1
        alg["same_success"] += bool(ra["success"]) == bool(rb["success"])
        alg["same_reason"] += ra["reason"] == rb["reason"]
        if bool(ra["success"]) != bool(rb["success"]) or ra["reason"] != rb["reason"]:
            diffs.append({"trial_id": tid, "algorithm": ra["algorithm"],
                          "platform": ra["platform"], "scenario": ra["scenario"],
                          "a": f"{ra['reason']} {ra.get('detail', '')}".strip(),
                          "b": f"{rb['reason']} {rb.get('detail', '')}".strip()})
    n = len(common)
    return {"common_trials": n, "only_in_a": len(set(a) - set(b)),
            "only_in_b": len(set(b) - set(a)), "algorithms": per,
            "same_success": sum(v["same_success"] for v in per.values()),
            "same_reason": sum(v["same_reason"] for v in per.values()),
            "disagreements": diffs}


def cmd_campaign_compare(args) -> int:
    from ft_sitl.missions.store import StoreError, load_rows

    try:
        _, ra = load_rows(Path(args.a))
        _, rb = load_rows(Path(args.b))
    except StoreError as exc:
        raise _cli_error()(str(exc)) from None
    res = compare_runs(ra, rb)
    if res["common_trials"] == 0:
        raise _cli_error()(f"{args.a} and {args.b} have no trial in common (different "
                           "campaigns or seeds?)")
    if args.json:
        print(json.dumps(res, indent=2))
        return 0
    n = res["common_trials"]
    print(f"{n} common trials: success/failure agrees in {res['same_success']} "
          f"({100.0 * res['same_success'] / n:.0f} %), the reason in {res['same_reason']} "
          f"({100.0 * res['same_reason'] / n:.0f} %)")
    for alg, v in sorted(res["algorithms"].items()):
        print(f"  {alg:12s} {v['trials']:4d} trials  success agrees "
              f"{100.0 * v['same_success'] / v['trials']:5.1f} %  reason agrees "
              f"{100.0 * v['same_reason'] / v['trials']:5.1f} %")
    for d in res["disagreements"]:
        print(f"  {d['trial_id'][:10]} {d['algorithm']} {d['platform']} {d['scenario']}: "
              f"A {d['a']} | B {d['b']}")
    return 0


# --- trial -----------------------------------------------------------------------------------
def _find_spec(args):
    from ft_sitl.missions.store import StoreError, load_rows
    from ft_sitl.missions.trial import TrialSpec, TrialSpecError

    if args.spec is not None:
        try:
            doc = json.loads(Path(args.spec).read_text())
        except FileNotFoundError:
            raise _cli_error()(f"--spec: {args.spec}: no such file") from None
        except (OSError, ValueError) as exc:
            raise _cli_error()(f"--spec: {args.spec}: not a JSON trial spec ({exc})") from None
        stored = None
    else:
        if args.dir is None or args.trial_id is None:
            raise _cli_error()("give a campaign directory and a trial id, or --spec FILE")
        try:
            _, rows = load_rows(args.dir)
        except StoreError as exc:
            raise _cli_error()(str(exc)) from None
        match = [r for r in rows if r["trial_id"].startswith(args.trial_id)]
        if not match:
            raise _cli_error()(f"no trial {args.trial_id!r} in {args.dir} "
                               f"({len(rows)} trials)")
        if len(match) > 1:
            raise _cli_error()(f"trial id {args.trial_id!r} is ambiguous in {args.dir}: "
                               f"{len(match)} trials start with it")
        stored = match[0]
        doc = json.loads(stored["spec"])
    try:
        return TrialSpec.from_dict(doc), stored
    except TrialSpecError as exc:
        raise _cli_error()(f"trial spec: {exc}") from None


# columns that depend on the wall clock, not on the spec
_NONDETERMINISTIC = ("wall_time_s", "planner_time_s", "finished_utc", "code_version")


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def cmd_trial_rerun(args) -> int:
    from ft_sitl.missions.trial import run_trial
    from ft_sitl.navigation.registry import NavigatorError
    from ft_sitl.physics.platform import PlatformError
    from ft_sitl.scenarios.scenario import ScenarioError

    spec, stored = _find_spec(args)
    try:
        outcome = run_trial(spec, record=bool(args.trajectory or args.render))
    except (NavigatorError, PlatformError, ScenarioError) as exc:
        raise _cli_error()(f"cannot rerun trial {spec.trial_id}: {exc}") from None
    row = outcome.row
    print(f"trial {spec.trial_id}: {row['algorithm']} on {row['platform']} in "
          f"{row['scenario']} (trial {spec.trial}): {row['reason']}"
          f"{' - ' + row['detail'] if row['detail'] else ''}")
    if not math.isnan(row["time_to_goal_s"]):
        print(f"  time to goal {row['time_to_goal_s']:.2f} s")
    print(f"  navigation {row['nav_time_s']:.2f} s, path {row['path_length_m']:.2f} m, "
          f"max speed {row['max_speed_m_s']:.2f} m/s, min clearance "
          f"{row['min_clearance_m']:.3f} m")
    status = 0
    if stored is not None:
        diff = [k for k in row if k not in _NONDETERMINISTIC and k in stored
                and not _same(row[k], stored[k])]
        if diff:
            print("  DIFFERENT from the stored result in: " + ", ".join(
                f"{k} ({stored[k]!r} -> {row[k]!r})" for k in diff[:8]))
            status = 1
        else:
            print("  identical to the stored result (all but wall-clock columns)")
    if args.trajectory:
        np_traj = outcome.trajectory
        with open(args.trajectory, "w") as fh:
            fh.write("t_s,x,y,z\n")
            for t, x, y, z in np_traj:
                fh.write(f"{t:.3f},{x:.4f},{y:.4f},{z:.4f}\n")
        print(f"  trajectory: {args.trajectory} ({len(np_traj)} samples, ENU m)")
    if args.render:
        from ft_sitl.scenarios.render import render_scenario

        render_scenario(outcome.scenario, args.render,
                        trajectory=outcome.trajectory[:, 1:4] if len(outcome.trajectory)
                        else None,
                        title=f"{row['algorithm']} on {row['platform']}: {row['reason']}")
        print(f"  render: {args.render}")
    return status


# --- navigators -----------------------------------------------------------------------------
def cmd_navigators_list(args) -> int:
    from ft_sitl.navigation.registry import available, parameters

    rows = []
    for name, cls in sorted(available().items()):
        if isinstance(cls, str):
            rows.append({"name": name, "error": cls})
            continue
        doc = (cls.__doc__ or sys.modules[cls.__module__].__doc__ or "").strip()
        rows.append({"name": name, "class": f"{cls.__module__}.{cls.__qualname__}",
                     "rate_hz": cls.rate_hz, "depth_camera": cls.camera is not None,
                     "unavailable": cls.unavailable(),
                     "parameters": {k: v for k, v in parameters(cls).items()},
                     "summary": doc.splitlines()[0] if doc else ""})
    if args.json:
        print(json.dumps(rows, indent=2, default=str))
        return 0
    for r in rows:
        if "error" in r:
            print(f"{r['name']:14s} UNAVAILABLE: {r['error']}")
            continue
        params = ", ".join(f"{k}={v!r}" for k, v in r["parameters"].items()) or "-"
        print(f"{r['name']:14s} {r['rate_hz']:g} Hz  params: {params}")
        if r["summary"]:
            print(f"{'':14s} {r['summary']}")
        if r["unavailable"]:
            print(f"{'':14s} not runnable here: {r['unavailable']}")
    return 0


def cmd_navigators_install(args) -> int:
    """Check a NavRL checkpoint and copy it where the navrl navigator looks."""
    import shutil

    from ft_sitl.navigation.navrl import CHECKPOINT_NAME, data_dir
    from ft_sitl.navigation.navrl_policy import CheckpointError, NavRLPolicy

    if args.name != "navrl":
        raise _cli_error()(f"install: {args.name!r} has no files to install (only navrl "
                           "needs model weights)")
    try:
        NavRLPolicy.from_checkpoint(args.path)
    except CheckpointError as exc:
        raise _cli_error()(f"install navrl: {exc}") from None
    except OSError as exc:
        raise _cli_error()(f"install navrl: {args.path}: {exc}") from None
    dest = data_dir() / CHECKPOINT_NAME
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_suffix(".tmp")
    shutil.copyfile(args.path, tmp)
    tmp.replace(dest)
    print(f"navrl: checkpoint installed at {dest}")
    return 0


# --- parsers ---------------------------------------------------------------------------------
def add_parsers(sub) -> None:
    camp = sub.add_parser("campaign", help="run benchmark campaigns and report them",
                          description="Run the FLYINGTRUST matrix (algorithms x platforms x "
                                      "scenarios x trials) and report it.")
    csub = camp.add_subparsers(dest="campaign_command", metavar="ACTION", required=True)
    cr = csub.add_parser("run", help="run (or resume) a campaign",
                         description="Run a campaign file or preset (quick, paper) into "
                                     "--out; rerunning the same command resumes it.")
    cr.add_argument("campaign", help="campaign file (.toml, .yaml) or preset: quick, paper")
    cr.add_argument("--out", required=True, metavar="DIR", help="result directory")
    cr.add_argument("--workers", type=int, default=1, help="worker processes (default 1)")
    cr.add_argument("--csv", action="store_true", help="also write trials.csv")
    cr.add_argument("--no-report", action="store_true", help="do not write the report")
    cr.add_argument("--limit", type=int, metavar="N", help="stop after N new trials")
    cr.add_argument("--quiet", action="store_true", help="no progress bar")
    cr.add_argument("--transport", choices=("inprocess", "mavlink"), default="inprocess",
                    help="inprocess (default): navigators called in lockstep; mavlink: each "
                         "trial's vehicle served over MAVLink and its navigator run as a "
                         "MAVSDK client process (docs/wire.md)")
    cr.add_argument("--speed-factor", type=float, default=2.0,
                    help="simulated/wall time over MAVLink (default 2)")
    cr.add_argument("--mqtt", metavar="URL", help="MQTT broker for the bus over MAVLink "
                    "(default: an embedded broker per worker)")
    cr.set_defaults(func=cmd_campaign_run)
    cc = csub.add_parser("check", help="validate a campaign and show its matrix")
    cc.add_argument("campaign", help="campaign file (.toml, .yaml) or preset: quick, paper")
    cc.add_argument("--json", action="store_true", help="machine-readable output")
    cc.set_defaults(func=cmd_campaign_check)
    crep = csub.add_parser("report", help="write the HTML/Markdown report of a result dir")
    crep.add_argument("dir", help="campaign result directory")
    crep.add_argument("--csv", action="store_true", help="also write trials.csv")
    crep.set_defaults(func=cmd_campaign_report)

    ccmp = csub.add_parser("compare", help="outcome agreement of two result dirs",
                           description="Compare two result directories trial by trial (the "
                                       "same campaign in-process and --transport mavlink, "
                                       "or two code versions): how often success and the "
                                       "reason agree, and which trials differ.")
    ccmp.add_argument("a", help="result directory A")
    ccmp.add_argument("b", help="result directory B")
    ccmp.add_argument("--json", action="store_true", help="machine-readable output")
    ccmp.set_defaults(func=cmd_campaign_compare)

    tr = sub.add_parser("trial", help="single trials")
    tsub = tr.add_subparsers(dest="trial_command", metavar="ACTION", required=True)
    trr = tsub.add_parser("rerun", help="replay one trial of a campaign and compare",
                          description="Replay one trial from its stored spec and check that "
                                      "it gives the same result.")
    trr.add_argument("dir", nargs="?", help="campaign result directory")
    trr.add_argument("trial_id", nargs="?", help="trial id (a unique prefix is enough)")
    trr.add_argument("--spec", metavar="FILE", help="a trial spec JSON file instead")
    trr.add_argument("--trajectory", metavar="CSV", help="save the flown trajectory")
    trr.add_argument("--render", metavar="PNG", help="draw the trajectory over the scenario")
    trr.set_defaults(func=cmd_trial_rerun)

    nav = sub.add_parser("navigators", help="the registered navigation algorithms")
    nsub = nav.add_subparsers(dest="navigators_command", metavar="ACTION", required=True)
    nl = nsub.add_parser("list", help="list navigators and their parameters")
    nl.add_argument("--json", action="store_true", help="machine-readable output")
    nl.set_defaults(func=cmd_navigators_list)
    ni = nsub.add_parser("install", help="install a navigator's model weights (navrl)",
                         description="Check a NavRL policy checkpoint (the authors' released "
                                     "navrl_checkpoint.pt) and copy it to the data directory "
                                     "where the navrl navigator finds it.")
    ni.add_argument("name", help="navigator (navrl)")
    ni.add_argument("path", help="checkpoint file")
    ni.set_defaults(func=cmd_navigators_install)

