"""The single-vehicle environments: Gymnasium's checker, determinism, how episodes end and
what they report, refused actions, settings and options, the spaces, rendering, docs."""

from __future__ import annotations

import re
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import ft_sitl.gym  # noqa: F401  (registers the environments)
from ft_sitl.gym import ENV_SCHEMA, ENVIRONMENTS, REWARD_SCHEMA, ActionError, EnvError
from ft_sitl.gym.batch import platform_vector
from ft_sitl.gym.envs import NavigateEnv
from ft_sitl.missions.spec import PROTOCOL_VERSION
from ft_sitl.physics.catalog import catalog
from tests.gym.gymutil import SMALL, roll, wall_scenario

DOCS = Path(__file__).resolve().parents[2] / "docs" / "gym.md"


@pytest.mark.parametrize("env_id,settings", [
    ("ftsitl/Navigate-v0", SMALL),
    ("ftsitl/Hover-v0", {}),
    ("ftsitl/Navigate-v0", {**SMALL, "sensor": "depth", "action": "attitude_rate"}),
    ("ftsitl/Navigate-v0", {**SMALL, "action": "motors", "platform": "generated",
                            "wind_speed_m_s": (0.0, 6.0), "turbulence": "light",
                            "position_noise_m": (0.0, 0.2)}),
    ("ftsitl/Navigate-v0", {**SMALL, "action": "acceleration", "movers": {"count": 3},
                            "mover_layouts": 2}),
])
def test_gymnasium_check_env_passes_without_warnings(env_id, settings):
    env = gym.make(env_id, **settings)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # any warning of the checker fails the test
        check_env(env.unwrapped)
    env.close()


def test_every_registered_environment_is_made():
    for env_id in ENVIRONMENTS:
        env = gym.make(env_id, **(SMALL if "Navigate" in env_id else {}))
        assert isinstance(env.unwrapped, NavigateEnv)
        env.close()


def test_the_same_seed_flies_the_same_episode():
    rng = np.random.default_rng(2)
    actions = rng.uniform(-1, 1, (150, 4)).astype(np.float32)
    settings = {**SMALL, "wind_speed_m_s": (0.0, 5.0), "turbulence": "moderate",
                "velocity_noise_m_s": (0.0, 0.2)}
    a = roll(NavigateEnv(**settings), actions, seed=9)
    b = roll(NavigateEnv(**settings), actions, seed=9)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        for u, v in zip(x, y):
            if isinstance(u, dict):
                assert u.keys() == v.keys() and all(np.array_equal(u[k], v[k]) for k in u)
            else:
                assert u == v
    c = roll(NavigateEnv(**settings), actions, seed=10)
    assert not np.array_equal(a[-1][0]["state"], c[-1][0]["state"])


def test_a_collision_ends_the_episode_with_its_outcome():
    env = NavigateEnv(platform="0.98kg-EGO Planner DIY", max_speed_m_s=3.0)
    obs, info = env.reset(seed=0, options={"scenario": wall_scenario()})
    assert info["outcome"] == "" and info["scenario"] == "wall"
    assert obs["state"][3] == pytest.approx(12.0)  # the goal 12 m ahead
    ahead = 1  # the level ray towards the goal (column 0, elevation 0 of -10..20 deg)
    assert obs["rays"][ahead] == 1.0  # the wall 5.85 m ahead: beyond the 4 m scan
    for _ in range(200):
        y = env.batch.sim.x[0, 1]
        obs, reward, terminated, truncated, info = env.step(np.array([1, 0, 0, 0],
                                                                     np.float32))
        if terminated or truncated:
            break
        if 8.0 - 0.15 - y < 3.9:  # the ray reads the wall's distance (the true one)
            assert obs["rays"][ahead] == pytest.approx((7.85 - env.batch.sim.x[0, 1]) / 4,
                                                       abs=1e-6)
    assert terminated and not truncated
    assert info["outcome"] == "collision"
    assert re.fullmatch(r"hit obstacle at \d\.\d m/s", info["detail"]), info["detail"]
    assert reward < -9.0  # the collision penalty (10) with a little progress
    assert info["distance_m"] == pytest.approx(6.0, abs=0.5)
    with pytest.raises(EnvError, match="after the episode ended"):
        env.step(np.zeros(4, np.float32))


def test_leaving_the_volume_and_the_time_limit_end_it_as_the_referee_does():
    env = NavigateEnv(**SMALL, platform="0.98kg-EGO Planner DIY")
    ends = roll(env, [np.array([0, 0, 1, 0], np.float32)] * 300, seed=1)
    *_, terminated, truncated, info = ends[-1]
    assert terminated and info["outcome"] == "out_of_bounds"
    assert info["detail"] == "climbed above the ceiling"
    env = NavigateEnv(**SMALL, timeout_s=0.5)
    ends = roll(env, [np.zeros(4, np.float32)] * 100, seed=1)
    assert len(ends) == 26  # reset + 25 actions of 20 ms
    *_, terminated, truncated, info = ends[-1]
    assert truncated and not terminated and info["outcome"] == "timeout"
    assert info["detail"] == "not in the goal sphere after 0.5 s (14.0 m away)"


def test_success_after_the_hold_with_the_bonus():
    env = NavigateEnv(family="arena", hold_s=0.2, goal_radius_m=0.5, sensor="none",
                      platform="0.98kg-EGO Planner DIY")
    obs, info = env.reset(seed=4)
    for _ in range(400):
        s = obs["state"]
        to_goal = s[0:3] * min(1.0, float(np.hypot(s[3], s[4])))  # goal frame
        action = np.clip(np.append(to_goal * [1.0, 1.0, 2.0], 0.0), -1, 1).astype(np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            break
    assert terminated and info["outcome"] == "success", info
    assert reward > 9.0 and info["distance_m"] <= 0.5


def test_the_hover_task_ends_only_on_crashes_and_its_time_limit():
    env = gym.make("ftsitl/Hover-v0", timeout_s=0.4)
    ends = roll(env, [np.zeros(4, np.float32)] * 100, seed=3)
    *_, terminated, truncated, info = ends[-1]
    assert truncated and not terminated and info["outcome"] == "timeout"
    assert info["detail"] == "time limit 0.4 s" and len(ends) == 21


@pytest.mark.parametrize("action,match", [
    (np.array([1.2, 0, 0, 0]), r"action\[0\] = 1.2 is outside the action space \[-1, 1\]"),
    (np.array([0, np.nan, 0, 0]), r"action\[1\] = nan is outside"),
    (np.array([0, 0, 0]), r"action: shape \(3,\), expected \(4,\)"),
    ("fast", r"action: 'fast' is not an array of numbers"),
])
def test_bad_actions_are_refused_by_name(action, match):
    env = NavigateEnv(**SMALL)
    env.reset(seed=0)
    with pytest.raises(ActionError, match=match):
        env.step(action)
    env.step(np.zeros(4, np.float32))  # the episode goes on


@pytest.mark.parametrize("settings,match", [
    ({"famly": "forest"}, "no parameter 'famly'; did you mean 'family'"),
    ({"control_hz": 30}, "control_hz 30 must divide physics_hz 1000"),
    ({"platform": "2kg-T-MOTOR"}, "neither a pool .* nor a platform"),
    ({"action": "thrust"}, "action: must be 'velocity' or 'acceleration'"),
    ({"scenario_index": (0, 3)}, r"scenario_index: must be \[lo, hi\] with 1 <= lo"),
    ({"reward": {"progres": 1.0}}, "reward has no parameter 'progres'; did you mean"),
    ({"family": "any", "scenario_params": {"size_m": [10.0, 10.0]}},
     "scenario_params need one benchmark family"),
    ({"scenario_params": {"density": 0.1}}, "scenario family 'forest' has no parameter"),
    ({"movers": {"cuont": 2}}, "movers has no parameter 'cuont'"),
    ({"render_mode": "human"}, "render_mode: 'human' is not one of rgb_array"),
    ({"scenario_versions": {"perlin": 9}}, r"scenario_versions: .*perlin: no generator "
                                           r"version 9 \(versions: 1, 2\)"),
    ({"scenario_versions": {"perlni": 1}}, "scenario_versions: unknown scenario family "
                                           "'perlni'; did you mean 'perlin'"),
    ({"scenario_versions": [1]}, "scenario_versions: a mapping of family to generator"),
])
def test_bad_settings_are_refused_by_name(settings, match):
    with pytest.raises(EnvError, match=match):
        NavigateEnv(**settings)


@pytest.mark.parametrize("options,match", [
    ({"platfrom": "x"}, "no reset option 'platfrom'; did you mean 'platform'"),
    ({"platform": "nope"}, "unknown platform 'nope'"),
    ({"platform": 3}, "option platform: a platform's name or a Platform"),
    ({"wind": {"speed": 3}}, "option wind has no parameter 'speed'"),
    ({"estimator": {"position_noise_m": -1.0}}, "option estimator: position_noise_m: must"),
    ({"scenario": {"family": "forest", "index": 11}}, "scenario: .*index"),
    ({"scenario": "forest"}, "option scenario: a Scenario or a mapping"),
])
def test_bad_reset_options_are_refused_by_name(options, match):
    env = NavigateEnv(**SMALL)
    with pytest.raises((EnvError, ValueError), match=match):
        env.reset(seed=0, options=options)
    with pytest.raises(EnvError, match="before reset"):
        NavigateEnv(**SMALL).step(np.zeros(4, np.float32))


@pytest.mark.slow
def test_pinned_generator_versions_build_the_older_worlds():
    """scenario_versions (and a scenario option's version) build a family's older
    generator; by default the newest. Maze has two versions with different layouts."""
    from ft_sitl.scenarios.families import REGISTRY, build_scenario
    assert REGISTRY["maze"].version == 2
    old = build_scenario("maze", 2, 0, version=1).mesh_digest()
    new = build_scenario("maze", 2, 0).mesh_digest()
    assert old != new

    def digest(env, options=None):
        env.reset(seed=0, options=options)
        return env.batch.world.scenario.mesh_digest()

    settings = {"family": "maze", "scenario_index": (2, 2), "sensor": "none"}
    assert digest(NavigateEnv(**settings)) == new
    pinned = NavigateEnv(**settings, scenario_versions={"Maze": 1})
    assert pinned.cfg.scenario_versions == {"maze": 1}
    assert digest(pinned) == old
    # a scenario option takes the environment's pinned version, or its own
    assert digest(pinned, {"scenario": {"family": "maze", "index": 2}}) == old
    assert digest(pinned, {"scenario": {"family": "maze", "index": 2, "version": 2}}) == new
    with pytest.raises(EnvError, match="maze: no generator version 3"):
        pinned.reset(seed=0, options={"scenario": {"family": "maze", "index": 2,
                                                   "version": 3}})


def test_reset_options_replace_the_episode_draws():
    env = NavigateEnv(**SMALL)
    obs, info = env.reset(seed=0, options={"platform": "5.45kg-JFRC", "wind": None,
                                           "estimator": {"position_bias_m": (0.5, 0, 0)}})
    assert info["platform"] == "5.45kg-JFRC"
    jfrc = platform_vector(catalog()["5.45kg-JFRC"], PROTOCOL_VERSION)
    assert np.array_equal(obs["platform"], jfrc.astype(np.float32))
    assert env.batch.sim.estimating(0)


def test_the_platform_vector_spans_the_catalog():
    vecs = np.array([platform_vector(p, PROTOCOL_VERSION) for p in catalog().values()])
    assert np.allclose(vecs.min(axis=0), 0.0) and np.allclose(vecs.max(axis=0), 1.0)


def test_spaces_and_observation_layout():
    env = NavigateEnv(**SMALL, sensor="depth", depth_step=40, action="motors")
    assert env.action_space.shape == (4,)
    assert env.observation_space["depth"].shape == (1, 12, 16)
    obs, _ = env.reset(seed=0)
    assert obs in env.observation_space and set(obs) == {"state", "edges", "platform",
                                                         "last_action", "depth"}
    e = obs["edges"]  # the 12 x 20 m area, flown along its length from near one end
    assert e[0] + e[2] == pytest.approx(20.0, abs=1e-4) and e[0] > e[2] > 0
    assert e[1] + e[3] == pytest.approx(12.0, abs=1e-4)
    hover = NavigateEnv(**SMALL, sensor="none")
    obs, _ = hover.reset(seed=0)
    s = obs["state"]
    assert np.allclose(s[0:3], [1, 0, 0]) and s[4] == 0.0  # straight ahead, level
    assert np.allclose(s[8:11], [0, 0, 1], atol=1e-6) and np.allclose(s[11:14], [1, 0, 0],
                                                                      atol=1e-6)
    assert s[17] == pytest.approx(1.5) and s[18] == pytest.approx(1.5)


def test_render_modes():
    env = NavigateEnv(**SMALL, render_mode="rgb_array", render_px=128)
    env.reset(seed=0)
    env.step(np.array([0.5, 0, 0, 0], np.float32))
    img = env.render()
    assert img.dtype == np.uint8 and img.ndim == 3 and img.shape[2] == 3
    assert max(img.shape[:2]) == 128 and (img == [220, 40, 40]).all(axis=2).any()  # vehicle
    for mode in ("depth_array", "depth"):
        env = NavigateEnv(**SMALL, render_mode=mode)
        env.reset(seed=0)
        depth = env.render()
        assert depth.shape == (120, 160) and depth.dtype == np.float32
        assert np.nanmax(depth) <= 10.0


def test_the_docs_tables_are_the_schemas():
    doc = DOCS.read_text()
    for name, schema in (("ENV_SCHEMA", ENV_SCHEMA), ("REWARD_SCHEMA", REWARD_SCHEMA)):
        assert (f"<!-- BEGIN generated: {name}.markdown() -->\n{schema.markdown()}\n"
                "<!-- END generated -->") in doc
    for env_id in ENVIRONMENTS:
        assert f"`{env_id}`" in doc
