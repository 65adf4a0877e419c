"""Where a campaign's trials fly: in this process, in a local pool of worker processes, or
on a Dask cluster.

Every executor implements :meth:`Executor.imap`: given a function that flies a chunk of
trials (a list of :class:`~ft_sitl.missions.spec.TrialSpec` dicts; scenes and meshes never
travel, workers build and cache them) it yields ``(worker, results)`` as chunks finish,
``results`` being ``(trial_id, row or None, error or None)`` per trial. The campaign
process consumes them and stays the one writer of the result directory.

One rule for trials that misbehave, applied by :func:`supervise` wherever trials fly in
worker processes (the local pool, and the process each Dask worker keeps for its trials):

- a trial that runs past its wall budget (plus :data:`KILL_GRACE_S`) has its process
  killed and is recorded as a navigator error; the trial's own watchdog
  (:mod:`~ft_sitl.missions.watchdog`) normally ends a hung Python navigator first, but
  cannot interrupt compiled code, which only the kill ends. On the local pool a trial that
  beats (a lockstep wire trial, whose clock goes at its navigator process's pace: the
  watchdog's :func:`~ft_sitl.missions.watchdog.beat`) has the budget counted from its
  last beat: killed when it stops progressing, not for being slow on a loaded machine;
- a trial whose process dies is flown once more in a fresh process (the death may have
  been someone else's doing: the OOM killer, an operator); dying again, it is recorded as
  a navigator error. Other trials are not affected.

The pool is pebble's (worker processes killed and replaced one at a time, a dead worker
failing only its own task), not the standard library's, whose whole pool breaks when one
worker dies.
"""

from __future__ import annotations

import collections
import concurrent.futures as cf
import ctypes
import itertools
import logging
import math
import multiprocessing as mp
import os
import shutil
import signal
import socket
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

from pebble import ProcessExpired, ProcessPool

from ft_sitl import __version__, numeric_env
from ft_sitl.missions import watchdog
from ft_sitl.missions.child_pool import ChildDied, ChildPool
from ft_sitl.missions.resources import RESOURCES
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.provenance import code_digest

__all__ = ["DIED_DETAIL", "KILL_GRACE_S", "DaskExecutor", "Executor", "ExecutorError",
           "LocalExecutor", "SerialExecutor", "code_digest", "overrun_detail", "stall_detail",
           "supervise", "worker_info"]

#: seconds past its wall budget a trial may run before its worker process is killed
KILL_GRACE_S = 5.0
#: flights a trial gets in fresh processes after its process died, before it is recorded
DEATH_RETRIES = 1
#: what a trial whose process died (twice) records
DIED_DETAIL = "the trial's process died (a crash in native code?)"
#: trials kept scheduled on the local pool per worker (the rest wait in order, so the
#: workers go through the campaign scenario by scenario)
WINDOW_PER_WORKER = 2
#: wall seconds between the local pool's looks at its trials' beacons
BEACON_POLL_S = 0.5


class ExecutorError(RuntimeError):
    """The executor cannot run the campaign (no scheduler there, workers with other code)."""


def overrun_detail(budget_s: float) -> str:
    """The navigator-error detail of a trial whose process was killed for its overrun."""
    return (f"the trial overran its wall-clock budget of {budget_s:g} s without returning "
            f"to the simulator (hung in compiled code?); its worker process was killed")


def stall_detail(budget_s: float) -> str:
    """The navigator-error detail of a beating trial whose process was killed because it
    stopped progressing."""
    return (f"the trial made no progress for its wall-clock budget of {budget_s:g} s "
            f"(hung in compiled code?); its worker process was killed")


def marker(d: dict, detail: str) -> tuple[str, dict, None]:
    """The result of a trial that ended with its process: the campaign turns it into a
    navigator-error row (:func:`~ft_sitl.missions.campaign.died_row`)."""
    return trial_id(d), {"__died__": True, "spec": d, "detail": detail}, None


def trial_id(d: dict) -> str:
    return TrialSpec.from_dict(d).trial_id


def worker_info() -> dict:
    """What a worker must share with the campaign process (and what it is)."""
    return {"version": __version__, "code": code_digest(),
            "isa": numeric_env.expected_level(),
            "python": ".".join(map(str, sys.version_info[:3])),
            "host": socket.gethostname(), "pid": os.getpid()}


def worker_label() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


# --- worker processes -------------------------------------------------------------------------
def worker_init(parent_pid: int | None = None, grid_dir: str | None = None) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
    _die_with_parent(parent_pid)
    if grid_dir is not None:
        RESOURCES.share_grids(grid_dir)


def _die_with_parent(parent_pid: int | None) -> None:
    """On Linux, have the kernel send this worker SIGTERM when its parent dies (killed,
    say, by SIGKILL, with no chance to stop its pool): orphaned workers would otherwise fly
    their trials to no one for minutes."""
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


def _labelled(fn: Callable, chunk: list[dict], beacon: str | None = None
              ) -> tuple[str, list]:
    watchdog.beacon_to(beacon)
    try:
        return worker_label(), fn(chunk)
    finally:
        watchdog.beacon_to(None)


def new_pool(workers: int, grid_dir: str | None):
    """A pebble pool of ``workers`` spawned processes (ft_sitl imported first in each, so
    its BLAS settings hold) sharing distance grids through ``grid_dir``."""
    return ProcessPool(max_workers=workers, initializer=worker_init,
                       initargs=(os.getpid(), grid_dir), context=mp.get_context("spawn"))


def supervise(pool, fn: Callable, trials: list[dict], budget_s: float | None,
              window: int, beacons: Path | None = None) -> Iterator[tuple[str, list]]:
    """Fly ``trials`` one per task on a pebble ``pool``, at most ``window`` scheduled at a
    time, in order; yield ``(worker, results)`` per trial as each ends. The module's rule
    for overruns and deaths applies; with ``beacons`` (a directory) a trial that beats is
    killed only :data:`KILL_GRACE_S` past its budget without a beat (the pool's future must
    stop its worker when cancelled while running, as pebble's does)."""
    timeout = None if budget_s is None else budget_s + KILL_GRACE_S
    queue = collections.deque(trials)
    deaths: collections.Counter = collections.Counter()
    running: dict = {}
    started: dict = {}
    watched = beacons is not None and timeout is not None
    while queue or running:
        while queue and len(running) < window:
            d = queue.popleft()
            if watched:
                beacon = beacons / f"{trial_id(d)}.beat"
                fut = pool.schedule(_labelled, args=(fn, [d], str(beacon)))
                started[fut] = (time.time(), beacon)
            else:
                fut = pool.schedule(_labelled, args=(fn, [d]), timeout=timeout)
            running[fut] = d
        done, _ = cf.wait(running, timeout=BEACON_POLL_S if watched else None,
                          return_when=cf.FIRST_COMPLETED)
        if watched:
            for fut in [f for f in running if f not in done]:
                t0, beacon = started[fut]
                if watchdog.quiet_s(beacon, t0) > timeout:
                    fut.cancel()  # (pebble stops the worker)
                    d = running.pop(fut)
                    started.pop(fut)
                    why = (stall_detail if watchdog.has_beaten(beacon, t0)
                           else overrun_detail)
                    beacon.unlink(missing_ok=True)
                    yield "killed", [marker(d, why(budget_s))]
        for fut in done:
            d = running.pop(fut)
            if watched:
                started.pop(fut)[1].unlink(missing_ok=True)
            try:
                yield fut.result()
            except TimeoutError:
                yield "killed", [marker(d, overrun_detail(budget_s))]
            except (ProcessExpired, ChildDied):
                deaths[trial_id(d)] += 1
                if deaths[trial_id(d)] <= DEATH_RETRIES:
                    queue.appendleft(d)
                else:
                    yield "died", [marker(d, DIED_DETAIL)]
            except Exception as exc:  # noqa: BLE001 - e.g. a result that does not pickle
                yield "?", [(trial_id(d), None, f"{type(exc).__name__}: {exc}")]


# --- executors --------------------------------------------------------------------------------
class Executor:
    """Runs chunks of trials somewhere; yields ``(worker, results)`` as they finish."""

    kind = "?"
    #: the wall budget of one trial (s, None: none); set by the campaign
    budget_s: float | None = None
    #: trials per chunk (same scenario configuration) handed out at once
    chunk_max = 40

    def start(self) -> None:
        """Connect or start whatever the executor needs (ExecutorError if it cannot)."""

    def imap(self, fn: Callable[[list[dict]], list], chunks: list[list[dict]]) -> Iterator:
        raise NotImplementedError

    def describe(self) -> dict:
        """Facts for the run record (runs.json)."""
        return {"executor": self.kind}

    def close(self) -> None:
        pass


class SerialExecutor(Executor):
    """In this process, in order (the Python API's default for ``workers=1``): no process
    boundary, so a crash or a hang in compiled code takes the campaign with it."""

    kind = "serial"

    def imap(self, fn, chunks):
        for chunk in chunks:
            yield worker_label(), fn(chunk)

    def describe(self):
        return {"executor": self.kind, "workers": 1}


class LocalExecutor(Executor):
    """A pebble pool of ``workers`` processes on this machine, one trial per task (so a
    death or a kill is that trial's alone). Workers share distance grids through
    ``grid_dir`` (a temporary directory when None), removed by :meth:`close`."""

    kind = "local"

    def __init__(self, workers: int, grid_dir: str | Path | None = None,
                 budget_s: float | None = None):
        self.workers = workers
        self.budget_s = budget_s
        self._grid_dir_arg = grid_dir
        self._grid_dir: str | None = None
        self._beacons: str | None = None
        self._pool = None

    def imap(self, fn, chunks):
        if self._grid_dir is None:
            if self._grid_dir_arg is None:
                self._grid_dir = tempfile.mkdtemp(prefix="ft-sitl-grids-")
            else:
                self._grid_dir = str(self._grid_dir_arg)
                os.makedirs(self._grid_dir, exist_ok=True)
        if self._beacons is None:
            self._beacons = tempfile.mkdtemp(prefix="ft-sitl-beacons-")
        self._pool = new_pool(self.workers, self._grid_dir)
        trials = [d for chunk in chunks for d in chunk]
        yield from supervise(self._pool, fn, trials, self.budget_s,
                             WINDOW_PER_WORKER * self.workers, beacons=Path(self._beacons))

    def describe(self):
        return {"executor": self.kind, "workers": self.workers}

    def close(self) -> None:
        if self._pool is not None:
            self._pool.stop()
            self._pool.join(timeout=10)
            self._pool = None
        if self._grid_dir is not None:
            shutil.rmtree(self._grid_dir, ignore_errors=True)
            self._grid_dir = None
        if self._beacons is not None:
            shutil.rmtree(self._beacons, ignore_errors=True)
            self._beacons = None


# --- Dask -------------------------------------------------------------------------------------
_DASK_POOL = None  # the process a Dask worker flies its trials in (started on first use)
_DASK_POOL_LOCK = threading.Lock()


def dask_chunk(fn: Callable, chunk: list[dict], code: str,
               budget_s: float | None, isa: str | None = None) -> tuple[str, list]:
    """The task a Dask worker runs: fly ``chunk`` under :func:`supervise` in a process of
    its own (started once per worker; it keeps its scenes between chunks), so a crash or a
    kill ends that process, not the worker. Refuses to run other code than the client's,
    or at another instruction-set level (ft_sitl.numeric_env: its rows would differ)."""
    global _DASK_POOL
    mine = code_digest()
    if mine != code:
        raise ExecutorError(f"worker {worker_label()} runs ft-sitl {__version__} with code "
                            f"digest {mine[:12]}, the campaign {code[:12]}: install the same "
                            f"ft-sitl on every worker")
    # (the trials fly in a child process that pins afresh from this environment)
    level = numeric_env.expected_level()
    if isa is not None and level != isa:
        raise ExecutorError(f"worker {worker_label()} would fly at instruction-set level "
                            f"{level}, the campaign at {isa}: start every worker with "
                            f"{numeric_env.LEVEL_VAR}={isa} (docs/distributed.md)")
    from distributed import get_worker  # (distributed loads only where Dask is used)
    label = get_worker().address
    with _DASK_POOL_LOCK:
        if _DASK_POOL is None or not _DASK_POOL.active:
            grids = Path(tempfile.gettempdir()) / f"ft-sitl-grids-{code[:12]}"
            grids.mkdir(exist_ok=True)
            # (started with subprocess: a default Dask worker is a daemonic process, from
            # which multiprocessing, and so pebble, may not start children)
            _DASK_POOL = ChildPool(str(grids))
        pool = _DASK_POOL
    results = []
    for _, res in supervise(pool, fn, chunk, budget_s, 1):
        results.extend(res)
    return label, results


class DaskExecutor(Executor):
    """Chunks of trials as tasks on a Dask cluster: an existing one (``scheduler``, e.g.
    ``tcp://host:8786``) or a ``LocalCluster`` of ``local_workers`` processes started here.

    Results stream back as chunks finish. A chunk whose worker dies or leaves is re-run by
    Dask on another worker; one that keeps killing workers (Dask's ``KilledWorker``) is split
    into single trials, and a single trial that still does is recorded as a navigator
    error. If the scheduler goes away, the client waits for it (``reconnect_s``) and submits
    what had not come back. Trials that come back twice are written once (the store keeps
    the first)."""

    kind = "dask"

    def __init__(self, scheduler: str | None = None, local_workers: int | None = None,
                 budget_s: float | None = None, chunk_max: int = 10,
                 reconnect_s: float = 120.0):
        if (scheduler is None) == (local_workers is None):
            raise ValueError("give a scheduler address or a number of local workers")
        self.scheduler = scheduler
        self.local_workers = local_workers
        self.budget_s = budget_s
        self.chunk_max = chunk_max
        self.reconnect_s = reconnect_s
        self.client = None
        self._cluster = None

    def start(self) -> None:
        from distributed import Client, LocalCluster  # (loads only where Dask is used: ~1 s)
        if self.scheduler is None:
            self._cluster = LocalCluster(
                n_workers=self.local_workers, threads_per_worker=1, processes=True,
                dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)
            self.client = Client(self._cluster)
        else:
            try:
                self.client = Client(self.scheduler, timeout=15)
            except (OSError, TimeoutError) as exc:
                raise ExecutorError(f"--scheduler {self.scheduler}: cannot connect ({exc})"
                                    ) from None
            self.client.wait_for_workers(1, timeout=self.reconnect_s)
        self.check_workers()

    def check_workers(self) -> dict:
        """Every connected worker's :func:`worker_info`; ExecutorError naming the workers
        that run other code."""
        infos = self.client.run(worker_info)
        mine = worker_info()
        problems = []
        for addr, info in sorted(infos.items()):
            if info["code"] != mine["code"]:
                problems.append(f"{addr} runs ft-sitl {info['version']} with code digest "
                                f"{info['code'][:12]}, this campaign {mine['version']} "
                                f"({mine['code'][:12]}): install the same ft-sitl there")
        if problems:
            raise ExecutorError("workers refused:\n  " + "\n  ".join(problems))
        return infos

    @property
    def dashboard(self) -> str | None:
        try:
            return self.client.dashboard_link if self.client is not None else None
        except Exception:  # noqa: BLE001 - no dashboard (bokeh missing): none to print
            return None

    def imap(self, fn, chunks):
        from distributed import as_completed  # (distributed only where Dask is used)
        from distributed.client import FutureCancelledError  # (likewise)
        from distributed.scheduler import KilledWorker  # (likewise)

        client = self.client
        code = code_digest()
        isa = numeric_env.in_force()["level"]
        tag = uuid.uuid4().hex[:8]
        pending = dict(enumerate(chunks))
        new_id = itertools.count(len(chunks))
        attempt = 0
        while pending:
            futures = {client.submit(dask_chunk, fn, c, code, self.budget_s, isa, pure=False,
                                     key=f"ft-sitl-{tag}-{attempt}-{i}"): i
                       for i, c in pending.items()}
            attempt += 1
            lost = 0
            for fut in as_completed(futures):
                i = futures[fut]
                chunk = pending[i]
                try:
                    label, results = fut.result()
                except KilledWorker:
                    del pending[i]
                    if len(chunk) > 1:  # find the trial that kills its workers
                        for d in chunk:
                            pending[next(new_id)] = [d]
                    else:
                        yield "died", [marker(chunk[0], DIED_DETAIL)]
                except ExecutorError:
                    raise
                except (FutureCancelledError, cf.CancelledError, OSError):
                    lost += 1  # the scheduler went away: submitted again below
                except Exception as exc:  # noqa: BLE001 - the trials could not run there
                    del pending[i]
                    yield "?", [(trial_id(d), None, f"{type(exc).__name__}: {exc}")
                                for d in chunk]
                else:
                    del pending[i]
                    yield label, results
            if lost:
                self._await_scheduler()

    def _await_scheduler(self) -> None:
        deadline = time.monotonic() + self.reconnect_s
        while time.monotonic() < deadline:
            if self.client.status == "running":
                try:
                    self.client.wait_for_workers(1, timeout=max(
                        deadline - time.monotonic(), 1.0))
                    self.check_workers()
                    return
                except (TimeoutError, OSError):
                    pass
            time.sleep(0.5)
        raise ExecutorError(f"lost the scheduler {self.scheduler or 'of the local cluster'} "
                            f"and it did not come back within {self.reconnect_s:g} s; "
                            f"finished trials are kept, run the same command to resume")

    def describe(self):
        n = len(self.client.scheduler_info().get("workers", {})) if self.client else 0
        return {"executor": self.kind, "workers": n,
                "scheduler": self.scheduler or "local cluster",
                "dashboard": self.dashboard}

    def close(self) -> None:
        if self.client is not None:
            try:
                self.client.close()
            except Exception:  # noqa: BLE001 - closing a client of a dead scheduler
                pass
            self.client = None
        if self._cluster is not None:
            self._cluster.close()
            self._cluster = None


def throughput(per_worker: dict[str, list[float]]) -> dict:
    """Per-worker trials, busy seconds (sum of trial wall time) and trials per busy second."""
    out = {}
    for w, walls in sorted(per_worker.items()):
        busy = float(sum(x for x in walls if math.isfinite(x)))
        out[w] = {"trials": len(walls), "busy_s": round(busy, 3),
                  "trials_per_s": round(len(walls) / busy, 4) if busy > 0 else None}
    return out
