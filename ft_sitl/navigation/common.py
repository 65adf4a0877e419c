"""Pieces the planners share: the depth camera they use, angle wrapping, a B-spline
trajectory started at a time, yaw pursuit and the NaN guard on every setpoint."""

from __future__ import annotations

import math

import numpy as np

from ft_sitl.autopilot.setpoints import Setpoint

#: after a failed plan, the next attempt waits this long (simulated s), doubling with each
#: further failure in a row up to RETRY_MAX_S
RETRY_S = 0.05
RETRY_MAX_S = 1.0


def wrap_angle(a: float) -> float:
    """a wrapped into [-pi, pi)."""
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def camera_config(camera: str, width: int | None, height: int | None, rate_hz: float | None):
    """The planners' depth camera: "benchmark" (160 x 120 @ 15 Hz) or "d435" (the originals'
    stream with every second pixel: 320 x 240 @ 30 Hz), optionally resized."""
    from dataclasses import replace

    from ft_sitl.scenarios.camera import CameraConfig

    base = CameraConfig(max_range_m=10.0)
    if camera == "benchmark":
        cfg = replace(base.subsampled(4), rate_hz=15.0)
    elif camera == "d435":
        cfg = replace(base.subsampled(2), rate_hz=30.0)
    else:
        raise ValueError(f"camera: {camera!r} is not 'benchmark' or 'd435'")
    if width is not None or height is not None:
        w = int(width or cfg.width)
        h = int(height or cfg.height)
        if not (16 <= w <= 1280 and 12 <= h <= 960):
            raise ValueError(f"camera_width/height: {w} x {h} outside 16..1280 x 12..960")
        step_x = base.width / w
        cfg = replace(base, width=w, height=h, fx=base.fx / step_x, fy=base.fy / step_x,
                      cx=(w - 1) / 2.0, cy=(h - 1) / 2.0, rate_hz=cfg.rate_hz)
    if rate_hz is not None:
        if not (isinstance(rate_hz, (int, float)) and 1.0 <= rate_hz <= 60.0):
            raise ValueError(f"camera_rate_hz: {rate_hz!r} must be within 1..60")
        cfg = replace(cfg, rate_hz=float(rate_hz))
    return cfg


class SplineTrajectory:
    """A B-spline trajectory started at navigation time ``t0`` (s)."""

    def __init__(self, spline, t0: float):
        self.spline = spline
        self.t0 = t0
        self.start = spline.position(0.0)

    def state(self, t: float):
        """Position, velocity, acceleration at time t (clamped to the trajectory)."""
        tau = min(max(t - self.t0, 0.0), self.spline.duration)
        pva = getattr(self.spline, "pva", None)
        if pva is not None:
            return pva(tau)
        return (self.spline.position(tau), self.spline.velocity(tau),
                self.spline.acceleration(tau))

    @property
    def end_time(self) -> float:
        return self.t0 + self.spline.duration


def pursue_yaw(yaw: float, direction, rate_hz: float) -> float:
    """One step of the planners' yaw: toward the horizontal ``direction`` (unchanged when it
    is shorter than 0.1 m), rate-limited to pi rad/s at ``rate_hz``, low-pass 0.5."""
    if float(np.hypot(direction[0], direction[1])) <= 0.1:
        return yaw
    step = wrap_angle(math.atan2(direction[1], direction[0]) - yaw)
    limit = math.pi / rate_hz
    return wrap_angle(yaw + 0.5 * max(-limit, min(limit, step)))


def checked_setpoint(t: float, p, v, a, yaw: float, yaw_rate: float | None = None) -> Setpoint:
    """The position + velocity + acceleration setpoint, or FloatingPointError when any part
    is not finite: a planner never commands NaN (the trial fails as a navigator error)."""
    if not (np.all(np.isfinite(p)) and np.all(np.isfinite(v)) and np.all(np.isfinite(a))
            and math.isfinite(yaw) and (yaw_rate is None or math.isfinite(yaw_rate))):
        raise FloatingPointError(f"non-finite setpoint at t = {t:.2f} s: p {p}, v {v}, "
                                 f"a {a}, yaw {yaw}, yaw rate {yaw_rate}")
    return Setpoint.position(p, velocity=v, acceleration=a, yaw=yaw, yaw_rate=yaw_rate)
