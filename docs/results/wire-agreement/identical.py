"""Count the trials whose rows are identical in two result directories (in-process and
lockstep over MAVLink), every column but the wall times (issue 45). Rows flown by
different code (a re-fly from a later snapshot) differ in ``software``'s code digest, which
names the code, not the flight: such rows count as identical when nothing else differs,
and the script says how many they were.

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


def _but_code(a, b) -> bool:
    """Whether two rows' ``software`` records differ in the code digest alone."""
    a, b = (json.loads(x) if isinstance(x, str) else dict(x) for x in (a, b))
    a.pop("code", None), b.pop("code", None)
    return a == b


def main(a: str, b: str) -> int:
    here, there = rows(Path(a)), rows(Path(b))
    both = sorted(here.keys() & there.keys())
    by_alg: dict = {}
    other_code = 0
    for t in both:
        differ = [k for k in here[t] if k not in WALL_COLUMNS
                  and json.dumps(here[t][k]) != json.dumps(there[t].get(k))]
        if differ == ["software"] and _but_code(here[t]["software"], there[t]["software"]):
            differ, other_code = [], other_code + 1
        n, same = by_alg.get(here[t]["algorithm"], (0, 0))
        by_alg[here[t]["algorithm"]] = (n + 1, same + (not differ))
        if differ:
            print(f"{t[:10]} {here[t]['algorithm']}: differ in {', '.join(differ)}")
    for alg, (n, same) in sorted(by_alg.items()):
        print(f"{alg}: {same}/{n} rows identical but the wall times")
    if other_code:
        print(f"({other_code} of them flown by different code: only the code digest differs)")
    return 0 if all(n == same for n, same in by_alg.values()) else 1


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:3]))
