"""The learned navigator: its policy file, that it sees what the policy saw in training
(the gym's observation, built by the same functions), and that it flies a trial without
the training stack."""

from __future__ import annotations

import dataclasses
import json
import math
import sys

import numpy as np
import pytest

from ft_sitl.autopilot.cascade import SP_POS, SP_VEL, SP_YAW
from ft_sitl.gym.batch import platform_vector
from ft_sitl.gym.envs import NavigateEnv
from ft_sitl.missions.spec import PROTOCOL_VERSION, PROTOCOLS, vehicle_half_span_m
from ft_sitl.missions.trial import TrialSpec, run_trial
from ft_sitl.navigation.base import Limits, Observation, Task
from ft_sitl.navigation.learned.learned import Learned, load_policy, shipped
from ft_sitl.navigation.learned.policy_io import (
    N_STATE,
    MlpPolicy,
    PolicyFileError,
    policy_input,
)
from ft_sitl.navigation.registry import NavigatorError, create
from ft_sitl.physics import dynamics as d
from ft_sitl.physics.catalog import get_platform
from tests.gym.gymutil import SMALL

AGILE = "0.98kg-EGO Planner DIY"


def _policy(rng, n_in=N_STATE + 12 + 144, meta=None):
    layers = [(rng.normal(size=(16, n_in)), rng.normal(size=16)),
              (rng.normal(size=(4, 16)), rng.normal(size=4))]
    m = dict(load_policy().meta) if meta is None else meta
    return MlpPolicy(layers, "tanh", m)


def test_a_policy_file_round_trips_and_acts_as_its_layers(tmp_path):
    rng = np.random.default_rng(0)
    p = _policy(rng)
    path = tmp_path / "p.npz"
    p.save(path)
    q = MlpPolicy.load(path)
    x = rng.normal(size=(5, p.input_size))
    (w0, b0), (w1, b1) = q.layers
    expected = np.clip(np.tanh(x @ w0.T + b0) @ w1.T + b1, -1, 1)
    np.testing.assert_allclose(q.act(x), expected, rtol=1e-12)
    assert q.meta["control_hz"] == p.meta["control_hz"] and q.meta["format"] == 1
    with pytest.raises(ValueError, match=r"policy input: shape \(N, 175\)"):
        q.act(np.zeros((1, 3)))


def test_bad_policy_files_are_refused_by_name(tmp_path):
    rng = np.random.default_rng(1)
    with pytest.raises(NavigatorError, match="policy '/nope.npz': neither a shipped policy"):
        create("learned", {"policy": "/nope.npz"})
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"not a zip")
    with pytest.raises(NavigatorError, match="junk.npz: not a policy file"):
        create("learned", {"policy": str(junk)})
    wrong_rays = tmp_path / "rays.npz"
    _policy(rng, n_in=N_STATE + 12 + 10).save(wrong_rays)
    with pytest.raises(NavigatorError, match="maps 41 inputs to 4 outputs.*36 x 4 rays maps 175"):
        create("learned", {"policy": str(wrong_rays)})
    bare = tmp_path / "bare.npz"
    _policy(rng, meta={"x": 1}).save(bare)
    with pytest.raises(NavigatorError, match="not a navigation policy.*lacks control_hz"):
        create("learned", {"policy": str(bare)})
    with pytest.raises(PolicyFileError, match="layer 1 takes 3 inputs; layer 0 gives 16"):
        MlpPolicy([(np.zeros((16, 5)), np.zeros(16)), (np.zeros((4, 3)), np.zeros(4))],
                  "tanh", {})
    with pytest.raises(PolicyFileError, match="non-finite"):
        MlpPolicy([(np.full((4, 5), np.nan), np.zeros(4))], "tanh", {})


def test_the_shipped_policy_says_how_it_was_trained():
    assert "v1" in shipped()
    m = load_policy("v1").meta
    assert m["env"]["platform"] == "generated" and m["env"]["family"] == "any"
    assert m["env"]["scenario_seed"][0] >= 1  # the benchmark's configurations held out
    assert m["trained_steps"] >= 1_000_000 and m["train"]["seed"] == 0
    assert json.loads(m["software"])["torch"]
    # trained under protocol 7, whose rules the environment still has: 8 changed only the
    # geofence arming check and NavRL's shield, 9 only the wire's random streams, 10 only
    # the precision of the trial driver's setpoints, 11 only EGO's replanning, none of
    # which a Gym episode has
    trained = PROTOCOLS[m["protocol"]]
    assert m["protocol"] == 7 and PROTOCOL_VERSION == 11
    assert dataclasses.replace(PROTOCOLS[11], version=7, summary=trained.summary,
                               arm_fence_check=False, navrl_shield_cluster_m=0.2,
                               wire_streams_shared=False, setpoints_as_on_the_wire=False,
                               ego_replan=("single", 0.8)) == trained


def _gym_and_navigator():
    """A gym episode and the navigator told the same task, at the episode's start."""
    m = load_policy().meta
    env = NavigateEnv(**SMALL, control_hz=m["control_hz"], max_yaw_rate_rad_s=0.0,
                      platform=AGILE)
    obs, _ = env.reset(seed=3)
    b = env.batch
    sc, plat = b.world.scenario, get_platform(AGILE)
    ind = plat.indicators()
    task = Task(start=sc.start.copy(), start_yaw=sc.start_yaw, goal=sc.goal.copy(),
                limits=Limits(), bounds_min=sc.bounds_min.copy(),
                bounds_max=sc.bounds_max.copy(), collision_radius_m=plat.collision_radius_m,
                twr_max=ind.twr_max, alpha_xy_max=ind.alpha_xy_max_rad_s2,
                alpha_z_max=ind.alpha_z_max_rad_s2,
                footprint_m=vehicle_half_span_m(PROTOCOL_VERSION, plat))
    nav = Learned(latency_s=0.0)
    nav.reset(task)
    return env, obs, nav


def _observation(x, t=0.0):
    q = x[d.X_QUAT:d.X_QUAT + 4]
    yaw = math.atan2(2 * (q[0] * q[3] + q[1] * q[2]), 1 - 2 * (q[2] ** 2 + q[3] ** 2))
    return Observation(time_s=t, position=x[d.X_POS:d.X_POS + 3].copy(),
                       velocity=x[d.X_VEL:d.X_VEL + 3].copy(), yaw=yaw,
                       attitude=q.copy(), angular_velocity=x[d.X_OMEGA:d.X_OMEGA + 3].copy())


def test_the_navigator_feeds_the_policy_what_the_environment_fed_it():
    """State, edges, platform and last action come out of the same functions bit for bit;
    the scan's layout is the environment's: with the map holding what the camera saw in a
    hover at the start, the forward rays read the environment's true distances (to the map's 0.1 m
    voxels), the rays behind (never seen) read nothing."""
    env, obs, nav = _gym_and_navigator()
    x = env.batch.sim.x[0].copy()
    assert not nav.map.first_occupied(x[:3], nav.rays_world, 0.05, 4.0).min() < 4.0
    cam = env.batch.world.camera(nav.camera)
    for k in range(10):  # (a voxel is occupied after several hits: a hover's frames)
        nav.observe(Observation(k / 30, x[:3], x[3:6], 0.0, x[6:10], x[10:13],
                                depth=cam.capture(round(k * 1e6 / 30), x[:3], x[6:10])))
    got = nav.inputs(_observation(x))
    want = policy_input(obs["state"][None], obs["edges"][None], obs["platform"][None],
                        obs["last_action"][None], obs["rays"][None])
    n = N_STATE + 12
    np.testing.assert_array_equal(got[0, :n], want[0, :n])
    np.testing.assert_allclose(obs["platform"],
                               platform_vector(get_platform(AGILE), PROTOCOL_VERSION),
                               rtol=1e-6)
    rays_true = want[0, n:].reshape(36, 4) * 4.0
    rays_map = got[0, n:].reshape(36, 4) * 4.0
    ahead = [0, 1, 2, 3, 35, 34, 33]  # columns within the camera's +-43 deg
    seen = rays_true[ahead] < 3.5
    assert seen.any(), "the test scene has an obstacle ahead"
    np.testing.assert_allclose(rays_map[ahead][seen], rays_true[ahead][seen], atol=0.2)
    assert np.all(rays_map[12:24] == 4.0)  # behind: nothing seen, nothing read
    env.close()


def test_it_turns_to_the_goal_then_holds_that_heading():
    env, obs, nav = _gym_and_navigator()
    x = env.batch.sim.x[0].copy()
    o = _observation(x)
    away = Observation(0.0, o.position, o.velocity, o.yaw + 2.0, o.attitude,
                       o.angular_velocity)
    sp = nav.step(away)
    np.testing.assert_allclose(sp.row[SP_POS:SP_POS + 3], nav.task.start)
    assert sp.row[SP_YAW] == pytest.approx(nav.goal_yaw)
    sp = nav.step(Observation(0.1, o.position, o.velocity, nav.goal_yaw, o.attitude,
                              o.angular_velocity))
    assert np.isnan(sp.row[SP_POS]) and np.all(np.isfinite(sp.row[SP_VEL:SP_VEL + 3]))
    assert sp.row[SP_YAW] == pytest.approx(nav.goal_yaw) and nav.replans == 1
    assert np.linalg.norm(sp.row[SP_VEL:SP_VEL + 2]) <= 4.0 * math.sqrt(2) + 1e-9
    env.close()


@pytest.mark.slow
def test_it_flies_a_benchmark_trial_without_the_training_stack(monkeypatch):
    for name in ("torch", "stable_baselines3"):  # not importable while it flies
        monkeypatch.setitem(sys.modules, name, None)
    row = run_trial(TrialSpec(algorithm="learned", platform=AGILE, family="forest",
                              scenario_index=1)).row
    assert row["algorithm"] == "learned" and row["replans"] > 10
    assert row["reason"] not in ("navigator_error", "approach_failed"), row["detail"]
    assert row["mean_speed_m_s"] > 0.5  # it flies (not a hover until the timeout)
