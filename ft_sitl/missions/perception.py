"""What the navigator perceives, made imperfect: latency, state noise, dropped frames.

A trial's ``perception`` settings (declared once in :data:`SCHEMA`) change what the
in-process driver hands the navigator during navigation, not the vehicle:

- **latency:** the state and the depth frames reach the navigator ``latency_s`` after
  they were measured and captured (its clock, ``Observation.time_s``, is now: it acts on
  an old picture of the world, as a planner fed by a slow pipeline does). The delay is
  served at the navigator's steps, so it is rounded up to whole steps (the first
  ``latency_s`` of navigation hand over the state at its start);
- **state noise:** Gaussian noise on the position (``position_noise_m``, each axis) and
  the velocity (``velocity_noise_m_s``) the navigator is told;
- **dropped frames:** each depth frame is lost with probability ``frame_dropout``.

The noise and dropouts draw from the trial's own stream (seeded from its seed and
repetition), so a trial reruns bit for bit. The approach phase is not affected (the
navigator observes the hover as before), and neither is the flight controller, which
flies on the true state. Over MAVLink the navigator runs in its own process with the
transport's own timing; perception settings are refused there.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ft_sitl.schema import Param, Schema

SCHEMA = Schema((
    Param("latency_s", 0.0, "s", (0.0, 1.0),
          doc="delay from measurement to the navigator (rounded up to its steps)"),
    Param("position_noise_m", 0.0, "m", (0.0, 5.0),
          doc="position noise, standard deviation per axis"),
    Param("velocity_noise_m_s", 0.0, "m/s", (0.0, 5.0),
          doc="velocity noise, standard deviation per axis"),
    Param("frame_dropout", 0.0, "-", (0.0, 1.0), doc="probability a depth frame is lost"),
))


class Perception:
    """The settings and, during a navigation, the pipeline between the vehicle's state and
    camera and the navigator."""

    def __init__(self, values: dict | None = None, owner: str = "perception"):
        self.values = SCHEMA.resolve(values, owner)

    @property
    def ideal(self) -> bool:
        return all(v == 0.0 for v in self.values.values())

    def start(self, rng: np.random.Generator) -> None:
        """A new navigation: an empty pipeline, noise from ``rng``."""
        self.rng = rng
        self.latency_us = round(self.values["latency_s"] * 1e6)
        self.queue: deque = deque()
        self.state = None
        self.frame = None

    def pass_through(self, t_us: int, sample: tuple, frame):
        """Measured at ``t_us`` (navigation clock): ``sample`` (position, velocity, yaw,
        attitude, body rates) and a depth frame or None; what the navigator gets now, the
        same shapes. Noise is added when a sample is measured, a frame dropped when it is
        captured."""
        v = self.values
        position, velocity, yaw, attitude, rates = sample
        if v["position_noise_m"] > 0:
            position = position + self.rng.normal(0.0, v["position_noise_m"], 3)
        if v["velocity_noise_m_s"] > 0:
            velocity = velocity + self.rng.normal(0.0, v["velocity_noise_m_s"], 3)
        if frame is not None and v["frame_dropout"] > 0 and \
                self.rng.random() < v["frame_dropout"]:
            frame = None
        measured = (position, velocity, yaw, attitude, rates)
        if not self.latency_us:
            return measured, frame
        self.queue.append((t_us + self.latency_us, measured, frame))
        out_frame = None
        while self.queue and self.queue[0][0] <= t_us:
            _, self.state, f = self.queue.popleft()
            if f is not None:
                out_frame = f  # (the newest frame released now)
        if self.state is None:  # nothing old enough yet: the first measurement
            self.state = self.queue[0][1]
        return self.state, out_frame
