"""``ft-sitl campaign``, ``ft-sitl trial`` and ``ft-sitl navigators`` with real files.

Most tests call ``ft_sitl.cli.main`` in-process (the console script's code path); a few run
the installed script. The campaigns fly the conftest ``yard``: four short trials.
"""

import csv
import json
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image

from ft_sitl.cli import main
from ft_sitl.missions.campaign import run_campaign
from ft_sitl.missions.campaign_file import load_campaign
from ft_sitl.missions.spec import PROTOCOL_VERSION, PROTOCOLS
from tests.missions.conftest import (
    PLATFORM,
    YARD_START,
    campaign_file,
    read_jsonl,
    run_exe,
)

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
CAMPAIGN = """\
name = "cli"
trials = 2
platforms = ["1.00kg-SunnySky"]
scenarios = [{{file = "{yard}"}}]
algorithms = ["straight", {{name = "straight", label = "slow", params = {{speed_m_s = 2.0}}}}]
"""


def cli(capsys, *args):
    """(exit status, stdout, stderr) of ``ft-sitl ARGS`` run in-process."""
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def campaign(tmp_path_factory, yard):
    return campaign_file(tmp_path_factory.mktemp("cli"), "cli.toml",
                         CAMPAIGN.format(yard=yard))


@pytest.fixture(scope="module")
def done(tmp_path_factory, campaign):
    """A finished result directory of the campaign (no report)."""
    out = tmp_path_factory.mktemp("done") / "out"
    summary = run_campaign(load_campaign(campaign), out, progress=False)
    assert (summary.ran, summary.errors) == (4, [])
    return out


# --- campaign check --------------------------------------------------------------------------
def test_check_prints_the_matrix(capsys, campaign, yard):
    rc, out, err = cli(capsys, "campaign", "check", campaign)
    assert (rc, err) == (0, "")
    assert out.splitlines() == [
        "campaign 'cli': 4 trials = 2 algorithms x 1 platforms x 1 scenario families x 2 trials",
        "  algorithms: straight, slow",
        f"  platforms:  {PLATFORM}",
        "  scenarios:  yard [1] x2 each",   # (two trials, one configuration)
        "  limits: 4 m/s, 90 s, goal sphere 2 m held 3 s",
    ]
    rc, out, _ = cli(capsys, "campaign", "check", campaign, "--json")
    assert rc == 0
    assert json.loads(out) == {
        "name": "cli", "trials": 4, "algorithms": ["straight", "slow"],
        "platforms": [PLATFORM],
        "scenarios": [{"family": "yard", "indices": [1], "flies": [{"index": 1, "times": 2}],
                       "never_flies": []}],
        "trials_per_combination": 2,
        "limits": {"max_speed_m_s": 4.0, "timeout_s": 90.0, "goal_radius_m": 2.0,
                   "hold_s": 3.0}, "wind": [{}], "gains": ["bandwidth"],
        "thrust_floor": "px4", "params": [{}],
        "actuators": [{}], "perception": [{}], "estimator": [{}], "failures": [{}],
        "movers": [{}], "fence": [{}], "aggressiveness": [], "notes": []}


def test_check_says_which_listed_configurations_fly_and_warns_of_the_others(capsys,
                                                                            tmp_path):
    # trials cycle over the indices: one trial flies configuration 1 only
    body = (f'algorithms = ["straight"]\nplatforms = ["{PLATFORM}"]\ntrials = 1\n'
            'scenarios = [{family = "forest", indices = [1, 2]},\n'
            '             {family = "maze", indices = [3, 4, 5]}]\n')
    path = campaign_file(tmp_path, "cycle.toml", body)
    rc, out, err = cli(capsys, "campaign", "check", path)
    assert rc == 0
    assert ("  scenarios:  forest [1] (listed [1, 2]: 2 never flies), maze [3] (listed "
            "[3, 4, 5]: 4, 5 never fly)") in out.splitlines()
    assert err.splitlines() == [
        f"warning: {path}: scenarios[0] (forest): configuration 2 listed but never flown: "
        "trials = 1 cycles over indices [1, 2] (trial t flies indices[t % 2]); set trials = "
        "2 to fly each once, or list only those that fly",
        f"warning: {path}: scenarios[1] (maze): configurations 4, 5 listed but never flown: "
        "trials = 1 cycles over indices [3, 4, 5] (trial t flies indices[t % 3]); set "
        "trials = 3 to fly each once, or list only those that fly"]
    rc, out, _ = cli(capsys, "campaign", "check", path, "--json")
    forest, maze = json.loads(out)["scenarios"]
    assert forest["flies"] == [{"index": 1, "times": 1}] and forest["never_flies"] == [2]
    assert maze["never_flies"] == [4, 5]
    # five trials over two configurations: 3 and 2 of each
    path.write_text(body.replace("trials = 1", "trials = 5"))
    rc, out, err = cli(capsys, "campaign", "check", path)
    assert (rc, err) == (0, "")
    assert "  scenarios:  forest [1 x3, 2 x2], maze [3 x2, 4 x2, 5 x1]" in out.splitlines()
    # a run says it too, before anything else
    path.write_text(body)
    rc, _, err = cli(capsys, "campaign", "run", path, "--out", tmp_path / "out",
                     "--limit", 0)
    assert rc == 2 and err.splitlines()[0].startswith(
        f"warning: {path}: scenarios[0] (forest): configuration 2 listed but never flown")


def test_check_shows_every_axis(capsys, tmp_path, yard):
    body = (f'algorithms = ["straight"]\nplatforms = ["{PLATFORM}"]\n'
            f'scenarios = [{{file = "{yard}"}}]\ntrials = 1\n'
            'estimator = [{}, {position_noise_m = 0.1}]\n'
            'failures = [{}, {at_s = 5.0, unit = "gps", type = "off"}]\n'
            'movers = [{}, {count = 8, speed_m_s = 3.0}]\n')
    path = campaign_file(tmp_path, "axes.toml", body)
    rc, out, err = cli(capsys, "campaign", "check", path)
    assert (rc, err) == (0, "")
    lines = out.splitlines()
    assert lines[0].endswith("1 trials x 2 estimators x 2 failure settings x 2 mover "
                             "settings"), lines[0]
    assert "  estimator:  the truth; position_noise_m 0.1" in lines
    assert "  failures:   none; at_s 5, unit gps, type off, instance 1" in lines
    assert "  movers:     static; count 8, speed_m_s 3" in lines
    rc, out, _ = cli(capsys, "campaign", "check", path, "--json")
    info = json.loads(out)
    assert info["trials"] == 8 and info["movers"] == [{}, {"count": 8, "speed_m_s": 3.0}]


def test_check_a_preset(capsys):
    rc, out, _ = cli(capsys, "campaign", "check", "paper", "--json")
    info = json.loads(out)
    assert rc == 0 and info["name"] == "paper"
    assert info["trials"] == 2520 * len(info["algorithms"])
    assert len(info["platforms"]) == 36 and info["trials_per_combination"] == 10


# --- campaign run and report -----------------------------------------------------------------
@pytest.mark.slow  # two trials flown
def test_the_progress_bar_shows_the_time_left_from_the_mix(capsys, campaign, tmp_path):
    rc, _, err = cli(capsys, "campaign", "run", campaign, "--out", tmp_path / "out",
                     "--limit", "2", "--no-report")
    assert rc == 0
    bars = [b for b in err.replace("\r", "\n").splitlines() if b.startswith("cli:")]
    # tqdm's own "<remaining" is replaced by missions/progress.py's estimate, from the
    # reference costs before the first trial (two straight trials: 0.16 s) on
    assert bars and all("<" not in b and b.endswith(" left]") for b in bars), bars
    assert "about 00:00 left]" in bars[0]


@pytest.mark.slow  # a campaign and its report
def test_run_with_limit_then_resume_with_report_and_csv(capsys, campaign, tmp_path):
    out = tmp_path / "out"
    rc, stdout, err = cli(capsys, "campaign", "run", campaign, "--out", out, "--limit", "1",
                          "--quiet", "--no-report")
    assert (rc, err) == (0, "")
    assert stdout.startswith("1 trials run, 0 already done, 4 in the campaign; ")
    assert stdout.rstrip().endswith(f"-> {out}")
    assert len(read_jsonl(out / "trials.jsonl")) == 1
    assert len(pd.read_parquet(out / "trials.parquet")) == 1
    assert not (out / "report").exists()

    rc, stdout, err = cli(capsys, "campaign", "run", campaign, "--out", out, "--quiet",
                          "--csv")
    assert (rc, err) == (0, "")
    lines = stdout.splitlines()
    assert lines[0].startswith("3 trials run, 1 already done, 4 in the campaign; ")
    assert lines[1] == f"table: {out / 'trials.csv'}"
    report = out / "report"
    assert lines[2] == f"report: {report / 'report.html'}  (summary: {report / 'summary.md'})"
    table = pd.read_csv(out / "trials.csv")
    assert len(table) == 4 and set(table["algorithm"]) == {"straight", "slow"}
    html = (report / "report.html").read_text()
    assert "straight" in html and "slow" in html
    assert "| straight" in (report / "summary.md").read_text()
    runs = json.loads((out / "runs.json").read_text())
    assert [(r["trials_run"], r["trials_skipped"]) for r in runs] == [(1, 0), (3, 1)]

    rc, stdout, err = cli(capsys, "campaign", "run", campaign, "--out", out, "--quiet",
                          "--no-report")
    assert rc == 0 and stdout.startswith("0 trials run, 4 already done, 4 in the campaign")


@pytest.mark.slow  # a campaign report
def test_report_of_a_result_directory(capsys, done, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(done, out)
    rc, stdout, err = cli(capsys, "campaign", "report", out)
    assert (rc, err) == (0, "")
    report = out / "report"
    assert stdout == f"report: {report / 'report.html'}  (summary: {report / 'summary.md'})\n"
    assert (report / "report.html").stat().st_size > 10_000
    assert (report / "composite_score.png").read_bytes()[:8] == PNG_MAGIC


# --- trial rerun -----------------------------------------------------------------------------
def _row(done, algorithm="straight", trial=0):
    rows = read_jsonl(done / "trials.jsonl")
    return next(r for r in rows if (r["algorithm"], r["trial"]) == (algorithm, trial))


def test_rerun_by_id_prefix_is_identical_and_saves_trajectory_and_render(capsys, done,
                                                                         tmp_path):
    row = _row(done, "slow", 1)
    prefix = row["trial_id"][:7]
    assert [r["trial_id"].startswith(prefix) for r in read_jsonl(done / "trials.jsonl")
            ].count(True) == 1
    traj, png = tmp_path / "flown.csv", tmp_path / "flown.png"
    rc, out, err = cli(capsys, "trial", "rerun", done, prefix, "--trajectory", traj,
                       "--render", png)
    assert (rc, err) == (0, "")
    lines = out.splitlines()
    assert lines[0] == (f"trial {row['trial_id']}: slow on {PLATFORM} in yard (trial 1): "
                        f"{row['reason']} - {row['detail']}")
    assert row["reason"] == "collision"
    assert lines[1] == (f"  flown under protocol version {PROTOCOL_VERSION}: "
                        f"{PROTOCOLS[PROTOCOL_VERSION].summary}")
    assert lines[2] == (f"  navigation {row['nav_time_s']:.2f} s, path "
                        f"{row['path_length_m']:.2f} m, max speed {row['max_speed_m_s']:.2f} "
                        f"m/s, min clearance {row['min_clearance_m']:.3f} m")
    assert "  identical to the stored result (all but wall-clock columns)" in lines
    with open(traj, newline="") as fh:
        table = list(csv.reader(fh))
    assert table[0] == ["t_s", "x", "y", "z"]
    samples = np.array(table[1:], dtype=float)
    assert f"  trajectory: {traj} ({len(samples)} samples, ENU m)" in lines
    assert samples[-1, 0] == pytest.approx(row["nav_time_s"], abs=1e-3)
    assert np.linalg.norm(samples[0, 1:] - YARD_START) < 0.3  # from the start waypoint
    assert samples[-1, 2] < 10.0  # stopped at the wall (y = 9.8 m)
    assert f"  render: {png}" in lines and png.read_bytes()[:8] == PNG_MAGIC
    with Image.open(png) as im:   # the picture's title names the scenario, then the flight
        title = im.info["Title"]
    assert title.startswith(f"{row['scenario']}: ") and title.endswith(
        f" - slow on {PLATFORM}: {row['reason']}")


def test_rerun_reports_a_stored_result_that_differs(capsys, done, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(done, out)
    rows = read_jsonl(out / "trials.jsonl")
    stored = rows[0]["path_length_m"]
    rows[0]["path_length_m"] = stored + 1.0
    (out / "trials.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    rc, text, _ = cli(capsys, "trial", "rerun", out, rows[0]["trial_id"])
    assert rc == 1
    assert f"  DIFFERENT from the stored result in: path_length_m ({stored + 1.0!r} -> " \
           f"{stored!r})" in text.splitlines()


def test_rerun_from_a_spec_file(capsys, done, tmp_path):
    row = _row(done)
    spec = tmp_path / "spec.json"
    spec.write_text(row["spec"])
    rc, out, err = cli(capsys, "trial", "rerun", "--spec", spec)
    assert (rc, err) == (0, "")
    assert out.splitlines()[0].startswith(f"trial {row['trial_id']}: straight on {PLATFORM}")
    assert "identical" not in out  # nothing stored to compare with


def _parquet_only(done, tmp_path):
    """A result directory holding only the campaign's trials.parquet (like
    docs/results/paper: no campaign.json, no trials.jsonl)."""
    out = tmp_path / "table"
    out.mkdir()
    shutil.copyfile(done / "trials.parquet", out / "trials.parquet")
    return out


def test_rerun_from_a_directory_holding_only_trials_parquet(capsys, done, tmp_path):
    out = _parquet_only(done, tmp_path)
    row = _row(done, "slow", 1)
    rc, text, err = cli(capsys, "trial", "rerun", out, row["trial_id"][:8])
    assert (rc, err) == (0, "")
    # a committed campaign keeps its campaign.json beside the table (docs/results/envelope):
    # without trials.jsonl its rows are the table's
    shutil.copyfile(done / "campaign.json", out / "campaign.json")
    rc, again, err = cli(capsys, "trial", "rerun", out, row["trial_id"][:8])
    assert (rc, err) == (0, "") and "  identical to the stored result" in again
    lines = text.splitlines()
    assert lines[0].startswith(f"trial {row['trial_id']}: slow on {PLATFORM} in yard (trial 1)")
    assert "  identical to the stored result (all but wall-clock columns)" in lines
    # a changed table value is found as in a campaign directory
    df = pd.read_parquet(out / "trials.parquet")
    k = int(np.flatnonzero(df["trial_id"] == row["trial_id"])[0])
    df.loc[k, "max_tilt_deg"] += 0.5
    df.to_parquet(out / "trials.parquet", index=False)
    rc, text, _ = cli(capsys, "trial", "rerun", out, row["trial_id"])
    assert rc == 1
    assert any(ln.startswith("  DIFFERENT from the stored result in: max_tilt_deg (")
               for ln in text.splitlines())


def test_rerun_sample_is_stratified_reproducible_and_reports_differences(capsys, done,
                                                                        tmp_path):
    rows = {r["trial_id"]: r for r in read_jsonl(done / "trials.jsonl")}
    rc, text, err = cli(capsys, "trial", "rerun", done, "--sample", 2, "--sample-seed", 3)
    assert (rc, err) == (0, "")
    lines = text.splitlines()
    assert lines[-1] == "2 of 2 identical" and len(lines) == 3
    picked = [next(t for t in rows if t.startswith(ln.split()[0])) for ln in lines[:2]]
    # one trial per (algorithm, family) cell before any cell gets a second
    assert sorted(rows[t]["algorithm"] for t in picked) == ["slow", "straight"]
    for t, ln in zip(picked, lines):
        r = rows[t]
        assert ln == (f"{t[:10]} {r['algorithm']} yard {r['scenario']} (trial {r['trial']}): "
                      "identical")
    # the parquet-only table, same seed: the same trials; one of them altered -> exit 1
    table = _parquet_only(done, tmp_path)
    df = pd.read_parquet(table / "trials.parquet")
    df.loc[df["trial_id"] == picked[1], "path_length_m"] += 1.0
    df.to_parquet(table / "trials.parquet", index=False)
    rc, text, _ = cli(capsys, "trial", "rerun", table, "--sample", 2, "--sample-seed", 3)
    assert rc == 1
    lines = text.splitlines()
    assert lines[0].endswith(": identical") and lines[0].startswith(picked[0][:10])
    assert lines[1].startswith(f"{picked[1][:10]} ")
    assert ": DIFFERENT in path_length_m (" in lines[1]
    assert lines[2] == "1 of 2 identical"


@pytest.mark.parametrize(("args", "needle"), [
    (["--sample", "0"], "--sample: 0 must be within 1..4 (the trials in {done})"),
    (["--sample", "5"], "--sample: 5 must be within 1..4"),
    (["abc", "--sample", "1"], "--sample: give a result directory alone"),
    (["--sample", "1", "--render", "x.png"], "--trajectory and --render take one trial"),
])
def test_rerun_sample_bad_input(capsys, done, args, needle):
    rc, out, err = cli(capsys, "trial", "rerun", done, *args)
    assert (rc, out) == (2, "")
    assert err.startswith("ft-sitl: error: ") and needle.format(done=done) in err
    assert len(err.splitlines()) == 1


# --- navigators list -------------------------------------------------------------------------
def test_navigators_list(capsys):
    rc, out, _ = cli(capsys, "navigators", "list")
    assert rc == 0
    lines = out.splitlines()
    k = lines.index("straight       20 Hz  params: speed_m_s=None")
    assert lines[k + 1] == ("               The straight-flight baseline (paper Sec. IV-A): "
                            "no sensing, no avoidance.")
    names = [ln.split()[0] for ln in lines if not ln.startswith(" ")]
    assert names == sorted(names) and "UNAVAILABLE" not in out
    rc, out, _ = cli(capsys, "navigators", "list", "--json")
    rows = {r["name"]: r for r in json.loads(out)}
    assert rows["straight"] == {
        "name": "straight", "class": "ft_sitl.navigation.planners.straight.StraightLine",
        "rate_hz": 20.0, "depth_camera": False, "unavailable": None,
        "parameters": {"speed_m_s": None},
        "summary": "The straight-flight baseline (paper Sec. IV-A): no sensing, no avoidance."}


def test_navigators_show_prints_every_declared_parameter(capsys):
    from ft_sitl.navigation.registry import describe

    rc, out, _ = cli(capsys, "navigators", "show", "ego")
    assert rc == 0
    lines = out.splitlines()
    assert lines[1].split() == ["parameter", "default", "unit", "allowed", "meaning"]
    declared = describe("ego").rows()
    assert len(lines) == 2 + len(declared) and len(declared) >= 8
    for row, line in zip(declared, lines[2:]):
        assert line.split()[0] == row["name"] and row["unit"] in line and row["range"] in line
    assert any(ln.startswith("planning_horizon_m ") and " m " in ln for ln in lines)
    rc, out, _ = cli(capsys, "navigators", "show", "ego", "--json")
    assert json.loads(out) == {"name": "ego", "parameters": declared}
    rc, out, err = cli(capsys, "navigators", "show", "eggo")
    assert (rc, out) == (2, "")
    assert "unknown navigator 'eggo'; did you mean 'ego'?" in err


def test_navigators_list_shows_plugins_and_broken_entry_points(capsys, plugins):
    rc, out, _ = cli(capsys, "navigators", "list")
    assert rc == 0
    lines = out.splitlines()
    assert "t_hover        20 Hz  params: sleep_s=0.0" in lines
    assert "t_killer       20 Hz  params: -" in lines
    broken = [ln for ln in lines if ln.startswith("t_broken")]
    assert len(broken) == 1 and "UNAVAILABLE: entry point" in broken[0]
    assert "No module named 'ftnav_testplugins_missing'" in broken[0]
    rc, out, _ = cli(capsys, "navigators", "list", "--json")
    rows = {r["name"]: r for r in json.loads(out)}
    assert {"straight", "t_hover", "t_killer", "t_broken", "t_notnav"} <= set(rows)
    assert set(rows["t_broken"]) == {"name", "error"}
    assert rows["t_hover"]["class"] == "ftnav_testplugins.Hover"


# --- bad input -------------------------------------------------------------------------------
@pytest.mark.parametrize("args, message", [
    (["campaign", "check", "quik"], "quik: no such campaign file (presets: quick, paper, gains)"),
    (["campaign", "run", "quik", "--out", "{tmp}/o"],
     "quik: no such campaign file (presets: quick, paper, gains)"),
    (["campaign", "run", "{campaign}", "--out", "{tmp}/o", "--workers", "0"],
     "--workers: 0 must be at least 1"),
    (["campaign", "check", "{tmp}/bad.toml"],
     "{tmp}/bad.toml: unknown key(s) 'trails' (did you mean 'trials'?); allowed: name, trials, "
     "seed, scenario_seed, platforms, platform_files, scenarios, indices, physics_hz, protocol, "
     "gains, algorithms, limits, weights, description, wind, params, actuators, perception, "
     "estimator, failures, movers, fence, aggressiveness, thrust_floor"),
    (["campaign", "report", "{tmp}"],
     "{tmp}: not a campaign result directory (no campaign.json)"),
    (["campaign", "report", "{tmp}/empty"], "{tmp}/empty: no finished trials yet"),
    (["campaign", "run", "{tmp}/other.toml", "--out", "{done}"],
     "{done} holds the results of a different campaign ('cli'); use another --out "
     "directory, or the same campaign file to resume"),
    (["trial", "rerun", "{done}", "fffffffffff"], "no trial 'fffffffffff' in {done} (4 trials)"),
    (["trial", "rerun", "{done}", ""],
     "trial id '' is ambiguous in {done}: 4 trials start with it"),
    (["trial", "rerun", "{tmp}", "abc"],
     "{tmp}: not a campaign result directory (no campaign.json)"),
    (["trial", "rerun"], "give a campaign directory and a trial id, or --spec FILE"),
    (["trial", "rerun", "--spec", "{tmp}/nothere.json"],
     "--spec: {tmp}/nothere.json: no such file"),
    (["trial", "rerun", "--spec", "{tmp}/bad.toml"], "--spec: {tmp}/bad.toml: not a JSON "
                                                     "trial spec ("),
    (["trial", "rerun", "--spec", "{tmp}/spec.json"],
     "trial spec: scenario_index: must be an integer >= 1, got 0"),
])
def test_bad_input_is_one_line_exit_2(capsys, tmp_path, campaign, done, args, message):
    (tmp_path / "bad.toml").write_text('algorithms = ["straight"]\ntrails = 3\n')
    (tmp_path / "other.toml").write_text(campaign.read_text().replace('"cli"', '"other"'))
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "campaign.json").write_text('{"spec": {"name": "empty"}}')
    doc = json.loads(_row(done)["spec"])
    (tmp_path / "spec.json").write_text(json.dumps({**doc, "scenario_index": 0}))
    before = (done / "trials.jsonl").read_bytes()
    subst = {"{tmp}": str(tmp_path), "{done}": str(done), "{campaign}": str(campaign)}

    def fill(text):
        for k, v in subst.items():
            text = text.replace(k, v)
        return text

    rc, out, err = cli(capsys, *map(fill, args))
    assert (rc, out) == (2, "")
    assert err == f"ft-sitl: error: {fill(message)}\n" or (
        message.endswith("(") and err.startswith(f"ft-sitl: error: {fill(message)}")
        and err.count("\n") == 1), err
    assert (done / "trials.jsonl").read_bytes() == before
    assert not (tmp_path / "o").exists()


@pytest.mark.e2e  # the ft-sitl script
def test_bad_input_from_the_installed_script(tmp_path):
    proc = run_exe("campaign", "run", "quik", "--out", tmp_path / "o")
    assert proc.returncode == 2 and proc.stdout == ""
    assert proc.stderr == "ft-sitl: error: quik: no such campaign file (presets: quick, " \
                          "paper, gains)\n"
    proc = run_exe("trial", "rerun", tmp_path, "abc")
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1
    assert "not a campaign result directory" in proc.stderr and "Traceback" not in proc.stderr


# --- known bugs (strict: each mark goes with its fix) ----------------------------------------
def test_a_negative_limit_is_bad_input(capsys, campaign, tmp_path):
    rc, _, err = cli(capsys, "campaign", "run", campaign, "--out", tmp_path / "o", "--limit",
                     "-1", "--quiet", "--no-report")
    assert rc == 2 and err.startswith("ft-sitl: error: --limit"), err


def test_rerun_without_the_navigator_is_bad_input(capsys, done, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(done, out)
    rows = read_jsonl(out / "trials.jsonl")
    spec = json.loads(rows[0]["spec"])
    rows[0]["spec"] = json.dumps({**spec, "algorithm": "not_installed"})
    (out / "trials.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    try:
        rc, _, err = cli(capsys, "trial", "rerun", out, rows[0]["trial_id"])
    except Exception as exc:  # noqa: BLE001 - the bug: report it as a failure
        pytest.fail(f"main raised {type(exc).__name__}: {exc}")
    assert rc == 2 and "unknown navigator 'not_installed'" in err


def _children(pid: int) -> list[int]:
    """Live (not zombie) processes whose parent is pid."""
    out = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            stat = open(f"/proc/{d}/stat").read()
        except OSError:
            continue
        fields = stat[stat.rindex(")") + 2:].split()
        if int(fields[1]) == pid and fields[0] != "Z":
            out.append(int(d))
    return out


def _alive(pid: int) -> bool:
    try:
        stat = open(f"/proc/{pid}/stat").read()
    except OSError:
        return False
    return stat[stat.rindex(")") + 2:].split()[0] != "Z"


@pytest.mark.e2e  # a campaign run
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux")
def test_workers_stop_when_the_campaign_process_is_killed(tmp_path):
    """SIGKILL leaves the campaign process no chance to stop its pool: the workers must not
    go on flying queued trials for no one (the kernel's parent-death signal ends them)."""
    import signal
    import subprocess
    import time

    from tests.missions.conftest import EXE

    proc = subprocess.Popen([EXE, "campaign", "run", "quick", "--out", str(tmp_path / "o"),
                             "--workers", "2", "--quiet", "--no-report"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 120
        while len(workers) < 2 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
            workers = [c for c in _children(proc.pid)
                       if b"resource_tracker" not in open(f"/proc/{c}/cmdline", "rb").read()]
        assert len(workers) >= 2, "the campaign never started its two workers"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        deadline = time.monotonic() + 60
        while any(_alive(w) for w in workers) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not any(_alive(w) for w in workers), "workers outlived the campaign process"
    finally:
        if proc.poll() is None:
            proc.kill()
        for w in workers:
            if _alive(w):
                os.kill(w, signal.SIGKILL)


def test_rerun_of_a_row_built_by_an_older_generator_rebuilds_that_scene(capsys, tmp_path,
                                                                          monkeypatch):
    """A committed protocol-5 Maze row was built by Maze's first generator (no version in
    its spec): rerun rebuilds that maze, says so, and gives the stored row, although new
    trials now fly a newer Maze. (The row was made before the instruction-set pins; the
    straight baseline's flight is the same under them, so it is flown here under the pins,
    which the user's FT_SITL_ISA asks for, with a note.)"""
    from pathlib import Path

    from ft_sitl.scenarios.families import REGISTRY

    assert REGISTRY["maze"].version > 1
    src = Path(__file__).parents[2] / "docs" / "results" / "paper-sample-v5"
    df = pd.read_parquet(src / "trials.parquet")
    row = df[(df.family == "maze") & (df.algorithm == "straight")].iloc[0]
    assert "scenario_version" not in json.loads(row.spec)
    out = tmp_path / "v5"
    out.mkdir()
    df[df.trial_id == row.trial_id].to_parquet(out / "trials.parquet", index=False)
    monkeypatch.setenv("FT_SITL_ISA", "x86-64-v3")
    rc, text, err = cli(capsys, "trial", "rerun", out, row.trial_id)
    assert (rc, err) == (0, "")
    lines = text.splitlines()
    assert lines[0].startswith("note: these rows were made at instruction-set level host")
    assert lines[3] == (f"  scenario built by generator version 1 of maze (newest: "
                        f"{REGISTRY['maze'].version}): {REGISTRY['maze'].changes[1]}")
    assert "  identical to the stored result (all but wall-clock columns)" in lines


@pytest.mark.e2e  # a trial rerun in a child
def test_rerun_flies_rows_at_the_instruction_set_level_they_were_made_at(capsys, tmp_path,
                                                                          monkeypatch):
    """A row made before the pins (no ``isa`` in its software column) is re-run by a child
    process at ``host``, the level it was made at, which says so; rows made at two levels
    are refused together; a row that records x86-64-v3 flies in this process."""
    src = Path(__file__).parents[2] / "docs" / "results" / "paper-sample-v5"
    df = pd.read_parquet(src / "trials.parquet")
    row = df[(df.family == "maze") & (df.algorithm == "straight")].iloc[0]
    monkeypatch.delenv("FT_SITL_ISA", raising=False)
    out = tmp_path / "old"
    out.mkdir()
    df[df.trial_id == row.trial_id].to_parquet(out / "trials.parquet", index=False)
    rc, text, err = cli(capsys, "trial", "rerun", out, row.trial_id)
    lines = text.splitlines()
    assert rc == 0, (text, err)
    assert lines[0] == ("these rows were made at instruction-set level host (before ft-sitl "
                        "pinned one, 2026-12-07): re-running them at that level "
                        "(FT_SITL_ISA=host); at host a row re-runs bit for bit only on the "
                        "processor that made it (docs/results/README.md)")
    assert "  identical to the stored result (all but wall-clock columns)" in lines

    two = df[(df.algorithm == "straight")].head(2).copy()
    two["software"] = ['{"isa": "x86-64-v3"}', ""]
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    two.to_parquet(mixed / "trials.parquet", index=False)
    rc, text, err = cli(capsys, "trial", "rerun", mixed, "--sample", "2")
    assert rc == 2 and "made at different instruction-set levels (host, x86-64-v3)" in err

    new = mixed / "new"
    new.mkdir()
    two.head(1).to_parquet(new / "trials.parquet", index=False)
    rc, text, err = cli(capsys, "trial", "rerun", new, "--sample", "1")
    assert "instruction-set level" not in text and "1 of 1 identical" in text, (text, err)
