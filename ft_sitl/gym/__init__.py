"""Gymnasium environments over the simulator (reference: docs/gym.md).

Importing this package registers them with Gymnasium::

    import gymnasium as gym
    import ft_sitl.gym  # noqa: F401  (registers ftsitl/Navigate-v0, ftsitl/Hover-v0)

    env = gym.make("ftsitl/Navigate-v0")                     # one vehicle
    envs = gym.make_vec("ftsitl/Navigate-v0", num_envs=256)  # 256 in one physics call

The layer sits above the mission runner (it judges episodes with the benchmark's own
rules, :mod:`ft_sitl.missions.protocol`) and below the command line.
"""

from __future__ import annotations

import gymnasium

from ft_sitl.gym.config import (
    ENV_SCHEMA,
    REWARD_SCHEMA,
    ActionError,
    EnvError,
)
from ft_sitl.gym.envs import NavigateEnv, NavigateVectorEnv

__all__ = ["ENV_SCHEMA", "ENVIRONMENTS", "REWARD_SCHEMA", "ActionError", "EnvError",
           "NavigateEnv", "NavigateVectorEnv"]

#: the registered environments: id -> the settings they add to the defaults
ENVIRONMENTS = {
    # fly to the goal of a Forest configuration (1..10, the benchmark's seed 0) on a
    # catalog platform, velocity actions, a ray scan; judged as the benchmark judges
    "ftsitl/Navigate-v0": {},
    # hold a point 0.5-3 m from the start in an empty 20 x 20 x 6 m box for 20 s: no goal
    # rule (only crashes and the time limit end it), rewarded for closing in and staying
    "ftsitl/Hover-v0": {"family": "arena", "goal_rule": False, "sensor": "none",
                        "timeout_s": 20.0, "goal_radius_m": 0.3,
                        "reward": {"progress": 1.0, "distance": 0.5, "in_goal": 1.0}},
}

for _id, _kwargs in ENVIRONMENTS.items():
    if _id not in gymnasium.registry:
        gymnasium.register(id=_id, entry_point="ft_sitl.gym.envs:NavigateEnv",
                           vector_entry_point="ft_sitl.gym.envs:NavigateVectorEnv",
                           kwargs=dict(_kwargs))
