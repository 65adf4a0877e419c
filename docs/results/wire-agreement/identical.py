"""Count the trials whose rows are identical in two result directories (in-process and
lockstep over MAVLink), every column but the wall times (issue 45).

    python docs/results/wire-agreement/identical.py runs/pgo-inproc runs/pgo-lockstep
"""

import json
import sys
from pathlib import Path

#: the columns that measure wall time (and when the row was written)
WALL_COLUMNS = ("wall_time_s", "planner_time_s", "finished_utc")


def rows(d: Path) -> dict:
    return {r["trial_id"]: r for r in map(json.loads, (d / "trials.jsonl").read_text()
                                          .splitlines())}


def main(a: str, b: str) -> int:
    here, there = rows(Path(a)), rows(Path(b))
    both = sorted(here.keys() & there.keys())
    by_alg: dict = {}
    for t in both:
        differ = [k for k in here[t] if k not in WALL_COLUMNS
                  and json.dumps(here[t][k]) != json.dumps(there[t].get(k))]
        n, same = by_alg.get(here[t]["algorithm"], (0, 0))
        by_alg[here[t]["algorithm"]] = (n + 1, same + (not differ))
        if differ:
            print(f"{t[:10]} {here[t]['algorithm']}: differ in {', '.join(differ)}")
    for alg, (n, same) in sorted(by_alg.items()):
        print(f"{alg}: {same}/{n} rows identical but the wall times")
    return 0 if all(n == same for n, same in by_alg.values()) else 1


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
