"""Campaigns (ft_sitl.missions.campaign, .campaign_file, .store) and the navigator registry.

Parsing: every mistake is one CampaignError naming the file and the key. Matrix: trial
counts, configurations, seeds, ids. Running: a campaign killed with SIGKILL mid-run resumes
to exactly the trials of an uninterrupted run; a navigator that kills its worker process is
recorded and the campaign goes on. Result directory: the lock comes before campaign.json,
files are replaced durably, a directory that lost campaign.json resumes only its own
campaign, damaged lines are reported and their trials flown again; bad environment
variables are one error line from the CLI. Registry: navigators from a real entry point (a
``*.dist-info`` on the path, see conftest), broken ones reported without hiding the others.
"""

import collections
import fcntl
import json
import math
import os
import signal
import subprocess
import threading
import time
from pathlib import Path

import pandas as pd
import pytest

from ft_sitl.missions.campaign import GRID_CACHE_DIR, run_campaign
from ft_sitl.missions.campaign_file import CampaignError, load_campaign
from ft_sitl.missions.results import COLUMNS, RowError, to_frame
from ft_sitl.missions.spec import platform_for
from ft_sitl.missions.store import ResultStore, StoreError, load_rows
from ft_sitl.navigation.base import Limits, Navigator
from ft_sitl.navigation.planners.straight import StraightLine
from ft_sitl.navigation.registry import NavigatorError, available, create, parameters
from ft_sitl.physics.catalog import catalog
from ft_sitl.scenarios.families import FAMILIES
from tests.missions.conftest import (
    EXE,
    PLATFORM,
    campaign_file,
    read_jsonl,
    run_exe,
    write_yard,
)

WALL_CLOCK = ("wall_time_s", "planner_time_s", "finished_utc")


def same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def _error(path) -> str:
    with pytest.raises(CampaignError) as exc:
        load_campaign(path)
    return str(exc.value)


# --- parse errors ----------------------------------------------------------------------------
BASE = 'algorithms = ["straight"]\n'
ERRORS = [
    # (file body, what the message must contain after "FILE: ")
    (BASE + "trails = 3", "unknown key(s) 'trails' (did you mean 'trials'?); allowed: name, "),
    ("trials = 3", "missing key 'algorithms'"),
    ('algorithms = ["stright"]',
     "algorithms[0]: unknown navigator 'stright'; did you mean 'straight'?"),
    ('algorithms = [{name = "straight", params = {speed = 3}}]',
     "algorithms[0]: navigator 'straight' has no parameter 'speed'; did you mean "
     "'speed_m_s'?"),
    ('algorithms = [{name = "straight", params = {speed_m_s = -1}}]',
     "algorithms[0]: navigator 'straight': speed_m_s: must be a number 0.1..50, or none "
     "(m/s), got -1"),
    ('algorithms = [{name = "straight", lable = "x"}]',
     "algorithms[0]: unknown key(s) 'lable' (did you mean 'label'?); allowed: name, label, "
     "params, command"),
    ('algorithms = [{label = "x"}]', "algorithms[0]: missing 'name'"),
    ('algorithms = ["straight", {name = "straight"}]',
     "algorithms[1]: label 'straight' is used twice"),
    ('algorithms = [{name = "straight", label = "a"}, {name = "straight", label = "a"}]',
     "algorithms[1]: label 'a' is used twice"),
    (BASE + 'platforms = ["1.00kg-SunnySk"]',
     "platforms[0]: unknown platform '1.00kg-SunnySk'; did you mean '1.00kg-SunnySky'"),
    (BASE + 'platforms = ["user"]', "platforms: no user platforms"),
    (BASE + "platforms = [3]", "platforms[0]: must be a platform name or a category"),
    (BASE + "scenarios = [3]", "scenarios[0]: must be a family name or a table"),
    (BASE + 'scenarios = ["maze", "forst"]',
     "scenarios[1]: unknown scenario family 'forst'; did you mean 'forest'?"),
    (BASE + 'scenarios = [{family = "maze", index = 3}]',
     "scenarios[0]: unknown key(s) 'index' (did you mean 'indices'?); allowed: family, "
     "indices, file"),
    (BASE + "indices = [0]", "indices: must be an integer 1..10, got 0"),
    (BASE + "indices = []", "indices: must be a non-empty list"),
    (BASE + 'indices = ["1"]', "indices: must be an integer 1..10, got '1'"),
    (BASE + 'scenarios = [{family = "maze", indices = [2, 11]}]',
     "scenarios[0]: indices: must be an integer 1..10, got 11"),
    (BASE + "trials = 0", "trials: must be an integer 1..10000, got 0"),
    (BASE + "seed = -1", "seed: must be an integer >= 0, got -1"),
    (BASE + "physics_hz = 333", "physics_hz: 333 must divide 1,000,000"),
    (BASE + 'gains = "PX4"', "gains: must be one of 'bandwidth', 'px4' (the controller-gain "
     "mode, docs/missions.md) or a list of different ones, got 'PX4'"),
    (BASE + "gains = 1", "gains: must be one of 'bandwidth', 'px4'"),
    (BASE + 'name = ""', "name: must be a non-empty string"),
    (BASE + "limits = 3", "limits: must be a table, got 3"),
    (BASE + "[limits]\ntimeout_s = -1",
     "limits: timeout_s: must be a number 0.1..3600 (s), got -1"),
    (BASE + "[limits]\ntimeout = 5",
     "limits: unknown key(s) 'timeout' (did you mean 'timeout_s'?); allowed: max_speed_m_s, "),
    (BASE + '[limits]\nhold_s = "3"', "limits: hold_s: must be a number 0.001..600 (s), got '3'"),
    (BASE + "[weights]\nbeta = 2", "weights.beta must be a number in [0, 1] (eq. 18), got 2"),
    (BASE + "[weights]\nbeta = true",
     "weights.beta must be a number in [0, 1] (eq. 18), got True"),
    (BASE + "[weights]\nscenarios = {classic = -1}",
     "weights.scenarios['classic'] = -1: weights must be finite numbers > 0"),
    # 0 was accepted by the file check and refused by the scorer's: one rule now
    (BASE + "[weights]\nplatforms = {real = 0}",
     "weights.platforms['real'] = 0: weights must be finite numbers > 0"),
    (BASE + "[weights]\nscenarios = {cave = 1}", "weights.scenarios: unknown key 'cave': "
     "neither a category"),
    (BASE + "[weights]\nscenarios = 3", "weights.scenarios: must be a table of weights"),
    (BASE + "[weights]\ngamma = 1", "weights: unknown key(s) 'gamma'; allowed: scenarios, "
     "platforms, beta"),
    (BASE + "weights = 1", "weights: must be a table, got 1"),
]


@pytest.mark.parametrize("body, message", ERRORS, ids=[m[:40] for _, m in ERRORS])
def test_a_bad_campaign_names_the_file_and_the_key(tmp_path, body, message):
    path = campaign_file(tmp_path, "bad.toml", body)
    assert _error(path).startswith(f"{path}: {message}")


def test_a_missing_user_file_is_named(tmp_path):
    path = campaign_file(tmp_path, "c.toml", BASE + 'scenarios = [{file = "nothere.yaml"}]')
    assert _error(path) == f"{path}: scenarios[0]: {tmp_path / 'nothere.yaml'}: no such " \
                           "spec file"
    path = campaign_file(tmp_path, "c.toml", BASE + 'platform_files = ["nothere.toml"]')
    msg = _error(path)
    assert msg.startswith(f"{path}: platform_files: ") and "nothere.toml" in msg


def test_syntax_errors_name_the_file_and_the_line(tmp_path):
    path = campaign_file(tmp_path, "c.yaml", "algorithms: [straight\ntrials: 3\n")
    msg = _error(path)
    assert msg.startswith(f"{path}: not valid YAML (line 2, column ") and "\n" not in msg
    path = campaign_file(tmp_path, "c.toml", 'algorithms = ["straight"\ntrials = 3\n')
    msg = _error(path)
    assert msg.startswith(f"{path}: not valid TOML: ") and "line 2" in msg
    path = campaign_file(tmp_path, "list.yaml", "- straight\n- trials\n")
    assert _error(path) == f"{path}: the top level must be a table of keys (algorithms, ...), " \
                           "got list"
    path = campaign_file(tmp_path, "empty.yaml", "")
    assert _error(path) == f"{path}: the top level must be a table of keys (algorithms, ...), " \
                           "got nothing"


def test_wrong_suffix_and_missing_file(tmp_path):
    path = campaign_file(tmp_path, "c.json", '{"algorithms": ["straight"]}')
    assert _error(path) == f"{path}: unknown campaign file type .json; use .toml, .yaml or .yml"
    missing = tmp_path / "nothere.toml"
    assert _error(missing) == f"{missing}: no such campaign file (presets: quick, paper, gains)"
    assert _error("quik") == "quik: no such campaign file (presets: quick, paper, gains)"


# --- presets and the matrix ------------------------------------------------------------------
def test_the_paper_preset_is_the_papers_matrix():
    c = load_campaign("paper")
    assert c.name == "paper" and c.trials == 10 and c.limits == Limits()
    # one fixed PX4 tuning on every airframe, as the paper flew (docs/missions.md)
    assert c.gains == "px4" and load_campaign("quick").gains == "bandwidth"
    assert len(c.platforms) == 36 and {p.name for p in c.platforms} == set(catalog())
    assert [s.family for s in c.scenarios] == list(FAMILIES)
    assert all(s.indices == tuple(range(1, 11)) for s in c.scenarios)
    assert c.weights == {"scenarios": {"classic": 1.2, "theoretical": 1.0},
                         "platforms": {"real": 1.5, "virtual": 1.0}, "beta": 0.3}
    specs = c.trial_specs()
    per_algorithm = collections.Counter(s.label for s in specs)
    assert set(per_algorithm) == {a.label for a in c.algorithms} >= {"straight"}
    assert set(per_algorithm.values()) == {2520}
    # each (algorithm, platform, family) flies configurations 1..10 once each
    combos = collections.defaultdict(list)
    for s in specs:
        combos[(s.label, s.platform, s.family)].append(s.scenario_index)
    assert len(combos) == 36 * 7 * len(c.algorithms)
    assert all(sorted(v) == list(range(1, 11)) for v in combos.values())


def test_the_quick_preset(navrl_checkpoint, monkeypatch):
    monkeypatch.setenv("FT_SITL_NAVRL_CHECKPOINT", str(navrl_checkpoint))
    c = load_campaign("quick")
    assert collections.Counter(p.category for p in c.platforms) == {"real": 3, "virtual": 3}
    assert all(s.indices == (1, 2) for s in c.scenarios)
    specs = c.trial_specs()
    assert len(specs) == 6 * 7 * 2 * len(c.algorithms)
    assert {a.name for a in c.algorithms} == {"straight", "ego", "fast", "pgo", "navrl",
                                              "learned"}
    assert c.notes == []
    assert len({s.trial_id for s in specs}) == len(specs)


MATRIX = """\
name = "matrix"
trials = 5
seed = 11
scenario_seed = 2
physics_hz = 500
platforms = ["1.00kg-SunnySky", "virtual", "0.55kg-UAV 1"]
platform_files = ["mine.toml"]
scenarios = ["Narrow-Gap", {family = "maze", indices = [4, 6]}]
indices = [1, 2, 3]
algorithms = ["straight", {name = "straight", label = "slow", params = {speed_m_s = 2.0}}]
[limits]
timeout_s = 30.0
"""
MINE = """\
[platform]
name = "1.30kg-lab-quad"
layout = "quad_x"
mass_kg = 1.30
twr_max = 2.8
alpha_xy_max_rad_s2 = 180.0
alpha_z_max_rad_s2 = 12.0
"""


def test_trial_specs_cover_the_matrix(tmp_path):
    campaign_file(tmp_path, "mine.toml", MINE)
    c = load_campaign(campaign_file(tmp_path, "m.toml", MATRIX.replace(
        '"0.55kg-UAV 1"]', '"0.55kg-UAV 1", "user"]')))
    names = [p.name for p in c.platforms]
    # categories expand in catalog order, names are not repeated
    virtual = [p.name for p in catalog().values() if p.category == "virtual"]
    assert names == ["1.00kg-SunnySky", *virtual, "1.30kg-lab-quad"]
    specs = c.trial_specs()
    assert len(specs) == 2 * len(names) * 2 * 5
    assert len({s.trial_id for s in specs}) == len(specs)
    assert len({s.seed for s in specs}) == len(specs)
    # the controlled series is a category too, which "all" leaves out
    series = load_campaign(campaign_file(tmp_path, "s.toml", MATRIX.replace(
        'platforms = ["1.00kg-SunnySky", "virtual", "0.55kg-UAV 1"]',
        'platforms = "series"'))).platforms
    assert [p.category for p in series] == ["series"] * 33
    assert series[0].name.startswith("series-")
    for s in specs:
        indices = (1, 2, 3) if s.family == "narrow_gap" else (4, 6)
        assert s.scenario_index == indices[s.trial % len(indices)]
        assert (s.campaign, s.scenario_seed, s.physics_hz) == ("matrix", 2, 500)
        assert s.limits == Limits(timeout_s=30.0, max_acc_m_s2=3.0)  # (protocol 3's default)
        assert s.algorithm == "straight"
        assert s.algorithm_params == ({"speed_m_s": 2.0} if s.label == "slow" else {})
    # grouped by scenario configuration (a worker builds each collision grid once)
    keys = [(s.family, s.scenario_index) for s in specs]
    assert len(set(keys)) == len([k for i, k in enumerate(keys) if i == 0 or keys[i - 1] != k])
    # a user platform travels with its trials; catalog platforms by name only
    user = [s for s in specs if s.platform == "1.30kg-lab-quad"]
    assert user and all(s.platform_def is not None for s in user)
    p = platform_for(user[0])
    assert p.physical_dict() == c.platforms[-1].physical_dict()
    assert all(s.platform_def is None for s in specs if s.platform != "1.30kg-lab-quad")


def test_seeds_do_not_depend_on_the_rest_of_the_matrix(tmp_path):
    one = load_campaign(campaign_file(tmp_path, "a.toml", """\
        trials = 2
        seed = 11
        platforms = ["1.00kg-SunnySky"]
        scenarios = ["maze"]
        algorithms = ["straight"]
        """)).trial_specs()
    campaign_file(tmp_path, "mine.toml", MINE)
    big = load_campaign(campaign_file(tmp_path, "m.toml", MATRIX)).trial_specs()
    seeds = {(s.label, s.platform, s.family, s.trial): s.seed for s in big}
    assert [s.seed for s in one] == [seeds[("straight", PLATFORM, "maze", t)] for t in (0, 1)]
    again = load_campaign(campaign_file(tmp_path, "b.toml", """\
        trials = 2
        seed = 12
        platforms = ["1.00kg-SunnySky"]
        scenarios = ["maze"]
        algorithms = ["straight"]
        """)).trial_specs()
    assert {s.seed for s in again}.isdisjoint({s.seed for s in one})


def test_yaml_and_toml_of_one_campaign_give_the_same_trials(tmp_path):
    write_yard(tmp_path)
    campaign_file(tmp_path, "mine.toml", MINE)
    toml = campaign_file(tmp_path, "same.toml", """\
        trials = 3
        seed = 4
        platforms = ["1.00kg-SunnySky", "user"]
        platform_files = ["mine.toml"]
        scenarios = ["sudden_drop", {family = "Maze", indices = [2]}, {file = "yard.yaml"}]
        algorithms = [{name = "straight", label = "s3", params = {speed_m_s = 3.0}}]
        [limits]
        hold_s = 2.0
        [weights]
        beta = 0.5
        """)
    yaml = campaign_file(tmp_path, "same.yaml", """\
        trials: 3
        seed: 4
        platforms: ["1.00kg-SunnySky", user]
        platform_files: mine.toml
        scenarios:
          - sudden_drop
          - {family: Maze, indices: 2}
          - file: yard.yaml
        algorithms:
          - name: straight
            label: s3
            params: {speed_m_s: 3.0}
        limits: {hold_s: 2.0}
        weights: {beta: 0.5}
        """)
    a, b = load_campaign(toml), load_campaign(yaml)
    assert a.name == b.name == "same"  # the file's stem
    assert a.spec_dict() == b.spec_dict()
    ids = [s.trial_id for s in a.trial_specs()]
    assert ids == [s.trial_id for s in b.trial_specs()]
    assert len(ids) == len(set(ids)) == 1 * 2 * 3 * 3
    files = {s.scenario_file for s in a.trial_specs()} - {None}
    assert files == {str((tmp_path / "yard.yaml").resolve())}


# --- the registry and entry points -----------------------------------------------------------
def test_only_the_builtin_navigators_without_plugins():
    nav = available()
    assert nav["straight"] is StraightLine
    assert not any(name.startswith("t_") for name in nav)


def test_entry_point_navigators_are_found_and_broken_ones_reported(plugins):
    nav = available()
    assert nav["straight"] is StraightLine
    hover = nav["t_hover"]
    assert isinstance(hover, type) and issubclass(hover, Navigator)
    assert hover.__module__ == "ftnav_testplugins" and hover.__name__ == "Hover"
    assert parameters(hover) == {"sleep_s": 0.0}
    broken = nav["t_broken"]
    assert isinstance(broken, str) and "failed to load" in broken
    assert "No module named 'ftnav_testplugins_missing'" in broken
    assert nav["t_notnav"] == "entry point 'ftnav_testplugins:NOT_A_NAVIGATOR' is not a " \
                              "Navigator subclass"
    assert isinstance(create("t_hover", {"sleep_s": 0.0}), hover)
    with pytest.raises(NavigatorError, match="^navigator 't_broken': entry point .* failed"):
        create("t_broken")
    with pytest.raises(NavigatorError, match="has no parameter 'sleep'; did you mean "
                                             "'sleep_s'"):
        create("t_hover", {"sleep": 1})


def test_a_campaign_flies_an_entry_point_navigator(plugins, yard, tmp_path):
    body = f"""\
        trials = 2
        platforms = ["{PLATFORM}"]
        scenarios = [{{file = "{yard}"}}]
        algorithms = "all"
        [limits]
        timeout_s = 1.0
        """
    c = load_campaign(campaign_file(tmp_path, "c.toml", body))
    loadable = sorted(n for n, cls in available().items()
                      if not isinstance(cls, str) and cls.unavailable() is None)
    assert [a.label for a in c.algorithms] == loadable
    assert {"straight", "t_hover", "t_killer"} <= set(loadable)
    assert not {"t_broken", "t_notnav"} & set(loadable)
    bad = campaign_file(tmp_path, "b.toml", body.replace('"all"', '["t_hover", "t_broken"]'))
    msg = _error(bad)
    assert msg.startswith(f"{bad}: algorithms[1]: navigator 't_broken': entry point ")
    c = load_campaign(campaign_file(tmp_path, "c.toml", body.replace('"all"', '["t_hover"]')))
    summary = run_campaign(c, tmp_path / "out", progress=False)
    assert (summary.total, summary.ran, summary.skipped, summary.errors) == (2, 2, 0, [])
    rows = read_jsonl(tmp_path / "out" / "trials.jsonl")
    assert [r["algorithm"] for r in rows] == ["t_hover"] * 2
    assert all(r["reason"] == "timeout" for r in rows)


def test_the_trial_wall_budget_comes_from_the_environment(plugins, yard, tmp_path,
                                                          monkeypatch):
    body = f"""\
        trials = 1
        platforms = ["{PLATFORM}"]
        scenarios = [{{file = "{yard}"}}]
        algorithms = [{{name = "t_hover", params = {{sleep_s = 30.0}}}}]
        [limits]
        timeout_s = 2.0
        """
    c = load_campaign(campaign_file(tmp_path, "c.toml", body))
    monkeypatch.setenv("FT_SITL_TRIAL_WALL_BUDGET_S", "1.5")
    summary = run_campaign(c, tmp_path / "out", progress=False)
    assert (summary.ran, summary.errors) == (1, [])
    row = read_jsonl(tmp_path / "out" / "trials.jsonl")[0]
    assert row["reason"] == "navigator_error"
    assert "wall-clock budget of 1.5 s" in row["detail"]
    for bad in ("0", "-3", "soon", "nan"):
        monkeypatch.setenv("FT_SITL_TRIAL_WALL_BUDGET_S", bad)
        with pytest.raises(CampaignError, match=f"FT_SITL_TRIAL_WALL_BUDGET_S='{bad}'"):
            run_campaign(c, tmp_path / f"bad{bad}", progress=False)


# --- resume after SIGKILL --------------------------------------------------------------------
RESUME = """\
name = "resume"
trials = 2
seed = 3
platforms = ["1.00kg-SunnySky"]
scenarios = [{file = "yard_a.yaml"}, {file = "yard_b.yaml"}, {file = "yard_c.yaml"},
             {file = "yard_d.yaml"}]
algorithms = ["straight", {name = "t_hover", label = "hover", params = {sleep_s = 0.25}}]
[limits]
timeout_s = 3.0
"""
N_RESUME = 4 * 2 * 2


def _resume_dir(root):
    for k, name in enumerate(("yard_a", "yard_b", "yard_c", "yard_d")):
        # four scenario configurations: four chunks of work, finishing one by one
        write_yard(root, name, wall=((2.0 + k, 9.8, 0.0), (8.0 - k / 2, 10.2, 3.0)))
    return campaign_file(root, "resume.toml", RESUME)


def _run_until_rows(campaign, out, n, env) -> subprocess.Popen:
    """``ft-sitl campaign run`` (2 workers, its own session) started and left running once
    ``n`` rows are in its trials.jsonl; killed (with its workers) if that fails."""
    assert EXE
    trials = out / "trials.jsonl"
    proc = subprocess.Popen([EXE, "campaign", "run", str(campaign), "--out", str(out),
                             "--workers", "2", "--no-report", "--quiet"], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while not (trials.exists() and trials.read_bytes().count(b"\n") >= n):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "no trial finished in 120 s"
            time.sleep(0.02)
    except BaseException:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
        raise
    return proc


@pytest.mark.e2e
def test_a_killed_campaign_resumes_to_the_uninterrupted_result(tmp_path, cli_env, plugins):
    campaign = _resume_dir(tmp_path)
    out = tmp_path / "killed"
    trials = out / "trials.jsonl"
    proc = _run_until_rows(campaign, out, 4, cli_env)
    os.killpg(proc.pid, signal.SIGKILL)  # the runner and its worker processes
    proc.communicate()
    raw = trials.read_bytes()
    written = raw[:raw.rfind(b"\n") + 1]  # (the kill may even have cut a write short)
    done_before = [json.loads(line) for line in written.decode().splitlines()]
    assert 4 <= len(done_before) < N_RESUME, "the kill must interrupt the campaign"
    with open(trials, "ab") as fh:  # a write cut short
        fh.write(b'{"trial_id": "0123456789abcdef", "algorithm": "stra')

    proc = run_exe("campaign", "run", campaign, "--out", out, "--workers", "2", "--no-report",
                   "--quiet", env=cli_env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"{N_RESUME - len(done_before)} trials run, "
                                  f"{len(done_before)} already done, {N_RESUME} in the "
                                  "campaign;")
    assert not (out / GRID_CACHE_DIR).exists()  # the workers' shared grids are gone
    rows = read_jsonl(trials)  # the torn line is gone, every line complete
    ids = [r["trial_id"] for r in rows]
    assert len(ids) == len(set(ids)) == N_RESUME
    assert trials.read_bytes().startswith(written)  # nothing rewritten

    reference = tmp_path / "reference"
    summary = run_campaign(load_campaign(campaign), reference, progress=False)
    assert (summary.ran, summary.errors) == (N_RESUME, [])
    ref = {r["trial_id"]: r for r in read_jsonl(reference / "trials.jsonl")}
    assert set(ref) == set(ids)
    assert {r["trial_id"] for r in rows} == {s.trial_id for s in
                                             load_campaign(campaign).trial_specs()}
    for r in rows:
        want = ref[r["trial_id"]]
        assert [k for k in COLUMNS if k not in WALL_CLOCK and not same(r[k], want[k])] == []
    assert collections.Counter(r["reason"] for r in rows if r["algorithm"] == "hover") == {
        "timeout": N_RESUME // 2}

    df = pd.read_parquet(out / "trials.parquet")
    assert list(df.columns) == list(COLUMNS) and len(df) == N_RESUME
    assert set(df["trial_id"]) == set(ids)
    assert df["reason"].dtype.name == "category"
    runs = json.loads((out / "runs.json").read_text())
    assert [r["trials_run"] for r in runs] == [N_RESUME - len(done_before)]  # kill -9: no entry

    # a different campaign into the same directory is refused, nothing is touched
    before = trials.read_bytes()
    other = load_campaign(campaign_file(tmp_path, "other.toml",
                                        RESUME.replace("seed = 3", "seed = 4")))
    with pytest.raises(StoreError, match=f"^{out} holds the results of a different campaign "
                                         r"\('resume'\); use another --out directory"):
        run_campaign(other, out, progress=False)
    assert trials.read_bytes() == before


@pytest.mark.e2e
def test_a_terminated_campaign_records_its_run_and_keeps_its_rows(tmp_path, cli_env, plugins):
    """SIGTERM (kill, a batch system's time limit) stops a campaign as Ctrl-C does: exit
    130 with a message, the workers gone, every finished row kept, and runs.json records
    the run, marked interrupted, with the trials it flew; the resume completes it."""
    campaign = _resume_dir(tmp_path)
    out = tmp_path / "terminated"
    trials = out / "trials.jsonl"
    proc = _run_until_rows(campaign, out, 2, cli_env)
    try:
        proc.send_signal(signal.SIGTERM)  # the runner only: it stops its workers
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    assert proc.returncode == 130, err
    assert "interrupted: finished trials are in" in err.decode()
    rows = read_jsonl(trials)
    assert 2 <= len(rows) < N_RESUME, "the signal must interrupt the campaign"
    runs = json.loads((out / "runs.json").read_text())
    assert len(runs) == 1 and runs[0]["interrupted"] is True
    assert runs[0]["trials_run"] == len(rows) and runs[0]["wall_time_s"] > 0
    assert not (out / GRID_CACHE_DIR).exists()  # closed as at a normal end

    proc = run_exe("campaign", "run", campaign, "--out", out, "--workers", "2", "--no-report",
                   "--quiet", env=cli_env)
    assert proc.returncode == 0, proc.stderr
    runs = json.loads((out / "runs.json").read_text())
    assert [(r["trials_run"], r["interrupted"]) for r in runs] == [
        (len(rows), True), (N_RESUME - len(rows), False)]
    assert len({r["trial_id"] for r in read_jsonl(trials)}) == N_RESUME


def _row(tid: str, v: int, reason: str = "timeout") -> dict:
    return {"trial_id": tid, "v": v, "reason": reason, "success": reason == "success"}


def test_a_damaged_tail_is_cut_before_appending(tmp_path):
    store = ResultStore(tmp_path)
    store.open({"spec": {"name": "x"}})
    store.append(_row("a", 1))
    store.append(_row("a", 2))  # already done: ignored
    store.close()
    with open(tmp_path / "trials.jsonl", "ab") as fh:
        fh.write(b'{"trial_id": "b", "v"')
    store = ResultStore(tmp_path)
    store.open({"spec": {"name": "x"}})
    assert list(store.done) == ["a"]
    store.append(_row("b", 3, "success"))
    store.close()
    assert read_jsonl(tmp_path / "trials.jsonl") == [_row("a", 1), _row("b", 3, "success")]
    with pytest.raises(StoreError, match="holds the results of a different campaign"):
        ResultStore(tmp_path).open({"spec": {"name": "y"}})


def test_a_table_written_from_a_store_never_opened_holds_its_trials(tmp_path):
    # (2026-12-07: write_tables() on a store nobody had opened or loaded wrote an empty
    # trials.parquet over a campaign's table)
    store = ResultStore(tmp_path)
    store.open({"spec": {"name": "x"}})
    store.append(_row("a", 1))
    store.append(_row("b", 2, "success"))
    store.close()
    written = ResultStore(tmp_path).write_tables()
    table = pd.read_parquet(written[0])
    assert sorted(table["trial_id"]) == ["a", "b"]
    assert ResultStore(tmp_path / "none").rows() == []


@pytest.mark.parametrize("row,message", [
    (_row("c", 1, "crashed"), r"trial c: reason 'crashed' is not one of success, collision"),
    ({"trial_id": "c", "success": True, "reason": "timeout"},
     r"trial c: success True does not match reason 'timeout'"),
    ({"trial_id": "c", "reason": "success"}, r"trial c: success None does not match"),
])
def test_a_row_with_an_unknown_outcome_is_refused_and_nothing_written(tmp_path, row, message):
    store = ResultStore(tmp_path)
    store.open({"spec": {"name": "x"}})
    store.append(_row("a", 1))
    with pytest.raises(RowError, match=message):
        store.append(row)
    store.close()
    assert read_jsonl(tmp_path / "trials.jsonl") == [_row("a", 1)]
    with pytest.raises(RowError, match=message):
        to_frame([_row("a", 1), row])


# --- a navigator that kills its worker process -----------------------------------------------
KILLER = """\
name = "killer"
trials = 2
platforms = ["1.00kg-SunnySky"]
scenarios = [{file = "yard.yaml"}]
algorithms = [
  "straight",
  "t_killer",
  {name = "t_hover", label = "hover", params = {sleep_s = 0.3}},
]
[limits]
timeout_s = 2.0
"""


@pytest.fixture(scope="module")
def killer_run(tmp_path_factory, cli_env):
    root = tmp_path_factory.mktemp("killer")
    write_yard(root)
    campaign = campaign_file(root, "killer.toml", KILLER)
    proc = run_exe("campaign", "run", campaign, "--out", root / "out", "--workers", "2",
                   "--no-report", "--quiet", env=cli_env)
    assert proc.returncode == 0, proc.stderr
    return proc, read_jsonl(root / "out" / "trials.jsonl")


@pytest.mark.e2e
def test_a_worker_killing_navigator_is_recorded_and_the_campaign_goes_on(killer_run):
    proc, rows = killer_run
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("6 trials run, 0 already done, 6 in the campaign;")
    assert len(rows) == len({r["trial_id"] for r in rows}) == 6
    killed = [r for r in rows if r["algorithm"] == "t_killer"]
    assert len(killed) == 2
    for r in killed:
        assert (r["reason"], r["success"]) == ("navigator_error", False)
        assert r["detail"] == "the trial's process died (a crash in native code?)"
        assert (r["platform"], r["family"], r["scenario"]) == (PLATFORM, "yard", "yard")
        assert json.loads(r["spec"])["algorithm"] == "t_killer"
    assert collections.Counter(r["algorithm"] for r in rows) == {"straight": 2, "t_killer": 2,
                                                                 "hover": 2}


@pytest.mark.e2e
def test_trials_next_to_a_worker_killing_navigator_keep_their_outcome(killer_run):
    _, rows = killer_run
    innocent = {(r["algorithm"], r["trial"]): r["reason"] for r in rows
                if r["algorithm"] != "t_killer"}
    assert innocent == {("straight", 0): "timeout", ("straight", 1): "timeout",
                        ("hover", 0): "timeout", ("hover", 1): "timeout"}


# --- known bugs (strict: each mark goes with its fix) ----------------------------------------
def test_duplicate_scenario_entries_are_refused_or_merged(tmp_path):
    path = campaign_file(tmp_path, "dup.toml", BASE + 'scenarios = ["narrow_gap", '
                                                      '"Narrow-Gap"]\nindices = [1]\n')
    try:
        specs = load_campaign(path).trial_specs()
    except CampaignError as exc:
        assert str(exc).startswith(f"{path}: scenarios[1]: ")
        return
    assert len({s.trial_id for s in specs}) == len(specs)


@pytest.mark.parametrize("weights", ["scenarios = {clasic = 1.2}", "platforms = {reel = 1.5}",
                                     "scenarios = {classic = 0}"])
def test_weights_the_score_refuses_are_refused_by_the_campaign(tmp_path, weights):
    path = campaign_file(tmp_path, "w.toml", BASE + f"[weights]\n{weights}\n")
    assert _error(path).startswith(f"{path}: weights.")


def test_the_gains_key_reaches_every_trial_and_is_left_out_at_the_default(tmp_path):
    body = BASE + 'platforms = ["1.00kg-SunnySky"]\nscenarios = ["forest"]\nindices = [1]\n' \
                  "trials = 1\n"
    plain = load_campaign(campaign_file(tmp_path, "plain.toml", body))
    bandwidth = load_campaign(campaign_file(tmp_path, "plain.yaml", "gains: bandwidth\n" +
                                            "algorithms: [straight]\nplatforms: "
                                            "[1.00kg-SunnySky]\nscenarios: [forest]\n"
                                            "indices: [1]\ntrials: 1\n"))
    px4 = load_campaign(campaign_file(tmp_path, "px4.toml", body + 'gains = "px4"\n'))
    assert (plain.gains, bandwidth.gains, px4.gains) == ("bandwidth", "bandwidth", "px4")
    # the default leaves the campaign and its trials as they were before the key existed
    assert "gains" not in plain.spec_dict() and plain.spec_dict() == bandwidth.spec_dict()
    assert [s.trial_id for s in plain.trial_specs()] == \
        [s.trial_id for s in bandwidth.trial_specs()]
    assert px4.spec_dict()["gains"] == "px4"
    (spec,) = px4.trial_specs()
    assert spec.gains == "px4" and spec.trial_id != plain.trial_specs()[0].trial_id


def test_a_directory_of_other_gains_is_refused_naming_them(tmp_path):
    store = ResultStore(tmp_path)
    store.open({"spec": {"name": "x", "trials": 1, "gains": "px4"}})
    store.close()
    with pytest.raises(StoreError, match=r"holds trials flown with gains = 'px4'; this run "
                                         r"would fly gains = 'bandwidth': set gains = 'px4'"):
        ResultStore(tmp_path).open({"spec": {"name": "x", "trials": 1}})


def test_a_directory_of_another_protocol_version_is_refused_by_version(tmp_path):
    """Rows of two protocol versions never mix in one directory; the message says which
    version the directory holds and how to resume it."""
    store = ResultStore(tmp_path)
    store.open({"spec": {"name": "x", "trials": 1, "protocol": 7}})
    store.close()
    with pytest.raises(StoreError, match=r"holds trials flown under protocol version 7; this "
                                         r"run would fly version 1, .*set protocol = 7 in the "
                                         r"campaign file to resume it"):
        ResultStore(tmp_path).open({"spec": {"name": "x", "trials": 1}})
    with pytest.raises(StoreError, match="holds the results of a different campaign"):
        ResultStore(tmp_path).open({"spec": {"name": "x", "trials": 2}})


# --- the result directory: lock, durable writes, lost campaign.json, damaged lines ----------
STORE = """\
name = "{name}"
trials = {trials}
seed = {seed}
platforms = ["1.00kg-SunnySky"]
scenarios = [{{file = "yard.yaml"}}]
algorithms = ["straight"]
[limits]
timeout_s = 3.0
"""


def _store_campaign(root, name="store", trials=2, seed=1, file=None):
    write_yard(root)
    return campaign_file(root, file or f"{name}-{seed}.toml",
                         STORE.format(name=name, trials=trials, seed=seed))


def test_the_lock_is_taken_before_campaign_json_is_read_or_written(tmp_path):
    other = open(tmp_path / ".lock", "w")  # noqa: SIM115 - another runner holding the lock
    fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
    with pytest.raises(StoreError, match=f"^{tmp_path} is in use by another campaign run"):
        ResultStore(tmp_path).open({"spec": {"name": "x"}})
    assert not (tmp_path / "campaign.json").exists()  # nothing written without the lock
    other.close()
    store = ResultStore(tmp_path)
    assert store.open({"spec": {"name": "x"}}) == []
    store.close()
    other = open(tmp_path / ".lock", "w")  # noqa: SIM115
    fcntl.flock(other, fcntl.LOCK_EX | fcntl.LOCK_NB)
    # checked under the lock: a runner waiting on it does not even read campaign.json
    with pytest.raises(StoreError, match="is in use by another campaign run"):
        ResultStore(tmp_path).open({"spec": {"name": "y"}})
    other.close()
    with pytest.raises(StoreError, match="holds the results of a different campaign"):
        ResultStore(tmp_path).open({"spec": {"name": "y"}})
    store = ResultStore(tmp_path)  # the refused open let go of the lock
    store.open({"spec": {"name": "x"}})
    store.close()


def test_every_file_is_replaced_durably(tmp_path, monkeypatch):
    """campaign.json, runs.json and trials.parquet: the temporary file is fsync'ed before
    it replaces the old one, and the directory after (else a power cut can leave an empty
    file)."""
    campaign = load_campaign(_store_campaign(tmp_path, trials=1))
    out = (tmp_path / "out").resolve()
    events = []
    fsync, replace = os.fsync, os.replace

    def logged_fsync(fd):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        fsync(fd)

    def logged_replace(src, dst):
        events.append(("replace", str(Path(src).resolve()), str(Path(dst).resolve())))
        replace(src, dst)

    monkeypatch.setattr(os, "fsync", logged_fsync)
    monkeypatch.setattr(os, "replace", logged_replace)
    summary = run_campaign(campaign, out, progress=False)
    assert (summary.ran, summary.errors) == (1, [])
    for name in ("campaign.json", "runs.json", "trials.parquet"):
        (k,) = [k for k, e in enumerate(events) if e[0] == "replace" and e[2] == str(out / name)]
        assert events[k - 1] == ("fsync", events[k][1]), name  # the new file's data
        assert events[k + 1] == ("fsync", str(out)), name  # the rename
    assert ("fsync", str(out / "trials.jsonl")) in events


@pytest.mark.e2e
def test_a_directory_that_lost_campaign_json_resumes_only_its_own_campaign(tmp_path, cli_env):
    mine = _store_campaign(tmp_path, name="mine")
    out = tmp_path / "out"
    assert run_campaign(load_campaign(mine), out, progress=False).ran == 2
    spec_path, trials = out / "campaign.json", out / "trials.jsonl"
    written, rows = spec_path.read_text(), trials.read_bytes()
    spec_path.unlink()

    # another campaign, and the same name with another seed: refused, nothing written
    for other, found in ((_store_campaign(tmp_path, name="other"),
                          "holds 2 trials of campaign 'mine', not of this one ('other')"),
                         (_store_campaign(tmp_path, name="mine", seed=2),
                          "holds 2 trials of campaign 'mine', 2 of which are not trials of "
                          "this campaign file")):
        proc = run_exe("campaign", "run", other, "--out", out, "--no-report", "--quiet",
                       env=cli_env)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.startswith(f"ft-sitl: error: {out} has no campaign.json and "
                                      f"{found}")
        assert proc.stderr.count("\n") == 1
        assert not spec_path.exists() and trials.read_bytes() == rows
    with pytest.raises(StoreError, match="holds 2 trials, which cannot be checked"):
        ResultStore(out).open(json.loads(written))  # no trial ids to check them against

    # its own campaign: campaign.json written again, nothing flown twice
    proc = run_exe("campaign", "run", mine, "--out", out, "--no-report", "--quiet",
                   env=cli_env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("0 trials run, 2 already done, 2 in the campaign;")
    assert f"warning: {out} has no campaign.json; the 2 trials it holds are all trials of " \
           "this campaign ('mine'): campaign.json written again" in proc.stderr
    assert json.loads(spec_path.read_text()) == json.loads(written)
    assert trials.read_bytes() == rows

    # an empty campaign.json (what a power cut could leave before it was fsync'ed)
    spec_path.write_text("")
    summary = run_campaign(load_campaign(mine), out, progress=False)
    assert (summary.ran, summary.skipped) == (0, 2)
    assert json.loads(spec_path.read_text()) == json.loads(written)

    # the rows of trials.parquet count as well
    spec_path.unlink()
    trials.unlink()
    other = load_campaign(_store_campaign(tmp_path, name="other"))
    with pytest.raises(StoreError, match="has no campaign.json and holds 2 trials of "
                                         "campaign 'mine', not of this one"):
        run_campaign(other, out, progress=False)


@pytest.mark.e2e
def test_a_damaged_line_is_reported_and_its_trial_flown_again_once(tmp_path, cli_env):
    path = _store_campaign(tmp_path, trials=3)
    out = tmp_path / "out"
    assert run_campaign(load_campaign(path), out, progress=False).ran == 3
    trials = out / "trials.jsonl"
    lines = trials.read_bytes().split(b"\n")
    lost = json.loads(lines[1])["trial_id"]
    lines[1] = b"\0" * len(lines[1])  # what a power cut can leave in the middle of a file
    trials.write_bytes(b"\n".join(lines))

    notes = []
    campaign, rows = load_rows(out, on_note=notes.append)
    assert sorted(r["trial_id"] for r in rows) == sorted(
        json.loads(lines[k])["trial_id"] for k in (0, 2))
    assert notes == [f"{trials}: 1 damaged line skipped (line 2: not a trial row); a trial "
                     "stored only there is missing from these results until the campaign "
                     "is run again"]

    proc = run_exe("campaign", "run", path, "--out", out, "--no-report", "--quiet",
                   env=cli_env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("1 trials run, 2 already done, 3 in the campaign;")
    assert f"warning: {trials}: 1 damaged line skipped (line 2: not a trial row); a trial " \
           "stored only there is flown again" in proc.stderr
    after = trials.read_bytes().split(b"\n")
    assert after[:4] == lines[:3] + [after[3]]  # nothing rewritten; one line appended
    assert json.loads(after[3])["trial_id"] == lost
    df = pd.read_parquet(out / "trials.parquet")
    assert sorted(df["trial_id"]) == sorted(s.trial_id for s in
                                            load_campaign(path).trial_specs())
    assert list(df["trial_id"]).count(lost) == 1


@pytest.mark.e2e
def test_a_bad_trial_wall_budget_is_one_error_line_from_the_cli(tmp_path, cli_env):
    path = _store_campaign(tmp_path)
    for bad in ("abc", "0"):
        proc = run_exe("campaign", "run", path, "--out", tmp_path / "out", "--quiet",
                       env={**cli_env, "FT_SITL_TRIAL_WALL_BUDGET_S": bad})
        assert (proc.returncode, proc.stdout) == (2, "")
        assert proc.stderr == (f"ft-sitl: error: FT_SITL_TRIAL_WALL_BUDGET_S='{bad}': must "
                               "be a positive number of seconds or 'none'\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.e2e
def test_a_bad_navrl_checkpoint_variable_is_one_error_line_from_the_cli(tmp_path, cli_env):
    navrl = campaign_file(tmp_path, "navrl.toml", STORE.format(name="n", trials=1, seed=1)
                          .replace('["straight"]', '["navrl"]'))
    write_yard(tmp_path)
    spec = load_campaign(_store_campaign(tmp_path)).trial_specs()[0].to_dict()
    (tmp_path / "spec.json").write_text(json.dumps({**spec, "algorithm": "navrl",
                                                    "label": "navrl"}))
    not_a_checkpoint = tmp_path / "navrl.toml"
    every = [("campaign", "run", navrl, "--out", tmp_path / "out"),
             ("trial", "rerun", "--spec", tmp_path / "spec.json"),
             ("navigate", "--algorithm", "navrl", "--scenario", tmp_path / "yard.yaml")]
    for value, commands in ((tmp_path / "missing.pt", every[:1]), (not_a_checkpoint, every)):
        for command in commands:
            proc = run_exe(*command, env={**cli_env, "FT_SITL_NAVRL_CHECKPOINT": str(value)})
            assert proc.returncode == 2, (command, proc.stderr)
            assert proc.stderr.startswith("ft-sitl: error: "), command
            assert f"FT_SITL_NAVRL_CHECKPOINT={value}: " in proc.stderr, command
            assert proc.stderr.count("\n") == 1, (command, proc.stderr)
    assert not (tmp_path / "out").exists()


def test_a_signal_taken_by_another_thread_waits_until_the_row_is_counted():
    """The kernel gives a process signal to any thread not blocking it; Python then runs
    the handler in the main thread at its next instruction. The row's write and count must
    still come first, and the signal must act after them, once."""
    from ft_sitl.missions.campaign import _signals_deferred

    def interrupt(signum, frame):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, interrupt)
    steps = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with _signals_deferred():
                steps.append("written")
                other = threading.Thread(target=lambda: signal.pthread_kill(
                    threading.get_ident(), signal.SIGTERM))
                other.start()
                other.join()
                time.sleep(0.05)  # many instructions at which the handler could have run
                steps.append("counted")
            steps.append("not reached")
        assert signal.getsignal(signal.SIGTERM) is interrupt
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert steps == ["written", "counted"]
