"""The campaign's time left (ft_sitl.missions.progress): a function of the pending mix and
the costs observed, checked as one (no clock), and on the recorded wall times of a real
run (docs/results/paper/timing)."""

import heapq
from collections import Counter
from pathlib import Path

import pandas as pd
import pytest

from ft_sitl.missions.progress import (
    REFERENCE_COST_S,
    REFERENCE_FAMILIES,
    SHRINK,
    RemainingTime,
    reference_cost_s,
)

DOCS = Path(__file__).resolve().parents[2] / "docs" / "results" / "paper"
REF = {("ego", "forest"): 2.0, ("ego", "maze"): 8.0, ("straight", "forest"): 0.1}


def test_before_any_trial_the_reference_costs_shared_by_the_workers():
    eta = RemainingTime(REF, workers=2)
    pending = {("ego", "forest"): 10, ("ego", "maze"): 5, ("straight", "forest"): 20}
    assert eta.seconds(pending) == pytest.approx((10 * 2.0 + 5 * 8.0 + 20 * 0.1) / 2)
    assert eta.seconds({k: 0 for k in pending}) == 0.0


def test_a_workers_first_trial_of_a_navigator_is_warm_up_not_its_cost():
    eta = RemainingTime(REF, workers=2)
    eta.observe("ego", "forest", "A", 20.0)   # A compiles EGO's kernels
    for _ in range(6):
        eta.observe("ego", "forest", "A", 1.0)
    # the steady trials alone set the cost: the run is twice as fast as the reference
    assert eta.scale() == pytest.approx(0.5)
    assert eta.cost_s("ego", "forest") == pytest.approx(1.0)
    assert eta.cost_s("ego", "maze") == pytest.approx(4.0)   # scaled, not forest's 1 s
    # worker B has yet to fly EGO: one warm-up (19 s over the 2 s the trial was expected
    # to cost then) is still to come, A's is paid
    left = eta.seconds({("ego", "maze"): 3})
    assert left == pytest.approx((3 * 4.0 + (20.0 - 2.0)) / 2)
    eta.observe("ego", "maze", "B", 30.0)
    assert eta.seconds({("ego", "maze"): 2}) == pytest.approx(2 * 4.0 / 2)


def test_the_first_cheap_trials_scale_the_expensive_ones_instead_of_standing_for_them():
    # the straight baseline first (a twentieth of its reference), EGO in Maze pending
    eta = RemainingTime(REF, workers=1)
    for w in ("A", "A", "A", "A", "A"):
        eta.observe("straight", "forest", w, 0.05)
    left = eta.seconds({("ego", "maze"): 10, ("straight", "forest"): 5})
    assert left == pytest.approx(10 * 8.0 * 0.5 + 5 * 0.05)
    # (the rate of the trials so far, 0.05 s each, would have said 0.75 s)


def test_one_slow_trial_moves_its_cell_by_a_shrunk_step():
    eta = RemainingTime(REF, workers=1)
    eta.observe("ego", "forest", "A", 2.0)   # warm-up
    for wall in (2.0, 2.0, 2.0, 2.0):
        eta.observe("ego", "maze", "A", 8.0)   # scale 1
        eta.observe("ego", "forest", "A", wall)
    eta.observe("ego", "forest", "A", 12.0)
    scale = (4 * 8.0 + 4 * 2.0 + 12.0) / (4 * 8.0 + 5 * 2.0)
    expected = (4 * 2.0 + 12.0 + SHRINK * scale * 2.0) / (5 + SHRINK)
    assert eta.cost_s("ego", "forest") == pytest.approx(expected)


def test_without_a_worker_count_the_workers_seen_share_the_work():
    eta = RemainingTime(REF)
    assert eta.seconds({("ego", "forest"): 4}) == pytest.approx(8.0)
    for w in ("A", "B", "A", "B"):
        eta.observe("straight", "forest", w, 0.1)
    assert eta.seconds({("straight", "forest"): 4}) == pytest.approx(4 * 0.1 / 2)


def test_bad_inputs_are_one_line_errors():
    with pytest.raises(ValueError, match=r"reference cost of \('ego', 'forest'\): 0 must be"):
        RemainingTime({("ego", "forest"): 0})
    with pytest.raises(ValueError, match="workers: -1 must be a whole number >= 0"):
        RemainingTime(REF, workers=-1)
    with pytest.raises(ValueError, match=r"\('pgo', 'forest'\) has no reference cost"):
        RemainingTime(REF).seconds({("pgo", "forest"): 1})
    eta = RemainingTime(REF, workers=1)
    eta.observe("ego", "forest", "A", float("nan"))   # ignored
    assert eta.seconds({("ego", "forest"): 1}) == pytest.approx(2.0)


def test_reference_costs_for_unknown_navigators_and_families():
    assert reference_cost_s("ego", "maze") == REFERENCE_COST_S["ego"][5]
    j = REFERENCE_FAMILIES.index("urban")
    assert reference_cost_s("mine", "urban") == pytest.approx(
        sum(r[j] for r in REFERENCE_COST_S.values()) / len(REFERENCE_COST_S))
    assert reference_cost_s("pgo", "my_mesh") == pytest.approx(
        sum(REFERENCE_COST_S["pgo"]) / len(REFERENCE_FAMILIES))


def test_the_recorded_timing_run_estimated_early_from_its_mix():
    """docs/results/paper/timing: 1,400 trials' recorded wall times (a real run, its
    warm-ups included), flown again on two workers in their order. After 10 trials the
    rate so far says more than three times the time actually left (its first trials
    compile the planners); the mix's estimate is within a factor 2, and both agree later."""
    walls = pd.read_csv(DOCS / "timing" / "slice-2026-11-28-wall.csv")
    rows = pd.read_parquet(DOCS / "trials.parquet", columns=["trial_id", "algorithm",
                                                              "family"])
    rows["trial_id"] = rows["trial_id"].str[:16]
    trials = walls.merge(rows, on="trial_id")
    assert len(trials) == 1400
    free = [(0.0, "A"), (0.0, "B")]
    done = []
    for t in trials.itertuples():   # two workers, each takes the next trial when free
        start, worker = heapq.heappop(free)
        done.append((start + t.wall_time_s, worker, t.algorithm, t.family, t.wall_time_s))
        heapq.heappush(free, (start + t.wall_time_s, worker))
    done.sort()
    end = done[-1][0]
    pending = Counter(zip(trials["algorithm"], trials["family"]))
    eta = RemainingTime({k: reference_cost_s(*k) for k in pending}, workers=2)
    ratios = {}
    for k, (at, worker, algo, family, wall) in enumerate(done, 1):
        pending[(algo, family)] -= 1
        eta.observe(algo, family, worker, wall)
        if k in (10, 700):
            true = end - at
            rate = at / k * (len(done) - k)
            ratios[k] = (rate / true, eta.seconds(pending) / true)
    assert ratios[10][0] > 3.0 and 0.5 < ratios[10][1] < 2.0, ratios
    assert all(0.75 < r < 1.3 for r in ratios[700]), ratios
