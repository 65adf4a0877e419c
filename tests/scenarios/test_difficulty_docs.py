"""docs/scenarios.md's difficulty tables and docs/results/scenario-difficulty/README.md's
FlightBench tables are the committed measurements, and those are of the configurations
the generators build now (scripts/scenario_difficulty.py writes them all; rerun it when
this fails)."""

import json
from pathlib import Path

import pytest

from ft_sitl.scenarios.difficulty import Difficulty, markdown_summary, markdown_table
from ft_sitl.scenarios.families import FAMILIES, build_scenario
from ft_sitl.scenarios.flightbench_metrics import (
    PARAMS,
    FlightBenchMetrics,
)
from ft_sitl.scenarios.flightbench_metrics import markdown_summary as flightbench_summary
from ft_sitl.scenarios.flightbench_metrics import markdown_table as flightbench_table
from ft_sitl.scenarios.scenario import INDEX_RANGE

DOCS = Path(__file__).resolve().parents[2] / "docs"
RESULTS = DOCS / "results" / "scenario-difficulty" / "difficulty.json"
RERUN = "rerun scripts/scenario_difficulty.py (docs/scenarios.md, 'Difficulty')"


@pytest.fixture(scope="module")
def measured():
    return json.loads(RESULTS.read_text())


def _block(key: str, body: str) -> str:
    return (f"<!-- BEGIN generated: scenario_difficulty {key} -->\n{body}\n"
            f"<!-- END generated -->")


def test_the_tables_are_the_measurements(measured):
    text = (DOCS / "scenarios.md").read_text()
    assert list(measured["families"]) == list(FAMILIES)
    by_family = {f: [Difficulty.from_dict(e["difficulty"]) for e in entries]
                 for f, entries in measured["families"].items()}
    assert _block("summary", markdown_summary(by_family)) in text, RERUN
    lo, hi = INDEX_RANGE
    for family, results in by_family.items():
        assert [d.index for d in results] == list(range(lo, hi + 1))
        assert {d.seed for d in results} == {measured["seed"]}
        assert _block(family, markdown_table(results)) in text, f"{family}: {RERUN}"
        assert (DOCS / "img" / f"difficulty-{family}.png").stat().st_size > 20_000


def test_the_flightbench_tables_are_the_measurements(measured):
    text = (RESULTS.parent / "README.md").read_text()
    pairs, by_family = [], {}
    for family, entries in measured["families"].items():
        for e in entries:
            d = Difficulty.from_dict(e["difficulty"])
            m = FlightBenchMetrics.from_dict(e["flightbench"])
            assert m.scenario == d.scenario
            assert m.params == PARAMS.defaults(), f"{d.scenario}: not FlightBench's values"
            pairs.append((d, m))
            by_family.setdefault(family, []).append(m)
    assert len(pairs) == 70
    assert _block("flightbench-summary", flightbench_summary(by_family)) in text, RERUN
    assert _block("flightbench", flightbench_table(pairs)) in text, RERUN


@pytest.mark.slow
def test_the_measurements_are_of_todays_configurations(measured):
    for family, entries in measured["families"].items():
        sc = build_scenario(family, 1, measured["seed"])
        assert entries[0]["mesh_sha256"] == sc.mesh_digest(), f"{family}: {RERUN}"
