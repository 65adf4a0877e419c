"""NavRL: the checkpoint reader, the numpy policy, the lidar, the ORCA shield, the navigator's
deployment logic and real trials with the authors' released weights."""

import dataclasses
import json
import math
import os
import pickle
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import trimesh
from scipy.signal import correlate

from ft_sitl.autopilot.cascade import SP_POS, SP_VEL, SP_YAW
from ft_sitl.cli.missions import differences
from ft_sitl.missions.campaign_file import load_campaign
from ft_sitl.missions.plan import navigator_params
from ft_sitl.missions.trial import TrialSpec, run_trial
from ft_sitl.navigation.base import Limits, Observation, ObstacleStates, Task
from ft_sitl.navigation.learned.navrl import (
    ENV_VAR,
    NavRL,
    cast_lidar,
    cluster_spheres,
    dbscan,
    dynamic_obstacle_input,
    dynamic_spheres,
    goal_frame,
    lidar_directions,
    obstacle_in_range,
    orca_plane,
    safe_velocity,
    shield,
)
from ft_sitl.navigation.learned.navrl_policy import (
    EXPECTED_SHAPES,
    CheckpointError,
    NavRLPolicy,
    _conv2d,
    load_checkpoint,
)
from ft_sitl.navigation.registry import NavigatorError, create
from ft_sitl.scenarios.camera import DepthCamera
from ft_sitl.scenarios.movers import movers_from_list

AGILE = "0.98kg-EGO Planner DIY"
REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def weights(navrl_checkpoint):
    return load_checkpoint(navrl_checkpoint)


@pytest.fixture(scope="module")
def policy(weights):
    return NavRLPolicy(weights)


@pytest.fixture
def with_checkpoint(navrl_checkpoint, monkeypatch, tmp_path):
    monkeypatch.setenv(ENV_VAR, str(navrl_checkpoint))
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "data"))
    return navrl_checkpoint


@pytest.fixture
def without_checkpoint(monkeypatch, tmp_path):
    monkeypatch.delenv(ENV_VAR, raising=False)
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "empty"))


# --- the checkpoint reader -------------------------------------------------------------------

def test_released_checkpoint_loads_with_the_architecture_shapes(weights):
    for name, shape in EXPECTED_SHAPES.items():
        assert weights[name].shape == shape, name
        assert weights[name].dtype == np.float32
        assert np.all(np.isfinite(weights[name]))
    # the critic and value normaliser are in the file too (not used for acting)
    assert weights["critic.module.weight"].shape == (1, 256)
    # trained weights, not an initialisation: the conv kernels are not all equal
    assert np.std(weights["feature_extractor.module.0.module.0.weight"]) > 1e-3


def _rewrite(src: Path, dst: Path, change) -> Path:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for info in zin.infolist():
            data = change(info.filename, zin.read(info.filename))
            if data is not None:
                zout.writestr(info.filename, data)
    return dst


def test_checkpoint_errors_name_the_problem(navrl_checkpoint, tmp_path):
    with pytest.raises(CheckpointError, match="no such file"):
        load_checkpoint(tmp_path / "missing.pt")
    junk = tmp_path / "junk.pt"
    junk.write_bytes(b"not a zip at all")
    with pytest.raises(CheckpointError, match="not a PyTorch zip checkpoint"):
        load_checkpoint(junk)
    gone = _rewrite(navrl_checkpoint, tmp_path / "gone.pt",
                    lambda n, d: None if n.endswith("/data/6") else d)
    with pytest.raises(CheckpointError, match="data/6 is missing"):
        load_checkpoint(gone)
    short = _rewrite(navrl_checkpoint, tmp_path / "short.pt",
                     lambda n, d: d[:-4] if n.endswith("/data/7") else d)
    with pytest.raises(CheckpointError, match=r"data/7: 508 bytes, expected 128 x 4"):
        load_checkpoint(short)


def test_checkpoint_with_code_is_refused_without_running_it(navrl_checkpoint, tmp_path):
    marker = tmp_path / "ran"
    evil = pickle.dumps(_Evil(str(marker)), protocol=2)
    bad = _rewrite(navrl_checkpoint, tmp_path / "evil.pt",
                   lambda n, d: evil if n.endswith("data.pkl") else d)
    with pytest.raises(CheckpointError, match=r"refers to (posix|os)\.system"):
        load_checkpoint(bad)
    assert not marker.exists()


class _Evil:
    def __init__(self, path):
        self.path = path

    def __reduce__(self):
        return (os.system, (f"touch {self.path}",))


def test_policy_refuses_other_architectures(weights):
    w = dict(weights)
    w["actor.module.0.module.alpha_layer.weight"] = np.zeros((2, 256), np.float32)
    with pytest.raises(CheckpointError, match=r"alpha_layer.weight has shape \(2, 256\)"):
        NavRLPolicy(w, source="x.pt")
    w = {k: v for k, v in weights.items() if "module.3.module.3" not in k}
    with pytest.raises(CheckpointError, match="not a NavRL policy: missing"):
        NavRLPolicy(w)
    w = dict(weights)
    w["feature_extractor.module.0.module.7.bias"] = np.full(128, np.nan, np.float32)
    with pytest.raises(CheckpointError, match="module.7.bias holds non-finite"):
        NavRLPolicy(w)


# --- the numpy forward pass --------------------------------------------------------------------

def test_conv_matches_scipy_with_stride_and_padding():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(4, 36, 4))
    w = rng.normal(size=(16, 4, 5, 3))
    b = rng.normal(size=16)
    out = _conv2d(x, w, b, (2, 1), (2, 1))
    xp = np.pad(x, ((0, 0), (2, 2), (1, 1)))
    ref = np.stack([correlate(xp, w[o], mode="valid")[0] for o in range(16)]) + b[:, None, None]
    np.testing.assert_allclose(out, ref[:, ::2, ::1], atol=1e-12)
    assert _conv2d(out, rng.normal(size=(16, 16, 5, 3)), b, (2, 2), (2, 1)).shape == (16, 9, 2)


def _lidar(beams, dist):
    deficit = np.zeros((36, 4))
    deficit[beams, :] = 4.0 - dist
    return deficit


def test_released_policy_steers_away_from_the_obstacle_side(policy):
    state = np.array([1.0, 0.0, 0.0, 20.0, 0.0, 1.0, 0.0, 0.0])
    zeros = np.zeros((5, 10))
    for dist in (0.8, 1.5, 2.5):
        left = policy.mean_action(state, _lidar([1, 2, 3], dist), zeros)
        right = policy.mean_action(state, _lidar([33, 34, 35], dist), zeros)
        # goal frame: y points left; the mean 0.5 is no lateral velocity
        assert left[1] < 0.45 < 0.55 < right[1], (dist, left, right)
        assert np.all((left > 0) & (left < 1)) and np.all((right > 0) & (right < 1))
    with pytest.raises(ValueError, match="lidar: 10 values, the policy takes 144"):
        policy.mean_action(state, np.zeros(10), zeros)


# --- lidar and goal frame ---------------------------------------------------------------------

def test_goal_frame_and_lidar_geometry():
    f = goal_frame([0.0, 3.0, 1.0])  # north, the vertical part ignored
    np.testing.assert_allclose(f, [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-12)
    d = lidar_directions(math.pi / 2)
    assert d.shape == (36, 4, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0)
    np.testing.assert_allclose(d[0, 1], [0, 1, 0], atol=1e-12)  # beam 0 at the goal, 0 deg
    np.testing.assert_allclose(d[9, 1], [-1, 0, 0], atol=1e-12)  # 90 deg counter-clockwise
    assert math.degrees(math.asin(d[0, 0, 2])) == pytest.approx(-10.0)
    assert math.degrees(math.asin(d[0, 3, 2])) == pytest.approx(20.0)


def test_cast_lidar_finds_a_wall_and_reports_range_otherwise():
    def wall(points):  # a wall 2 m east of the vehicle
        return points[..., 0] >= 2.0

    pos = np.array([0.0, 0.0, 1.5])
    dist = cast_lidar(wall, pos, lidar_directions(0.0))
    assert dist[0, 1] == pytest.approx(2.0, abs=0.05)
    assert dist[3, 1] == pytest.approx(2.0 / math.cos(math.radians(30)), abs=0.06)
    assert dist[18, 1] == 4.0  # looking west: nothing within range
    assert obstacle_in_range(4.0 - dist)
    assert not obstacle_in_range(4.0 - cast_lidar(lambda p: p[..., 0] >= 3.9, pos,
                                                  lidar_directions(0.0)))
    # only the -10 deg row sees something: not "in range" (the original ignores that row)
    low = np.zeros((36, 4))
    low[0, 0] = 2.0
    assert not obstacle_in_range(low)


# --- the shield ---------------------------------------------------------------------------

def test_dbscan_groups_near_points_and_drops_noise():
    pts = np.array([[0, 0, 0], [0.15, 0, 0], [0.3, 0, 0],  # a chain: one cluster
                    [5, 5, 0], [5, 5.1, 0],  # a pair
                    [9, 9, 9]], dtype=float)  # noise
    clusters = dbscan(pts)
    assert sorted(map(list, clusters)) == [[0, 1, 2], [3, 4]]
    spheres = cluster_spheres(pts, np.array([-1.0, 0.0, 0.0]))
    centre, radius = spheres[0]
    assert radius == pytest.approx(1.5 * 0.15)
    np.testing.assert_allclose(centre, [0.15 + 0.15, 0, 0])  # pushed away from the vehicle


def test_the_shield_clusters_hits_as_the_deployment_does_and_older_protocols_keep_0_2_m():
    # safeAction.cpp: DBSCAN(2, 0.2) on the *squared* distance: neighbours within 0.447 m
    pair = np.array([[2.0, 0.0, 1.0], [2.0, 0.3, 1.0]])
    pos = np.zeros(3)
    assert [list(c) for c in dbscan(pair)] == [[0, 1]]
    assert cluster_spheres(pair, pos)[0][1] == pytest.approx(1.5 * 0.15)
    assert dbscan(pair, 0.2) == [] and cluster_spheres(pair, pos, 0.2) == []  # both noise
    assert dbscan(np.array([[0.0, 0, 0], [math.sqrt(0.2) - 1e-9, 0, 0]])) != []
    # the navigator's parameter; a trial of protocol 7 or older pins what its rows flew
    from ft_sitl.missions.plan import navigator_params
    from ft_sitl.missions.spec import TrialSpec

    spec = TrialSpec("navrl", "0.98kg-EGO Planner DIY", "forest")
    assert spec.protocol >= 8 and "shield_cluster_radius_m" not in navigator_params(spec)
    old = dataclasses.replace(spec, protocol=7)
    assert navigator_params(old)["shield_cluster_radius_m"] == 0.2
    mine = dataclasses.replace(old, algorithm_params={"shield_cluster_radius_m": 0.3})
    assert navigator_params(mine)["shield_cluster_radius_m"] == 0.3  # the spec's wins


def test_dbscan_finds_random_separated_clusters_in_input_order():
    rng = np.random.default_rng(5)
    blobs, pts = [], []
    for c in range(6):  # chains of 2..9 points 0.15 m apart, blobs >= 2 m apart
        start = np.array([3.0 * c, rng.uniform(-1, 1), rng.uniform(0, 2)])
        step = rng.normal(size=3)
        step *= 0.15 / np.linalg.norm(step)
        blobs.append([start + i * step for i in range(int(rng.integers(2, 10)))])
    noise = [np.array([3.0 * c + 1.5, 5.0, 5.0]) for c in range(4)]
    pts = [p for b in blobs for p in b] + noise
    order = rng.permutation(len(pts))
    shuffled = np.array(pts)[order]
    label_of = np.empty(len(pts), int)  # original index -> blob (-1 noise)
    i = 0
    for k, b in enumerate(blobs):
        label_of[i:i + len(b)] = k
        i += len(b)
    label_of[i:] = -1
    clusters = dbscan(shuffled)
    assert len(clusters) == len(blobs)
    seen = set()
    for members in clusters:
        assert list(members) == sorted(members)
        blob = {int(label_of[order[m]]) for m in members}
        assert len(blob) == 1 and -1 not in blob
        assert len(members) == len(blobs[blob.pop()])
        seen.update(int(m) for m in members)
    # numbered by their lowest member; noise left out
    assert [int(c[0]) for c in clusters] == sorted(int(c[0]) for c in clusters)
    assert len(seen) == len(pts) - len(noise)
    assert dbscan(np.zeros((0, 3))) == []


def test_orca_shield_turns_a_colliding_command_and_keeps_a_safe_one():
    pos = np.zeros(3)
    obstacle = (np.array([2.0, 0.0, 0.0]), 0.5)
    toward = np.array([1.0, 0.0, 0.0])
    point, normal, in_vo = orca_plane(pos, toward, 0.0, obstacle[0], np.zeros(3), obstacle[1])
    assert in_vo
    v = safe_velocity(toward, [(point, normal, in_vo)], math.sqrt(3.0))
    assert (v - point) @ normal >= -1e-6
    assert abs(v[1]) + abs(v[2]) > 0.1 or v[0] < 0.8  # it deviates or slows down
    # the new velocity stays clear of the sphere for the 2 s horizon
    t = np.linspace(0.0, 2.0, 201)
    assert np.min(np.linalg.norm(t[:, None] * v - obstacle[0], axis=1)) >= obstacle[1] - 1e-3
    away = np.array([-1.0, 0.0, 0.0])
    assert not orca_plane(pos, away, 0.0, obstacle[0], np.zeros(3), obstacle[1])[2]


def test_shield_uses_ray_hits_and_leaves_free_commands_alone():
    pos = np.array([0.0, 0.0, 1.5])
    rays = lidar_directions(0.0)
    free = (pos + rays * 4.0).reshape(-1, 3)  # every ray at range: no cluster
    cmd = np.array([1.0, 0.0, 0.0])
    out, solved = shield(pos, cmd, free, math.sqrt(3.0))
    assert not solved and np.array_equal(out, cmd)
    dist = cast_lidar(lambda p: p[..., 0] >= 0.8, pos, rays)  # a wall 0.8 m ahead
    hits = (pos + rays * dist[..., None]).reshape(-1, 3)
    out, solved = shield(pos, cmd, hits, math.sqrt(3.0))
    assert solved and np.linalg.norm(out - cmd) > 0.2  # the command was changed


def test_infeasible_constraints_give_the_least_violating_velocity():
    planes = [(np.array([1.0, 0, 0]), np.array([1.0, 0, 0]), True),
              (np.array([-1.0, 0, 0]), np.array([-1.0, 0, 0]), True)]  # v_x >= 1 and <= -1
    v = safe_velocity(np.array([0.3, 0.0, 0.0]), planes, 2.0)
    assert np.all(np.isfinite(v)) and abs(v[0]) < 1e-3 and np.linalg.norm(v) <= 2.0 + 1e-6


# --- the navigator ----------------------------------------------------------------------------

def _task(start_yaw=0.0):
    return Task(start=np.array([0.0, 0.0, 1.5]), start_yaw=start_yaw,
                goal=np.array([30.0, 0.0, 1.5]), limits=Limits(),
                bounds_min=np.array([-5.0, -10.0, 0.0]), bounds_max=np.array([35.0, 10.0, 4.0]),
                collision_radius_m=0.3, twr_max=3.0, alpha_xy_max=100.0, alpha_z_max=10.0)


def _obs(t, yaw, pos=(0.0, 0.0, 1.5), vel=(0.0, 0.0, 0.0)):
    return Observation(time_s=t, position=np.array(pos), velocity=np.array(vel), yaw=yaw,
                       attitude=np.array([1.0, 0, 0, 0]), angular_velocity=np.zeros(3))


def test_navigator_turns_first_waits_then_flies_at_the_limit(with_checkpoint):
    nav = NavRL(latency_s=0.0)
    nav.reset(_task(start_yaw=math.pi))
    sp = nav.step(_obs(0.0, yaw=math.pi))
    assert sp.row[SP_YAW] == pytest.approx(0.0)  # turn toward the goal, in place
    np.testing.assert_allclose(sp.row[SP_POS:SP_POS + 3], [0, 0, 1.5])
    turned = nav.step(_obs(0.05, yaw=0.0))  # aligned: ten control periods of waiting
    assert turned is sp
    t = 0.05
    for _ in range(10):
        t += 0.05
        out = nav.step(_obs(t, yaw=0.0))
    assert math.isnan(out.row[SP_POS]) and out.row[SP_POS + 2] == pytest.approx(1.5)
    np.testing.assert_allclose(out.row[SP_VEL:SP_VEL + 2], [1.0, 0.0], atol=1e-9)
    near = nav.step(_obs(t + 0.05, yaw=0.0, pos=(28.0, 0.0, 1.5)))  # within 3 m: 0.5 m/s
    np.testing.assert_allclose(near.row[SP_VEL:SP_VEL + 2], [0.5, 0.0], atol=1e-9)


def test_navigator_latency_delays_the_command(with_checkpoint):
    nav = NavRL(latency_s=0.03)
    nav.reset(_task(start_yaw=math.pi))
    first = nav.step(_obs(0.0, yaw=math.pi))
    assert first.row[SP_YAW] == pytest.approx(math.pi)  # still holding the start
    assert nav.step(_obs(0.02, yaw=math.pi)).row[SP_YAW] == pytest.approx(math.pi)
    assert nav.step(_obs(0.03, yaw=math.pi)).row[SP_YAW] == pytest.approx(0.0)


def test_without_checkpoint_navrl_is_refused_by_name_and_left_out_of_all(without_checkpoint):
    with pytest.raises(NavigatorError, match=f"navrl.*{ENV_VAR}"):
        create("navrl")
    with pytest.raises(NavigatorError, match="checkpoint: /nope.pt: no such file"):
        create("navrl", {"checkpoint": "/nope.pt"})
    c = load_campaign("quick")
    assert "navrl" not in [a.name for a in c.algorithms]
    assert any("navrl" in n and ENV_VAR in n for n in c.notes)


@pytest.mark.e2e  # the ft-sitl script
def test_install_command_makes_navrl_available(without_checkpoint, navrl_checkpoint, tmp_path):
    env = dict(os.environ)
    cli = [str(Path(sys.executable).parent / "ft-sitl")]
    bad = subprocess.run(cli + ["navigators", "install", "navrl", str(tmp_path / "x.pt")],
                         env=env, capture_output=True, text=True)
    assert bad.returncode == 2 and "x.pt: no such file" in bad.stderr
    ok = subprocess.run(cli + ["navigators", "install", "navrl", str(navrl_checkpoint)],
                        env=env, capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    installed = Path(env["XDG_DATA_HOME"]) / "ft-sitl" / "navrl" / "navrl_checkpoint.pt"
    assert installed.read_bytes() == navrl_checkpoint.read_bytes()
    assert "navrl" in [a.name for a in load_campaign("paper").algorithms]


@pytest.mark.slow  # a trial
def test_real_forest_trial_succeeds_near_one_metre_per_second(with_checkpoint):
    row = run_trial(TrialSpec(algorithm="navrl", platform=AGILE, family="forest",
                              scenario_index=1)).row
    assert row["reason"] == "success", row["detail"]
    assert 0.7 < row["mean_speed_m_s"] < 1.1  # the deployment's 1 m/s cap, not 4 m/s
    assert row["planner_calls"] > 0 and row["min_clearance_m"] > 0.0


@pytest.mark.e2e  # campaign and rerun in children
def test_rerun_by_the_command_matches_the_worker_row_bit_for_bit(navrl_checkpoint, tmp_path):
    """A NavRL trial flown by a campaign worker (one BLAS thread) and again by `ft-sitl trial
    rerun` started with no BLAS thread variables: the same row to the last bit. (With a
    multi-threaded BLAS this trial's path and energy differed in the last bits.)"""
    exe = Path(sys.executable).parent / "ft-sitl"
    env = {k: v for k, v in os.environ.items()
           if k not in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
    env["FT_SITL_NAVRL_CHECKPOINT"] = str(navrl_checkpoint)
    camp = tmp_path / "c.toml"
    camp.write_text('name = "blas"\nalgorithms = ["navrl"]\nplatforms = ["4.20kg-UAV 13"]\n'
                    'scenarios = ["random_angle_cylinder"]\nindices = [1]\ntrials = 1\n'
                    'seed = 0\n')
    out = tmp_path / "o"
    run = subprocess.run([str(exe), "campaign", "run", str(camp), "--out", str(out),
                          "--workers", "2", "--quiet", "--no-report"], env=env,
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    row = json.loads((out / "trials.jsonl").read_text().splitlines()[0])
    assert row["nav_time_s"] > 20.0, row["detail"]  # a long policy flight
    rerun = subprocess.run([str(exe), "trial", "rerun", str(out), row["trial_id"]], env=env,
                           capture_output=True, text=True, timeout=600)
    assert rerun.returncode == 0, rerun.stderr
    assert "identical to the stored result" in rerun.stdout, rerun.stdout


# --- moving obstacles ------------------------------------------------------------------------

def test_dynamic_input_is_the_deployments_encoding():
    """The released deployment's rows (navigation.py, get_action): unit vector to the
    obstacle and its horizontal and vertical distance in the goal frame (vertical zeroed
    for one taller than 1 m), its velocity in the goal frame, width category
    ceil((max(x, y size) + 0.6) / 0.25) - 1 in 0..3, 1 if at most 1 m tall; a row of an
    obstacle without height keeps only its velocity; the first 5 only."""
    frame = goal_frame([0.0, 5.0, 0.0])  # goal due north: x_g north, y_g west
    pos = np.array([1.0, 2.0, 1.5])
    obstacles = ObstacleStates(
        position=np.array([[1.0, 5.0, 0.9], [3.0, 2.0, 2.0], [0.0, 0.0, 1.0]]
                          + [[9.0, 9.0, 1.0]] * 3),
        velocity=np.array([[1.0, 0.0, 0.0], [0.0, -0.5, 0.0], [0.2, 0.3, 0.0]]
                          + [[0.0, 0.0, 0.0]] * 3),
        size=np.array([[0.6, 0.6, 1.8], [0.1, 0.05, 0.3], [0.5, 0.5, 0.0]]
                      + [[1.0, 1.0, 1.0]] * 3))
    got = dynamic_obstacle_input(obstacles, pos, frame)
    n = math.hypot(2.0, 0.5)
    want = np.zeros((5, 10))
    want[0] = [1, 0, 0, 3, 0, 0, -1, 0, 3, 0]  # a person 3 m ahead, walking east
    want[1] = [0, -2 / n, 0.5 / n, 2, 0.5, -0.5, 0, 0, 2, 1]  # a small ball to the east
    want[2] = [0, 0, 0, 0, 0, 0.3, -0.2, 0, 0, 0]  # no height: only its velocity
    want[3] = want[4] = 0.0
    np.testing.assert_allclose(got[:3], want[:3], atol=1e-12)
    assert got.shape == (5, 10) and np.all(got[3:, 8] == 3) and np.all(got[3:, 9] == 1)
    assert not dynamic_obstacle_input(ObstacleStates.empty(), pos, frame).any()


def test_shield_keeps_clear_of_a_moving_obstacle_coming_at_the_vehicle():
    person = ObstacleStates(np.array([[2.0, 0.0, 0.9]]), np.array([[-1.0, 0.0, 0.0]]),
                            np.array([[0.6, 0.6, 1.8]]))
    spheres = dynamic_spheres(person)  # three stacked, a side (0.6 m) apart
    np.testing.assert_allclose([c[2] for c, _, _ in spheres], [0.3, 0.9, 1.5])
    assert all(r == pytest.approx(0.3 * math.sqrt(2)) for _, _, r in spheres)
    pos, want, none = np.array([0.0, 0.0, 1.5]), np.array([1.0, 0.0, 0.0]), np.zeros((0, 3))
    v, solved = shield(pos, want, none, 2.0, 0.0, person, 0.6)
    assert solved and abs(v[1]) > 0.3  # sideways out of its way
    away = ObstacleStates(person.position, -1.5 * person.velocity, person.size)
    v, solved = shield(pos, want, none, 2.0, 0.0, away, 0.6)  # faster away than we close
    assert not solved and np.array_equal(v, want)


def _hover_beside_a_crossing_person(mode: str):
    """NavRL (the released policy, ``dynamic_obstacles`` = mode) hovering at the start,
    turned toward the goal, while a person walks across 3 m ahead and out of the view;
    steps at 100 Hz, the benchmark camera at 30 Hz. Returns the navigator and its dynamic
    input at every control period once settled (time, input, the truth's centre)."""
    nav = NavRL(latency_s=0.0, dynamic_obstacles=mode)
    nav.reset(_task())
    far = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    far.apply_translation((-60.0, 0.0, 1.0))  # never seen
    cam = DepthCamera(nav.camera, far)
    person = movers_from_list([{"shape": "person", "radius_m": 0.3, "height_m": 1.8,
                                "points": [[3.0, -4.5], [3.0, 5.0]], "speed_m_s": 1.2}])
    inputs = []
    next_frame_us = 0
    for k in range(650):  # 6.5 s
        t_us = k * 10_000
        frame = None
        if t_us >= next_frame_us:
            frame = cam.capture(t_us, [0.0, 0.0, 1.5], [1.0, 0, 0, 0], movers=person,
                                movers_time_us=t_us)
            next_frame_us += round(nav.camera.period_us)
        centre, vel, size = person.boxes(t_us)
        obs = Observation(time_s=t_us * 1e-6, position=np.array([0.0, 0.0, 1.5]),
                          velocity=np.zeros(3), yaw=0.0, attitude=np.array([1.0, 0, 0, 0]),
                          angular_velocity=np.zeros(3), depth=frame,
                          movers=ObstacleStates(centre, vel, size))
        nav.step(obs)
        if k % 5 == 0 and nav.settled > 10:
            inputs.append((t_us * 1e-6, nav.dynamic.copy(), centre[0]))
    return nav, inputs


@pytest.mark.slow  # trials
def test_tracked_and_true_moving_obstacles_give_the_policy_similar_inputs(with_checkpoint):
    """A person crossing 3 m ahead in plain view: once the tracker has followed it for
    0.7 s, the policy's dynamic input from the tracker matches the one from the ground
    truth (direction within 8 deg, distance within 0.35 m, velocity within 0.4 m/s, the
    same size categories); with "off" the input stays zero. The map of "tracked" and
    "truth" keeps nothing of the person once it has gone; the plain map ("off") keeps part
    of its trail (a hovering camera: docs/planners.md, "Moving obstacles")."""
    runs = {m: _hover_beside_a_crossing_person(m) for m in ("truth", "tracked", "off")}
    truth, tracked = runs["truth"][1], runs["tracked"][1]
    assert [t for t, _, _ in truth] == [t for t, _, _ in tracked]
    rows = [(a[0], b[0]) for (_, a, c), (_, b, _) in zip(truth, tracked)
            if abs(c[1]) < 2.0]  # within 4 m and fully in view
    near = [(a, b) for a, b in rows if b.any()]
    assert len(near) > 0.8 * len(rows) > 40
    for a, b in near[14:]:  # 0.7 s of tracking
        assert math.degrees(math.acos(np.clip(a[:3] @ b[:3], -1, 1))) < 8.0
        assert abs(a[3] - b[3]) < 0.35 and a[4] == b[4] == 0.0  # a tall one: level
        assert np.linalg.norm(a[5:8] - b[5:8]) < 0.4
        assert tuple(a[8:]) == tuple(b[8:]) == (3.0, 0.0)
    assert runs["truth"][0].dynamic_steps > 40 and runs["tracked"][0].dynamic_steps > 40
    off = runs["off"][0]
    assert off.dynamic_steps == 0 and not any(d.any() for _, d, _ in runs["off"][1])
    assert not off.free_history and off.tracker is None
    walked = np.array([[x, y, z] for x in (2.75, 2.85, 2.95) for y in np.arange(-2.0, 2.0, 0.1)
                       for z in np.arange(0.15, 1.8, 0.1)])
    assert off.map.occupied(walked).sum() > 20
    for mode in ("truth", "tracked"):
        assert runs[mode][0].map.occupied_count == 0, mode


def test_truth_needs_the_ground_truth_in_the_observation(with_checkpoint):
    nav = NavRL(dynamic_obstacles="truth")
    assert nav.needs_mover_truth and not NavRL().needs_mover_truth
    nav.reset(_task())
    with pytest.raises(ValueError, match="only the in-process trial driver"):
        nav.step(_obs(0.0, yaw=0.0))
    nav.step(Observation(**{**_obs(0.0, yaw=0.0).__dict__, "movers": ObstacleStates.empty()}))


@pytest.mark.slow  # three trials
@pytest.mark.parametrize("mode", ["tracked", "truth", "off"])
def test_trial_with_movers_ends_by_the_protocol_with_each_option(with_checkpoint, mode):
    """A short Maze trial among 40 walking people: every option flies to a protocol
    outcome; "tracked" and "truth" feed the policy moving obstacles, "off" none."""
    spec = TrialSpec(algorithm="navrl", platform=AGILE, family="maze", scenario_index=1,
                     algorithm_params={"dynamic_obstacles": mode}, limits=Limits(timeout_s=6.0),
                     movers={"count": 40, "keep_out_m": 2.0, "speed_m_s": 1.0, "path": "line",
                             "path_length_m": [4, 8]})
    nav = create("navrl", {"dynamic_obstacles": mode})
    row = run_trial(spec, navigator=nav).row
    assert row["reason"] in {"success", "timeout", "collision", "mover_collision"}, row["detail"]
    assert row["mover_count"] == 40 and row["planner_calls"] > 0
    assert (nav.dynamic_steps > 20) == (mode != "off")


#: rows made under the instruction-set pins (x86-64-v3: they re-run on any processor with
#: AVX2 and FMA; docs/results/README.md)
V6 = REPO / "docs" / "results" / "paper-pinned-sample" / "trials.parquet"
#: a stored protocol-6 NavRL trial (Maze 6, 3.50kg-SunnySky: a collision after 3.5 s of
#: navigation)
V6_TRIAL = "c83b28442a7a0881"


def _stored(trial_id: str) -> tuple[TrialSpec, dict]:
    df = pd.read_parquet(V6)
    stored = df[df.trial_id == trial_id].iloc[0].to_dict()
    return TrialSpec.from_dict(json.loads(stored["spec"])), stored


@pytest.mark.slow  # a Maze trial
def test_rows_of_earlier_protocols_fly_as_they_were_stored(with_checkpoint):
    """Before protocol 7 NavRL saw no moving obstacles: its trials fly with
    dynamic_obstacles = "off" (pinned by their protocol) and give the stored row bit for
    bit."""
    spec, stored = _stored(V6_TRIAL)
    assert json.loads(stored["software"])["isa"] == "x86-64-v3"
    assert spec.protocol == 6 and "dynamic_obstacles" not in spec.algorithm_params
    assert navigator_params(spec)["dynamic_obstacles"] == "off"
    assert differences(run_trial(spec).row, stored) == []


@pytest.mark.slow  # two trials
def test_in_a_static_world_the_detector_changes_nothing(with_checkpoint):
    """The same trial under protocol 7 ("tracked" by default): in a static world the
    detector reports nothing, so the flight and its row are those of "off"."""
    spec, _ = _stored(V6_TRIAL)
    spec = dataclasses.replace(spec, protocol=7)
    assert "dynamic_obstacles" not in navigator_params(spec)
    nav = create("navrl", navigator_params(spec))
    assert nav.dynamic_mode == "tracked"
    tracked = run_trial(spec, navigator=nav).row
    off = run_trial(dataclasses.replace(
        spec, algorithm_params={"dynamic_obstacles": "off"})).row
    keys = [k for k in tracked if k not in ("trial_id", "algorithm_params", "spec",
                                             "wall_time_s", "planner_time_s", "finished_utc")]
    assert {k: tracked[k] for k in keys} == {k: off[k] for k in keys}
    assert nav.tracker.frames > 50 and nav.dynamic_steps == 0
