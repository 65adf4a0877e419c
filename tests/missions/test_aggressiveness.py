"""The aggressiveness axis: named levels of the protocol's dynamic limits (speed cap and
acceleration limit), crossed with the matrix; each sets the trial's limits, which reach
the planners, PX4's MPC_XY_VEL_MAX and the rows; a paper-level trial flies what a trial
without the axis flies; campaigns without the axis keep their trial ids; bad levels are
named by file, entry, key and range."""

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from ft_sitl.autopilot.cascade import SP_VEL
from ft_sitl.missions.aggressiveness import LEVELS, level_of
from ft_sitl.missions.campaign import run_campaign
from ft_sitl.missions.campaign_file import CampaignError, load_campaign
from ft_sitl.missions.plan import plan_trial
from ft_sitl.missions.results import COLUMNS, rows_from_parquet, to_frame
from ft_sitl.missions.spec import PROTOCOL_VERSION, PROTOCOLS, TrialSpec, TrialSpecError
from ft_sitl.missions.trial import run_trial
from ft_sitl.navigation.base import LIMITS, Limits, Observation, Task
from ft_sitl.navigation.learned.navrl import NavRL
from ft_sitl.navigation.registry import create
from tests.missions.conftest import PLATFORM, campaign_file, read_jsonl, run_exe

WALL_CLOCK = ("wall_time_s", "planner_time_s", "finished_utc")
RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"

LEVELED = """\
name = "levels"
algorithms = ["straight"]
platforms = ["{platform}"]
scenarios = [{{file = "yard.yaml"}}]
trials = 1
aggressiveness = ["gentle", "paper", "brisk", "aggressive",
                  {{name = "fast-gentle", max_speed_m_s = 6, max_acc_m_s2 = 2}}]
[limits]
timeout_s = 20.0
"""


def same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def test_the_declared_levels_run_gentle_to_beyond_the_weakest_platform():
    assert [(lv.name, lv.max_speed_m_s, lv.max_acc_m_s2) for lv in LEVELS.values()] == [
        ("gentle", 2.0, 2.0), ("paper", 4.0, 3.0), ("brisk", 6.0, 6.0),
        ("aggressive", 8.0, 10.0)]
    # paper is the protocol's defaults: the default limits of a spec of the newest version
    paper = LEVELS["paper"]
    assert paper.limits(Limits()) == TrialSpec("straight", PLATFORM, "forest").limits
    assert paper.max_acc_m_s2 == PROTOCOLS[PROTOCOL_VERSION].max_acc_m_s2
    # aggressive asks more horizontal acceleration than the weakest catalog platform
    # (TWR 1.4) holds at constant altitude, and more than PX4's 45 deg tilt limit gives
    g, weakest = 9.80665, 1.4
    assert LEVELS["aggressive"].max_acc_m_s2 > g * math.sqrt(weakest ** 2 - 1)
    assert LEVELS["aggressive"].max_acc_m_s2 > g * math.tan(math.radians(45.0))
    assert LEVELS["brisk"].max_acc_m_s2 < g * math.sqrt(weakest ** 2 - 1)
    for lv in LEVELS.values():  # within what the protocol's limits allow
        for key in ("max_speed_m_s", "max_acc_m_s2"):
            lo, hi = LIMITS[key].range
            assert lo <= getattr(lv, key) <= hi
    # a table naming a declared level with its values is that level
    assert level_of({"name": "brisk", "max_speed_m_s": 6, "max_acc_m_s2": 6}, "x") is \
        LEVELS["brisk"]


def test_every_trial_flies_at_every_level_with_one_seed(yard):
    c = load_campaign(campaign_file(yard.parent, "levels.toml",
                                    LEVELED.format(platform=PLATFORM)))
    specs = c.trial_specs()
    assert [(s.aggressiveness, s.limits.max_speed_m_s, s.limits.max_acc_m_s2)
            for s in specs] == [("gentle", 2.0, 2.0), ("paper", 4.0, 3.0),
                                ("brisk", 6.0, 6.0), ("aggressive", 8.0, 10.0),
                                ("fast-gentle", 6.0, 2.0)]
    assert len({s.seed for s in specs}) == 1 and len({s.trial_id for s in specs}) == 5
    # the rest of the limits are the campaign's
    assert {(s.limits.timeout_s, s.limits.goal_radius_m, s.limits.hold_s)
            for s in specs} == {(20.0, 2.0, 3.0)}
    assert c.spec_dict()["aggressiveness"][4] == {"name": "fast-gentle",
                                                  "max_speed_m_s": 6.0, "max_acc_m_s2": 2.0}
    # the level is part of the spec: it round-trips, and its name is in the id
    for s in specs:
        back = TrialSpec.from_dict(json.loads(s.to_json()))
        assert back == s and back.trial_id == s.trial_id
    # ... and a paper-level trial is the trial without the axis but for its name
    plain = load_campaign(campaign_file(yard.parent, "plain.toml", "\n".join(
        line for line in LEVELED.format(platform=PLATFORM).splitlines()
        if "aggressiveness" not in line and "fast-gentle" not in line)))
    (no_axis,) = plain.trial_specs()
    assert "aggressiveness" not in no_axis.to_dict() and no_axis.aggressiveness is None
    assert "aggressiveness" not in plain.spec_dict()
    paper = specs[1].to_dict()
    assert paper.pop("aggressiveness") == "paper"
    assert paper == no_axis.to_dict()


def test_campaigns_without_the_axis_keep_their_trial_ids():
    # ids of the presets as they were before the axis existed (computed at bd3250f, when
    # protocol 9 was the newest: a spec names its version, so the ids of the same trials
    # under a newer version differ by that field alone)
    quick = [replace(s, protocol=9) for s in load_campaign("quick").trial_specs()]
    assert (quick[0].trial_id, quick[-1].trial_id) == ("dff37a3b94334a07",
                                                       "b440e8f0c46437fe")
    assert all(s.aggressiveness is None and "aggressiveness" not in s.to_dict()
               for s in quick)
    with pytest.raises(TrialSpecError, match="aggressiveness: must be a level's name"):
        TrialSpec("straight", PLATFORM, "forest", aggressiveness="")


@pytest.mark.slow
def test_a_level_reaches_the_planners_px4_and_the_row_and_caps_the_flight(yard):
    c = load_campaign(campaign_file(yard.parent, "levels.toml",
                                    LEVELED.format(platform=PLATFORM)))
    specs = c.trial_specs()
    speeds = []
    for spec in specs[:4]:
        level = LEVELS[spec.aggressiveness]
        plan = plan_trial(spec)
        assert plan.flight_params["MPC_XY_VEL_MAX"] == level.max_speed_m_s
        task = plan.task()
        assert (task.limits.max_speed_m_s, task.limits.max_acc_m_s2) == (
            level.max_speed_m_s, level.max_acc_m_s2)
        # every planner plans with the level, as its original is configured
        ego, fast, pgo = (create(n, {}) for n in ("ego", "fast", "pgo"))
        for nav in (ego, fast, pgo):
            nav.reset(task)
            assert (nav.vmax, nav.max_acc) == (level.max_speed_m_s, level.max_acc_m_s2)
        assert (ego.optimizer.params.max_vel, ego.optimizer.params.max_acc) == (
            level.max_speed_m_s, level.max_acc_m_s2)
        assert (fast.kino_params.max_vel, fast.kino_params.max_acc,
                fast.optimizer.params.max_vel, fast.optimizer.params.max_acc) == (
            level.max_speed_m_s, level.max_acc_m_s2) * 2
        assert (pgo.params.max_vel, pgo.params.max_acc) == (level.max_speed_m_s,
                                                            level.max_acc_m_s2)
        # the straight baseline flies at the level's speed cap, into the yard's wall
        row = run_trial(spec).row
        assert set(row) == set(COLUMNS) and row["reason"] == "collision"
        assert (row["aggressiveness"], row["speed_limit_m_s"], row["acc_limit_m_s2"]) == (
            level.name, level.max_speed_m_s, level.max_acc_m_s2)
        assert row["max_speed_m_s"] <= 1.06 * level.max_speed_m_s
        speeds.append(row["max_speed_m_s"])
    assert speeds[0] >= 1.9 and speeds == sorted(speeds) and speeds[3] > 7.0


@pytest.mark.slow
def test_a_paper_level_trial_flies_what_the_trial_without_the_axis_flies(yard):
    c = load_campaign(campaign_file(yard.parent, "levels.toml",
                                    LEVELED.format(platform=PLATFORM)))
    paper = c.trial_specs()[1]
    plain = TrialSpec.from_dict({k: v for k, v in paper.to_dict().items()
                                 if k != "aggressiveness"})
    a, b = run_trial(paper).row, run_trial(plain).row
    assert (a["aggressiveness"], b["aggressiveness"]) == ("paper", "")
    differ = [k for k in COLUMNS if k not in WALL_CLOCK and not same(a[k], b[k])]
    assert differ == ["trial_id", "aggressiveness", "spec"]


def test_navrl_flies_its_deployments_speed_at_every_level(navrl_checkpoint):
    # the released policy's action range is the deployment's 1 m/s whatever the level
    def commands(level):
        nav = NavRL(checkpoint=str(navrl_checkpoint), latency_s=0.0)
        nav.reset(Task(start=np.array([0.0, 0.0, 1.5]), start_yaw=0.0,
                       goal=np.array([30.0, 0.0, 1.5]), limits=level.limits(Limits()),
                       bounds_min=np.array([-5.0, -10.0, 0.0]),
                       bounds_max=np.array([35.0, 10.0, 4.0]), collision_radius_m=0.3,
                       twr_max=3.0, alpha_xy_max=100.0, alpha_z_max=10.0))
        return np.array([nav.step(Observation(
            time_s=0.05 * k, position=np.array([0.0, 0.0, 1.5]), velocity=np.zeros(3),
            yaw=0.0, attitude=np.array([1.0, 0, 0, 0]), angular_velocity=np.zeros(3))).row
            for k in range(15)])
    rows = {name: commands(level) for name, level in LEVELS.items()}
    for name in ("gentle", "brisk", "aggressive"):
        np.testing.assert_array_equal(rows[name], rows["paper"])
    np.testing.assert_allclose(rows["aggressive"][-1, SP_VEL:SP_VEL + 2], [1.0, 0.0],
                               atol=1e-9)


def test_rows_written_before_the_columns_get_them_from_their_spec():
    # the committed rows of protocol 6 and of protocol 1 (no acceleration limit)
    for directory, acc in (("paper-pinned-sample", 3.0), ("paper-sample", math.nan)):
        rows = rows_from_parquet(RESULTS / directory / "trials.parquet")
        assert not any("speed_limit_m_s" in r for r in rows)
        df = to_frame(rows)
        assert set(df["aggressiveness"]) == {""}
        assert set(df["speed_limit_m_s"]) == {4.0}
        assert same(float(df["acc_limit_m_s2"].iloc[0]), acc)
        assert df["acc_limit_m_s2"].isna().all() == math.isnan(acc)


@pytest.mark.e2e
def test_a_leveled_campaign_runs_reruns_and_is_checked(yard, tmp_path, cli_env):
    path = campaign_file(yard.parent, "levels.toml", LEVELED.format(platform=PLATFORM))
    proc = run_exe("campaign", "check", path, env=cli_env)
    assert proc.returncode == 0, proc.stderr
    assert "x 5 aggressiveness levels" in proc.stdout
    assert "aggressiveness: gentle (2 m/s, 2 m/s^2); paper (4 m/s, 3 m/s^2); brisk (6 m/s, " \
           "6 m/s^2); aggressive (8 m/s, 10 m/s^2); fast-gentle (6 m/s, 2 m/s^2)" \
        in proc.stdout
    proc = run_exe("campaign", "check", path, "--json", env=cli_env)
    assert json.loads(proc.stdout)["aggressiveness"][0] == {
        "name": "gentle", "max_speed_m_s": 2.0, "max_acc_m_s2": 2.0}

    summary = run_campaign(load_campaign(path), tmp_path / "out", progress=False)
    assert (summary.ran, summary.errors) == (5, [])
    rows = {r["aggressiveness"]: r for r in read_jsonl(tmp_path / "out" / "trials.jsonl")}
    assert set(rows) == {"gentle", "paper", "brisk", "aggressive", "fast-gentle"}
    df = to_frame(rows.values())
    assert df["aggressiveness"].dtype == "category"
    assert dict(zip(df["aggressiveness"], df["acc_limit_m_s2"], strict=True))[
        "fast-gentle"] == 2.0
    proc = run_exe("trial", "rerun", tmp_path / "out", rows["aggressive"]["trial_id"],
                   env=cli_env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "identical to the stored result" in proc.stdout


BASE = f'algorithms = ["straight"]\nplatforms = ["{PLATFORM}"]\n'


@pytest.mark.parametrize("text, message", [
    ('aggressiveness = ["gentel"]',
     "c.toml: aggressiveness[0]: unknown aggressiveness level 'gentel'; did you mean "
     "'gentle'? (levels: gentle (2 m/s, 2 m/s^2), paper (4 m/s, 3 m/s^2), brisk (6 m/s, "
     "6 m/s^2), aggressive (8 m/s, 10 m/s^2); or a table with name, max_speed_m_s, "
     "max_acc_m_s2)"),
    ('aggressiveness = ["paper", {name = "x", max_speed_m_s = -2, max_acc_m_s2 = 3}]',
     "c.toml: aggressiveness[1]: max_speed_m_s: must be a number 0.1..20 (m/s), got -2"),
    ('aggressiveness = {name = "x", max_speed_m_s = 2, max_acc_m_s2 = 300}',
     "c.toml: aggressiveness: max_acc_m_s2: must be a number 0.1..100 (m/s^2), got 300"),
    ('aggressiveness = [{name = "x", max_speed_m_s = 2, max_acc_m_s2 = 0}]',
     "c.toml: aggressiveness[0]: max_acc_m_s2: must be a number 0.1..100 (m/s^2), got 0"),
    ('aggressiveness = [{name = "x", max_speed_m_s = 30, max_acc_m_s2 = 3}]',
     "c.toml: aggressiveness[0]: max_speed_m_s: must be a number 0.1..20 (m/s), got 30"),
    ('aggressiveness = [{name = "x", max_speed_m_s = 2, max_acc_m_s2 = 3, max_jerk = 4}]',
     "c.toml: aggressiveness[0]: unknown key(s) 'max_jerk'; allowed: name, max_speed_m_s, "
     "max_acc_m_s2"),
    ('aggressiveness = [{name = "x", max_speed_m_s = 2}]',
     "c.toml: aggressiveness[0]: missing key(s) max_acc_m_s2"),
    ('aggressiveness = [{name = "", max_speed_m_s = 2, max_acc_m_s2 = 3}]',
     "c.toml: aggressiveness[0]: name: must be a non-empty string (the level's name in the "
     "rows), got ''"),
    ('aggressiveness = [{name = "gentle", max_speed_m_s = 3, max_acc_m_s2 = 2}]',
     "c.toml: aggressiveness[0]: name: 'gentle' is a declared level, gentle (2 m/s, "
     "2 m/s^2): give the name alone for it, or another name for yours"),
    ('aggressiveness = ["paper", "paper"]',
     "c.toml: aggressiveness[1]: the level name 'paper' twice (also aggressiveness[0])"),
    ('aggressiveness = ["gentle", {name = "slow", max_speed_m_s = 2, max_acc_m_s2 = 2}]',
     "c.toml: aggressiveness[1]: slow (2 m/s, 2 m/s^2) flies the same limits as "
     "aggressiveness[0], gentle (2 m/s, 2 m/s^2)"),
    ("aggressiveness = []",
     "c.toml: aggressiveness: must be a level (a name or a table) or a non-empty list of "
     "them, got []"),
    ("aggressiveness = [4]",
     "c.toml: aggressiveness[0]: must be a level's name (gentle, paper, brisk, aggressive) "
     "or a table with name, max_speed_m_s, max_acc_m_s2, got 4"),
    ('aggressiveness = ["gentle"]\n[limits]\nmax_speed_m_s = 3.0',
     "c.toml: limits.max_speed_m_s: the aggressiveness axis sets it for each level; leave "
     "it out of [limits] (or drop the axis)"),
    ('protocol = 2\naggressiveness = "gentle"',
     "c.toml: aggressiveness: protocol version 2 has no acceleration limit (each planner "
     "used its own; it came with version 3), so its trials cannot fly a level"),
])
def test_bad_levels_are_named_by_file_entry_key_and_range(tmp_path, text, message):
    path = campaign_file(tmp_path, "c.toml", BASE + text + "\n")
    with pytest.raises(CampaignError) as exc:
        load_campaign(path)
    assert str(exc.value) == f"{tmp_path}/{message}"


def test_a_yaml_null_acceleration_is_refused_too(tmp_path):
    path = campaign_file(tmp_path, "c.yaml", "algorithms: [straight]\naggressiveness:\n"
                         "  - {name: x, max_speed_m_s: 2, max_acc_m_s2: null}\n")
    with pytest.raises(CampaignError, match=r"c.yaml: aggressiveness\[0\]: max_acc_m_s2: "
                                            r"must be a number 0.1..100 \(m/s\^2\), got None"):
        load_campaign(path)
