"""SITL instance numbers (instance i serves ports 14540+i, 14580+i, 18570+i, as PX4 SITL
instance i) shared by the processes of one machine through lock files: a trial over
MAVLink takes a free number (:class:`InstanceLock`), a SITL on fixed numbers holds them
(:func:`instances_held`: ``ft-sitl sitl --instance``, the tests' servers), so the two never
bind the same ports."""

from __future__ import annotations

import fcntl
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

INSTANCE_BASE = 20
INSTANCE_SLOTS = 40


def _lock_file(i: int) -> Path:
    """The lock file of SITL instance number i on this machine."""
    d = Path(tempfile.gettempdir()) / "ft-sitl-instances"
    d.mkdir(exist_ok=True)
    return d / f"{i}.lock"


def _try_lock(i: int):
    """Instance i's lock file, locked for this process (held until closed), or None when
    another holds it."""
    fh = open(_lock_file(i), "w")  # noqa: SIM115 - held by the caller
    try:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        fh.close()
        return None
    return fh


class InstanceBusy(RuntimeError):
    """A SITL instance number another process of this machine holds."""


@contextmanager
def instances_held(first: int, count: int = 1, wait_s: float = 0.0):
    """Hold the instance numbers ``first .. first + count - 1`` (their lock files) while a
    SITL serves them on fixed ports (``ft-sitl sitl --instance``, the tests' servers), so
    no wire trial of this machine picks them (:class:`InstanceLock` skips held numbers).
    Waits up to ``wait_s`` for another holder to let go, then raises
    :class:`InstanceBusy` naming the instance."""
    held = []
    try:
        for i in range(first, first + count):
            deadline = time.monotonic() + wait_s
            while (fh := _try_lock(i)) is None:
                if time.monotonic() >= deadline:
                    raise InstanceBusy(
                        f"SITL instance {i} (ports {14540 + i}, {14580 + i}, "
                        f"{18570 + i}) is in use by another ft-sitl process on this "
                        f"machine (a trial over MAVLink or a sitl)")
                time.sleep(0.1)
            held.append(fh)
        yield list(range(first, first + count))
    finally:
        for fh in held:
            fh.close()


@contextmanager
def free_instances(count: int = 1, usable=lambda i: True, base: int = INSTANCE_BASE,
                   slots: int = INSTANCE_SLOTS):
    """Hold the lowest ``count`` consecutive instance numbers within ``base ..
    base + slots - 1`` that no process of this machine holds and for which ``usable(i)``
    says yes (their ports are free), for as long as the context lasts; yields the first.
    Taking them is atomic among ft-sitl processes: a number is chosen only while its lock is
    held. Raises :class:`InstanceBusy` when no such run of numbers is free."""
    for first in range(base, base + slots - count + 1):
        held = []
        for i in range(first, first + count):
            fh = _try_lock(i)
            if fh is None or not usable(i):
                if fh is not None:
                    fh.close()
                break
            held.append(fh)
        if len(held) < count:
            for fh in held:
                fh.close()
            continue
        try:
            yield first
        finally:
            for fh in held:
                fh.close()
        return
    raise InstanceBusy(f"no {count} consecutive SITL instance numbers free in {base}.."
                       f"{base + slots - 1} (each held by another ft-sitl process of this "
                       f"machine or with a port taken)")


class InstanceLock:
    """An exclusive instance number (ports 14580+i, 14540+i, 18570+i) among the processes
    of this machine, held with a lock file."""

    def __init__(self, base: int = INSTANCE_BASE, slots: int = INSTANCE_SLOTS):
        self.base, self.slots = base, slots
        self.instance = None
        self._fh = None

    def __enter__(self) -> int:
        for i in range(self.base, self.base + self.slots):
            fh = _try_lock(i)
            if fh is not None:
                self._fh, self.instance = fh, i
                return i
        raise RuntimeError(f"no free SITL instance in {self.base}..{self.base + self.slots - 1}")

    def __exit__(self, *exc) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None
