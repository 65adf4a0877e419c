"""Campaign axes: wind, controller-gain modes, PX4 parameters, actuators, perception and
the flight controller's estimator. Every trial of the matrix
flies in each value of each axis, with the same seed; rows carry the values; trials at the
defaults keep their ids; a turbulent trial reruns bit for bit; the report plots success
against the wind; bad values are named by file, axis entry, key and range."""

import json

import numpy as np
import pytest

from ft_sitl.missions.campaign import run_campaign
from ft_sitl.missions.campaign_file import CampaignError, load_campaign
from ft_sitl.missions.perception import Perception
from ft_sitl.missions.report import write_report
from ft_sitl.missions.results import to_frame
from ft_sitl.missions.spec import TrialSpec
from ft_sitl.missions.trial import run_trial
from ft_sitl.transport import transport
from tests.missions.conftest import campaign_file, read_jsonl, run_exe

WINDY = """\
name = "windy"
algorithms = ["straight"]
platforms = ["0.98kg-EGO Planner DIY"]
scenarios = [{file = "yard.yaml"}]
trials = 1
wind = [
  {},
  {speed_m_s = 7, from_deg = 90},
  {speed_m_s = 7, from_deg = 90, turbulence = "standard", gust_m_s = 4, gust_start_s = 6},
]
[limits]
timeout_s = 6.0
"""


@pytest.mark.e2e
def test_every_trial_flies_in_every_wind_with_one_seed(yard, tmp_path, cli_env):
    path = campaign_file(yard.parent, "windy.toml", WINDY)
    c = load_campaign(path)
    specs = c.trial_specs()
    assert [s.wind for s in specs] == [None, {"speed_m_s": 7.0, "from_deg": 90.0},
                                       {"speed_m_s": 7.0, "from_deg": 90.0,
                                        "turbulence": "standard", "gust_m_s": 4.0,
                                        "gust_start_s": 6.0}]
    assert len({s.seed for s in specs}) == 1 and len({s.trial_id for s in specs}) == 3
    # a calm trial's spec (and id) is what it was before winds existed
    calm = specs[0]
    assert "wind" not in calm.to_dict()
    assert calm.trial_id == TrialSpec.from_dict(
        {k: v for k, v in calm.to_dict().items()}).trial_id

    summary = run_campaign(c, tmp_path / "out", progress=False)
    assert (summary.ran, summary.errors) == (3, [])
    rows = {r["wind"]: r for r in read_jsonl(tmp_path / "out" / "trials.jsonl")}
    assert set(rows) == {"", '{"from_deg":90.0,"speed_m_s":7.0}',
                         '{"from_deg":90.0,"gust_m_s":4.0,"gust_start_s":6.0,"speed_m_s":7.0,'
                         '"turbulence":"standard"}'}
    calm_row = rows[""]
    assert (calm_row["wind_speed_m_s"], calm_row["turbulence"], calm_row["gust_m_s"]) == \
        (0.0, "none", 0.0)
    steady = rows['{"from_deg":90.0,"speed_m_s":7.0}']
    assert (steady["wind_speed_m_s"], steady["turbulence"]) == (7.0, "none")
    # a 7 m/s wind from the east across the yard's north-bound line: the flight differs
    assert steady["path_length_m"] != calm_row["path_length_m"]
    assert steady["max_tilt_deg"] > calm_row["max_tilt_deg"]

    # the turbulent, gusty trial reruns bit for bit from its row
    gusty = next(r for r in rows.values() if r["turbulence"] == "standard")
    proc = run_exe("trial", "rerun", tmp_path / "out", gusty["trial_id"], env=cli_env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "identical" in proc.stdout
    again = run_trial(TrialSpec.from_dict(json.loads(gusty["spec"]))).row
    assert again["path_length_m"] == gusty["path_length_m"]

    # the report plots success against the wind when there is an axis, and not without
    proc = run_exe("campaign", "report", tmp_path / "out", env=cli_env)
    assert proc.returncode == 0, proc.stderr
    page = (tmp_path / "out" / "report" / "report.html").read_text()
    assert 'alt="success_vs_wind"' in page and "Success against the mean wind speed" in page
    assert (tmp_path / "out" / "report" / "success_vs_wind.png").stat().st_size > 5000
    calm_only = to_frame([r for r in read_jsonl(tmp_path / "out" / "trials.jsonl")
                          if r["wind"] == ""])
    paths = write_report(calm_only, tmp_path / "calm", campaign_spec={}, meta={})
    assert "success_vs_wind" not in paths["report.html"].read_text()


# --- the controller axes: gain modes and PX4 parameters -------------------------------------------
GAINS = """\
name = "gains"
algorithms = ["straight"]
platforms = ["2.00kg-T-MOTOR"]
scenarios = [{file = "yard.yaml"}]
trials = 1
gains = ["bandwidth", "px4"]
params = [{}, {MPC_XY_P = 0.5, MPC_XY_VEL_P_ACC = 1.2}]
[limits]
timeout_s = 5.0
"""


def test_gain_modes_and_px4_parameters_are_axes(yard, tmp_path):
    c = load_campaign(campaign_file(yard.parent, "gains.toml", GAINS))
    specs = c.trial_specs()
    assert [(s.gains, s.params) for s in specs] == [
        ("bandwidth", None), ("bandwidth", {"MPC_XY_P": 0.5, "MPC_XY_VEL_P_ACC": 1.2}),
        ("px4", None), ("px4", {"MPC_XY_P": 0.5, "MPC_XY_VEL_P_ACC": 1.2})]
    assert len({s.seed for s in specs}) == 1
    assert "params" not in specs[0].to_dict() and "gains" not in specs[0].to_dict()
    summary = run_campaign(c, tmp_path / "out", progress=False)
    assert (summary.ran, summary.errors) == (4, [])
    rows = read_jsonl(tmp_path / "out" / "trials.jsonl")
    by = {(r["gains"], r["params"]): r for r in rows}
    assert set(by) == {("bandwidth", ""), ("px4", ""),
                       ("bandwidth", '{"MPC_XY_P":0.5,"MPC_XY_VEL_P_ACC":1.2}'),
                       ("px4", '{"MPC_XY_P":0.5,"MPC_XY_VEL_P_ACC":1.2}')}
    # the parameters reach the controller: the same trial flies differently
    paths = {k: r["path_length_m"] for k, r in by.items()}
    assert len(set(paths.values())) == 4, paths


# --- the actuator axis --------------------------------------------------------------------------
ACTUATORS = """\
name = "actuators"
algorithms = ["straight"]
platforms = ["1.00kg-SunnySky"]
scenarios = [{file = "yard.yaml"}]
trials = 1
actuators = [{}, {fail_motor = 3, fail_at_s = 4}]
[limits]
timeout_s = 6.0
"""


def test_actuators_are_an_axis_and_a_failed_motor_ends_the_flight(yard, tmp_path):
    c = load_campaign(campaign_file(yard.parent, "act.toml", ACTUATORS))
    specs = c.trial_specs()
    assert [s.actuators for s in specs] == [None, {"fail_motor": 3, "fail_at_s": 4.0}]
    summary = run_campaign(c, tmp_path / "out", progress=False)
    assert (summary.ran, summary.errors) == (2, [])
    rows = {r["actuators"]: r for r in read_jsonl(tmp_path / "out" / "trials.jsonl")}
    nominal, failed = rows[""], rows['{"fail_at_s":4.0,"fail_motor":3}']
    assert nominal["reason"] != failed["reason"] or \
        failed["saturation_fraction"] > nominal["saturation_fraction"]
    assert failed["saturation_fraction"] > 0.0


def test_the_gains_preset_flies_both_gain_modes_across_the_catalog():
    c = load_campaign("gains")
    specs = c.trial_specs()
    assert c.modes() == ["bandwidth", "px4"] and len(c.platforms) == 36
    assert [s.family for s in c.scenarios] == ["forest", "urban", "random_angle_cylinder"]
    assert len(specs) == len(c.algorithms) * 36 * 3 * 3 * 2
    pairs = {}
    for s in specs:  # each trial in both modes, with one seed
        pairs.setdefault((s.label, s.platform, s.family, s.trial), set()).add((s.gains, s.seed))
    assert all(len(v) == 2 and len({seed for _, seed in v}) == 1 for v in pairs.values())


# --- the perception axis ------------------------------------------------------------------------
def test_latency_delays_what_the_navigator_sees_by_whole_steps():
    p = Perception({"latency_s": 0.1})
    p.start(np.random.default_rng(0))
    seen = []
    for k in range(8):  # a navigator stepping every 40 ms; frames at 0, 80, 160 ms
        t_us = 40_000 * k
        sample = (np.array([k, 0.0, 0.0]), np.zeros(3), 0.0, np.array([1.0, 0, 0, 0]),
                  np.zeros(3))
        (pos, *_), frame = p.pass_through(t_us, sample, f"frame@{t_us}" if k % 2 == 0 else None)
        seen.append((int(pos[0]), frame))
    # 100 ms late, served at the first step at or after: measured at 40 ms (k = 1), it is
    # released at 140 ms and shows at the 160 ms step; before any release, the first one
    assert seen == [(0, None), (0, None), (0, None), (0, "frame@0"), (1, None),
                    (2, "frame@80000"), (3, None), (4, "frame@160000")]


def test_noise_and_dropouts_are_seeded_and_ideal_perception_changes_nothing():
    def run(values, seed):
        p = Perception(values)
        p.start(np.random.default_rng(seed))
        sample = (np.zeros(3), np.zeros(3), 0.0, np.array([1.0, 0, 0, 0]), np.zeros(3))
        out = [p.pass_through(k * 20_000, sample, "f") for k in range(2000)]
        return np.array([o[0][0] for o in out]), [o[1] for o in out]
    pos, frames = run({"position_noise_m": 0.3, "frame_dropout": 0.25}, 1)
    assert pos.std(axis=0) == pytest.approx([0.3] * 3, rel=0.1)
    assert frames.count(None) / len(frames) == pytest.approx(0.25, abs=0.04)
    again, _ = run({"position_noise_m": 0.3, "frame_dropout": 0.25}, 1)
    assert np.array_equal(pos, again)
    ideal, kept = run(None, 1)
    assert not ideal.any() and kept.count(None) == 0 and Perception().ideal


PERCEIVING = """\
name = "perceiving"
algorithms = ["ego"]
platforms = ["0.98kg-EGO Planner DIY"]
scenarios = [{file = "yard.yaml"}]
trials = 1
perception = [{}, {latency_s = 0.3, position_noise_m = 0.2}]
[limits]
timeout_s = 12.0
"""


@pytest.mark.e2e
def test_perception_is_an_axis_that_reruns_and_is_refused_over_mavlink(yard, tmp_path,
                                                                       cli_env):
    c = load_campaign(campaign_file(yard.parent, "perceiving.toml", PERCEIVING))
    specs = c.trial_specs()
    assert [s.perception for s in specs] == [None, {"latency_s": 0.3,
                                                    "position_noise_m": 0.2}]
    assert "perception" not in specs[0].to_dict()
    summary = run_campaign(c, tmp_path / "out", progress=False)
    assert (summary.ran, summary.errors) == (2, [])
    rows = {r["perception"]: r for r in read_jsonl(tmp_path / "out" / "trials.jsonl")}
    late = rows['{"latency_s":0.3,"position_noise_m":0.2}']
    assert late["path_length_m"] != rows[""]["path_length_m"]  # it flew differently
    page = write_report(to_frame(list(rows.values())), tmp_path / "rep", campaign_spec={},
                        meta={})["report.html"].read_text()
    assert 'alt="success_vs_latency"' in page and 'alt="success_vs_wind"' not in page
    proc = run_exe("trial", "rerun", tmp_path / "out", late["trial_id"], env=cli_env)
    assert proc.returncode == 0 and "identical" in proc.stdout, proc.stdout + proc.stderr
    with pytest.raises(CampaignError, match="^--transport mavlink: perception: latency"):
        run_campaign(c, tmp_path / "wire", progress=False,
                     transport=transport("mavlink"))


# --- the estimator axis ------------------------------------------------------------------------
ESTIMATING = """\
name = "estimating"
algorithms = ["straight"]
platforms = ["1.00kg-SunnySky"]
scenarios = [{file = "yard.yaml"}]
trials = 1
[[estimator]]
[[estimator]]
position_bias_m = [0, 0.6, 0]
velocity_latency_s = 0.05
position_noise_m = 0.05
noise_correlation_s = 0.5
[limits]
timeout_s = 6.0
"""


@pytest.mark.e2e
def test_the_estimator_is_an_axis_the_flight_judged_on_the_truth_and_reruns(yard, tmp_path,
                                                                            cli_env):
    c = load_campaign(campaign_file(yard.parent, "estimating.toml", ESTIMATING))
    specs = c.trial_specs()
    assert specs[0].estimator is None and "estimator" not in specs[0].to_dict()
    assert specs[1].estimator == {"position_bias_m": [0.0, 0.6, 0.0], "position_noise_m": 0.05,
                                  "velocity_latency_s": 0.05, "noise_correlation_s": 0.5}
    summary = run_campaign(c, tmp_path / "out", progress=False)
    assert (summary.ran, summary.errors) == (2, [])
    rows = {r["estimator"]: r for r in read_jsonl(tmp_path / "out" / "trials.jsonl")}
    biased = rows[json.dumps(specs[1].estimator, sort_keys=True, separators=(",", ":"))]
    assert biased["path_length_m"] != rows[""]["path_length_m"]  # it flew differently
    assert to_frame(list(rows.values()))["estimator"].tolist().count("") == 1
    proc = run_exe("trial", "rerun", tmp_path / "out", biased["trial_id"], env=cli_env)
    assert proc.returncode == 0 and "identical" in proc.stdout, proc.stdout + proc.stderr


# --- bad axis values ----------------------------------------------------------------------------
@pytest.mark.parametrize("text,message", [
    ("wind = [{speed_m_s = -3}]", "wind[0]: speed_m_s: must be a number 0..40 (m/s), got -3"),
    ("wind = [{}, {speed = 3}]", "wind[1] has no parameter 'speed'; did you mean 'speed_m_s'?"),
    ('wind = {turbulence = "strong"}', "wind: turbulence: must be 'none' or 'light' or 'moderate' "
                                "or 'severe' or 'standard', got 'strong'"),
    ("wind = 5", "wind: must be a table of wind settings or a non-empty list of them, got 5"),
    ("wind = []", "wind: must be a table of wind settings or a non-empty list of them"),
    ("wind = [{speed_m_s = 3}, {speed_m_s = 3.0}]", "wind[1]: the same wind settings twice"),
    ("wind = [{gust_duration_s = 0}]", "wind[0]: gust_duration_s: must be a number 0.05..120 (s)"),
    ('params = {MPC_XY_Q = 1}', "params: unknown parameter 'MPC_XY_Q'; did you mean 'MPC_XY_P'"),
    ('params = {MPC_XY_P = 9}', "params: MPC_XY_P: 9 1/s is outside [0, 2] 1/s"),
    ('params = [{}, {MPC_XY_VEL_MAX = 2}]', "params[1]: MPC_XY_VEL_MAX is set by the trial "
                                            "protocol: use limits.max_speed_m_s instead"),
    ('params = [{FT_GAIN_MODE = 1}]', "params[0]: FT_GAIN_MODE is set by the trial protocol: "
                                      "use gains instead"),
    ('params = [{MPC_XY_P = 1}, {MPC_XY_P = 1.0}]', "params[1]: the same PX4 parameters twice"),
    ('params = {COM_RC_OVERRIDE = 2}', "params: COM_RC_OVERRIDE is a stored PX4 parameter that "
                                      "ft-sitl does not act on, so a trial cannot vary it"),
    ('gains = ["px4", "px4"]', "gains: must be one of 'bandwidth', 'px4'"),
    ('gains = ["px4", "PX4"]', "gains: must be one of 'bandwidth', 'px4'"),
    ('gains = []', "gains: must be one of"),
    ("actuators = {fail_motor = 7}", "actuators: fail_motor: 7 must be within 0..4 (the "
                                     "fewest motors of the campaign's platforms)"),
    ("actuators = [{}, {efficiency = 0}]", "actuators[1]: efficiency: must be a number "
                                           "0.05..1"),
    ("actuators = [{lag = 1}]", "actuators[0] has no parameter 'lag'; did you mean 'lag_s'?"),
    ("perception = {latency_s = 2}", "perception: latency_s: must be a number 0..1 (s), got 2"),
    ("perception = [{delay = 0.1}]", "perception[0] has no parameter 'delay'"),
    ("perception = [{}, {frame_dropout = 1.5}]", "perception[1]: frame_dropout: must be a "
                                                 "number 0..1"),
    ("estimator = {position_latency_s = 1.5}", "estimator: position_latency_s: must be a number "
                                               "0..1 (s), got 1.5"),
    ("estimator = [{}, {position_bias_m = 0.5}]", "estimator[1]: position_bias_m: must be 3 "
                                                  "numbers, each -100..100 (m), got 0.5"),
    ("estimator = [{noise = 0.1}]", "estimator[0] has no parameter 'noise'"),
])
def test_bad_axis_values_are_named_by_file_entry_key_and_range(tmp_path, text, message):
    body = f'algorithms = ["straight"]\nplatforms = ["1.00kg-SunnySky"]\n{text}\n'
    path = campaign_file(tmp_path, "bad.toml", body)
    with pytest.raises(CampaignError) as exc:
        load_campaign(path)
    assert str(exc.value).startswith(f"{path}: {message}"), str(exc.value)


def test_depth_image_noise_replaces_the_navigators_camera_noise(yard):
    from ft_sitl.missions.plan import plan_trial
    from ft_sitl.missions.protocol import trial_vehicle
    from ft_sitl.missions.trial import _Eyes, load_scenario_for
    from ft_sitl.navigation.registry import create

    nav = create("ego", {})
    assert Perception({"latency_s": 0.1}).camera_config(nav.camera) is nav.camera
    clean = TrialSpec(algorithm="ego", platform="1.00kg-SunnySky", family="yard",
                      scenario_file=str(yard))
    noisy = TrialSpec(**{**clean.__dict__, "perception": {"depth_noise_k": 0.004,
                                                          "depth_dropout": 0.1}})
    sc = load_scenario_for(clean)
    _, fleet = trial_vehicle(plan_trial(clean))
    fleet.sim.start_hovering(0, sc.start, sc.start_yaw)
    frames = []
    for spec in (clean, noisy):
        eyes = _Eyes(nav, plan_trial(spec, navigator=nav))
        frames.append(eyes.frame(fleet, 0))
    cfg = eyes.camera.config
    assert (cfg.noise_k, cfg.dropout) == (0.004, 0.1)
    assert (cfg.width, cfg.rate_hz) == (nav.camera.width, nav.camera.rate_hz)
    seen = frames[0].valid
    assert seen.mean() > 0.05  # the yard is in view
    both = seen & frames[1].valid
    assert both.sum() / seen.sum() == pytest.approx(0.9, abs=0.02)  # a tenth dropped
    err = frames[1].depth[both] - frames[0].depth[both]
    z = frames[0].depth[both]
    assert np.std(err / (0.004 * z * z)) == pytest.approx(1.0, abs=0.05)  # sigma = k z^2


# --- the failure-injection axis -----------------------------------------------------------------
FAILING = """\
name = "failing"
algorithms = ["straight"]
platforms = ["1.00kg-SunnySky"]
scenarios = [{file = "yard.yaml"}]
trials = 1
failures = [{}, {at_s = 3, unit = "motor", type = "off", instance = 2}]
[limits]
timeout_s = 6.0
"""


def test_a_failure_axis_injects_failures_at_their_times_and_rows_record_them(yard, tmp_path):
    c = load_campaign(campaign_file(yard.parent, "failing.toml", FAILING))
    specs = c.trial_specs()
    assert [s.failures for s in specs] == [
        None, [{"at_s": 3.0, "unit": "motor", "type": "off", "instance": 2}]]
    assert "failures" not in specs[0].to_dict()
    summary = run_campaign(c, tmp_path / "out", progress=False)
    assert (summary.ran, summary.errors) == (2, [])
    rows = {r["failures"]: r for r in read_jsonl(tmp_path / "out" / "trials.jsonl")}
    failed = rows['[{"at_s":3.0,"instance":2,"type":"off","unit":"motor"}]']
    assert failed["saturation_fraction"] > rows[""]["saturation_fraction"]
    assert failed["reason"] != "success"  # a quadrotor that loses a motor does not arrive
    with pytest.raises(CampaignError, match=r"failures\[1\]: instance: 7 must be within "
                                            r"0\.\.4"):
        load_campaign(campaign_file(yard.parent, "bad.toml", FAILING.replace("instance = 2",
                                                                          "instance = 7")))
    with pytest.raises(CampaignError, match=r"failures\[1\]: unit: must be 'motor' or"):
        load_campaign(campaign_file(yard.parent, "bad2.toml", FAILING.replace('"motor"',
                                                                           '"rotor"')))


# --- the moving-obstacle axis --------------------------------------------------------------------
MOVING = """\
name = "moving"
algorithms = ["straight"]
platforms = ["1.00kg-SunnySky"]
scenarios = [{file = "yard.yaml"}]
trials = 1
[[movers]]
[[movers]]
count = 6
path = "crossing"
crossing_s = [0.5, 2.0]
keep_out_m = 1.0
speed_m_s = 1.0
[limits]
timeout_s = 8.0
"""


@pytest.mark.e2e
def test_movers_are_an_axis_rows_record_them_the_report_plots_them_and_they_rerun(
        yard, tmp_path, cli_env):
    c = load_campaign(campaign_file(yard.parent, "moving.toml", MOVING))
    specs = c.trial_specs()
    assert [s.movers for s in specs] == [None, {"count": 6, "path": "crossing",
                                                "crossing_s": [0.5, 2.0],
                                                "keep_out_m": 1.0, "speed_m_s": 1.0}]
    assert "movers" not in specs[0].to_dict() and specs[0].seed == specs[1].seed
    summary = run_campaign(c, tmp_path / "out", progress=False)
    assert (summary.ran, summary.errors) == (2, [])
    rows = read_jsonl(tmp_path / "out" / "trials.jsonl")
    static, moving = sorted(rows, key=lambda r: r["mover_count"])
    assert (static["mover_count"], static["mover_speed_m_s"], static["movers"]) == (0, 0.0, "")
    assert moving["mover_count"] > 0 and moving["mover_speed_m_s"] == 1.0
    assert json.loads(moving["movers"])["path"] == "crossing"
    page = write_report(to_frame(rows), tmp_path / "rep", campaign_spec={},
                        meta={})["report.html"].read_text()
    assert 'alt="success_vs_movers"' in page and 'alt="success_vs_mover_speed"' in page
    proc = run_exe("trial", "rerun", tmp_path / "out", moving["trial_id"], env=cli_env)
    assert proc.returncode == 0 and "identical" in proc.stdout, proc.stdout + proc.stderr


@pytest.mark.parametrize("text, message", [
    ("movers = {count = 100}", "movers: count: must be an integer 0..64"),
    ("movers = [{}, {speed = 2}]", "movers[1] has no parameter 'speed'"),
    ("movers = [{count = 2}, {count = 2}]", "movers[1]: the same mover settings twice"),
    ("movers = {count = 2, density_per_1000m2 = 1}", "movers: give count or "
                                                     "density_per_1000m2, not both"),
])
def test_bad_mover_axis_values_are_named(tmp_path, text, message):
    body = f'algorithms = ["straight"]\nplatforms = ["1.00kg-SunnySky"]\n{text}\n'
    path = campaign_file(tmp_path, "bad.toml", body)
    with pytest.raises(CampaignError) as exc:
        load_campaign(path)
    assert str(exc.value).startswith(f"{path}: {message}"), str(exc.value)


def test_every_algorithm_and_platform_meets_the_same_movers_in_trial_k():
    """Movers are scenario content: the placement follows the configuration and the trial
    number, not the algorithm, the platform or the campaign's seed (a paired comparison)."""
    from ft_sitl.missions.resources import RESOURCES

    def movers(**kw):
        spec = TrialSpec(**{"algorithm": "straight", "platform": "1.00kg-SunnySky",
                            "family": "forest", "scenario_index": 2, "trial": 1, "seed": 5,
                            "movers": {"count": 5}, **kw})
        return RESOURCES.scenario(spec).movers.poses(3_000_000)

    same = movers()
    for kw in ({"algorithm": "ego"}, {"platform": "0.98kg-EGO Planner DIY"}, {"seed": 99},
               {"label": "other"}):
        assert np.array_equal(movers(**kw), same), kw
    for kw in ({"trial": 2}, {"scenario_index": 3}, {"scenario_seed": 1}):
        other = movers(**kw)
        assert other.shape != same.shape or not np.array_equal(other, same), kw
