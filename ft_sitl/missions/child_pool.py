"""A trial process started with ``subprocess``, for workers that may not have children.

A Dask worker started the default way (``dask worker``, dask-jobqueue, a managed cluster)
is a daemonic process, and Python's multiprocessing refuses to start a child from one, so
pebble's pool cannot run there. :class:`ChildPool` starts its one child with
``subprocess`` instead (``python -m ft_sitl.missions.child_pool``), which the daemon flag
does not restrict, and offers the two things :func:`~ft_sitl.missions.executors.supervise`
uses of a pebble pool: ``schedule(fn, args, timeout)`` returning a future, and ``active``.
The same rule holds: a task past its timeout has the child killed (the future raises
:class:`TimeoutError`), a child that dies fails only the task it was running
(:class:`ChildDied`), and the next task starts a fresh child.

The wire between them is the child's stdin and a duplicate of its stdout: length-prefixed
pickles of ``(fn, args)`` in, ``(ok, result or exception)`` out. Whatever the trial prints
to its standard output goes to its standard error, so it cannot corrupt that channel.
"""

from __future__ import annotations

import concurrent.futures as cf
import os
import pickle
import queue
import select
import signal
import struct
import subprocess
import sys
import threading
import time

_HEADER = struct.Struct("<Q")


class ChildDied(RuntimeError):
    """The child process ended while it ran a task (a crash in native code, a kill)."""


def _send(fh, obj) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    fh.write(_HEADER.pack(len(data)) + data)
    fh.flush()


def _read_exactly(fd: int, n: int, deadline: float | None) -> bytes | None:
    """``n`` bytes from ``fd``; None at end of file; TimeoutError past ``deadline``."""
    out = bytearray()
    while len(out) < n:
        wait = None if deadline is None else max(0.0, deadline - time.monotonic())
        ready, _, _ = select.select([fd], [], [], wait)
        if not ready:
            raise TimeoutError
        chunk = os.read(fd, n - len(out))
        if not chunk:
            return None
        out += chunk
    return bytes(out)


class ChildPool:
    """One child process (started on the first task, again after a death or a kill) that
    runs tasks one at a time (module docstring). ``grid_dir``: where it shares distance
    grids with other processes (RESOURCES.share_grids)."""

    def __init__(self, grid_dir: str | None = None):
        self.grid_dir = grid_dir
        self.active = True
        self._proc: subprocess.Popen | None = None
        self._tasks: queue.SimpleQueue = queue.SimpleQueue()
        self._runner: threading.Thread | None = None
        self._lock = threading.Lock()

    def _child(self) -> subprocess.Popen:
        if self._proc is None or self._proc.poll() is not None:
            argv = [sys.executable, "-m", "ft_sitl.missions.child_pool", str(os.getpid()),
                    self.grid_dir or ""]
            self._proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                          bufsize=0)
        return self._proc

    def schedule(self, fn, args=(), timeout: float | None = None) -> cf.Future:
        """Run ``fn(*args)`` in the child; a future of its result. Tasks run in the order
        given, one at a time, on one thread that lives as long as the pool: the child is
        started from it, and Linux sends a child its parent-death signal when the thread
        that started it ends, not the process."""
        fut: cf.Future = cf.Future()
        fut.set_running_or_notify_cancel()
        if not self.active:
            fut.set_exception(ChildDied("the pool was stopped"))
            return fut
        with self._lock:
            if self._runner is None:
                self._runner = threading.Thread(target=self._serve_tasks, daemon=True,
                                                name="ft-sitl-child-pool")
                self._runner.start()
        self._tasks.put((fut, fn, args, timeout))
        return fut

    def _serve_tasks(self) -> None:
        while True:
            item = self._tasks.get()
            if item is None:
                return
            self._run(*item)

    def _run(self, fut: cf.Future, fn, args, timeout: float | None) -> None:
        if not self.active:
            fut.set_exception(ChildDied("the pool was stopped"))
            return
        try:
            proc = self._child()
            deadline = None if timeout is None else time.monotonic() + timeout
            _send(proc.stdin, (fn, args))
            fd = proc.stdout.fileno()
            head = _read_exactly(fd, _HEADER.size, deadline)
            body = None if head is None else _read_exactly(
                fd, _HEADER.unpack(head)[0], deadline)
        except TimeoutError:
            self._kill()
            fut.set_exception(TimeoutError(f"the task ran past {timeout:g} s"))
            return
        except (BrokenPipeError, OSError) as exc:
            self._kill()
            fut.set_exception(ChildDied(f"the child process died ({exc})"))
            return
        if body is None:
            code = self._kill()
            fut.set_exception(ChildDied(f"the child process died (exit {code})"))
            return
        ok, value = pickle.loads(body)
        if ok:
            fut.set_result(value)
        else:
            fut.set_exception(value)

    def _kill(self):
        proc, self._proc = self._proc, None
        if proc is None:
            return None
        if proc.poll() is None:
            proc.kill()
        return proc.wait()

    def stop(self) -> None:
        self.active = False
        self._tasks.put(None)
        self._kill()

    def join(self, timeout: float | None = None) -> None:
        """(pebble's pool has it; stop() already waited for the child)"""


def _serve(parent_pid: int, grid_dir: str | None) -> None:
    """The child's loop: tasks in on stdin, results out on the original stdout."""
    from ft_sitl.missions.executors import worker_init  # (the child's own set-up)

    channel = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # what the trial prints goes to stderr, not into the channel
    sys.stdout = sys.stderr
    worker_init(parent_pid, grid_dir)
    inbox = sys.stdin.buffer
    while True:
        head = inbox.read(_HEADER.size)
        if len(head) < _HEADER.size:
            return  # the parent closed the pipe: done
        fn, args = pickle.loads(inbox.read(_HEADER.unpack(head)[0]))
        try:
            reply = (True, fn(*args))
        except BaseException as exc:  # noqa: BLE001 - the parent decides what it means
            reply = (False, exc)
        try:
            _send(channel, reply)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:
            _send(channel, (False, RuntimeError(f"the task's result does not pickle: "
                                                f"{exc}")))


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    _serve(int(sys.argv[1]), sys.argv[2] or None)
