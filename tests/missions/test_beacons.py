"""The local pool's wall budget for trials that beat (ft_sitl.missions.watchdog.beat, as a
lockstep wire trial does each time its simulated clock goes on): counted from the last
beat, so a trial that keeps progressing outlives its budget, while one that stops beating
and one that never beat are killed as before (executors.supervise with ``beacons``).

The trials here are real worker functions in real pebble worker processes (spawned; they
import this module); they only beat and sleep, so the test is about the supervisor's rule,
not a navigator. Budgets are the smallest the rule can be shown with: 1 s, the kill
``KILL_GRACE_S`` (5 s) past it.
"""

import time

import pytest

from ft_sitl.missions import watchdog
from ft_sitl.missions.campaign_file import load_campaign
from ft_sitl.missions.executors import (
    KILL_GRACE_S,
    new_pool,
    overrun_detail,
    stall_detail,
    supervise,
    trial_id,
)
from tests.missions.conftest import campaign_file, write_yard

pytestmark = pytest.mark.e2e  # (worker processes: tests/lanes.py)

BUDGET_S = 1.0
#: how long the progressing trial runs: well past its budget and the kill's grace
PROGRESSING_S = 3 * (BUDGET_S + KILL_GRACE_S)


def _rows(chunk, tag):
    return [(trial_id(d), {"tag": tag}, None) for d in chunk]


def progressing(chunk):
    """Beats (at most once a second, the watchdog's throttle) for PROGRESSING_S."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < PROGRESSING_S:
        watchdog.beat()
        time.sleep(0.1)
    return _rows(chunk, "progressing")


def stalls(chunk):
    """Beats for a while, then stops progressing (for good, as a hang)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < 2.0:
        watchdog.beat()
        time.sleep(0.1)
    time.sleep(3600)
    return _rows(chunk, "stalled")


def never_beats(chunk):
    time.sleep(3600)
    return _rows(chunk, "hung")


def _warm(n):
    time.sleep(0.5)
    return n


def warm_pool(workers: int):
    """A pool whose workers have started (spawning and importing ft_sitl takes seconds on a
    loaded machine, and a trial's budget counts from when it was scheduled)."""
    pool = new_pool(workers, None)
    futures = [pool.schedule(_warm, args=(i,)) for i in range(workers)]
    assert sorted(f.result() for f in futures) == list(range(workers))
    return pool


def dispatch(chunk):
    """The worker function: what each trial does is picked by its trial's index."""
    idx = chunk[0]["trial"]
    return (progressing, stalls, never_beats)[idx](chunk)


def test_a_beating_trial_outlives_its_budget_and_a_stalled_one_does_not(tmp_path):
    write_yard(tmp_path)
    path = campaign_file(tmp_path, "three.toml", """\
        name = "three"
        trials = 3
        platforms = ["1.00kg-SunnySky"]
        scenarios = [{file = "yard.yaml"}]
        algorithms = ["straight"]
        """)
    specs = [s.to_dict() for s in load_campaign(path).trial_specs()]
    assert [d["trial"] for d in specs] == [0, 1, 2]
    ids = [trial_id(d) for d in specs]
    beacons = tmp_path / "beacons"
    beacons.mkdir()
    pool = warm_pool(3)
    try:
        out = {}
        for worker, results in supervise(pool, dispatch, specs, BUDGET_S, 3,
                                         beacons=beacons):
            for tid, row, err in results:
                out[tid] = (worker, row, err)
    finally:
        pool.stop()
        pool.join(timeout=10)
    worker, row, err = out[ids[0]]
    assert err is None and row == {"tag": "progressing"} and worker != "killed"
    worker, row, _ = out[ids[1]]
    assert worker == "killed" and row["detail"] == stall_detail(BUDGET_S)
    worker, row, _ = out[ids[2]]
    assert worker == "killed" and row["detail"] == overrun_detail(BUDGET_S)
    assert list(beacons.iterdir()) == []  # each trial's beacon removed when it ended


def test_without_beacons_the_budget_counts_from_the_start(tmp_path):
    """The rule before beats (and for in-process trials, which never beat): the same
    progressing trial is killed at its budget."""
    write_yard(tmp_path)
    path = campaign_file(tmp_path, "one.toml", """\
        name = "one"
        trials = 1
        platforms = ["1.00kg-SunnySky"]
        scenarios = [{file = "yard.yaml"}]
        algorithms = ["straight"]
        """)
    specs = [s.to_dict() for s in load_campaign(path).trial_specs()]
    pool = warm_pool(1)
    try:
        out = [r for _, results in supervise(pool, dispatch, specs, BUDGET_S, 1)
               for r in results]
    finally:
        pool.stop()
        pool.join(timeout=10)
    assert out[0][1]["detail"] == overrun_detail(BUDGET_S)


def test_beat_marks_only_a_named_beacon_and_at_most_once_a_second(tmp_path):
    path = tmp_path / "t.beat"
    watchdog.beat()  # no beacon: nothing
    assert not path.exists()
    t0 = time.time()
    watchdog.beacon_to(path)
    try:
        watchdog.beat()
        first = path.stat().st_mtime_ns
        watchdog.beat()  # within BEAT_EVERY_S of the first: not marked again
        assert path.stat().st_mtime_ns == first
        assert watchdog.has_beaten(path, t0 - 1.0)
        assert watchdog.quiet_s(path, t0 - 3600.0) < 3600.0
    finally:
        watchdog.beacon_to(None)
    assert not watchdog.has_beaten(tmp_path / "other.beat", t0)
