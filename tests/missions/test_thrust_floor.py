"""The campaign key ``thrust_floor`` (issue 44): in mode "weight" each trial's MPC_THR_MIN
comes from its platform (at most 0.36 of its weight, PX4's 0.12 at TWR_max <= 3); the
default "px4" changes nothing. Trials whose floor the rule leaves at 0.12 keep their ids;
a TWR-6 trial carries MPC_THR_MIN 0.06 in its spec and its flight controller flies it."""

import json
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from ft_sitl.autopilot import cascade
from ft_sitl.cli import main
from ft_sitl.missions.campaign_file import CampaignError, load_campaign, parse_campaign
from ft_sitl.missions.thrust_floor import (
    WEIGHT_FRACTION,
    thrust_min_override,
    weight_floor,
)
from ft_sitl.missions.trial import run_trial
from ft_sitl.physics.catalog import PlatformRegistry
from tests.missions.conftest import campaign_file

ROOT = Path(__file__).resolve().parents[2]
SERIES_ACC = ROOT / "docs" / "results" / "envelope" / "series-acc.toml"
REGISTRY = PlatformRegistry()


def twr(name: str) -> float:
    return REGISTRY.get(name).indicators().twr_max


def series_acc(**extra):
    """The committed series-acc campaign, with ``extra`` keys added to its file's table."""
    doc = tomllib.loads(SERIES_ACC.read_text())
    doc.update(extra)
    return parse_campaign(doc, SERIES_ACC)


# --- the rule -------------------------------------------------------------------------------
def test_the_rule_keeps_pxs_default_up_to_twr_3_and_the_weight_share_above():
    assert [weight_floor(t) for t in (1.2, 3.0, 4.0, 6.0)] == [0.12, 0.12, 0.09, 0.06]
    # the series members' TWR_max as computed (3.000000000000001, 5.999999999999998): the
    # float noise does not move them off PX4's step
    assert weight_floor(twr("series-5.00kg-UAV16-twr3.0")) == 0.12
    assert twr("series-5.00kg-UAV16-twr3.0") != 3.0
    assert weight_floor(twr("series-5.00kg-UAV16-twr6.0")) == 0.06
    assert weight_floor(twr("series-0.55kg-UAV1-twr6.0")) == 0.06
    # the catalog's highest TWR_max (1.00kg-SunnySky, 6.0)
    top = max(REGISTRY.category("real") + REGISTRY.category("virtual"),
              key=lambda p: p.indicators().twr_max)
    assert (top.name, round(top.indicators().twr_max, 9)) == ("1.00kg-SunnySky", 6.0)
    assert weight_floor(top.indicators().twr_max) == 0.06
    # rounded down to 0.01: never above the weight share; PX4's lower bound 0.05 from 7.2
    assert [weight_floor(t) for t in (4.2, 4.6, 7.2, 8.0)] == [0.08, 0.07, 0.05, 0.05]
    for t in np.linspace(1.05, 7.2, 200):
        assert weight_floor(t) * t <= WEIGHT_FRACTION + 1e-9
        assert weight_floor(t) == 0.12 or weight_floor(t) * t > WEIGHT_FRACTION - 0.01 * t
    with pytest.raises(ValueError, match="twr_max: must be a positive number, got 0"):
        weight_floor(0)


def test_the_override_is_none_in_px4_mode_and_where_the_trial_flies_the_value_anyway():
    six, three = REGISTRY.get("series-0.55kg-UAV1-twr6.0"), REGISTRY.get(
        "series-0.55kg-UAV1-twr3.0")
    assert thrust_min_override("px4", six, None) is None
    assert thrust_min_override("weight", six, None) == 0.06
    assert thrust_min_override("weight", six, {"MPC_XY_P": 0.5}) == 0.06
    assert thrust_min_override("weight", six, {"MPC_THR_MIN": 0.06}) is None
    assert thrust_min_override("weight", three, None) is None


# --- campaigns ------------------------------------------------------------------------------
def test_the_default_changes_nothing_in_a_committed_campaign():
    c = load_campaign(SERIES_ACC)
    assert c.thrust_floor == "px4"
    specs = c.trial_specs()
    assert [s.trial_id for s in specs[:3]] == ["212b532985759ee3", "c20181377a3acd9c",
                                              "f6b81daeaa746cd6"]
    assert all(s.params is None for s in specs)
    stored = pd.read_parquet(SERIES_ACC.with_suffix("") / "trials.parquet", columns=["trial_id"])
    assert set(stored.trial_id) <= {s.trial_id for s in specs}
    meta = json.loads((SERIES_ACC.with_suffix("") / "campaign.json").read_text())
    assert json.loads(json.dumps(c.spec_dict())) == meta["spec"]  # (so it resumes)


def test_weight_mode_changes_only_the_trials_above_twr_3():
    before, after = series_acc().trial_specs(), series_acc(thrust_floor="weight")
    assert after.spec_dict()["thrust_floor"] == "weight"
    specs = after.trial_specs()
    assert len(specs) == len(before) == 3960
    floors = {}
    for old, new in zip(before, specs, strict=True):
        assert (old.platform, old.seed, old.scenario_index) == (new.platform, new.seed,
                                                                 new.scenario_index)
        if twr(new.platform) <= 3.0 + 1e-9:
            assert new.trial_id == old.trial_id and new.params is None
        else:
            assert new.to_dict() == {**old.to_dict(), "params": new.params}
            floors.setdefault(new.platform, set()).add(json.dumps(new.params))
    assert floors["series-0.55kg-UAV1-twr6.0"] == {'{"MPC_THR_MIN": 0.06}'}
    assert floors["series-5.00kg-UAV16-twr6.0"] == {'{"MPC_THR_MIN": 0.06}'}
    assert floors["series-5.00kg-UAV16-twr4.0"] == {'{"MPC_THR_MIN": 0.09}'}
    # the alpha series holds TWR_max 3.6: 0.36 / 3.6 = 0.10
    assert floors["series-0.55kg-UAV1-axy232"] == {'{"MPC_THR_MIN": 0.1}'}
    unchanged = {s.platform for s in specs if s.params is None}
    assert unchanged == {f"series-{b}-twr{t}" for b in ("0.55kg-UAV1", "5.00kg-UAV16")
                         for t in ("1.2", "1.5", "2.0", "3.0")}


def test_the_floor_joins_each_parameter_set_of_the_axis():
    c = series_acc(thrust_floor="weight", params=[{}, {"MPC_XY_P": 0.5}],
                   platforms=["series-0.55kg-UAV1-twr6.0", "series-0.55kg-UAV1-twr2.0"],
                   scenarios=["forest"], indices=[1], trials=1, aggressiveness="paper")
    assert [(s.platform, s.params) for s in c.trial_specs()] == [
        ("series-0.55kg-UAV1-twr6.0", {"MPC_THR_MIN": 0.06}),
        ("series-0.55kg-UAV1-twr6.0", {"MPC_THR_MIN": 0.06, "MPC_XY_P": 0.5}),
        ("series-0.55kg-UAV1-twr2.0", None),
        ("series-0.55kg-UAV1-twr2.0", {"MPC_XY_P": 0.5})] * 3  # (three algorithms)


BASE = """\
algorithms = ["straight"]
platforms = ["1.00kg-SunnySky"]
scenarios = ["forest"]
trials = 1
"""


@pytest.mark.parametrize("text, message", [
    ('thrust_floor = "PX4"', "thrust_floor: must be 'px4' or 'weight', got 'PX4' "
                             "(docs/missions.md, \"Thrust floor\")"),
    ('thrust_floor = 0.06', "thrust_floor: must be 'px4' or 'weight', got 0.06"),
    ('thrust_floor = "weight"\nparams = {MPC_THR_MIN = 0.06}',
     "params: MPC_THR_MIN is set by thrust_floor = 'weight' (per platform); drop one of "
     "the two"),
    ('thrust_floor = "weight"\nparams = [{}, {MPC_XY_P = 0.5, MPC_THR_MIN = 0.1}]',
     "params[1]: MPC_THR_MIN is set by thrust_floor = 'weight' (per platform); drop one "
     "of the two"),
])
def test_bad_modes_and_a_floor_set_twice_are_one_line_errors(tmp_path, text, message):
    path = campaign_file(tmp_path, "c.toml", BASE + text + "\n")
    with pytest.raises(CampaignError) as err:
        load_campaign(path)
    assert str(err.value).startswith(f"{path}: {message}"), str(err.value)
    assert "\n" not in str(err.value)


def test_px4_mode_leaves_an_explicit_floor_to_the_parameters(tmp_path):
    path = campaign_file(tmp_path, "c.toml", BASE + 'params = {MPC_THR_MIN = 0.08}\n')
    assert [s.params for s in load_campaign(path).trial_specs()] == [{"MPC_THR_MIN": 0.08}]


def test_campaign_check_shows_each_platforms_floor(tmp_path, capsys):
    path = campaign_file(tmp_path, "c.toml", """\
        algorithms = ["straight"]
        platforms = ["series-0.55kg-UAV1-twr6.0", "series-0.55kg-UAV1-twr4.0",
                     "series-0.55kg-UAV1-twr2.0"]
        scenarios = ["forest"]
        indices = [1]
        trials = 1
        thrust_floor = "weight"
        """)
    assert main(["campaign", "check", str(path)]) == 0
    out = capsys.readouterr().out
    assert ("  thrust floor: weight (MPC_THR_MIN 0.06 on series-0.55kg-UAV1-twr6.0; 0.09 on "
            "series-0.55kg-UAV1-twr4.0; the others as their parameters say)\n") in out
    assert main(["campaign", "check", "--json", str(path)]) == 0
    assert json.loads(capsys.readouterr().out)["thrust_floor"] == "weight"


# --- a flight -------------------------------------------------------------------------------
@pytest.mark.slow
def test_a_twr6_trial_in_weight_mode_flies_the_lower_floor(yard):
    c = load_campaign(campaign_file(yard.parent, "floor.toml", """\
        algorithms = ["straight"]
        platforms = ["series-0.55kg-UAV1-twr6.0"]
        scenarios = [{file = "yard.yaml"}]
        trials = 1
        thrust_floor = "weight"
        [limits]
        timeout_s = 2.0
        """))
    (spec,) = c.trial_specs()
    assert spec.params == {"MPC_THR_MIN": 0.06}
    seen = []

    def monitor(fleet, t_nav_us):
        thrust_max = fleet.sim.platforms[0].thrust_max_n
        seen.append((fleet.params[0]["MPC_THR_MIN"],
                     fleet.sim.gains[0][cascade.G_FMIN] / thrust_max))

    out = run_trial(spec, monitor=monitor)
    assert seen, out.row["reason"]
    assert {m for m, _ in seen} == {0.06}
    assert np.allclose([f for _, f in seen], 0.06, rtol=1e-12)
    assert json.loads(out.row["params"]) == {"MPC_THR_MIN": 0.06}
