"""scripts/trace_replay.py's counterfactuals (``--set``) on committed rows: what each
change does to a stored spec, and the one-line refusals. The flights themselves are the
script's run (docs/results/envelope/replay-twr6-rac)."""

import importlib.util
import json
from pathlib import Path

import pytest

from ft_sitl.missions.results import rows_from_parquet
from ft_sitl.missions.spec import TrialSpec

ROOT = Path(__file__).resolve().parents[2]
ROWS = ROOT / "docs" / "results" / "envelope" / "series-acc"
_spec = importlib.util.spec_from_file_location("trace_replay",
                                               ROOT / "scripts" / "trace_replay.py")
replay = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(replay)

TWR6, TWR3 = "ee5c799a", "5fbedb1f"  # PGO, RAC-1, 6 m/s^2, the 5.00 kg body's TWR 6 and 3


@pytest.fixture(scope="module")
def rows():
    return rows_from_parquet(ROWS / "trials.parquet")


def _spec_of(rows, prefix):
    return TrialSpec.from_dict(json.loads(replay._find(rows, prefix, ROWS)["spec"]))


def test_each_change_sets_only_its_field(rows):
    spec = _spec_of(rows, TWR6)
    changes = replay._changes(["gains=bandwidth", "params.MPC_THR_MIN=0.06",
                               f"seed=FROM:{TWR3}"], rows, ROWS)
    new = replay.changed(spec, changes)
    assert spec.gains == "px4" and spec.params is None
    assert new.gains == "bandwidth"
    assert new.params == {"MPC_THR_MIN": 0.06}
    assert new.seed == _spec_of(rows, TWR3).seed != spec.seed
    assert new.platform == spec.platform and new.limits == spec.limits
    assert new.trial_id != spec.trial_id
    assert replay.changed(spec, []) == spec


@pytest.mark.parametrize("item, says", [
    ("gains", "expected KEY=VALUE"),
    ("params.MPC_THR_MIN=low", "must be a number"),
    ("seed=12", "allowed keys are gains=MODE, params.NAME=NUMBER and seed=FROM:ID"),
    ("wind=3", "allowed keys are"),
    ("seed=FROM:ffffffffffff", "matches 0 rows"),
])
def test_bad_changes_are_refused_in_one_line(rows, item, says):
    with pytest.raises(SystemExit) as exc:
        replay._changes([item], rows, ROWS)
    assert says in str(exc.value) and "\n" not in str(exc.value)
