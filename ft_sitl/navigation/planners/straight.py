"""The straight-flight baseline (paper Sec. IV-A): no sensing, no avoidance.

It flies the straight start -> goal line at constant speed: a reference point moves along
the line from the start at ``speed`` (default: the speed cap, 4 m/s), and the navigator
sends it as a PX4 position setpoint with the line's velocity as feed-forward, heading along
the line. Once the reference reaches the goal it holds there. Whatever lies on the line is
hit; the benchmark uses it as the floor every algorithm should beat.
"""

from __future__ import annotations

import math

import numpy as np

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.navigation.base import Navigator, Observation, Task
from ft_sitl.schema import Param, Schema


class StraightLine(Navigator):
    name = "straight"
    rate_hz = 20.0

    schema = Schema((
        Param("speed_m_s", None, "m/s", (0.1, 50.0), kind="float",
              doc="flight speed along the line, capped at the speed limit (none: the cap)"),
    ))

    def __init__(self, **params):
        super().__init__(**params)
        self.speed_m_s = self.settings["speed_m_s"]

    def reset(self, task: Task) -> None:
        super().reset(task)
        d = task.goal - task.start
        self._length = float(np.linalg.norm(d))
        self._u = d / self._length if self._length > 0 else np.zeros(3)
        cap = task.limits.max_speed_m_s
        self._v = min(self.speed_m_s, cap) if self.speed_m_s is not None else cap
        self._yaw = math.atan2(d[1], d[0]) if self._length > 0 else task.start_yaw

    def step(self, obs: Observation) -> Setpoint:
        s = self._v * obs.time_s
        if s >= self._length:
            return Setpoint.position(self.task.goal, yaw=self._yaw)
        return Setpoint.position(self.task.start + s * self._u, velocity=self._v * self._u,
                                 yaw=self._yaw)
