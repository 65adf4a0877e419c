"""Training (`ft-sitl train`): its configuration's checks, the message without the training
stack, and, where the optional stack is installed (the `train` extra; CI does not install
it), that a training is reproducible from its seed and that the exported numpy policy acts
as the trained network."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ft_sitl.cli import main as cli_main
from ft_sitl.gym.train import PRESET, TrainError, evaluate, load_config, policy_vec_env, train
from ft_sitl.navigation.learned.learned import load_policy
from ft_sitl.navigation.learned.policy_io import MlpPolicy
from ft_sitl.scenarios.families import REGISTRY
from tests.gym.gymutil import SMALL

HAS_STACK = all(importlib.util.find_spec(m) is not None for m in ("torch", "stable_baselines3"))
needs_stack = pytest.mark.skipif(not HAS_STACK, reason="the optional training stack "
                                 "(pip install 'ft-sitl[train]') is not installed")
CLI = [str(Path(sys.executable).parent / "ft-sitl")]


def test_the_preset_is_the_shipped_policys_configuration():
    cfg = load_config()
    meta = load_policy().meta
    assert {k: list(v) if isinstance(v, tuple) else v
            for k, v in cfg["train"].items()} == meta["train"]
    versions = cfg["env"].pop("scenario_versions")
    assert cfg["env"] == meta["env"]
    # the families' generators it was trained with, pinned (Random Perlin-Noise's version 2
    # came later): every family named, each version one the family has
    assert set(versions) == set(REGISTRY) and versions["perlin"] == 1
    assert all(REGISTRY[f].check_version(v) == v for f, v in versions.items())


def test_a_configuration_records_the_generator_versions_it_draws(tmp_path):
    """A training's resolved configuration names the version of every family it may draw
    (its newest unless pinned), so config.json re-runs the same worlds later."""
    newest = {f: fam.version for f, fam in REGISTRY.items()}
    f = tmp_path / "any.toml"
    f.write_text("[env]\nfamily = 'any'\nscenario_versions = { maze = 1 }\n")
    assert load_config(f)["env"]["scenario_versions"] == {**newest, "maze": 1}
    f.write_text("[env]\nfamily = 'narrow_gap'\n")
    assert load_config(f)["env"]["scenario_versions"] == {"narrow_gap": newest["narrow_gap"]}
    f.write_text("[env]\nfamily = 'any'\nscenario_versions = { perlin = 7 }\n")
    with pytest.raises(TrainError, match=r"\[env\]: .*perlin: no generator version 7"):
        load_config(f)


@pytest.mark.parametrize("text,message", [
    ("[train]\nseeds = 1\n", r"\[train\] has no parameter 'seeds'; did you mean 'seed'"),
    ("[train]\nnum_envs = 0\n", r"num_envs.*0"),
    ("[env]\nfamily = 'moon'\n", r"\[env\]: .*family: must be 'forest' or .*got 'moon'"),
    ("[env]\naction = 'motors'\n", r"velocity actions from a ray scan"),
    ("[reward]\nprogres = 1.0\n", r"progres"),
    ("[train]\nbatch_size = 99999\n", r"batch_size 99999 exceeds a rollout"),
    ("[agent]\n", r"unknown table\(s\) agent"),
    ("train = 3\n", r"train must be a table"),
    ("[train\n", r"training config .*bad\.toml"),
])
def test_bad_configurations_name_what_is_wrong(tmp_path, text, message):
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(TrainError, match=message):
        load_config(f)


@pytest.mark.e2e
def test_the_command_checks_and_refuses_by_name(tmp_path, capsys):
    ok = subprocess.run(CLI + ["train", "--out", str(tmp_path / "o"), "--check",
                               "--steps", "5000"], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    assert f"{PRESET}: valid" in ok.stdout and '"total_steps": 5000' in ok.stdout
    bad = tmp_path / "b.toml"
    bad.write_text("[train]\nhidden = [64]\n")
    code = cli_main(["train", "--config", str(bad), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "hidden" in err and not (tmp_path / "o").exists()


@pytest.mark.e2e
def test_without_the_stack_training_says_what_to_install(tmp_path):
    code = ("import sys; sys.modules['torch'] = None; sys.modules['stable_baselines3'] = None\n"
            "from ft_sitl.gym.train import load_config, train, TrainError\n"
            "try:\n    train(load_config(), sys.argv[1], progress=False)\n"
            "except TrainError as e:\n    print(e)\n")
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "o")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "pip install 'ft-sitl[train]'" in out.stdout


def test_the_evaluation_flies_a_policy_as_the_environment_judges_it():
    rows = evaluate(load_policy(), {**load_config()["env"], **SMALL, "timeout_s": 8.0},
                    episodes_per_family=2, families=["forest"], num_envs=2)
    assert len(rows) == 2 and {r["family"] for r in rows} == {"forest"}
    assert all(r["outcome"] and r["time_s"] > 0 for r in rows)


SHORT = {"total_steps": 1024, "num_envs": 4, "n_steps": 128, "batch_size": 256,
         "world_every": 200, "save_every": 512}


def _short_config(tmp_path, **over):
    f = tmp_path / "short.toml"
    f.write_text("[env]\nfamily = 'forest'\nscenario_index = [2, 2]\n"
                 "scenario_params = { size_m = [12.0, 20.0] }\n")  # (a world in 0.2 s)
    return load_config(f, {**SHORT, **over})


@needs_stack
def test_a_training_is_reproducible_from_its_seed_and_exports_the_actor(tmp_path):
    from stable_baselines3 import PPO  # the optional stack (skipped without it)

    cfg = _short_config(tmp_path)
    a = train(cfg, tmp_path / "a", progress=False)
    b = train(cfg, tmp_path / "b", progress=False)
    pa, pb = MlpPolicy.load(a), MlpPolicy.load(b)
    for (wa, ba), (wb, bb) in zip(pa.layers, pb.layers):
        np.testing.assert_array_equal(wa, wb)
        np.testing.assert_array_equal(ba, bb)
    assert (tmp_path / "a" / "training.png").stat().st_size > 0
    assert (tmp_path / "a" / "policy-latest.npz").is_file()
    curve = (tmp_path / "a" / "training.csv").read_text().splitlines()
    assert curve[0].startswith("steps,wall_s,episodes,success") and len(curve) == 3
    # the numpy policy is the trained actor: SB3's deterministic action, clipped
    venv = policy_vec_env(cfg["env"], cfg["reward"], 4, 1000, 0)
    model = PPO("MlpPolicy", venv, seed=1, device="cpu",
                policy_kwargs={"net_arch": {"pi": [32, 32], "vf": [32, 32]}})
    from ft_sitl.gym.train import export_policy, policy_meta  # (same module, grouped here)
    mine = export_policy(model, {**policy_meta(cfg, 0), "activation": "tanh"})
    obs = venv.reset()
    for _ in range(20):
        theirs, _ = model.predict(obs, deterministic=True)
        np.testing.assert_allclose(mine.act(obs), np.clip(theirs, -1, 1), atol=1e-5)
        obs, _, _, _ = venv.step(theirs)
    venv.close()


@needs_stack
def test_the_adapter_hands_sb3_terminal_observations_and_new_worlds(tmp_path):
    cfg = _short_config(tmp_path)
    venv = policy_vec_env(cfg["env"], cfg["reward"], 3, 5, 0)
    obs = venv.reset()
    assert obs.shape == (3, venv.observation_space.shape[0]) and venv.resets == 1
    for k in range(1, 6):
        venv.step_async(np.zeros((3, 4), np.float32))
        obs, rew, done, infos = venv.step_wait()
        if k < 5:
            assert not done.any() or all("terminal_observation" in infos[i]
                                         for i in np.flatnonzero(done))
    # the fifth step changed the world: every episode ended, truncated, and restarted
    assert done.all() and venv.resets == 2
    assert all(i["TimeLimit.truncated"] and i["terminal_observation"].shape == obs.shape[1:]
               for i in infos)
    venv.close()
