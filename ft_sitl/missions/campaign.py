"""Campaigns: the algorithm x platform x scenario x trial matrix, run and resumed.

The campaign file (what to run, TOML or YAML) and its parsing are in
:mod:`ft_sitl.missions.campaign_file` (:func:`~ft_sitl.missions.campaign_file.load_campaign`).

Running: :func:`run_campaign` hands trials, grouped by scenario configuration (a worker
builds each scenario's collision grid once), to an :class:`Executor`: in-process
(``workers=1``) or a pool of worker processes; a distributed executor only has to
implement :meth:`Executor.imap`. Each finished trial is written to the
:class:`~ft_sitl.missions.store.ResultStore` at once; a rerun of the same campaign into
the same directory skips finished trials.
"""

from __future__ import annotations

import ctypes
import functools
import json
import multiprocessing as mp
import os
import platform as pyplatform
import shutil
import signal
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from ft_sitl import __version__
from ft_sitl.missions.campaign_file import Campaign, CampaignError
from ft_sitl.missions.protocol import failed_row
from ft_sitl.missions.resources import RESOURCES
from ft_sitl.missions.results import Outcome
from ft_sitl.missions.spec import TrialSpec, platform_for
from ft_sitl.missions.store import ResultStore
from ft_sitl.missions.trial import run_trial
from ft_sitl.missions.trial_wire import run_trial_wire, worker_bus
from ft_sitl.missions.watchdog import wall_budget_from_env

__all__ = ["CHUNK_MAX", "GRID_CACHE_DIR", "Executor", "ProcessExecutor", "RunSummary",
           "SerialExecutor", "Transport", "died_row", "machine_info", "record_run",
           "report_meta", "run_campaign", "run_chunk"]

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
    always flies over MAVLink."""

    kind: str = "inprocess"
    speed_factor: float = 2.0
    mqtt: str | None = None

    def __post_init__(self):
        if self.kind not in ("inprocess", "mavlink"):
            raise CampaignError(f"--transport: {self.kind!r} is not inprocess or mavlink")
        sf = self.speed_factor
        if isinstance(sf, bool) or not isinstance(sf, (int, float)) or not 0.1 <= sf <= 20:
            raise CampaignError(f"--speed-factor: {sf!r} must be within 0.1..20")


def run_chunk(specs: list[dict], transport: Transport | None = None
              ) -> list[tuple[str, dict | None, str | None]]:
    """Run trials (as spec dicts) one after the other: (trial_id, row or None, error)."""
    out = []
    transport = transport or Transport()
    for d in specs:
        spec = TrialSpec.from_dict(d)
        try:
            if transport.kind == "mavlink" or spec.algorithm == "command":
                row = run_trial_wire(spec, speed_factor=transport.speed_factor,
                                     **worker_bus(transport.mqtt)).row
            else:
                row = run_trial(spec, wall_budget_s=wall_budget_from_env()).row
            out.append((spec.trial_id, row, None))
        except KeyboardInterrupt:
            raise
        except BaseException as exc:  # noqa: BLE001 - reported, the campaign goes on
            out.append((spec.trial_id, None, f"{type(exc).__name__}: {exc}"))
    return out


class Executor:
    """Runs chunks of trials somewhere; yields each chunk's results as it finishes."""

    def imap(self, fn: Callable[[list[dict]], list], chunks: list[list[dict]]) -> Iterator:
        raise NotImplementedError

    def close(self) -> None:
        pass


class SerialExecutor(Executor):
    """In this process, in order (``--workers 1``)."""

    def imap(self, fn, chunks):
        for chunk in chunks:
            yield chunk, fn(chunk)


def _worker_init(parent_pid: int | None = None, grid_dir: str | None = None) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
    _die_with_parent(parent_pid)
    if grid_dir is not None:
        RESOURCES.share_grids(grid_dir)


def _die_with_parent(parent_pid: int | None) -> None:
    """On Linux, have the kernel send this worker SIGTERM when the campaign process dies
    (killed, say, by SIGTERM or SIGKILL, with no chance to stop its pool): orphaned workers
    would otherwise fly their queued trials to no one for minutes."""

    if not sys.platform.startswith("linux"):
        return

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        pr_set_pdeathsig = 1
        if libc.prctl(pr_set_pdeathsig, int(signal.SIGTERM), 0, 0, 0) != 0:
            return
    except (OSError, AttributeError):
        return
    if parent_pid is not None and os.getppid() != parent_pid:  # died before the prctl
        os.kill(os.getpid(), signal.SIGTERM)


class ProcessExecutor(Executor):
    """A pool of worker processes. A worker that dies (a navigator's segfault, the OOM
    killer) takes only its chunk down: that chunk is retried one trial per process, and a
    trial that kills its process again is recorded as a navigator error."""

    def __init__(self, workers: int, grid_dir: str | Path | None = None):
        self.workers = workers
        self._pool = None
        # where the workers share distance grids (removed by close(); a temporary
        # directory when not given)
        self._grid_dir_arg = grid_dir
        self._grid_dir: str | None = None

    def _new_pool(self):
        if self._grid_dir is None:
            if self._grid_dir_arg is None:
                self._grid_dir = tempfile.mkdtemp(prefix="ft-sitl-grids-")
            else:
                self._grid_dir = str(self._grid_dir_arg)
                os.makedirs(self._grid_dir, exist_ok=True)

        # workers inherit the environment, with ft_sitl.numeric_env's BLAS settings (one
        # thread, pinned kernels) set on this process's import of ft_sitl
        return ProcessPoolExecutor(self.workers, mp_context=mp.get_context("spawn"),
                                   initializer=_worker_init,
                                   initargs=(os.getpid(), self._grid_dir))

    def imap(self, fn, chunks):
        pending = list(chunks)
        suspects: list[list[dict]] = []  # trials in flight when a worker died
        self._pool = self._new_pool()
        running: dict = {}
        while pending or running or suspects:
            if suspects and not running:
                # a suspect runs alone, so a death is its own
                chunk = suspects.pop(0)
                fut = self._pool.submit(fn, chunk)
                try:
                    yield chunk, fut.result()
                except BrokenProcessPool:
                    yield chunk, [_died(chunk[0])]
                    self._pool.shutdown(wait=False, cancel_futures=True)
                    self._pool = self._new_pool()
                continue
            while pending and not suspects and len(running) < 2 * self.workers:
                chunk = pending.pop(0)
                running[self._pool.submit(fn, chunk)] = chunk
            if not running:
                continue
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            broken = False
            for fut in done:
                chunk = running.pop(fut)
                try:
                    yield chunk, fut.result()
                except BrokenProcessPool:
                    broken = True
                    suspects.extend([d] for d in chunk)
            if broken:
                for chunk in running.values():
                    suspects.extend([d] for d in chunk)
                running.clear()
                self._pool.shutdown(wait=False, cancel_futures=True)
                self._pool = self._new_pool()
        self.close()

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
            self._pool = None
        if self._grid_dir is not None:

            shutil.rmtree(self._grid_dir, ignore_errors=True)
            self._grid_dir = None


def _died(d: dict):
    """The row of a trial whose process died: a navigator error (it is the only foreign
    code a trial runs)."""
    spec = TrialSpec.from_dict(d)
    return spec.trial_id, {"__died__": True, "spec": d}, None


def _chunks(specs: list[TrialSpec]) -> list[list[dict]]:
    groups: dict = {}
    for s in specs:
        groups.setdefault((s.scenario_file, s.family, s.scenario_index), []).append(
            s.to_dict())
    out = []
    for g in groups.values():
        for k in range(0, len(g), CHUNK_MAX):
            out.append(g[k:k + CHUNK_MAX])
    return out


def died_row(d: dict) -> dict:
    """A navigator-error row for a trial whose worker process died."""
    spec = TrialSpec.from_dict(d)
    return failed_row(spec, platform_for(spec), RESOURCES.scenario(spec),
                      Outcome.NAVIGATOR_ERROR,
                      "the trial's process died (a crash in native code?)")


def machine_info() -> dict:
    """CPU model, cores, OS and Python of this machine (for reports)."""

    model = pyplatform.processor() or ""
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.lower().startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
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
    os.replace(tmp, path)


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


def run_campaign(campaign: Campaign, out_dir: str | Path, *, workers: int = 1,
                 executor: Executor | None = None, progress: bool = True,
                 limit: int | None = None, transport: Transport | None = None) -> RunSummary:
    """Run (or resume) a campaign into out_dir. ``limit``: stop after that many new trials
    (tests, smoke runs); ``transport``: in-process (default) or over MAVLink."""

    try:
        wall_budget_from_env()  # a bad value is one clear error, not one per trial
    except ValueError as exc:
        raise CampaignError(str(exc)) from None
    specs = campaign.trial_specs()
    meta = {"spec": campaign.spec_dict(), "total_trials": len(specs),
            "code_version": __version__}
    store = ResultStore(out_dir)
    store.open(meta)
    todo = [s for s in specs if s.trial_id not in store.done]
    skipped = len(specs) - len(todo)
    if limit is not None:
        todo = todo[:limit]
    ex = executor or (SerialExecutor() if workers <= 1 else
                      ProcessExecutor(workers, Path(out_dir) / GRID_CACHE_DIR))
    errors: list[tuple[str, str]] = []
    t0 = time.perf_counter()
    started = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    bar = None
    if progress:

        bar = tqdm(total=len(specs), initial=skipped, unit="trial", dynamic_ncols=True,
                   desc=campaign.name, smoothing=0.05)
    ran = 0
    try:
        fn = functools.partial(run_chunk, transport=transport or Transport())
        for _chunk, results in ex.imap(fn, _chunks(todo)):
            for tid, row, err in results:
                if row is not None and row.get("__died__"):
                    row = died_row(row["spec"])
                if row is not None:
                    store.append(row)
                    ran += 1
                else:
                    errors.append((tid, err))
                if bar is not None:
                    bar.update(1)
    finally:
        if bar is not None:
            bar.close()
        ex.close()
        store.close()
        wall = time.perf_counter() - t0
        record_run(Path(out_dir), {
            "started_utc": started,
            "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "wall_time_s": round(wall, 3), "trials_run": ran, "trials_skipped": skipped,
            "errors": len(errors), "workers": workers, "machine": machine_info(),
            "transport": (transport or Transport()).kind,
            "code_version": __version__})
    if store.done:
        store.write_tables()
    return RunSummary(len(specs), skipped, ran, errors, wall)
