"""The vector environment: N vehicles in one compiled physics call equal N single
environments step by step (same seeds: bit-identical observations, rewards, ends and
outcomes, across autoresets), Gymnasium's vector API (make_vec, spaces, autoreset modes,
partial resets, infos), refused actions naming the sub-environment, batched rendering."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode

import ft_sitl.gym  # noqa: F401  (registers the environments)
from ft_sitl.gym import ActionError, EnvError, NavigateEnv, NavigateVectorEnv
from tests.gym.gymutil import SMALL

N = 4


def same_obs(single: dict, batch: dict, i: int, where) -> None:
    for k, v in single.items():
        assert np.array_equal(v, batch[k][i]), (where, k, v, batch[k][i])


def walk(rng, a):
    """Random actions biased forward: vehicles fly into the trees, episodes end."""
    a = np.clip(0.8 * a + 0.5 * rng.uniform(-1, 1, a.shape), -1, 1)
    a[:, 0] = np.clip(a[:, 0] + 0.5, -1, 1)
    return a


@pytest.mark.parametrize("mode,settings", [
    (AutoresetMode.NEXT_STEP, {}),
    # turbulence and estimator noise are drawn per physics step of the shared clock: the
    # same-step autoreset starts a sub-environment's episodes when the single one's start
    (AutoresetMode.SAME_STEP, {"wind_speed_m_s": (0.0, 5.0), "turbulence": "moderate",
                               "position_noise_m": (0.0, 0.1),
                               "velocity_noise_m_s": (0.0, 0.1)}),
])
def test_n_vehicles_equal_n_single_environments(mode, settings):
    settings = {**SMALL, "timeout_s": 1.5, **settings}
    vec = NavigateVectorEnv(N, autoreset_mode=mode, **settings)
    singles = [NavigateEnv(**settings) for _ in range(N)]
    obs, info = vec.reset(seed=7)
    for i, env in enumerate(singles):
        o, inf = env.reset(seed=7 + i)
        same_obs(o, obs, i, "reset")
        assert inf["platform"] == info["platform"][i]
    rng = np.random.default_rng(0)
    a = np.zeros((N, 4))
    pending = [False] * N
    outcomes = set()
    for t in range(160):
        a = walk(rng, a)
        act = a.astype(np.float32)
        obs, reward, term, trunc, info = vec.step(act)
        for i, env in enumerate(singles):
            if pending[i]:  # next-step autoreset: this call reset it
                o, inf = env.reset()
                r, te, tu = 0.0, False, False
            else:
                o, r, te, tu, inf = env.step(act[i])
                if (te or tu) and mode == AutoresetMode.SAME_STEP:
                    final = info["final_obs"][i]
                    assert all(np.array_equal(v, final[k]) for k, v in o.items()), (t, i)
                    assert info["final_info"]["outcome"][i] == inf["outcome"]
                    assert info["final_info"]["detail"][i] == inf["detail"]
                    outcomes.add(inf["outcome"])
                    o, inf = env.reset()
            same_obs(o, obs, i, (t, i))
            assert (r, te, tu) == (reward[i], term[i], trunc[i]), (t, i)
            if not ((te or tu) and mode == AutoresetMode.SAME_STEP):
                assert (inf["outcome"], inf["detail"], inf["platform"]) == \
                    (info["outcome"][i], info["detail"][i], info["platform"][i]), (t, i)
                outcomes.add(inf["outcome"])
            pending[i] = (te or tu) and mode == AutoresetMode.NEXT_STEP
    # episodes ended, by the time limit and by crashes, and restarted
    assert "timeout" in outcomes and outcomes & {"collision", "out_of_bounds"}, outcomes


def test_make_vec_builds_the_batched_environment():
    envs = gym.make_vec("ftsitl/Navigate-v0", num_envs=3, **SMALL)
    assert isinstance(envs, NavigateVectorEnv) and envs.num_envs == 3
    assert envs.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    assert envs.action_space.shape == (3, 4)
    assert envs.observation_space["rays"].shape == (3, 144)
    obs, info = envs.reset(seed=1)
    assert obs in envs.observation_space
    assert info["_outcome"].all() and list(info["scenario"]) == ["forest-02-s0"] * 3
    obs, reward, term, trunc, info = envs.step(envs.action_space.sample())
    assert obs in envs.observation_space and reward.shape == (3,) and term.dtype == bool
    envs.close()


def test_partial_resets_without_autoreset():
    envs = NavigateVectorEnv(3, autoreset_mode="Disabled", **SMALL, timeout_s=0.1)
    with pytest.raises(EnvError, match="the first reset resets every sub-environment"):
        envs.reset(options={"reset_mask": np.array([True, False, False])})
    envs.reset(seed=0)
    for _ in range(5):
        *_, trunc, info = envs.step(np.zeros((3, 4), np.float32))
    assert trunc.all() and list(info["outcome"]) == ["timeout"] * 3
    with pytest.raises(EnvError, match="sub-environment 0's episode ended: reset it"):
        envs.step(np.zeros((3, 4), np.float32))
    mask = np.array([False, True, False])
    with pytest.raises(EnvError, match="only when all of them reset"):
        envs.reset(options={"reset_mask": mask, "movers": {"count": 1}})
    obs, info = envs.reset(options={"reset_mask": mask, "platform": "5.45kg-JFRC"})
    assert list(info["_platform"]) == [False, True, False]
    assert info["platform"][1] == "5.45kg-JFRC" and info["time_s"][1] == 0.0
    assert envs.batch.done.tolist() == [True, False, True]


def test_bad_actions_name_the_sub_environment():
    envs = NavigateVectorEnv(3, **SMALL)
    envs.reset(seed=0)
    a = np.zeros((3, 4), np.float32)
    a[2, 1] = -1.5
    with pytest.raises(ActionError, match=r"sub-environment 2: action\[1\] = -1.5 is outside"):
        envs.step(a)
    with pytest.raises(ActionError, match=r"action: shape \(4,\), expected \(3, 4\)"):
        envs.step(np.zeros(4, np.float32))
    with pytest.raises(EnvError, match="num_envs: a positive integer"):
        NavigateVectorEnv(0)
    with pytest.raises(EnvError, match="autoreset_mode: 'Later' is not one of"):
        NavigateVectorEnv(2, autoreset_mode="Later")


def test_rendering_is_batched():
    envs = NavigateVectorEnv(2, render_mode="depth_array", **SMALL)
    envs.reset(seed=0)
    frames = envs.render()
    assert len(frames) == 2 and frames[0].shape == (120, 160)
    envs = NavigateVectorEnv(2, render_mode="rgb_array", render_px=64, **SMALL)
    envs.reset(seed=0)
    frames = envs.render()
    assert len(frames) == 2 and frames[1].dtype == np.uint8 and max(frames[1].shape) == 64
