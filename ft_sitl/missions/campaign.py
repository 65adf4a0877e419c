"""Campaigns: the algorithm x platform x scenario x trial matrix, run and resumed.

The campaign file (what to run, TOML or YAML) and its parsing are in
:mod:`ft_sitl.missions.campaign_file` (:func:`~ft_sitl.missions.campaign_file.load_campaign`).

Running: :func:`run_campaign` hands trials, grouped by scenario configuration (a worker
builds each scenario's collision grid once), to an executor
(:mod:`ft_sitl.missions.executors`): in this process, a local pool of worker processes, or
a Dask cluster. Each finished trial is written to the
:class:`~ft_sitl.missions.store.ResultStore` at once, by this process only; a rerun of the
same campaign into the same directory skips finished trials.
"""

from __future__ import annotations

import functools
import json
import os
import platform as pyplatform
import signal
import sys
import threading
import time
import traceback
from collections import Counter, defaultdict
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from ft_sitl import __version__, numeric_env
from ft_sitl.missions.campaign_file import COMMAND, Campaign, CampaignError
from ft_sitl.missions.durable import durable_replace
from ft_sitl.missions.executors import (
    DIED_DETAIL,
    DaskExecutor,
    Executor,
    ExecutorError,
    LocalExecutor,
    SerialExecutor,
    throughput,
)
from ft_sitl.missions.plan import PERCEPTION_WIRE
from ft_sitl.missions.progress import RemainingTime, reference_cost_s
from ft_sitl.missions.protocol import failed_row
from ft_sitl.missions.resources import RESOURCES
from ft_sitl.missions.results import Outcome
from ft_sitl.missions.reuse import check_sources, reuse_rows
from ft_sitl.missions.spec import TrialSpec, platform_for
from ft_sitl.missions.store import ResultStore
from ft_sitl.missions.trial import run_trial
from ft_sitl.missions.watchdog import TRIAL_WALL_BUDGET_S, wall_budget_from_env

__all__ = ["CHUNK_MAX", "GRID_CACHE_DIR", "DaskExecutor", "Executor", "ExecutorError",
           "LocalExecutor", "RunSummary", "SerialExecutor", "Transport", "died_row",
           "machine_info", "record_run", "report_meta", "run_campaign", "run_chunk"]

CHUNK_MAX = 40
#: the workers' shared distance grids, inside the output directory while a run lasts (a
#: killed run leaves at most trial.GRID_CACHE_KEEP grids there; the next run reuses them
#: and removes the directory when it ends)
GRID_CACHE_DIR = ".grid-cache"


# --- executors ------------------------------------------------------------------------------
@dataclass(frozen=True)
class Transport:
    """How trials fly: ``inprocess`` (the navigator called in lockstep) or ``mavlink`` (the
    vehicle served over MAVLink at ``speed_factor``, the navigator in another process,
    ``mqtt`` the bus broker URL or None for the embedded one). A ``command`` algorithm
    always flies over MAVLink.

    ``wire`` is what flies one trial over MAVLink (``wire(spec, speed_factor, mqtt)`` ->
    the row): the transport room above this layer provides it
    (:func:`ft_sitl.transport.transport`); without it only in-process trials fly."""

    kind: str = "inprocess"
    speed_factor: float = 2.0
    mqtt: str | None = None
    wire: Callable | None = None
    #: over MAVLink, registered navigators fly in lockstep (rows equal to in-process ones);
    #: False: free-running, paced against the wall clock (runs.json records which)
    lockstep: bool = True
    #: over MAVLink, the autopilot whose face serves the vehicle, as ``wire`` was made for
    #: it (ft_sitl.mavlink.autopilots; None: not said); runs.json records it
    autopilot: str | None = None

    def __post_init__(self):
        if self.kind not in ("inprocess", "mavlink"):
            raise CampaignError(f"--transport: {self.kind!r} is not inprocess or mavlink")
        sf = self.speed_factor
        if isinstance(sf, bool) or not isinstance(sf, (int, float)) or not 0.1 <= sf <= 20:
            raise CampaignError(f"--speed-factor: {sf!r} must be within 0.1..20")

    def over_the_wire(self, spec: TrialSpec) -> bool:
        return self.kind == "mavlink" or spec.algorithm == COMMAND


def run_chunk(specs: list[dict], transport: Transport | None = None,
              wall_budget_s: float | None = TRIAL_WALL_BUDGET_S
              ) -> list[tuple[str, dict | None, str | None]]:
    """Run trials (as spec dicts) one after the other: (trial_id, row or None, error)."""
    out = []
    transport = transport or Transport()
    for d in specs:
        spec = TrialSpec.from_dict(d)
        try:
            if transport.over_the_wire(spec):
                row = transport.wire(spec, transport.speed_factor, transport.mqtt)
            else:
                row = run_trial(spec, wall_budget_s=wall_budget_s).row
            out.append((spec.trial_id, row, None))
        except KeyboardInterrupt:
            raise
        except BaseException as exc:  # noqa: BLE001 - reported, the campaign goes on
            # (the traceback on the worker's stderr: the campaign prints the one-line error)
            print(f"trial {spec.trial_id} could not run:\n{traceback.format_exc()}",
                  file=sys.stderr, flush=True)
            out.append((spec.trial_id, None, f"{type(exc).__name__}: {exc}"))
    return out


def _chunks(specs: list[TrialSpec], size: int = CHUNK_MAX) -> list[list[dict]]:
    groups: dict = {}
    for s in specs:
        groups.setdefault((s.scenario_file, s.family, s.scenario_index), []).append(
            s.to_dict())
    out = []
    for g in groups.values():
        for k in range(0, len(g), size):
            out.append(g[k:k + size])
    return out


def died_row(d: dict, detail: str = DIED_DETAIL) -> dict:
    """A navigator-error row for a trial whose worker process died or was killed."""
    spec = TrialSpec.from_dict(d)
    return failed_row(spec, platform_for(spec), RESOURCES.scenario(spec),
                      Outcome.NAVIGATOR_ERROR, detail)


def machine_info() -> dict:
    """CPU model, cores, OS and Python of this machine (for reports)."""

    model = numeric_env.cpu_model_name() or pyplatform.processor()
    return {"cpu_model": model or "unknown", "n_cpus": os.cpu_count(),
            "os": f"{pyplatform.system()} {pyplatform.release()}",
            "python": pyplatform.python_version()}


def record_run(out_dir: Path, entry: dict) -> None:
    """Append one run's facts to DIR/runs.json (every run and resume of the campaign)."""

    path = Path(out_dir) / "runs.json"
    runs = []
    if path.exists():
        try:
            runs = json.loads(path.read_text())
        except (OSError, ValueError):
            runs = []
    runs.append(entry)
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(runs, indent=2))
    durable_replace(tmp, path)


def report_meta(out_dir: Path, campaign: dict) -> dict:
    """The report's run facts from DIR/runs.json."""

    path = Path(out_dir) / "runs.json"
    runs = []
    if path.exists():
        try:
            runs = json.loads(path.read_text())
        except (OSError, ValueError):
            runs = []
    meta = {"code_version": campaign.get("code_version", __version__),
            "machine": runs[-1]["machine"] if runs else machine_info()}
    if runs:
        meta["started_utc"] = runs[0]["started_utc"]
        meta["finished_utc"] = runs[-1]["finished_utc"]
        meta["wall_time_s"] = round(sum(r["wall_time_s"] for r in runs), 2)
        if all(isinstance(r.get("trials_run"), int) for r in runs):
            meta["trials_run"] = sum(r["trials_run"] for r in runs)
        meta["runs (resumes)"] = len(runs)
        meta["workers"] = runs[-1].get("workers")
    return meta


@dataclass
class RunSummary:
    total: int
    skipped: int
    ran: int
    errors: list[tuple[str, str]]
    wall_s: float


@contextmanager
def _signals_deferred():
    """Ctrl-C and SIGTERM wait while a finished row is written and counted, then act: the
    KeyboardInterrupt they raise between the write and the count left a row in
    trials.jsonl that runs.json did not count. The deferral is in Python's handlers, not
    a thread's signal mask: the kernel hands a process signal to any thread that does not
    block it (tqdm's monitor, an executor's threads), and Python then runs the handler in
    the main thread wherever it is. Off the main thread (no handlers to swap) it is a
    no-op."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    watched = (signal.SIGINT, signal.SIGTERM)
    old = {s: signal.signal(s, lambda signum, _frame: caught.append(signum)) for s in watched}
    try:
        yield
    finally:
        for s, handler in old.items():
            signal.signal(s, signal.SIG_DFL if handler is None else handler)
        for s in dict.fromkeys(caught):
            signal.raise_signal(s)  # the handler in force before acts on it now


def run_campaign(campaign: Campaign, out_dir: str | Path, *, workers: int = 1,
                 executor: Executor | None = None, progress: bool = True,
                 limit: int | None = None, transport: Transport | None = None,
                 reuse: Sequence[str | Path] = ()) -> RunSummary:
    """Run (or resume) a campaign into out_dir. ``executor``: where trials fly (default:
    in this process for ``workers=1``, else a :class:`LocalExecutor` of that many
    processes); ``limit``: stop after that many new trials (tests, smoke runs);
    ``transport``: in-process (default) or over MAVLink; ``reuse``: result directories
    whose rows of this campaign's trials are taken instead of flown
    (:mod:`~ft_sitl.missions.reuse`)."""

    try:
        budget = wall_budget_from_env()  # a bad value is one clear error, not one per trial
    except ValueError as exc:
        raise CampaignError(str(exc)) from None
    specs = campaign.trial_specs()
    transport = transport or Transport()
    if transport.kind == "mavlink" and any(s.perception is not None for s in specs):
        raise CampaignError(f"--transport mavlink: {PERCEPTION_WIRE}")
    if transport.wire is None and any(transport.over_the_wire(s) for s in specs):
        raise CampaignError("this campaign flies trials over MAVLink (--transport mavlink, or "
                            "a 'command' algorithm), which needs the MAVLink transport: "
                            "run it with `ft-sitl campaign run`, or pass "
                            "transport=ft_sitl.transport.transport(...)")
    meta = {"spec": campaign.spec_dict(), "total_trials": len(specs),
            "code_version": __version__}
    check_sources(reuse, out_dir)
    store = ResultStore(out_dir)
    for note in store.open(meta, trial_ids=[s.trial_id for s in specs]):
        print(f"warning: {note}", file=sys.stderr)
    try:
        reused = reuse_rows(store, reuse, [s.trial_id for s in specs],
                            append=_append_deferred(store))
    except BaseException:
        store.close()
        raise
    for src, n in reused.items():
        print(f"note: {n} trial{'s' if n != 1 else ''} taken from {src} (--reuse)",
              file=sys.stderr)
    todo = [s for s in specs if s.trial_id not in store.done]
    skipped = len(specs) - len(todo)
    if limit is not None:
        todo = todo[:limit]
    ex = executor or (SerialExecutor() if workers <= 1 else
                      LocalExecutor(workers, Path(out_dir) / GRID_CACHE_DIR, budget))
    ex.budget_s = budget  # the campaign's budget is the one its executor enforces
    errors: list[tuple[str, str]] = []
    t0 = time.perf_counter()
    started = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    bar = None
    ran = 0
    per_worker: dict[str, list[float]] = defaultdict(list)
    completed = False
    try:
        ex.start()
        dashboard = getattr(ex, "dashboard", None)
        if dashboard and progress:
            print(f"Dask dashboard: {dashboard}", file=sys.stderr)
        if progress:
            # the time left from the campaign's mix, not tqdm's rate of the first trials
            # (compilation warm-up, one navigator in one family): missions/progress.py
            keys = {s.trial_id: (s.label or s.algorithm, s.family) for s in todo}
            pending = Counter(keys.values())
            eta = RemainingTime({key: reference_cost_s(s.algorithm, s.family)
                                 for s in todo if (key := keys[s.trial_id])},
                                _describe(ex).get("workers"))
            bar = tqdm(total=len(specs), initial=skipped, unit="trial", dynamic_ncols=True,
                       desc=campaign.name, smoothing=0.05, postfix=_left(eta.seconds(pending)),
                       bar_format="{l_bar}{bar}| {n_fmt}/{total_fmt} "
                                  "[{elapsed}, {rate_fmt}{postfix}]")
        fn = functools.partial(run_chunk, transport=transport,
                               wall_budget_s=budget)
        for worker, results in ex.imap(fn, _chunks(todo, ex.chunk_max)):
            for tid, row, err in results:
                died = row is not None and row.get("__died__")
                if died:
                    row = died_row(row["spec"], row.get("detail", DIED_DETAIL))
                if bar is not None and (key := keys.pop(tid, None)) is not None:
                    pending[key] -= 1
                    if row is not None and not died:   # (a death's time is not a cost)
                        eta.observe(*key, worker, float(row.get("wall_time_s") or 0.0))
                    bar.set_postfix_str(_left(eta.seconds(pending)), refresh=False)
                if row is not None:
                    if tid not in store.done:  # (a chunk Dask ran twice: written once)
                        per_worker[worker].append(float(row.get("wall_time_s") or 0.0))
                        with _signals_deferred():  # the row and its count, or neither
                            store.append(row)
                            ran += 1
                else:
                    errors.append((tid, err))
                if bar is not None:
                    bar.update(1)
        completed = True
    finally:
        if bar is not None:
            bar.close()
        described = _describe(ex)
        ex.close()
        store.close()
        wall = time.perf_counter() - t0
        record_run(Path(out_dir), {
            "started_utc": started,
            "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "wall_time_s": round(wall, 3), "trials_run": ran, "trials_skipped": skipped,
            "errors": len(errors), "workers": described.get("workers", workers),
            **({"trials_reused": reused} if reused else {}),
            "interrupted": not completed,
            **{k: v for k, v in described.items() if k != "workers"},
            "throughput": throughput(per_worker),
            "machine": machine_info(),
            "numeric": numeric_env.in_force(),
            "transport": transport.kind,
            **({"lockstep": transport.lockstep, "autopilot": transport.autopilot}
               if transport.kind == "mavlink" else {}),
            "code_version": __version__})
    if store.done:
        store.write_tables()
    return RunSummary(len(specs), skipped, ran, errors, wall)


def _append_deferred(store: ResultStore) -> Callable[[dict], None]:
    """``store.append`` with a SIGINT/SIGTERM arriving mid-write acted on after it."""
    def append(row: dict) -> None:
        with _signals_deferred():
            store.append(row)
    return append


def _left(seconds: float) -> str:
    return f"about {tqdm.format_interval(seconds)} left"


def _describe(ex: Executor) -> dict:
    try:
        return ex.describe()
    except Exception:  # noqa: BLE001 - the record is written even for a broken executor
        return {"executor": ex.kind}
