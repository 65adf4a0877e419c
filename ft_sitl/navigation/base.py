"""The Navigator protocol: what a navigation algorithm sees and what it returns.

A navigator flies one trial's navigation phase. The trial runner (``ft_sitl.missions``)
calls :meth:`Navigator.reset` once with the :class:`Task` (start, goal, limits, flight
volume, platform indicators, a seeded RNG), then :meth:`Navigator.step` at the
navigator's own rate (``rate_hz``, simulated time) with an :class:`Observation`, and sends
the returned :class:`~ft_sitl.autopilot.setpoints.Setpoint` to the flight controller as a
PX4 offboard setpoint: exactly what a MAVSDK/MAVLink navigator does over the wire
(``ft_sitl.navigation`` over MAVSDK uses the same objects).

A navigator that needs depth images sets ``camera`` to a
:class:`~ft_sitl.scenarios.camera.CameraConfig`; it then gets a fresh
:class:`~ft_sitl.scenarios.camera.DepthFrame` in ``Observation.depth`` whenever one is due
at the camera's rate (else None). A navigator that sets ``needs_mover_truth`` gets the
moving obstacles' ground truth (:class:`ObstacleStates`) in ``Observation.movers`` at every
step: from the in-process trial driver only (a navigator flown over the wire gets None).

A navigator that cannot go on (no path) raises :class:`GiveUp`; the trial then fails as a
timeout with the navigator's reason (the protocol counts "no plan" as a timeout). Any other
exception, or a return value that is not a valid Setpoint, fails the trial as a navigator
error; the campaign goes on.

Before navigation starts the vehicle flies the approach (arming, take-off, the start
waypoint) under the flight controller; from protocol version 3 on the navigator is reset
before it and gets what the camera sees on the way through :meth:`Navigator.observe`.

Frames: world ENU (x east, y north, z up), metres, radians, like the rest of ft_sitl.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.schema import Schema

#: navigation starts once the vehicle is stable at the start waypoint: within
#: STABLE_POS_M of it (m) and slower than STABLE_SPEED_M_S (m/s) for STABLE_FOR_S (s). The
#: protocol judges it (ft_sitl.missions.protocol); a navigator flying its own approach
#: over the wire (ft-sitl navigate) waits for the same.
STABLE_POS_M = 0.3
STABLE_SPEED_M_S = 0.3
STABLE_FOR_S = 1.0


class GiveUp(Exception):  # noqa: N818 - a signal, not an error
    """Raised by a navigator that has no way to the goal; the message says why."""


@dataclass(frozen=True)
class Limits:
    """The benchmark's limits, identical for every algorithm (protocol Sec. IV-B).

    ``max_acc_m_s2`` is the acceleration limit every planner plans with (protocol 3 on;
    None: each planner's own ``max_acc_m_s2`` parameter, the rule before). It is a
    planning constraint, like the paper's "acceleration constraints": the flight controller
    does not clamp the navigator's setpoints to it (docs/control.md, stage 3)."""

    max_speed_m_s: float = 4.0
    timeout_s: float = 90.0
    goal_radius_m: float = 2.0
    hold_s: float = 3.0
    max_acc_m_s2: float | None = None

    def __post_init__(self):
        for name in ("max_speed_m_s", "timeout_s", "goal_radius_m", "hold_s",
                     "max_acc_m_s2"):
            v = getattr(self, name)
            if v is None and name == "max_acc_m_s2":
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v <= 0:
                raise ValueError(f"limits.{name}: must be a positive number, got {v!r}")
            object.__setattr__(self, name, float(v))

    def as_dict(self) -> dict:
        """The limits as data (``max_acc_m_s2`` left out when None, so the specs of trials
        written before it existed keep their ids)."""
        d = {"max_speed_m_s": self.max_speed_m_s, "timeout_s": self.timeout_s,
             "goal_radius_m": self.goal_radius_m, "hold_s": self.hold_s}
        if self.max_acc_m_s2 is not None:
            d["max_acc_m_s2"] = self.max_acc_m_s2
        return d


@dataclass(frozen=True, eq=False)
class Task:
    """What a navigator is told at the start of a navigation phase."""

    start: np.ndarray
    start_yaw: float
    goal: np.ndarray
    limits: Limits
    bounds_min: np.ndarray
    bounds_max: np.ndarray
    collision_radius_m: float
    twr_max: float
    alpha_xy_max: float
    alpha_z_max: float
    rng: np.random.Generator = field(default_factory=lambda: np.random.default_rng(0))
    #: how far navigators keep obstacles away (m): the platform's footprint (its collision
    #: radius) from protocol 4 on, which each planner inflates its map by as a user sets
    #: the original for their airframe; None: the navigator's own default (before 4)
    footprint_m: float | None = None

    @property
    def ceiling(self) -> float:
        return float(self.bounds_max[2])


@dataclass(frozen=True, eq=False)
class ObstacleStates:
    """Moving obstacles as boxes, world ENU: ``position`` (M, 3) box centres (m),
    ``velocity`` (M, 3) (m/s), ``size`` (M, 3) full edge lengths of the axis-aligned
    boxes (m). What a detector reports, or the simulator's ground truth."""

    position: np.ndarray
    velocity: np.ndarray
    size: np.ndarray

    def __post_init__(self):
        for name in ("position", "velocity", "size"):
            a = np.asarray(getattr(self, name), dtype=np.float64)
            if a.ndim != 2 or a.shape[1] != 3 or not np.all(np.isfinite(a)):
                raise ValueError(f"ObstacleStates.{name} must be a finite (M, 3) array, got "
                                 f"shape {a.shape}")
            object.__setattr__(self, name, a)
        if not len(self.position) == len(self.velocity) == len(self.size):
            raise ValueError("ObstacleStates: position, velocity and size need one row per "
                             "obstacle each")

    @property
    def count(self) -> int:
        return len(self.position)

    @classmethod
    def empty(cls) -> ObstacleStates:
        z = np.zeros((0, 3))
        return cls(z, z, z)

    def take(self, index) -> ObstacleStates:
        """The obstacles at ``index`` (an index array or a mask), in that order."""
        return ObstacleStates(self.position[index], self.velocity[index], self.size[index])


@dataclass(frozen=True, eq=False)
class Observation:
    """The vehicle's state as the flight controller estimates it, at ``time_s`` seconds
    after navigation start (simulated time)."""

    time_s: float
    position: np.ndarray
    velocity: np.ndarray
    yaw: float
    attitude: np.ndarray  # quaternion w, x, y, z (ENU / FLU)
    angular_velocity: np.ndarray  # body rates (FLU), rad/s
    depth: object | None = None  # a DepthFrame when one is due
    #: the moving obstacles' ground truth now (an ObstacleStates; empty in a static
    #: world), given only to a navigator whose ``needs_mover_truth`` is True, and only by
    #: the in-process trial driver (None otherwise)
    movers: ObstacleStates | None = None


class Navigator:
    """Base class of navigators. Subclasses set ``name`` and implement :meth:`step`.

    The navigator's parameters are declared once, in ``schema`` (a
    :class:`~ft_sitl.schema.Schema`: name, default, unit, range, doc of each); the
    registry validates a campaign's ``params`` with it, and they are stored with every
    trial's spec. The constructor takes them as keyword arguments and leaves them, checked
    and completed with the defaults, in ``self.settings``. ``rate_hz`` is how often
    :meth:`step` is called; ``replans`` is a counter the navigator increments when it plans
    again.
    """

    name: str = ""
    rate_hz: float = 20.0
    camera = None  # a CameraConfig to receive depth frames
    #: True: the trial driver puts the moving obstacles' ground truth in every
    #: Observation (``movers``); a navigator sets it when a parameter asks for the truth
    needs_mover_truth: bool = False
    schema: Schema = Schema()

    def __init__(self, **params):
        self.settings = type(self).schema.resolve(params, f"navigator {self.name!r}")
        self.replans = 0

    @classmethod
    def unavailable(cls) -> str | None:
        """Why this navigator cannot run on this machine (e.g. model weights the user has
        not supplied), or None. ``algorithms = "all"`` leaves such navigators out."""
        return None

    def reset(self, task: Task) -> None:
        """Called once before the first step of a navigation phase (from protocol 3 on,
        before the approach: :meth:`observe` then gets what the vehicle sees on its way
        to the start)."""
        self.task = task
        self.replans = 0

    def observe(self, obs: Observation) -> None:
        """What the vehicle sees before navigation starts (protocol 3 on: from arming,
        through take-off, the approach and the hover at the start), at the camera's rate;
        ``obs.time_s`` counts from arming. Nothing is returned: the flight controller
        flies the approach. The default ignores it; a navigator with a map fuses the
        depth frames, as the originals do from the moment their camera runs."""

    def step(self, obs: Observation) -> Setpoint:  # pragma: no cover - abstract
        raise NotImplementedError

