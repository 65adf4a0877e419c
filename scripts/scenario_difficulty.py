"""Measure the difficulty of every scenario configuration and write what docs/scenarios.md
shows (section "Difficulty"):

* ``docs/results/scenario-difficulty/difficulty.json``: every configuration's measures
  (:class:`ft_sitl.scenarios.difficulty.Difficulty`) with its mesh's SHA-256, so a test
  can tell when a generator has changed the configurations under the table;
* the summary table and one table per family in docs/scenarios.md, between their
  ``<!-- BEGIN generated: scenario_difficulty ... -->`` markers;
* ``docs/img/difficulty-<family>.png``: the family's hardest configuration by flight time
  (then by the narrowest spare), its shortest path and narrowest passage drawn;
* FlightBench's metrics (traversability obstruction, view occlusion, angle over length:
  :mod:`ft_sitl.scenarios.flightbench_metrics`) of every configuration, in the JSON beside
  the project's measures and as the 70-row table and family summary of
  ``docs/results/scenario-difficulty/README.md``.

Run after changing a generator, the solvability search or the difficulty measures::

    PYTHONPATH=$PWD .venv/bin/python scripts/scenario_difficulty.py

It measures the 70 configurations of seed 0 (``--seed``) for the largest platform's body
under the current protocol's limits, through the same cache as ``ft-sitl scenarios list
--difficulty`` (``--no-cache`` to measure afresh): about 1.5 minutes the first time on one
core, seconds after; FlightBench's metrics take about 9 minutes more the first time (cached
in ``$XDG_CACHE_HOME/ft-sitl/flightbench``). ``--no-images`` leaves the pictures alone;
``--check`` writes nothing and exits 1 when the docs differ from what it would write.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import ft_sitl  # noqa: F401  (first: pins the BLAS settings before numpy loads)

# isort: split
from tqdm import tqdm

from ft_sitl.missions.spec import flight_budget
from ft_sitl.physics.catalog import largest_platform
from ft_sitl.scenarios.difficulty import (
    Difficulty,
    cached_difficulty,
    default_cache_dir,
    markdown_summary,
    markdown_table,
)
from ft_sitl.scenarios.families import FAMILIES, build_scenario
from ft_sitl.scenarios.flightbench_metrics import FlightBenchMetrics, cached_flightbench
from ft_sitl.scenarios.flightbench_metrics import default_cache_dir as flightbench_cache_dir
from ft_sitl.scenarios.flightbench_metrics import markdown_summary as flightbench_summary
from ft_sitl.scenarios.flightbench_metrics import markdown_table as flightbench_table
from ft_sitl.scenarios.render import render_scenario
from ft_sitl.scenarios.scenario import INDEX_RANGE

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results" / "scenario-difficulty" / "difficulty.json"
DOC = ROOT / "docs" / "scenarios.md"
README = RESULTS.parent / "README.md"
IMAGES = ROOT / "docs" / "img"
DPI = 72


def begin(key: str) -> str:
    return f"<!-- BEGIN generated: scenario_difficulty {key} -->"


END = "<!-- END generated -->"


def replace_block(text: str, key: str, body: str, where: Path = DOC) -> str:
    """``text`` (of the file ``where``) with the block between ``key``'s markers replaced
    by ``body``."""
    start = text.find(begin(key))
    if start < 0:
        raise SystemExit(f"{where}: no marker {begin(key)!r}")
    end = text.index(END, start)
    return text[:start] + f"{begin(key)}\n{body}\n" + text[end:]


def _measures(families: dict) -> dict:
    """The families' entries without the time each measurement took."""
    def untimed(entry: dict) -> dict:
        return {k: {**v, "compute_s": None} if isinstance(v, dict) else v
                for k, v in entry.items()}

    return {f: [untimed(e) for e in v] for f, v in families.items()}


def hardest(results: list[Difficulty]) -> Difficulty:
    """The configuration with the longest flight time, then the least room to spare."""
    return max(results, key=lambda d: (d.time_s if d.time_s is not None else float("inf"),
                                       -(d.passage_spare_m or 0.0)))


def picture(d: Difficulty, scenario, path: Path) -> None:
    title = (f"{d.scenario}: the largest body's shortest path ({d.path_m:.0f} m, "
             f"{d.turns} turns, {d.time_s:.0f} s at best) and narrowest passage "
             f"({d.passage_width_m:.2f} m, {d.passage_spare_m:.2f} m to spare)")
    render_scenario(scenario, path, trajectory=d.path, dpi=DPI, title=title,
                    trajectory_label="shortest path (largest body)",
                    marks=[(d.passage_point, "narrowest passage")])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, default=0, help="the configurations' seed (0)")
    ap.add_argument("--no-cache", action="store_true", help="measure afresh")
    ap.add_argument("--no-images", action="store_true", help="leave the pictures alone")
    ap.add_argument("--check", action="store_true",
                    help="write nothing; exit 1 if the docs are not what would be written")
    args = ap.parse_args(argv)
    if args.seed < 0:
        ap.error(f"--seed: {args.seed} must be a non-negative integer")
    platform, budget = largest_platform(), flight_budget()
    cache = None if args.no_cache else default_cache_dir()
    fb_cache = None if args.no_cache else flightbench_cache_dir()
    lo, hi = INDEX_RANGE
    jobs = [(f, i) for f in FAMILIES for i in range(lo, hi + 1)]
    by_family: dict[str, list[Difficulty]] = {}
    flightbench: dict[str, list[FlightBenchMetrics]] = {}
    digests: dict[str, list[str]] = {}
    scenarios = {}
    t0 = time.perf_counter()
    for family, index in tqdm(jobs, desc="difficulty", unit="config", dynamic_ncols=True):
        sc = build_scenario(family, index, args.seed)
        scenarios[sc.name] = sc
        by_family.setdefault(family, []).append(cached_difficulty(sc, platform, budget, cache))
        flightbench.setdefault(family, []).append(cached_flightbench(sc, None, fb_cache))
        digests.setdefault(family, []).append(sc.mesh_digest())
    elapsed = time.perf_counter() - t0
    measuring = sum(d.compute_s for found in by_family.values() for d in found)
    measuring += sum(m.compute_s for found in flightbench.values() for m in found)
    doc = {
        "about": "scenario difficulty, written by scripts/scenario_difficulty.py "
                 "(docs/scenarios.md, 'Difficulty')",
        "seed": args.seed,
        "platform": platform.name,
        "budget": {"speed_m_s": budget.speed_m_s, "acc_m_s2": budget.acc_m_s2,
                   "time_s": budget.time_s},
        "measuring_s": round(measuring, 1),
        "families": {f: [{"mesh_sha256": h, "difficulty": d.as_dict(),
                           "flightbench": m.as_dict()}
                          for h, d, m in zip(digests[f], found, flightbench[f])]
                     for f, found in by_family.items()},
    }
    text = DOC.read_text()
    new = replace_block(text, "summary", markdown_summary(by_family))
    for family, found in by_family.items():
        new = replace_block(new, family, markdown_table(found))
    readme = README.read_text()
    new_readme = replace_block(readme, "flightbench-summary",
                               flightbench_summary(flightbench), README)
    new_readme = replace_block(new_readme, "flightbench", flightbench_table(
        [(d, m) for f in by_family for d, m in zip(by_family[f], flightbench[f])]), README)
    results_text = json.dumps(doc, indent=1) + "\n"
    if args.check:
        old = json.loads(RESULTS.read_text()) if RESULTS.exists() else {}
        stale = [str(path) for path, differ in (
            (DOC, new != text),
            (README, new_readme != readme),
            (RESULTS, _measures(old.get("families", {})) != _measures(doc["families"])),
        ) if differ]
        print("up to date" if not stale else "stale: " + ", ".join(stale))
        return 1 if stale else 0
    RESULTS.parent.mkdir(parents=True, exist_ok=True)
    RESULTS.write_text(results_text)
    DOC.write_text(new)
    README.write_text(new_readme)
    print(f"wrote {RESULTS.relative_to(ROOT)} and the tables of {DOC.relative_to(ROOT)} and "
          f"{README.relative_to(ROOT)} "
          f"({elapsed:.0f} s; measuring took {measuring:.0f} s in all, cached or now)")
    if not args.no_images:
        IMAGES.mkdir(parents=True, exist_ok=True)
        for family, found in by_family.items():
            d = hardest(found)
            if d.path_m is None:
                print(f"{family}: {d.scenario} has no path; no picture")
                continue
            out = IMAGES / f"difficulty-{family}.png"
            picture(d, scenarios[d.scenario], out)
            print(f"wrote {out.relative_to(ROOT)} ({d.scenario})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
