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
- **dropped frames:** each depth frame is lost with probability ``frame_dropout``;
- **depth-image noise:** the navigator's depth camera gets the stereo noise model of
  :mod:`ft_sitl.scenarios.camera` (Gaussian on z-depth, ``sigma = depth_noise_k * z**2``;
  ``stereo_noise_k`` gives k for a rig, ~0.004 1/m for a D435 at 640 px) and a per-pixel
  dropout ``depth_dropout``, in place of the camera's own settings. Unlike the rest, this
  is the camera's: it holds for every frame, the approach's too (protocol 3 on).

The noise and dropouts draw from the trial's own stream (seeded from its seed and
repetition), so a trial reruns bit for bit. Apart from the depth-image noise, the
approach phase is not affected (the navigator observes the hover as before), and the
flight controller never is: its own estimate is the trial's ``estimator``
(:mod:`ft_sitl.autopilot.estimator`), which is also what the navigator's state starts
from before these settings act on it. Over MAVLink the navigator runs in its own process with the
transport's own timing; perception settings are refused there.
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace

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
    Param("depth_noise_k", 0.0, "1/m", (0.0, 0.1),
          doc="depth-image noise: standard deviation k z^2 at depth z"),
    Param("depth_dropout", 0.0, "-", (0.0, 0.99),
          doc="probability a depth pixel has no value"),
))


class Perception:
    """The settings and, during a navigation, the pipeline between the vehicle's state and
    camera and the navigator."""

    def __init__(self, values: dict | None = None, owner: str = "perception"):
        self.values = SCHEMA.resolve(values, owner)

    @property
    def ideal(self) -> bool:
        return all(v == 0.0 for v in self.values.values())

    def camera_config(self, cfg):
        """The navigator's camera configuration with this depth-image noise (``cfg``
        itself when neither is set)."""
        v = self.values
        if v["depth_noise_k"] == 0.0 and v["depth_dropout"] == 0.0:
            return cfg
        return replace(cfg, noise_k=v["depth_noise_k"], dropout=v["depth_dropout"])

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
