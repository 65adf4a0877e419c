"""The suite's lanes and the guard that keeps the unit lane to itself.

Tests marked ``e2e`` (pyproject.toml registers the marks) open network sockets or run
programs as child processes: real SITL/MAVLink/MAVSDK links, MQTT brokers, Dask
clusters, a browser, ``ft-sitl`` commands and other executables. Tests marked ``slow`` do
in-process work of seconds to a minute (trials flown, Perlin worlds built and solved,
campaign reports). The unit lane, ``pytest -m "not e2e and not slow"``, is everything
else; ``-m "e2e or slow"`` the rest. CI runs everything (the README's command selects no
mark).

The guard: an audit hook (``sys.addaudithook``, PEP 578) hears every ``bind``, ``connect``,
``sendto`` and ``sendmsg`` of an IPv4/IPv6 socket and every process started through
``subprocess``, ``os.system``, ``os.posix_spawn`` or ``os.spawn*`` while a test without the
mark is set up or run, and fails that test, naming what it did. It hears the calls of the
test's own thread and of every thread started after the test's setup began (the server
thread of a harness); threads that were running before it (what an earlier end-to-end test
left shutting down) are not the test's. Unix-domain sockets and process pools (the
campaign's local pebble pool, which forks or spawns without ``subprocess``) are allowed:
they serve no port. In every run, whichever marks it selects, so a new test that opens a
socket without the mark fails in CI too.

``tests/conftest.py`` registers the hooks; tests/test_lanes.py shows that the guard fails
a test that binds a socket or starts a process and passes an e2e-marked one that does.
"""

from __future__ import annotations

import socket
import sys
import threading
from contextlib import contextmanager

import pytest

MARK = "e2e"
NETWORK_FAMILIES = (socket.AF_INET, socket.AF_INET6)
SOCKET_EVENTS = frozenset({"socket.bind", "socket.connect", "socket.sendto", "socket.sendmsg"})
SPAWN_EVENTS = frozenset({"subprocess.Popen", "os.system", "os.posix_spawn", "os.spawn"})
WATCHED = SOCKET_EVENTS | SPAWN_EVENTS

# what the guard is recording into now (None: nothing), and the threads it does not hear
# (Thread objects, not idents: a new thread may get the ident of one that ended)
_seen: list[str] | None = None
_ignored: frozenset[threading.Thread] = frozenset()


def _describe(event: str, args: tuple) -> str | None:
    """What the audited call did, or None for one the unit lane may do."""
    if event in SOCKET_EVENTS:
        sock = args[0]
        if getattr(sock, "family", None) not in NETWORK_FAMILIES:
            return None
        return f"{event} {args[1]!r}"
    if event == "subprocess.Popen":  # (executable, args, cwd, env)
        argv = args[1]
        return f"{event} {argv!r}" if isinstance(argv, str) else \
            f"{event} {[str(a) for a in argv]!r}"
    return f"{event} {args[0]!r}"


def _audit(event: str, args: tuple) -> None:
    seen = _seen
    if seen is None or event not in WATCHED:
        return
    if _ignored and threading.current_thread() in _ignored:
        return
    try:
        what = _describe(event, args)
    except Exception as exc:  # noqa: BLE001 - an audit hook must not break the audited call
        what = f"{event} (undescribed: {exc!r})"
    if what is not None:
        seen.append(what)


_installed = False


def install() -> None:
    """Add the audit hook, once per process (it cannot be removed; idle, it returns at once)."""
    global _installed
    if not _installed:
        sys.addaudithook(_audit)
        _installed = True


@contextmanager
def watching(ignore_threads: frozenset[threading.Thread] | None = None):
    """Record what the current thread and threads started from now on do meanwhile; yields
    the list the records go into. Nests: an inner watch takes the records while it lasts."""
    global _seen, _ignored
    install()
    me = threading.current_thread()
    if ignore_threads is None:
        ignore_threads = running_threads()
    outer = (_seen, _ignored)
    seen: list[str] = []
    _seen, _ignored = seen, frozenset(ignore_threads) - {me}
    try:
        yield seen
    finally:
        _seen, _ignored = outer


def running_threads() -> frozenset[threading.Thread]:
    return frozenset(threading.enumerate())


_THREADS = pytest.StashKey[frozenset]()


def _guarded_phase(item: pytest.Item):
    if item.get_closest_marker(MARK) is not None:
        return (yield)
    if _THREADS not in item.stash:  # the threads running as the test's setup began
        item.stash[_THREADS] = running_threads()
    with watching(item.stash[_THREADS]) as seen:
        try:
            result = yield
        except BaseException:
            if seen:
                item.add_report_section("call", "lane guard", "\n".join(seen))
            raise
    if seen:
        shown = "\n  ".join(dict.fromkeys(seen))
        pytest.fail(f"{item.nodeid} is in the unit lane (no '{MARK}' mark) but opened a "
                    f"network socket or started a process:\n  {shown}\nmark it "
                    f"@pytest.mark.{MARK} (tests/lanes.py)", pytrace=False)
    return result


# Setup and call are guarded; teardown is not: the last test of a file or of the session
# tears down the module and session fixtures of its e2e neighbours (a broker, a server).
@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item):
    return (yield from _guarded_phase(item))


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item):
    return (yield from _guarded_phase(item))
