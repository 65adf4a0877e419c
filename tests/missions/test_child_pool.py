"""The trial process of a Dask worker (ft_sitl.missions.child_pool): a real child started
with subprocess, tasks pickled over its pipes; the supervisor's rule for overruns and
deaths (missions/executors.py) rests on what it reports."""

import operator
import os
import time

import pytest

from ft_sitl.missions.child_pool import ChildDied, ChildPool

pytestmark = pytest.mark.e2e  # a real child process


@pytest.fixture
def pool():
    p = ChildPool()
    yield p
    p.stop()


def test_results_exceptions_and_printing_come_back_in_order(pool):
    assert pool.schedule(operator.add, (2, 3)).result(timeout=60) == 5
    with pytest.raises(ValueError, match="invalid literal"):
        pool.schedule(int, ("x",)).result(timeout=60)
    first = pool._proc.pid
    # what a task prints goes to stderr, not into the results channel
    assert pool.schedule(print, ("noise on stdout",)).result(timeout=60) is None
    futures = [pool.schedule(operator.mul, (k, k)) for k in range(5)]
    assert [f.result(timeout=60) for f in futures] == [0, 1, 4, 9, 16]
    assert pool._proc.pid == first  # one child throughout: it keeps its caches


def test_an_overrun_kills_the_child_and_a_death_fails_only_its_task(pool):
    pool.schedule(operator.add, (1, 1)).result(timeout=60)
    first = pool._proc.pid
    t = time.monotonic()
    with pytest.raises(TimeoutError):
        pool.schedule(time.sleep, (600,), timeout=1.0).result(timeout=60)
    assert time.monotonic() - t < 30
    with pytest.raises(ProcessLookupError):
        os.kill(first, 0)  # killed, and reaped
    assert pool.schedule(operator.add, (2, 2)).result(timeout=60) == 4  # a fresh child
    second = pool._proc.pid
    with pytest.raises(ChildDied, match="exit 3"):
        pool.schedule(os._exit, (3,)).result(timeout=60)
    assert pool.schedule(operator.add, (3, 3)).result(timeout=60) == 6
    assert len({first, second, pool._proc.pid}) == 3
    pool.stop()
    with pytest.raises(ChildDied, match="stopped"):
        pool.schedule(operator.add, (1, 1)).result(timeout=60)
