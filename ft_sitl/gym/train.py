"""Training a navigation policy on the batched environment with Stable-Baselines3's PPO
(CPU), and exporting it as a numpy policy file the ``learned`` navigator flies
(:mod:`ft_sitl.navigation.learned.learned`; reference: docs/gym.md, "Training").

The training stack (``pip install 'ft-sitl[train]'``: Stable-Baselines3, PyTorch) is
imported only here, and only when a training runs; nothing else in ft-sitl needs it.

- :class:`PolicyVecEnv` adapts :class:`~ft_sitl.gym.envs.NavigateVectorEnv` (N vehicles in
  one compiled physics call) to Stable-Baselines3's ``VecEnv``: observations are the flat
  :func:`~ft_sitl.navigation.learned.policy_io.policy_input`, episodes auto-reset in the same step
  (``terminal_observation`` and ``TimeLimit.truncated`` in the infos, as SB3 expects), and
  every ``world_every`` steps the whole batch moves to a newly drawn world (the running
  episodes end there as truncated).
- :func:`train` runs a configuration (:data:`TRAIN_SCHEMA`, plus the environment's
  settings and reward weights), writes the training curve (``training.csv``,
  ``training.png``) and the policy (``policy.npz``) into a directory.

Reproducible from the seed on one machine: the environment's draws come from it, PyTorch
is seeded with it and runs on ``threads`` threads (PyTorch's CPU kernels give the same
result for the same thread count and build; another build may differ in the last bits).
"""

from __future__ import annotations

import csv
import json
import math
import time
import tomllib
from collections import Counter
from pathlib import Path

import numpy as np
import pandas as pd
from gymnasium import spaces
from tqdm import tqdm

from ft_sitl.gym.batch import catalog_range
from ft_sitl.gym.config import ANY, ARENA, EnvError, make_config
from ft_sitl.gym.envs import NavigateVectorEnv
from ft_sitl.navigation.learned.policy_io import MlpPolicy, policy_input
from ft_sitl.provenance import software
from ft_sitl.scenarios.families import REGISTRY
from ft_sitl.schema import Param, Schema, SchemaError

#: the training preset committed with the package (the shipped policy's configuration)
PRESET = Path(__file__).with_name("presets") / "learned.toml"

TRAIN_SCHEMA = Schema((
    Param("seed", 0, range=(0, 2**31 - 1),
          doc="seeds the environment's draws and PyTorch"),
    Param("total_steps", 10_000_000, "steps", (1, 10**10),
          doc="environment steps (actions of one vehicle) to train for"),
    Param("num_envs", 32, range=(1, 4096),
          doc="vehicles flown in one batch (one world)"),
    Param("world_every", 1024, "steps", (1, 10**9),
          doc="vector steps between new worlds (the whole batch resets into a newly drawn "
              "scenario)"),
    Param("n_steps", 128, "steps", (1, 10**6),
          doc="PPO: vector steps per rollout (n_steps x num_envs samples per update)"),
    Param("batch_size", 1024, "samples", (2, 10**7), doc="PPO: minibatch size"),
    Param("n_epochs", 5, range=(1, 100), doc="PPO: passes over each rollout"),
    Param("learning_rate", 3e-4, "-", (1e-7, 1.0), doc="Adam's step size"),
    Param("gamma", 0.99, "-", (0.0, 1.0), doc="discount per action"),
    Param("gae_lambda", 0.95, "-", (0.0, 1.0), doc="GAE's lambda"),
    Param("clip_range", 0.2, "-", (0.01, 1.0), doc="PPO's clip range"),
    Param("ent_coef", 0.0, "-", (0.0, 1.0), doc="entropy bonus"),
    Param("log_std_init", -0.5, "-", (-5.0, 2.0),
          doc="the Gaussian action noise's initial log standard deviation"),
    Param("hidden", (128, 128), "units", (1, 4096),
          doc="hidden layer sizes of the actor and of the critic (two layers)"),
    Param("activation", "tanh", choices=("tanh", "relu"), doc="between hidden layers"),
    Param("threads", 1, range=(1, 256), doc="PyTorch's CPU threads"),
    Param("save_every", 500_000, "steps", (1, 10**10),
          doc="write the policy so far (policy-latest.npz) this often"),
))

#: the environment settings training starts from (each may be changed in [env]): the
#: seven families on new seeds (the benchmark's configurations are seed 0, held out),
#: platforms generated in the catalog's design space, 10 Hz velocity actions without yaw
ENV_DEFAULTS = {
    "family": "any", "scenario_index": [1, 10], "scenario_seed": [1, 2**31 - 1],
    "platform": "generated", "control_hz": 10, "max_yaw_rate_rad_s": 0.0,
    "sensor": "rays",
}
#: the rays the policy file declares it was trained with (the navigator casts them alike)
RAY_KEYS = ("ray_columns", "ray_rows", "ray_elevation_deg", "ray_range_m")


class TrainError(ValueError):
    """A bad training configuration, or the training stack missing."""


def _import_stack():
    try:
        import stable_baselines3  # the optional training stack: only when training
        import torch  # (its PyTorch)
    except ImportError as exc:
        raise TrainError(f"training needs the optional training stack ({exc.name} is not "
                         "installed): pip install 'ft-sitl[train]' (see docs/gym.md, "
                         "\"Training\")") from None
    return stable_baselines3, torch


def load_config(path: str | Path | None = None, overrides: dict | None = None) -> dict:
    """A training configuration: the TOML file ``path`` (the preset when None) with tables
    ``[train]`` (:data:`TRAIN_SCHEMA`), ``[env]`` (the environment's settings over
    :data:`ENV_DEFAULTS`) and ``[reward]``; ``overrides`` replace [train] keys. Returns
    ``{"train", "env", "reward"}``, checked (TrainError naming the file and key)."""
    p = Path(path) if path is not None else PRESET
    try:
        doc = tomllib.loads(p.read_text())
    except OSError as exc:
        raise TrainError(f"training config {p}: {exc.strerror or exc}") from None
    except tomllib.TOMLDecodeError as exc:
        raise TrainError(f"training config {p}: {exc}") from None
    unknown = set(doc) - {"train", "env", "reward"}
    if unknown:
        raise TrainError(f"training config {p}: unknown table(s) {', '.join(sorted(unknown))} "
                         "(allowed: train, env, reward)")
    for key in ("train", "env", "reward"):
        if not isinstance(doc.get(key, {}), dict):
            raise TrainError(f"training config {p}: {key} must be a table")
    train_values = {**doc.get("train", {}), **(overrides or {})}
    try:
        train_cfg = TRAIN_SCHEMA.resolve(train_values, f"training config {p} [train]")
    except SchemaError as exc:
        raise TrainError(str(exc)) from None
    env = {**ENV_DEFAULTS, **doc.get("env", {})}
    reward = dict(doc.get("reward", {}))
    if env.get("action", "velocity") != "velocity" or env.get("sensor") != "rays":
        raise TrainError(f"training config {p} [env]: the learned navigator flies velocity "
                         "actions from a ray scan (action = 'velocity', sensor = 'rays')")
    try:  # the environment checks its own settings
        venv = NavigateVectorEnv(1, reward=reward, **env)
    except EnvError as exc:
        raise TrainError(f"training config {p} [env]: {exc}") from None
    venv.close()
    # every family the training may draw, at an explicit generator version: the resolved
    # configuration (config.json, the policy file) re-runs at a later commit
    env["scenario_versions"] = drawn_versions(venv.cfg)
    if train_cfg["batch_size"] > train_cfg["n_steps"] * train_cfg["num_envs"]:
        raise TrainError(f"training config {p} [train]: batch_size {train_cfg['batch_size']} "
                         f"exceeds a rollout (n_steps x num_envs = "
                         f"{train_cfg['n_steps'] * train_cfg['num_envs']})")
    return {"train": train_cfg, "env": env, "reward": reward}


def drawn_versions(cfg) -> dict:
    """``{family: generator version}`` of every family an environment's episodes may be
    drawn from (its ``family`` setting: one, all seven for 'any', none for the arena)."""
    fam = cfg["family"]
    families = list(REGISTRY) if fam == ANY else [] if fam == ARENA else [fam]
    return {f: cfg.version_of(f) or REGISTRY[f].version for f in families}


def _make_vec_env_base():
    # the optional training stack: imported only when a training runs
    from stable_baselines3.common.vec_env import VecEnv
    return VecEnv


def policy_vec_env(env_settings: dict, reward: dict, num_envs: int, world_every: int,
                   seed: int):
    """A :class:`PolicyVecEnv` (the class is built on first use: it subclasses
    Stable-Baselines3's ``VecEnv``, which is imported only for training)."""
    global PolicyVecEnv
    if not isinstance(PolicyVecEnv, type):
        PolicyVecEnv = _policy_vec_env_class(_make_vec_env_base())
    return PolicyVecEnv(env_settings, reward, num_envs, world_every, seed)


PolicyVecEnv: type | None = None


def _policy_vec_env_class(base):
    class _PolicyVecEnv(base):
        """Stable-Baselines3's view of a NavigateVectorEnv (module docstring)."""

        def __init__(self, env_settings, reward, num_envs, world_every, seed):
            self.venv = NavigateVectorEnv(num_envs, autoreset_mode="SameStep", reward=reward,
                                          **env_settings)
            size = sum(int(np.prod(s.shape))
                       for s in self.venv.single_observation_space.values())
            obs_space = spaces.Box(-np.inf, np.inf, (size,), np.float32)
            super().__init__(num_envs, obs_space, self.venv.single_action_space)
            self.world_every = world_every
            self.base_seed = seed
            self.resets = 0  # full resets so far (each draws a world)
            self.count = 0
            self.actions = None
            self.outcomes: Counter = Counter()  # since the last take_outcomes()
            self.returns: list[float] = []
            self.ep_return = np.zeros(num_envs)
            self.worlds: list[str] = []

        @staticmethod
        def flat(obs) -> np.ndarray:
            return policy_input(obs["state"], obs["edges"], obs["platform"],
                                obs["last_action"], obs["rays"])

        def _full_reset(self) -> np.ndarray:
            # seeds follow from the run's seed and the reset's number: reproducible
            seed = self.base_seed * 100_003 + self.resets * self.num_envs
            self.resets += 1
            obs, _ = self.venv.reset(seed=seed)
            self.worlds.append(self.venv.batch.world.name)
            self.ep_return[:] = 0.0
            return self.flat(obs)

        def reset(self):
            self.count = 0
            return self._full_reset()

        def step_async(self, actions):
            self.actions = np.clip(np.asarray(actions, dtype=np.float32), -1.0, 1.0)

        def step_wait(self):
            obs, reward, term, trunc, info = self.venv.step(self.actions)
            flat = self.flat(obs)
            done = term | trunc
            self.ep_return += reward
            infos = [{} for _ in range(self.num_envs)]
            if done.any():
                final = info["final_obs"]
                outcomes = info["final_info"]["outcome"]
                for i in np.flatnonzero(done):
                    o = final[i]
                    infos[i]["terminal_observation"] = self.flat(
                        {k: v[None] for k, v in o.items()})[0]
                    infos[i]["TimeLimit.truncated"] = bool(trunc[i] and not term[i])
                    self.outcomes[str(outcomes[i])] += 1
                    self.returns.append(float(self.ep_return[i]))
                    self.ep_return[i] = 0.0
            self.count += 1
            if self.count % self.world_every == 0:  # a new world: every episode ends
                for i in np.flatnonzero(~done):
                    infos[i]["terminal_observation"] = flat[i].copy()
                    infos[i]["TimeLimit.truncated"] = True
                done = np.ones(self.num_envs, bool)
                flat = self._full_reset()
            return flat, reward.astype(np.float32), done, infos

        def take_outcomes(self) -> tuple[Counter, list[float]]:
            out, ret = self.outcomes, self.returns
            self.outcomes, self.returns = Counter(), []
            return out, ret

        def close(self):
            self.venv.close()

        def get_attr(self, attr_name, indices=None):
            return [getattr(self, attr_name)] * len(self._indices(indices))

        def set_attr(self, attr_name, value, indices=None):
            setattr(self, attr_name, value)

        def env_method(self, method_name, *args, indices=None, **kwargs):
            raise NotImplementedError("PolicyVecEnv has no per-environment methods")

        def env_is_wrapped(self, wrapper_class, indices=None):
            return [False] * len(self._indices(indices))

        def _indices(self, indices):
            if indices is None:
                return range(self.num_envs)
            return [indices] if isinstance(indices, int) else indices

    return _PolicyVecEnv


#: the episode outcomes the training curve counts (fractions of the episodes that ended
#: in the rollout; the world changes' truncations are not episodes' ends)
CURVE_OUTCOMES = ("success", "collision", "mover_collision", "out_of_bounds",
                  "loss_of_control", "unstable", "timeout")
CURVE_FIELDS = ("steps", "wall_s", "episodes", *CURVE_OUTCOMES, "mean_return", "worlds")


def export_policy(model, meta: dict) -> MlpPolicy:
    """The actor of a Stable-Baselines3 PPO ``MlpPolicy`` as an :class:`MlpPolicy`: its
    hidden layers and the action head (the Gaussian's mean: the deterministic action)."""
    import torch.nn as nn  # the optional training stack (the model was trained with it)
    layers = []
    for m in model.policy.mlp_extractor.policy_net:
        if isinstance(m, nn.Linear):
            layers.append((m.weight.detach().cpu().numpy(), m.bias.detach().cpu().numpy()))
    head = model.policy.action_net
    layers.append((head.weight.detach().cpu().numpy(), head.bias.detach().cpu().numpy()))
    return MlpPolicy(layers, meta["activation"], meta)


def policy_meta(cfg: dict, steps: int) -> dict:
    """What the policy file records: how its input is built and its action scaled (the
    environment's settings the navigator must reproduce), the catalog range its platform
    vector is normalised to, and how it was trained."""
    env = dict(cfg["env"])
    env_cfg = make_config(env, dict(cfg["reward"]), env.pop("scenario_params", None),
                          env.pop("movers", None), env.pop("scenario_versions", None))
    v = env_cfg.values
    lo, hi = catalog_range(env_cfg.protocol)
    return {
        "activation": cfg["train"]["activation"],
        "control_hz": v["control_hz"],
        "max_speed_m_s": v["max_speed_m_s"],
        "max_climb_m_s": v["max_climb_m_s"],
        **{k: (list(v[k]) if isinstance(v[k], tuple) else v[k]) for k in RAY_KEYS},
        "platform_log_lo": lo.tolist(),
        "platform_log_hi": hi.tolist(),
        "protocol": env_cfg.protocol,
        "trained_steps": int(steps),
        "train": {k: (list(x) if isinstance(x, tuple) else x)
                  for k, x in cfg["train"].items()},
        "env": {k: (list(x) if isinstance(x, tuple) else x) for k, x in cfg["env"].items()},
        "reward": dict(env_cfg.reward),
        "software": software(),
    }


def train(cfg: dict, out: str | Path, progress: bool = True) -> Path:
    """Train with configuration ``cfg`` (:func:`load_config`) into directory ``out``:
    ``config.json`` (the resolved configuration), ``training.csv`` (one row per rollout:
    steps, wall time, the episodes that ended and their outcomes' fractions, mean return,
    worlds drawn), ``training.png`` and ``policy.npz``. Returns the policy file's path."""
    sb3, torch = _import_stack()
    # the optional training stack: imported only when a training runs
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback

    t = cfg["train"]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps(
        {k: {kk: (list(vv) if isinstance(vv, tuple) else vv) for kk, vv in v.items()}
         for k, v in cfg.items()}, indent=2, sort_keys=True) + "\n")
    torch.set_num_threads(int(t["threads"]))
    torch.manual_seed(int(t["seed"]))
    venv = policy_vec_env(cfg["env"], cfg["reward"], t["num_envs"], t["world_every"],
                          t["seed"])
    act = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[t["activation"]]
    hidden = [int(h) for h in t["hidden"]]
    model = PPO("MlpPolicy", venv, n_steps=t["n_steps"], batch_size=t["batch_size"],
                n_epochs=t["n_epochs"], learning_rate=t["learning_rate"], gamma=t["gamma"],
                gae_lambda=t["gae_lambda"], clip_range=t["clip_range"],
                ent_coef=t["ent_coef"], seed=t["seed"], device="cpu", verbose=0,
                policy_kwargs={"net_arch": {"pi": hidden, "vf": hidden},
                               "activation_fn": act, "log_std_init": t["log_std_init"]})
    curve_path = out / "training.csv"
    started = time.perf_counter()
    total = int(t["total_steps"])

    class Curve(BaseCallback):
        def __init__(self):
            super().__init__()
            self.f = open(curve_path, "w", newline="")  # noqa: SIM115 - closed at the end
            self.w = csv.writer(self.f)
            self.w.writerow(CURVE_FIELDS)
            self.bar = None
            self.next_save = int(t["save_every"])
            if progress:
                self.bar = tqdm(total=total, unit="step", desc="train", smoothing=0.05)

        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:
            outcomes, returns = venv.take_outcomes()
            n = sum(outcomes.values())
            fracs = [round(outcomes[k] / n, 4) if n else 0.0 for k in CURVE_OUTCOMES]
            self.w.writerow((self.num_timesteps, round(time.perf_counter() - started, 1), n,
                             *fracs,
                             round(float(np.mean(returns)), 3) if returns else math.nan,
                             venv.resets))
            self.f.flush()
            if self.num_timesteps >= self.next_save:
                self.next_save += int(t["save_every"])
                export_policy(model, policy_meta(cfg, self.num_timesteps)).save(
                    out / "policy-latest.npz")
            if self.bar is not None:
                self.bar.n = min(self.num_timesteps, total)
                self.bar.set_postfix(success=f"{fracs[0]:.2f}",
                                     collision=f"{fracs[1] + fracs[2]:.2f}")
                self.bar.refresh()

        def close(self):
            self.f.close()
            if self.bar is not None:
                self.bar.close()

    curve = Curve()
    try:
        model.learn(total_timesteps=total, callback=curve)
    finally:
        curve.close()
        venv.close()
    policy = export_policy(model, policy_meta(cfg, model.num_timesteps))
    path = out / "policy.npz"
    policy.save(path)
    plot_curve(curve_path, out / "training.png")
    return path


def plot_curve(csv_path: str | Path, png_path: str | Path) -> None:
    """The training curve: outcome fractions and mean return against steps."""
    # matplotlib: only for the plot (heavy to import)
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # (after choosing the Agg backend)
    df = pd.read_csv(csv_path)
    fig, (a, b) = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    # a world (one family) lasts world_every steps: smooth over many of them
    w = max(1, len(df) // 20)
    other = df["out_of_bounds"] + df["loss_of_control"] + df["unstable"]
    for series, label, colour in (
            (df["success"], "success", "tab:green"),
            (df["collision"] + df["mover_collision"], "collision", "tab:red"),
            (df["unstable"], "unstable (left the goal sphere in the hold)", "tab:purple"),
            (other - df["unstable"], "out of bounds / loss of control", "tab:orange"),
            (df["timeout"], "timeout", "tab:grey")):
        # episodes per rollout vary: weight each rollout's fractions by its episodes
        num = (series * df["episodes"]).rolling(w, min_periods=1).sum()
        den = df["episodes"].rolling(w, min_periods=1).sum().replace(0, np.nan)
        a.plot(df["steps"], num / den, label=label, color=colour)
    a.set_ylabel("fraction of episodes")
    a.set_ylim(0, 1)
    a.legend(loc="upper left", fontsize=8)
    b.plot(df["steps"], df["mean_return"].rolling(w, min_periods=1).mean(), color="k")
    b.set_ylabel("mean episode return")
    b.set_xlabel("environment steps")
    fig.suptitle(f"training ({len(df)} rollouts, rolling mean over {w})")
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)


def evaluate(policy: MlpPolicy, env_settings: dict, episodes_per_family: int = 8,
             seed: int = 1, families=None, num_envs: int = 8) -> list[dict]:
    """Fly ``policy`` (deterministic) in the environment (truth rays, as in training):
    per family, ``episodes_per_family`` episodes in batches of ``num_envs`` (one world per
    batch). Rows: family, scenario, platform, outcome, detail, time_s. Needs no training
    stack."""
    fams = list(families) if families is not None else list(REGISTRY)
    rows = []
    for k, fam in enumerate(fams):
        done_eps = 0
        r = 0
        while done_eps < episodes_per_family:
            n = min(num_envs, episodes_per_family - done_eps)
            env = NavigateVectorEnv(n, autoreset_mode="SameStep",
                                    **{**env_settings, "family": fam})
            obs, _ = env.reset(seed=seed * 1_000_003 + k * 10_007 + r * n)
            live = np.ones(n, bool)
            while live.any():
                a = policy.act(policy_input(obs["state"], obs["edges"], obs["platform"],
                                            obs["last_action"], obs["rays"]))
                obs, _, term, trunc, info = env.step(a.astype(np.float32))
                # (each slot's first episode counts; the ones it starts after are ignored)
                for i in np.flatnonzero(live & (term | trunc)):
                    fin = info["final_info"]
                    rows.append({"family": fam, "scenario": fin["scenario"][i],
                                 "platform": fin["platform"][i],
                                 "outcome": fin["outcome"][i], "detail": fin["detail"][i],
                                 "time_s": float(fin["time_s"][i])})
                live &= ~(term | trunc)
            env.close()
            done_eps += n
            r += 1
    return rows
