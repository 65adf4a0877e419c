"""The wall-clock budget of an in-process trial: a navigator that hangs (or is hundreds of
times slower than real time) fails its trial as a navigator error instead of stopping the
campaign.

A trial whose simulated clock advances at the pace of other processes (a lockstep wire
trial: the navigator computes in its own process) also *beats*: :func:`beat` marks the
file :func:`beacon_to` named (the executor names one per trial) each time the clock goes
on, at most once every :data:`BEAT_EVERY_S`. The executor then measures the budget from
the last beat rather than from the trial's start (:func:`quiet_s`), so a trial slowed by a
loaded machine is not killed while it progresses, and one that stops progressing is
(docs/missions.md, "One rule for trials that misbehave"). A trial that never beats keeps
the budget from its start."""

from __future__ import annotations

import math
import os
import signal
import threading
import time
from pathlib import Path

#: wall-clock budget of one in-process trial (s): far above any legitimate trial (the
#: slowest take ~10 s here)
TRIAL_WALL_BUDGET_S = 600.0
WALL_BUDGET_ENV = "FT_SITL_TRIAL_WALL_BUDGET_S"


def wall_budget_from_env() -> float | None:
    """The trial wall-clock budget campaigns use: ``$FT_SITL_TRIAL_WALL_BUDGET_S`` seconds
    ("none" for no limit), else :data:`TRIAL_WALL_BUDGET_S`. ValueError names the variable
    when it is not a positive number or "none"."""
    raw = os.environ.get(WALL_BUDGET_ENV)
    if raw is None or raw.strip() == "":
        return TRIAL_WALL_BUDGET_S
    if raw.strip().lower() == "none":
        return None
    try:
        v = float(raw)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{WALL_BUDGET_ENV}={raw!r}: must be a positive number of seconds "
                         f"or 'none'")
    return v


class WallBudgetExceeded(BaseException):
    """Raised into a trial that overran its wall-clock budget (a BaseException, so the
    navigator's own ``except Exception`` does not swallow it)."""


class WallWatchdog:
    """Interrupts the trial ``budget_s`` after it started: SIGALRM when the trial runs on
    the main thread of a POSIX process (a navigator stuck inside one step), plus a check
    between steps everywhere."""

    def __init__(self, wall0: float, budget_s: float | None):
        self.deadline = math.inf if budget_s is None else wall0 + budget_s
        self.budget_s = budget_s
        self._old = None

    def __enter__(self):
        if (self.budget_s is not None and hasattr(signal, "setitimer")
                and threading.current_thread() is threading.main_thread()
                and signal.getitimer(signal.ITIMER_REAL)[0] == 0.0):
            # (an alarm someone else armed, e.g. a test timeout, is left alone: then only
            # the check between steps applies)
            def fire(signum, frame):
                raise WallBudgetExceeded()
            self._old = signal.signal(signal.SIGALRM, fire)
            signal.setitimer(signal.ITIMER_REAL,
                             max(self.deadline - time.perf_counter(), 1e-3))
        return self

    def __exit__(self, *exc):
        if self._old is not None:
            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, self._old)
            self._old = None
        return False

    def check(self) -> None:
        if time.perf_counter() > self.deadline:
            raise WallBudgetExceeded()

    def detail(self, t_nav_s: float) -> str:
        """The navigator-error detail of a trial that overran its budget."""
        return (f"the trial overran its wall-clock budget of {self.budget_s:g} s at "
                f"{t_nav_s:.1f} s of navigation (a hung or far too slow navigator)")


# --- progress beats (module docstring) ------------------------------------------------------
#: wall seconds between two beats of a progressing trial (at most)
BEAT_EVERY_S = 1.0
_beacon: Path | None = None  # the file this process's trial beats (None: no one listens)
_last_beat = -math.inf


def beacon_to(path: Path | str | None) -> None:
    """Have :func:`beat` mark ``path`` from now on (None: beat nowhere). Set by the executor
    around each trial in its worker process: one trial flies in a process at a time."""
    global _beacon, _last_beat
    _beacon = None if path is None else Path(path)
    _last_beat = -math.inf


def beat() -> None:
    """The trial progressed: mark the beacon (its modification time), at most once every
    :data:`BEAT_EVERY_S`; nothing without a beacon. An unwritable beacon is not an error
    of the trial: the executor then measures from the trial's start, as without beats."""
    global _last_beat
    if _beacon is None:
        return
    now = time.monotonic()
    if now - _last_beat < BEAT_EVERY_S:
        return
    _last_beat = now
    try:
        _beacon.touch()
    except OSError:
        pass


def quiet_s(path: Path, started: float) -> float:
    """Wall seconds since the trial that beats ``path`` last progressed: since its last beat,
    or since ``started`` (``time.time()``) if it has not beaten since then."""
    try:
        last = max(started, path.stat().st_mtime)
    except OSError:
        last = started
    return time.time() - last


def has_beaten(path: Path, started: float) -> bool:
    """The trial beat ``path`` since ``started`` (``time.time()``)."""
    try:
        return path.stat().st_mtime >= started
    except OSError:
        return False
