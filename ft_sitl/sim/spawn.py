"""Where N vehicles of a fleet start: in a row on open ground, or at a scenario's takeoff
point and beside it, each clear of the scenario's obstacles."""

from __future__ import annotations

import math

import numpy as np

from ft_sitl.scenarios.collision import CollisionWorld

__all__ = ["SPACING_M", "SpawnError", "spawn_points"]

SPACING_M = 1.5
"""Distance between neighbouring vehicles across a scenario's start direction (m)."""


class SpawnError(ValueError):
    """A vehicle's spawn point is blocked by an obstacle or outside the scenario's area."""


def spawn_points(n: int, scenario=None, collision_radius_m: float = 0.0):
    """(spawn positions ENU m, spawn yaws rad) of ``n`` vehicles.

    Without a scenario: 2 m apart along +y from the origin, yaw 0. With one: the first at
    the scenario's takeoff point, further vehicles :data:`SPACING_M` apart on alternate
    sides across the start direction, all facing it; a vehicle's sphere (radius
    ``collision_radius_m``, resting on the ground) must be clear of obstacles and bounds,
    else :class:`SpawnError`.
    """
    if scenario is None:
        return [[0.0, 2.0 * i, 0.0] for i in range(n)], [0.0] * n
    yaw = scenario.start_yaw
    across = np.array([-math.sin(yaw), math.cos(yaw), 0.0])
    world = CollisionWorld(scenario.mesh, scenario.bounds_min, scenario.bounds_max)
    r = collision_radius_m
    spawn = []
    for k in range(n):
        off = SPACING_M * ((k + 1) // 2) * (1 if k % 2 else -1)
        pos = scenario.takeoff + off * across
        centre = pos + np.array([0.0, 0.0, r + 0.01])
        if world.clearance(centre, r, kinds=("obstacle", "bounds")) <= 0.0:
            raise SpawnError(f"vehicle {k + 1}'s spawn point {np.round(pos, 2).tolist()} in "
                             f"{scenario.name} is blocked by an obstacle or outside the area; "
                             f"use fewer instances")
        spawn.append(pos.tolist())
    return spawn, [yaw] * n
