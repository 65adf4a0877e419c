"""SITL instance numbers (instance i serves ports 14540+i, 14580+i, 18570+i, as PX4 SITL
instance i) shared by the processes of one machine through lock files: a trial over
MAVLink takes a free number (:class:`InstanceLock`), a SITL on fixed numbers holds them
(:func:`instances_held`: ``ft-sitl sitl --instance``, the tests' servers), so the two never
bind the same ports.

Numbers 40 apart share a port (instance i's client port 14540+i is instance i-40's API
listen port 14580+(i-40)), so holding a number also holds a lock file for each of its
ports: a number whose port another held number has is busy, whichever was taken first.
The numbers taken automatically (:data:`AUTO_INSTANCES`) are 20..39 and 80..99: none is 40
from another of them, nor from 0..19, the numbers people pick by hand (PX4 SITL's own
instances, ``ft-sitl sitl``'s default 0)."""

from __future__ import annotations

import fcntl
import tempfile
import time
from contextlib import contextmanager
from pathlib import Path

from ft_sitl.mavlink.ports import instance_ports, taken_ports

#: the numbers auto allocation takes, lowest first (module docstring)
AUTO_INSTANCES = tuple(range(20, 40)) + tuple(range(80, 100))


def _lock_dir() -> Path:
    d = Path(tempfile.gettempdir()) / "ft-sitl-instances"
    d.mkdir(exist_ok=True)
    return d


def _lock_file(i: int) -> Path:
    """The lock file of SITL instance number i on this machine."""
    return _lock_dir() / f"{i}.lock"


def _port_lock_file(port: int) -> Path:
    """The lock file of a UDP port an instance number serves."""
    return _lock_dir() / f"udp-{port}.lock"


def _try_lock_path(path: Path):
    """The file at ``path``, locked for this process (held until closed), or None when
    another holds it."""
    fh = open(path, "w")  # noqa: SIM115 - held by the caller
    try:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        fh.close()
        return None
    return fh


def _try_claim(i: int) -> tuple[list | None, int | None]:
    """Instance i's lock and its ports' locks, all held for this process: (the open files,
    None); or (None, the port another holder has, None for the number itself) and nothing
    held."""
    held = []
    fh = _try_lock_path(_lock_file(i))
    if fh is None:
        return None, None
    held.append(fh)
    for port in instance_ports(i).values():
        fh = _try_lock_path(_port_lock_file(port))
        if fh is None:
            for h in held:
                h.close()
            return None, port
        held.append(fh)
    return held, None


def _release(held: list) -> None:
    for fh in held:
        fh.close()


def _describe(i: int) -> str:
    p = instance_ports(i)
    return f"SITL instance {i} (ports {p['client']}, {p['api_listen']}, {p['gcs_listen']})"


class InstanceBusy(RuntimeError):
    """A SITL instance number another process of this machine holds."""


@contextmanager
def instances_held(first: int, count: int = 1, wait_s: float = 0.0):
    """Hold the instance numbers ``first .. first + count - 1`` (their lock files and their
    ports') while a SITL serves them on fixed ports (``ft-sitl sitl --instance``, the tests'
    servers), so no wire trial of this machine picks them or a number sharing a port with
    them. Waits up to ``wait_s`` for another holder to let go, then raises
    :class:`InstanceBusy` naming the instance (and the shared port)."""
    held = []
    try:
        for i in range(first, first + count):
            deadline = time.monotonic() + wait_s
            while True:
                claim, port = _try_claim(i)
                if claim is not None:
                    break
                if time.monotonic() >= deadline:
                    why = "" if port is None else (
                        f": its port {port} is another held instance number's")
                    raise InstanceBusy(f"{_describe(i)} is in use by another ft-sitl process "
                                       f"on this machine (a trial over MAVLink or a sitl)"
                                       f"{why}")
                time.sleep(0.1)
            held.extend(claim)
        yield list(range(first, first + count))
    finally:
        _release(held)


def _ranges(numbers) -> str:
    """``20..39, 80..99`` for the numbers (each run of consecutive ones as first..last)."""
    runs, numbers = [], list(numbers)
    start = prev = numbers[0]
    for n in numbers[1:] + [None]:
        if n is None or n != prev + 1:
            runs.append(f"{start}..{prev}")
            start = n
        prev = n
    return ", ".join(runs)


@contextmanager
def free_instances(count: int = 1, usable=lambda i: True, base: int | None = None,
                   slots: int | None = None):
    """Hold the lowest ``count`` consecutive instance numbers of :data:`AUTO_INSTANCES`
    (or of ``base .. base + slots - 1``) that no process of this machine holds, that share
    no port with a held number, and for which ``usable(i)`` says yes (their ports are
    free), for as long as the context lasts; yields the first. Taking them is atomic among
    ft-sitl processes: a number is chosen only while its locks are held. Raises
    :class:`InstanceBusy` when no such run of numbers is free."""
    numbers = AUTO_INSTANCES if base is None else tuple(range(base, base + slots))
    pool = set(numbers)
    for first in numbers:
        run = range(first, first + count)
        if not all(i in pool for i in run):
            continue
        held = []
        for i in run:
            claim, _ = _try_claim(i)
            if claim is None:
                break
            held.extend(claim)
            if not usable(i):
                break
        else:
            try:
                yield first
            finally:
                _release(held)
            return
        _release(held)
    raise InstanceBusy(f"no {count} consecutive SITL instance numbers free in "
                       f"{_ranges(numbers)} (each held by another ft-sitl process of this "
                       f"machine, sharing a port with one, or with a port taken)")


def ports_free(i: int) -> bool:
    """Whether instance i's three UDP ports can be bound now, on every address: the locks
    keep ft-sitl processes apart, not other programs (a test's or a user's socket, a PX4
    SITL, a client left behind by a killed run), so a number is taken only when its ports
    are free too."""
    return not taken_ports(i, "0.0.0.0", client=True)


class InstanceLock:
    """An exclusive instance number (ports 14580+i, 14540+i, 18570+i) among the processes
    of this machine, held with lock files: the lowest free one of :data:`AUTO_INSTANCES`
    (or of ``base .. base + slots - 1``) whose ports no other program holds
    (:func:`ports_free`; 2026-12-07: a wire trial took a number whose API port a program
    outside the locks held, and its server could not bind)."""

    def __init__(self, base: int | None = None, slots: int | None = None):
        self.numbers = AUTO_INSTANCES if base is None else tuple(range(base, base + slots))
        self.instance = None
        self._held = None

    def __enter__(self) -> int:
        for i in self.numbers:
            claim, _ = _try_claim(i)
            if claim is None:
                continue
            if ports_free(i):
                self._held, self.instance = claim, i
                return i
            _release(claim)
        raise RuntimeError(f"no free SITL instance in {_ranges(self.numbers)} (each held by "
                           f"another ft-sitl process of this machine, or with a port "
                           f"another program holds)")

    def __exit__(self, *exc) -> None:
        if self._held is not None:
            _release(self._held)
            self._held = None
