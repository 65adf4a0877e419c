"""What the gym tests share: a small Forest (a quick world to build) and a wall across the
start -> goal line."""

from __future__ import annotations

import numpy as np
import trimesh

from ft_sitl.scenarios.scenario import Scenario

#: Forest configuration 2 on a 12 x 20 m area: trees on the line, a grid built in ~0.2 s
SMALL = {"scenario_index": (2, 2), "scenario_params": {"size_m": [12.0, 20.0]}}


def wall_scenario() -> Scenario:
    """A 10 x 16 x 4 m volume with a 0.3 m wall across it at y = 8: flying straight from
    the start (5, 2, 1.5) to the goal (5, 14, 1.5) hits it."""
    wall = trimesh.creation.box(extents=[10.0, 0.3, 6.0])
    wall.apply_translation([5.0, 8.0, 3.0])
    return Scenario("wall", 1, 0, "user", wall, (0.0, 0.0, 0.0), (10.0, 16.0, 4.0),
                    (5.0, 2.0, 0.0), (5.0, 2.0, 1.5), np.pi / 2, (5.0, 14.0, 1.5))


def roll(env, actions, *, seed=None):
    """(observations, rewards, terminated, truncated, infos) of an episode flown with the
    actions in turn until it ends or they run out."""
    out = [env.reset(seed=seed)]
    for a in actions:
        out.append(env.step(a))
        if out[-1][2] or out[-1][3]:
            break
    return out
