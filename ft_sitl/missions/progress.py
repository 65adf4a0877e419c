"""How long a campaign has left: the progress bar's estimate, from the campaign's mix.

tqdm's own estimate divides the trials left by the rate so far. At the start of a run that
rate is the first trials', and they are the worst guide there is: a worker's first trial
of a navigator compiles its kernels (numba: 5-20 s, against about 1 s for the next ones;
docs/results/paper/timing), and trials run grouped by scenario configuration, algorithm by
algorithm, so the first ten are all one navigator in one family. On the ``quick`` preset
it showed 50 minutes at 10 of 420 trials of a 15-minute run.

:class:`RemainingTime` estimates from what is left to fly instead:

* A pending trial costs the mean wall time of the finished trials of its algorithm and
  scenario family, shrunk towards the cell's reference cost by :data:`SHRINK`
  pseudo-trials (one slow trial does not make a family slow).
* The reference cost of an algorithm in a family is :data:`REFERENCE_COST_S` (its mean
  wall time per trial in the committed campaigns; the families differ by up to 4x, the
  navigators by 100x) times how much slower or faster than that reference this run's
  finished trials have been (1 before any): so the first, cheap Forest trials scale the
  expensive Maze ones rather than stand for them. A navigator or family not in the table
  takes the mean of what is (:func:`reference_cost_s`).
* A worker's first trial of each algorithm is its warm-up: it is left out of those means,
  and each worker that has yet to fly an algorithm with trials pending adds one warm-up,
  at the mean excess of the warm-ups seen so far.
* The sum is shared by the workers (the executor's count, else the workers seen).

The estimate is a function of the pending mix and the costs observed, not of the clock,
so it is tested as one (tests/missions/test_progress.py).
"""

from __future__ import annotations

import math
from collections import defaultdict
from collections.abc import Mapping

#: mean wall time of one trial (s) per navigator and scenario family, over the committed
#: campaigns' rows: docs/results/paper/trials.parquet (12,600 trials under protocol 6, 2
#: workers on a 2-core AMD EPYC) and docs/results/learned/trials.parquet (learned, 2,520).
#: Only the ratios matter once a run has finished some trials.
REFERENCE_COST_S = {
    #           forest urban  r-a-cyl narrow drop   maze   perlin
    "ego":      (2.52, 1.98,  3.51,   5.54,  5.03,  7.53,  8.12),
    "fast":     (3.37, 1.62,  3.89,   2.71,  1.55,  7.44,  2.82),
    "learned":  (1.84, 1.98,  1.27,   5.15,  2.40,  0.76,  0.71),
    "navrl":    (6.58, 3.87,  11.03,  8.52,  6.29,  10.55, 8.02),
    "pgo":      (2.40, 2.72,  3.64,   5.37,  4.58,  3.03,  6.96),
    "straight": (0.09, 0.07,  0.13,   0.09,  0.05,  0.07,  0.07),
}
#: the families of REFERENCE_COST_S's columns, in order
REFERENCE_FAMILIES = ("forest", "urban", "random_angle_cylinder", "narrow_gap",
                      "sudden_drop", "maze", "perlin")
#: pseudo-trials a cell's mean is shrunk towards its reference cost with
SHRINK = 3.0


def reference_cost_s(navigator: str, family: str) -> float:
    """The reference wall time (s) of one trial of a navigator (its registered name) in a
    scenario family; a navigator without one (a user's, ``command``) takes the family's
    mean over the table's navigators, a family without one (a scenario file) the
    navigator's mean over the table's families."""
    rows = ([REFERENCE_COST_S[navigator]] if navigator in REFERENCE_COST_S
            else list(REFERENCE_COST_S.values()))
    if family in REFERENCE_FAMILIES:
        j = REFERENCE_FAMILIES.index(family)
        return sum(r[j] for r in rows) / len(rows)
    return sum(map(sum, rows)) / (len(rows) * len(REFERENCE_FAMILIES))


class _Mean:
    __slots__ = ("n", "total")

    def __init__(self):
        self.n = 0
        self.total = 0.0

    def add(self, x: float) -> None:
        self.n += 1
        self.total += x

    def shrunk(self, prior: float) -> float:
        return (self.total + SHRINK * prior) / (self.n + SHRINK)


class RemainingTime:
    """The seconds a campaign has left (see the module docstring).

    ``reference`` maps each (algorithm, family) of the campaign (the algorithm as the
    pending mix names it: the trial's label) to its reference cost per trial (s,
    :func:`reference_cost_s`); ``workers`` is how many trials fly at once (None or 0: as
    many as the workers seen). Feed it each finished trial with :meth:`observe`; ask
    :meth:`seconds` with the mix of trials still to fly."""

    def __init__(self, reference: Mapping[tuple[str, str], float],
                 workers: int | None = None):
        for key, cost in reference.items():
            if not (isinstance(cost, int | float) and math.isfinite(cost) and cost > 0):
                raise ValueError(f"reference cost of {key!r}: {cost!r} must be a positive "
                                 "number of seconds")
        if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                    or workers < 0):
            raise ValueError(f"workers: {workers!r} must be a whole number >= 0")
        self.reference = dict(reference)
        self.workers = workers or None
        self._cell: dict[tuple[str, str], _Mean] = defaultdict(_Mean)
        self._seen_s = 0.0        # steady trials' wall time
        self._expected_s = 0.0    # ... and their reference costs
        self._warm_excess = _Mean()
        self._warmed: set[tuple[str, str]] = set()
        self._workers_seen: set[str] = set()

    def observe(self, algorithm: str, family: str, worker: str, wall_s: float) -> None:
        """A finished trial: its algorithm, family, the worker that flew it and its wall
        time (s). A non-finite or negative wall time is ignored."""
        if not (isinstance(wall_s, int | float) and math.isfinite(wall_s) and wall_s >= 0):
            return
        self._workers_seen.add(worker)
        if (worker, algorithm) not in self._warmed:   # its warm-up: not a steady cost
            self._warmed.add((worker, algorithm))
            self._warm_excess.add(max(0.0, wall_s - self.cost_s(algorithm, family)))
            return
        self._cell[(algorithm, family)].add(wall_s)
        self._seen_s += wall_s
        self._expected_s += self._reference(algorithm, family)

    def scale(self) -> float:
        """How much slower (> 1) or faster this run's steady trials have been than their
        reference costs (1 before any)."""
        return self._seen_s / self._expected_s if self._seen_s > 0 else 1.0

    def _reference(self, algorithm: str, family: str) -> float:
        cost = self.reference.get((algorithm, family))
        if cost is None:
            raise ValueError(f"({algorithm!r}, {family!r}) has no reference cost: the "
                             "reference covers the campaign's (algorithm, family) pairs")
        return cost

    def cost_s(self, algorithm: str, family: str) -> float:
        """The expected wall time (s) of one more steady trial of ``algorithm`` in
        ``family``."""
        prior = self.scale() * self._reference(algorithm, family)
        cell = self._cell.get((algorithm, family))
        return cell.shrunk(prior) if cell is not None else prior

    def seconds(self, pending: Mapping[tuple[str, str], int]) -> float:
        """Seconds left for the trials of ``pending`` ({(algorithm, family): trials})."""
        workers = self.workers or max(1, len(self._workers_seen))
        total = 0.0
        warm = self._warm_excess.total / self._warm_excess.n if self._warm_excess.n else 0.0
        left_by_algo: dict[str, int] = defaultdict(int)
        for (algo, family), n in pending.items():
            if n > 0:
                total += n * self.cost_s(algo, family)
                left_by_algo[algo] += n
        for algo, n in left_by_algo.items():
            warmed = sum(1 for w in self._workers_seen if (w, algo) in self._warmed)
            total += min(n, max(0, workers - warmed)) * warm
        return total / workers
