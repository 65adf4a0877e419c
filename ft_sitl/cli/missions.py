"""``ft-sitl campaign`` and ``ft-sitl trial``: the benchmark itself."""

from __future__ import annotations

import collections
import dataclasses
import json
import math
import random
import signal
import subprocess
import sys
from pathlib import Path

from ft_sitl import numeric_env
from ft_sitl.autopilot.params import DEFAULT_GAINS, GAIN_MODES
from ft_sitl.bus.options import parse_broker_url
from ft_sitl.cli.common import CliError, option_value
from ft_sitl.mavlink.autopilots import DEFAULT_AUTOPILOT
from ft_sitl.missions.campaign import (
    GRID_CACHE_DIR,
    DaskExecutor,
    ExecutorError,
    LocalExecutor,
    report_meta,
    run_campaign,
)
from ft_sitl.missions.campaign_file import CampaignError, load_campaign
from ft_sitl.missions.report import write_report
from ft_sitl.missions.results import rows_from_parquet, to_frame
from ft_sitl.missions.spec import PROTOCOLS, TrialSpec, TrialSpecError
from ft_sitl.missions.store import (
    PARQUET_FILE,
    TRIALS_FILE,
    ResultStore,
    StoreError,
    load_rows,
)
from ft_sitl.missions.thrust_floor import THRUST_FLOOR
from ft_sitl.missions.trial import run_trial
from ft_sitl.navigation.registry import NavigatorError
from ft_sitl.physics.platform import PlatformError
from ft_sitl.scenarios.families import describe_family
from ft_sitl.scenarios.render import render_scenario, scenario_title
from ft_sitl.scenarios.scenario import ScenarioError
from ft_sitl.transport import transport as mavlink_transport
from ft_sitl.wire.navigate import NavigateError, require_mavsdk


def _campaign(source: str):
    try:
        return load_campaign(source)
    except CampaignError as exc:
        raise CliError(str(exc)) from None


# --- campaign ------------------------------------------------------------------------------
def configurations_flown(campaign) -> list[tuple[dict[int, int], list[int]]]:
    """Per scenario entry of ``campaign``: ``({configuration: its trials per algorithm x
    platform x axes combination}, [listed configurations no trial flies])``, in the order
    listed. Trials cycle over the listed indices (docs/missions.md, "The trial matrix"): with
    ``trials = 1`` and ``indices = [1, 2]`` only configuration 1 flies. Read off the entry's
    own trial specs, so it is the rule ``trial_specs`` applies, not a copy of it."""
    out = []
    for entry in campaign.scenarios:
        specs = dataclasses.replace(campaign, scenarios=[entry]).trial_specs()
        combinations = len(specs) // campaign.trials
        counts = collections.Counter(s.scenario_index for s in specs)
        listed = list(dict.fromkeys(entry.indices))
        out.append(({i: counts[i] // combinations for i in listed if counts[i]},
                    [i for i in listed if not counts[i]]))
    return out


def _flown_text(entry, flies: dict[int, int], never: list[int]) -> str:
    """``forest [1, 2]``; ``forest [1, 2] x3 each``; ``forest [1 x2, 2 x1]``;
    ``forest [1] (listed [1, 2]: 2 never flies)``."""
    times = set(flies.values())
    if len(times) == 1:
        text = f"{list(flies)}" + (f" x{times.pop()} each" if times != {1} else "")
    else:
        text = "[" + ", ".join(f"{i} x{n}" for i, n in flies.items()) + "]"
    if never:
        text += (f" (listed {list(entry.indices)}: {', '.join(map(str, never))} never "
                 f"fl{'ies' if len(never) == 1 else 'y'})")
    return f"{entry.family} {text}"


def _warn_unflown(c, source: str, flown) -> None:
    """A warning for each scenario entry that lists configurations no trial flies."""
    for k, (entry, (_, never)) in enumerate(zip(c.scenarios, flown, strict=True)):
        if never:
            n = len(entry.indices)
            _warn(f"{c.source or source}: scenarios[{k}] ({entry.family}): "
                  f"configuration{'s' if len(never) > 1 else ''} "
                  f"{', '.join(map(str, never))} listed but never flown: trials = {c.trials} "
                  f"cycles over indices {list(entry.indices)} (trial t flies indices[t % "
                  f"{n}]); set trials = {n} to fly each once, or list only those that fly")


def _floors_text(c) -> str:
    """The MPC_THR_MIN each platform's trials fly under the campaign's thrust floor (with
    the defaults of the params axis), grouped by value."""
    by: dict = {}
    for p in c.platforms:
        floor = (c.trial_params(p, None) or {}).get("MPC_THR_MIN")
        by.setdefault(floor, []).append(p.name)
    changed = "; ".join(f"{v:g} on {', '.join(names)}" for v, names in by.items()
                        if v is not None)
    if not changed:
        return "every platform as its parameters say"
    return f"MPC_THR_MIN {changed}" + ("; the others as their parameters say"
                                       if None in by else "")


def cmd_campaign_check(args) -> int:
    c = _campaign(args.campaign)
    specs = c.trial_specs()
    flown = configurations_flown(c)
    _warn_unflown(c, args.campaign, flown)
    info = {"name": c.name, "trials": len(specs),
            "algorithms": [a.label for a in c.algorithms],
            "platforms": [p.name for p in c.platforms],
            "scenarios": [{"family": s.family, "indices": list(s.indices),
                           "flies": [{"index": i, "times": n} for i, n in flies.items()],
                           "never_flies": never}
                          for s, (flies, never) in zip(c.scenarios, flown, strict=True)],
            "trials_per_combination": c.trials, "limits": c.limits.as_dict(),
            "wind": [w or {} for w in c.winds], "gains": c.modes(),
            "thrust_floor": c.thrust_floor,
            "params": [p or {} for p in c.param_sets],
            "actuators": [a or {} for a in c.actuator_sets],
            "perception": [p or {} for p in c.perceptions],
            "estimator": [e or {} for e in c.estimators],
            "failures": [f or {} for f in c.failure_sets],
            "movers": [m or {} for m in c.mover_sets],
            "fence": [f or {} for f in c.fences],
            "aggressiveness": [lv.as_dict() for lv in c.levels if lv is not None],
            "notes": list(c.notes)}
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    axes = "".join(f" x {n} {what}" for n, what in (
        (len(c.winds), "winds"), (len(c.modes()), "gain modes"),
        (len(c.param_sets), "parameter sets"), (len(c.actuator_sets), "actuator settings"),
        (len(c.perceptions), "perception settings"), (len(c.estimators), "estimators"),
        (len(c.failure_sets), "failure settings"), (len(c.mover_sets), "mover settings"),
        (len(c.fences), "fences"), (len(c.levels), "aggressiveness levels")) if n > 1)
    print(f"campaign {c.name!r}: {len(specs)} trials = {len(c.algorithms)} algorithms x "
          f"{len(c.platforms)} platforms x {len(c.scenarios)} scenario families x "
          f"{c.trials} trials{axes}")
    print(f"  algorithms: {', '.join(info['algorithms'])}")
    print(f"  platforms:  {', '.join(info['platforms'])}")
    print("  scenarios:  " + ", ".join(
        _flown_text(s, *f) for s, f in zip(c.scenarios, flown, strict=True)))
    if c.winds != [None]:
        print("  wind:       " + "; ".join(
            ", ".join(f"{k} {v}" for k, v in w.items()) if w else "calm" for w in c.winds))
    if len(c.modes()) > 1:
        print(f"  gains:      {', '.join(c.modes())}")
    if c.thrust_floor != THRUST_FLOOR.default:
        print(f"  thrust floor: {c.thrust_floor} ({_floors_text(c)})")
    for label, values, none in (("params", c.param_sets, "defaults"),
                                ("actuators", c.actuator_sets, "as built"),
                                ("perception", c.perceptions, "ideal"),
                                ("estimator", c.estimators, "the truth"),
                                ("failures", c.failure_sets, "none"),
                                ("movers", c.mover_sets, "static")):
        if values != [None]:
            print(f"  {label + ':':11s} " + "; ".join(
                ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{k} {v}"
                          for k, v in p.items()) if p else none for p in values))
    if c.fences != [None]:
        print("  fence:      " + "; ".join(_fence_summary(f) for f in c.fences))
    if c.levels != [None]:
        print("  aggressiveness: " + "; ".join(lv.summary() for lv in c.levels))
    lim = c.limits
    speed = "speed per level" if c.levels != [None] else f"{lim.max_speed_m_s:g} m/s"
    print(f"  limits: {speed}, {lim.timeout_s:g} s, goal sphere "
          f"{lim.goal_radius_m:g} m held {lim.hold_s:g} s")
    for note in c.notes:
        print(f"  note: {note}")
    return 0


def _fence_summary(fence: dict | None) -> str:
    """A trial fence in a few words: "land: 1 inclusion polygon, 5 m from home"."""
    if fence is None:
        return "none"
    parts = []
    for key, what in (("polygons", "polygon"), ("circles", "circle")):
        for kind in (True, False):
            n = sum(a["inclusion"] is kind for a in fence[key])
            if n:
                parts.append(f"{n} {'inclusion' if kind else 'exclusion'} {what}"
                             f"{'s' if n > 1 else ''}")
    if fence["max_hor_dist_m"]:
        parts.append(f"{fence['max_hor_dist_m']:g} m from home")
    if fence["max_ver_dist_m"]:
        parts.append(f"{fence['max_ver_dist_m']:g} m above home")
    return f"{fence['action']}: {', '.join(parts)}"


def _interrupt(signum, frame):
    raise KeyboardInterrupt(f"signal {signum}")


def cmd_campaign_run(args) -> int:
    c = _campaign(args.campaign)
    _warn_unflown(c, args.campaign, configurations_flown(c))
    if args.workers < 1:
        raise CliError(f"--workers: {args.workers} must be at least 1")
    if args.limit is not None and args.limit < 1:
        raise CliError(f"--limit: {args.limit} must be at least 1")
    executor = _executor(args)
    out = Path(args.out)
    try:
        if args.autopilot != DEFAULT_AUTOPILOT and args.transport != "mavlink":
            raise CliError(f"--autopilot {args.autopilot}: only with --transport mavlink "
                           "(in-process trials have no MAVLink face)")
        transport = mavlink_transport(args.transport, args.speed_factor, args.mqtt,
                                      lockstep=not args.free_running,
                                      autopilot=args.autopilot)
        if transport.kind == "mavlink":  # each trial's navigator flies as a MAVSDK client
            require_mavsdk()
    except (CampaignError, NavigateError) as exc:
        raise CliError(str(exc)) from None
    for note in c.notes:
        print(f"note: {note}", file=sys.stderr)
    if args.mqtt:
        option_value("--mqtt", parse_broker_url, args.mqtt)
    # SIGTERM (kill, a cluster's job limit) ends the run as Ctrl-C does: the finished
    # trials stay, the workers stop and runs.json records the run as interrupted
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        summary = run_campaign(c, out, executor=executor, progress=not args.quiet,
                               limit=args.limit, transport=transport,
                               reuse=args.reuse or ())
    except (StoreError, ExecutorError, CampaignError) as exc:
        raise CliError(str(exc)) from None
    except KeyboardInterrupt:
        print(f"interrupted: finished trials are in {out}; run the same command again to "
              f"resume", file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGTERM, previous)
    rate = summary.ran / summary.wall_s if summary.wall_s > 0 else math.nan
    print(f"{summary.ran} trials run, {summary.skipped} already done, {summary.total} in the "
          f"campaign; {summary.wall_s:.1f} s ({rate:.2f} trials/s) -> {out}")
    for tid, err in summary.errors[:10]:
        print(f"  trial {tid} could not run: {err}", file=sys.stderr)
    if summary.errors:
        print(f"{len(summary.errors)} trials could not run (not recorded; a rerun retries "
              f"them)", file=sys.stderr)
    if args.csv:
        store = ResultStore(out)
        store.load()
        if store.done:
            print(f"table: {store.write_tables(csv=True)[-1]}")
    if not args.no_report and (summary.ran or summary.skipped):
        _report(out, quiet=False, warn=False)  # (the run has said what it skipped)
    return 1 if summary.errors else 0


def _executor(args):
    """Where ``campaign run`` flies its trials: a local pool of --workers processes (also
    for one: a crash or a hang then ends a worker, not the campaign), or Dask."""
    if args.scheduler and args.cluster:
        raise CliError("--scheduler and --cluster: give one (an existing cluster, or "
                       "--cluster local to start one here)")
    if args.chunk_size is not None:
        if not (args.scheduler or args.cluster):
            raise CliError("--chunk-size: only with --scheduler or --cluster")
        if args.chunk_size < 1:
            raise CliError(f"--chunk-size: {args.chunk_size} must be at least 1")
    chunk = args.chunk_size or 10
    if args.scheduler:
        address = args.scheduler.strip()
        scheme, sep, rest = address.partition("://")
        if not sep or scheme not in ("tcp", "tls", "ucx", "ws", "wss", "inproc") or not rest:
            raise CliError(f"--scheduler: {args.scheduler!r} is not a scheduler address "
                           f"like tcp://host:8786")
        return DaskExecutor(scheduler=address, chunk_max=chunk)
    if args.cluster == "local":
        return DaskExecutor(local_workers=args.workers, chunk_max=chunk)
    return LocalExecutor(args.workers, Path(args.out) / GRID_CACHE_DIR)


def _warn(note: str) -> None:
    print(f"warning: {note}", file=sys.stderr)


def _load_rows(directory, warn: bool = True) -> tuple[dict, list[dict]]:
    """load_rows, its notes (damaged lines skipped) printed on stderr when ``warn``."""
    try:
        return load_rows(directory, on_note=_warn if warn else None)
    except StoreError as exc:
        raise CliError(str(exc)) from None


def _report(out: Path, quiet: bool = False, warn: bool = True) -> Path:
    campaign, rows = _load_rows(out, warn)
    if not rows:
        raise CliError(f"{out}: no finished trials yet")
    paths = write_report(to_frame(rows), out, campaign_spec=campaign.get("spec", {}),
                         meta=report_meta(out, campaign))
    page = paths["report.html"]
    if not quiet:
        print(f"report: {page}  (summary: {paths['summary.md']})")
    return page


def cmd_campaign_report(args) -> int:
    out = Path(args.dir)
    if args.csv:
        _load_rows(out, warn=False)  # (the report below says what it skipped)
        store = ResultStore(out)
        store.load()
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
    _, ra = _load_rows(Path(args.a))
    _, rb = _load_rows(Path(args.b))
    res = compare_runs(ra, rb)
    if res["common_trials"] == 0:
        raise CliError(f"{args.a} and {args.b} have no trial in common (different "
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
def _stored_rows(directory) -> list[dict]:
    """The finished rows of a result directory: a campaign's (campaign.json,
    trials.jsonl) or, without trials.jsonl, the table of one holding trials.parquet
    (e.g. docs/results/paper, or a committed campaign kept with its campaign.json)."""
    d = Path(directory)
    if not (d / TRIALS_FILE).exists() and (d / PARQUET_FILE).is_file():
        try:
            return rows_from_parquet(d / PARQUET_FILE)
        except (OSError, ValueError) as exc:
            raise CliError(f"{d / PARQUET_FILE}: unreadable ({exc})") from None
    return _load_rows(d)[1]


def _spec_of(doc):
    try:
        return TrialSpec.from_dict(doc)
    except TrialSpecError as exc:
        raise CliError(f"trial spec: {exc}") from None


def _find_spec(args):
    if args.spec is not None:
        try:
            doc = json.loads(Path(args.spec).read_text())
        except FileNotFoundError:
            raise CliError(f"--spec: {args.spec}: no such file") from None
        except (OSError, ValueError) as exc:
            raise CliError(f"--spec: {args.spec}: not a JSON trial spec ({exc})") from None
        return _spec_of(doc), None
    if args.dir is None or args.trial_id is None:
        raise CliError("give a campaign directory and a trial id, or --spec FILE")
    rows = _stored_rows(args.dir)
    match = [r for r in rows if r["trial_id"].startswith(args.trial_id)]
    if not match:
        raise CliError(f"no trial {args.trial_id!r} in {args.dir} ({len(rows)} trials)")
    if len(match) > 1:
        raise CliError(f"trial id {args.trial_id!r} is ambiguous in {args.dir}: "
                       f"{len(match)} trials start with it")
    stored = match[0]
    return _spec_of(json.loads(stored["spec"])), stored


def sample_stratified(rows: list[dict], n: int, seed: int) -> list[dict]:
    """``n`` rows picked round-robin over the (algorithm, family) cells: the cells in a
    shuffled order, each cell's rows shuffled; the same rows for the same ``seed``."""
    rng = random.Random(seed)
    cells: dict[tuple, list[dict]] = {}
    for r in sorted(rows, key=lambda r: r["trial_id"]):
        cells.setdefault((str(r["algorithm"]), str(r["family"])), []).append(r)
    order = sorted(cells)
    rng.shuffle(order)
    for key in order:
        rng.shuffle(cells[key])
    picked: list[dict] = []
    depth = 0
    while len(picked) < n:
        for key in order:
            if depth < len(cells[key]) and len(picked) < n:
                picked.append(cells[key][depth])
        depth += 1
    return picked


# columns that depend on the wall clock, not on the spec
_NONDETERMINISTIC = ("wall_time_s", "planner_time_s", "finished_utc", "code_version",
                     "software")


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def differences(new: dict, stored: dict) -> list[str]:
    """The columns in which a rerun's row differs from the stored one, as ``column
    (stored -> new)``; wall-clock columns are not compared, NaN equals NaN."""
    return [f"{k} ({stored[k]!r} -> {new[k]!r})" for k in new
            if k not in _NONDETERMINISTIC and k in stored and not _same(new[k], stored[k])]


def _rerun(spec, record: bool = False):
    try:
        return run_trial(spec, record=record)
    except (NavigatorError, PlatformError, ScenarioError) as exc:
        raise CliError(f"cannot rerun trial {spec.trial_id}: {exc}") from None


def _rerun_sample(args) -> int:
    if args.trial_id is not None or args.spec is not None:
        raise CliError("--sample: give a result directory alone, not a trial id or --spec")
    if args.trajectory or args.render:
        raise CliError("--trajectory and --render take one trial, not --sample")
    if args.dir is None:
        raise CliError("--sample: give a result directory")
    rows = _stored_rows(args.dir)
    if not 1 <= args.sample <= len(rows):
        raise CliError(f"--sample: {args.sample} must be within 1..{len(rows)} (the trials "
                       f"in {args.dir})")
    picked = sample_stratified(rows, args.sample, args.sample_seed)
    if (code := _at_rows_level(args, picked)) is not None:
        return code
    same = 0
    for stored in picked:
        spec = _spec_of(json.loads(stored["spec"]))
        diff = differences(_rerun(spec).row, stored)
        where = f"{spec.trial_id[:10]} {stored['algorithm']} {stored['family']} " \
                f"{stored['scenario']} (trial {spec.trial})"
        if diff:
            print(f"{where}: DIFFERENT in " + ", ".join(diff[:8]), flush=True)
        else:
            same += 1
            print(f"{where}: identical", flush=True)
    print(f"{same} of {len(picked)} identical")
    return 0 if same == len(picked) else 1


def level_of(stored: dict) -> str:
    """The instruction-set level a stored row was made at (ft_sitl.numeric_env): its
    ``software`` column's ``isa``; rows made before the pins (2026-12-07) record none and
    were made at ``host``."""
    try:
        sw = json.loads(stored.get("software") or "{}")
    except (TypeError, ValueError):
        sw = {}
    return sw.get("isa", numeric_env.HOST) if isinstance(sw, dict) else numeric_env.HOST


def _argv_of(args) -> list[str]:
    argv = ["trial", "rerun"]
    argv += [str(a) for a in (args.dir, args.trial_id) if a is not None]
    for flag, value in (("--spec", args.spec), ("--trajectory", args.trajectory),
                        ("--render", args.render), ("--sample", args.sample),
                        ("--sample-seed", args.sample_seed if args.sample else None)):
        if value is not None:
            argv += [flag, str(value)]
    return argv


def _at_rows_level(args, rows: list[dict]) -> int | None:
    """Re-run in a child process at the rows' instruction-set level when this process
    computes at another one (None: this process flies them). A level the user chose with
    FT_SITL_ISA is kept, with a note."""
    levels = {level_of(r) for r in rows}
    here = numeric_env.in_force()["level"]
    if levels == {here}:
        return None
    if len(levels) > 1:
        raise CliError(f"these rows were made at different instruction-set levels "
                       f"({', '.join(sorted(levels))}): rerun them one level at a time "
                       f"(FT_SITL_ISA, docs/results/README.md)")
    (level,) = levels
    made = f"made at instruction-set level {level}" + (
        " (before ft-sitl pinned one, 2026-12-07)" if level == numeric_env.HOST else "")
    if numeric_env.chosen_by_user():
        print(f"note: these rows were {made}; FT_SITL_ISA gives {here} here, so they "
              f"need not re-run identically",
              flush=True)
        return None
    print(f"these rows were {made}: re-running them at that level (FT_SITL_ISA={level})"
          + (f"; at {numeric_env.HOST} a row re-runs bit for bit only on the processor that "
             f"made it (docs/results/README.md)" if level == numeric_env.HOST else ""),
          flush=True)
    child = subprocess.Popen([sys.executable, "-m", "ft_sitl", *_argv_of(args)],
                             env=numeric_env.child_env(level), stdout=subprocess.PIPE,
                             text=True)
    assert child.stdout is not None
    for line in child.stdout:
        print(line, end="", flush=True)
    return child.wait()


def cmd_trial_rerun(args) -> int:
    if args.sample is not None:
        return _rerun_sample(args)
    spec, stored = _find_spec(args)
    if stored is not None and (code := _at_rows_level(args, [stored])) is not None:
        return code
    outcome = _rerun(spec, record=bool(args.trajectory or args.render))
    row = outcome.row
    print(f"trial {spec.trial_id}: {row['algorithm']} on {row['platform']} in "
          f"{row['scenario']} (trial {spec.trial}): {row['reason']}"
          f"{' - ' + row['detail'] if row['detail'] else ''}")
    print(f"  flown under protocol version {spec.protocol}: "
          f"{PROTOCOLS[spec.protocol].summary}")
    if spec.scenario_version is not None:
        fam = describe_family(spec.family)
        print(f"  scenario built by generator version {spec.scenario_version} of "
              f"{fam.name} (newest: {fam.version}): {fam.changes[spec.scenario_version]}")
    if spec.gains != DEFAULT_GAINS:
        print(f"  controller gains: {spec.gains} (FT_GAIN_MODE {GAIN_MODES[spec.gains]})")
    if not math.isnan(row["time_to_goal_s"]):
        print(f"  time to goal {row['time_to_goal_s']:.2f} s")
    print(f"  navigation {row['nav_time_s']:.2f} s, path {row['path_length_m']:.2f} m, "
          f"max speed {row['max_speed_m_s']:.2f} m/s, min clearance "
          f"{row['min_clearance_m']:.3f} m")
    status = 0
    if stored is not None:
        diff = differences(row, stored)
        if diff:
            print("  DIFFERENT from the stored result in: " + ", ".join(diff[:8]))
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
        render_scenario(outcome.scenario, args.render,
                        trajectory=outcome.trajectory[:, 1:4] if len(outcome.trajectory)
                        else None,
                        title=f"{scenario_title(outcome.scenario)} - {row['algorithm']} on "
                              f"{row['platform']}: {row['reason']}")
        print(f"  render: {args.render}")
    return status
