"""The cost of flying trials in a Dask worker's subprocess child (missions/child_pool.py)
against flying them in the calling process: the child's start (imports, first scene) and
the per-trial round trip (pickles over pipes), alternated trial by trial.

    python bench/bench_child_pool.py [--trials N]
"""

# isort: off
import ft_sitl  # noqa: F401  (first: the numeric pins hold in this process)
# isort: on

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

from ft_sitl.missions.campaign import run_chunk
from ft_sitl.missions.child_pool import ChildPool
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.navigation.base import Limits


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=20)
    args = ap.parse_args()
    specs = [TrialSpec("straight", "1.00kg-SunnySky", "forest", scenario_index=1, trial=k,
                       limits=Limits(timeout_s=5.0)).to_dict() for k in range(args.trials)]
    pool = ChildPool()
    t = time.perf_counter()
    pool.schedule(run_chunk, ([specs[0]],)).result()
    first_child = time.perf_counter() - t
    t = time.perf_counter()
    run_chunk([specs[0]])
    first_here = time.perf_counter() - t
    child, here = [], []
    for d in specs[1:]:
        t = time.perf_counter()
        pool.schedule(run_chunk, ([d],)).result()
        child.append(time.perf_counter() - t)
        t = time.perf_counter()
        run_chunk([d])
        here.append(time.perf_counter() - t)
    pool.stop()
    print(f"first trial: child {first_child:.2f} s (its start included), here "
          f"{first_here:.2f} s")
    print(f"then per trial (median of {len(child)}): child {statistics.median(child):.3f} s, "
          f"here {statistics.median(here):.3f} s, ratio "
          f"{statistics.median(child) / statistics.median(here):.2f}")


if __name__ == "__main__":
    main()
