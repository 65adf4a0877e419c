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

from ft_sitl.autopilot.params import PARAMS
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.schema import Param, Schema

#: navigation starts once the vehicle is stable at the start waypoint: within
#: STABLE_POS_M of it (m) and slower than STABLE_SPEED_M_S (m/s) for STABLE_FOR_S (s). The
#: protocol judges it (ft_sitl.missions.protocol); a navigator flying its own approach
#: over the wire (ft-sitl navigate) waits for the same.
STABLE_POS_M = 0.3
STABLE_SPEED_M_S = 0.3
STABLE_FOR_S = 1.0


class GiveUp(Exception):  # noqa: N818 - a signal, not an error
    """Raised by a navigator that has no way to the goal; the message says why."""


#: the benchmark's limits, declared once (protocol Sec. IV-B): :class:`Limits` takes its
#: defaults and ranges from here, and so do campaign files, the Gymnasium environments and
#: ``ft-sitl navigate``. Which version of the trial protocol changed which limit is in
#: ``ft_sitl.missions.spec.PROTOCOLS`` (the acceleration limit came with version 3).
LIMITS = Schema((
    # its range ends where the flight controller's MPC_XY_VEL_MAX does
    Param("max_speed_m_s", 4.0, "m/s", (0.1, PARAMS["MPC_XY_VEL_MAX"].hi),
          doc="the speed cap: planners plan with it, the flight controller enforces it "
              "(PX4's MPC_XY_VEL_MAX)"),
    Param("timeout_s", 90.0, "s", (0.1, 3600.0),
          doc="a navigation not in the goal sphere this long after it started is a timeout"),
    Param("goal_radius_m", 2.0, "m", (0.01, 100.0),
          doc="the goal sphere's radius"),
    Param("hold_s", 3.0, "s", (0.001, 600.0),
          doc="success: the time to stay in the goal sphere after entering it"),
    Param("max_acc_m_s2", None, "m/s^2", (0.1, 100.0), kind="float",
          doc="the acceleration limit every planner plans with, a planning constraint the "
              "flight controller does not clamp setpoints to (none: the protocol "
              "version's, 3 from version 3; before 3 each planner's own max_acc_m_s2)"),
))


@dataclass(frozen=True)
class Limits:
    """The benchmark's limits, identical for every algorithm (:data:`LIMITS` declares
    each: default, unit, range, meaning).

    ``max_acc_m_s2`` None means the rule of the trial's protocol version (a spec writes
    the version's value in; docs/control.md, stage 3, for why the flight controller does
    not clamp the navigator's setpoints to it)."""

    max_speed_m_s: float = LIMITS["max_speed_m_s"].default
    timeout_s: float = LIMITS["timeout_s"].default
    goal_radius_m: float = LIMITS["goal_radius_m"].default
    hold_s: float = LIMITS["hold_s"].default
    max_acc_m_s2: float | None = LIMITS["max_acc_m_s2"].default

    def __post_init__(self):
        for param in LIMITS:  # (SchemaError, a ValueError, naming the limit and its range)
            v = getattr(self, param.name)
            param.check(v, "limits")
            if v is not None:
                object.__setattr__(self, param.name, float(v))

    def as_dict(self) -> dict:
        """The limits as data (``max_acc_m_s2`` left out when None, so the specs of trials
        written before it existed keep their ids)."""
        d = {"max_speed_m_s": self.max_speed_m_s, "timeout_s": self.timeout_s,
             "goal_radius_m": self.goal_radius_m, "hold_s": self.hold_s}
        if self.max_acc_m_s2 is not None:
            d["max_acc_m_s2"] = self.max_acc_m_s2
        return d


#: the Task's vectors (world ENU, m), its finite numbers, and its optional positive ones
TASK_VECTORS = ("start", "goal", "bounds_min", "bounds_max", "origin")
TASK_NUMBERS = ("start_yaw", "collision_radius_m", "twr_max", "alpha_xy_max", "alpha_z_max")
TASK_OPTIONAL = ("footprint_m", "map_fusion_hz")


class TaskError(ValueError):
    """A task document is invalid; the message names the field."""


@dataclass(frozen=True, eq=False)
class Task:
    """What a navigator is told at the start of a navigation phase: the trial plan's face
    towards the navigator (:mod:`ft_sitl.missions.plan`), the same object in-process and
    over MAVLink, where it travels as :meth:`to_dict` (``ft-sitl navigate --task-json``,
    a user script's ``FT_SITL_TASK``).

    ``seed`` is the entropy of the navigator's random stream (a tuple of non-negative
    integers, numpy's ``SeedSequence``); ``rng`` is that stream, made once per task."""

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
    seed: tuple = (0,)
    #: how far navigators keep obstacles away (m): the platform's footprint (its collision
    #: radius) from protocol 4 on, which each planner inflates its map by as a user sets
    #: the original for their airframe; None: the navigator's own default (before 4)
    footprint_m: float | None = None
    #: where the vehicle took off (world ENU, m): the origin of the flight controller's
    #: local NED frame, which a navigator flying over MAVLink converts with
    origin: np.ndarray | None = None
    #: the navigator is reset before arming and observes the approach (protocol 3 on)
    observe_approach: bool = False
    #: the navigator's map takes the latest depth frame at this rate (Hz; protocol 6 on,
    #: the originals' map timer; None: every frame as it arrives)
    map_fusion_hz: float | None = None
    rng: np.random.Generator = field(init=False, repr=False)

    def __post_init__(self):
        seed = (self.seed,) if isinstance(self.seed, int) else self.seed
        if not (isinstance(seed, (tuple, list)) and seed and all(
                isinstance(k, (int, np.integer)) and not isinstance(k, bool) and k >= 0
                for k in seed)):
            raise TaskError(f"task seed: {self.seed!r} is not a non-negative integer or a "
                            f"list of them")
        object.__setattr__(self, "seed", tuple(int(k) for k in seed))
        if self.origin is None:
            object.__setattr__(self, "origin", np.zeros(3))
        object.__setattr__(self, "rng",
                           np.random.default_rng(np.random.SeedSequence(list(self.seed))))

    @property
    def ceiling(self) -> float:
        return float(self.bounds_max[2])

    def to_dict(self) -> dict:
        """The task as JSON-able data: one flat table (the limits' fields at its top), the
        document ``from_dict`` reads back into an equal task."""
        d = {k: [float(x) for x in getattr(self, k)] for k in TASK_VECTORS}
        d.update({k: float(getattr(self, k)) for k in TASK_NUMBERS})
        d.update({k: getattr(self, k) for k in TASK_OPTIONAL})
        d.update(seed=list(self.seed), observe_approach=self.observe_approach,
                 max_speed_m_s=self.limits.max_speed_m_s, timeout_s=self.limits.timeout_s,
                 goal_radius_m=self.limits.goal_radius_m, hold_s=self.limits.hold_s,
                 max_acc_m_s2=self.limits.max_acc_m_s2)
        return d

    @classmethod
    def from_dict(cls, doc) -> Task:
        """The task of a :meth:`to_dict` document; TaskError naming the field that is
        missing, unknown or wrong. (A ``seed`` given as one integer is the same stream as
        the list of that integer: documents written before it became a list read back.)"""
        if not isinstance(doc, dict):
            raise TaskError("task: must be a JSON object")
        limit_keys = tuple(LIMITS.names())
        known = set(TASK_VECTORS + TASK_NUMBERS + TASK_OPTIONAL + limit_keys) | {
            "seed", "observe_approach"}
        unknown = sorted(set(doc) - known)
        if unknown:
            raise TaskError(f"task: unknown field(s) {', '.join(unknown)}")
        missing = [k for k in ("start", "goal", "start_yaw") if k not in doc]
        if missing:
            raise TaskError(f"task: missing field(s) {', '.join(missing)}")
        defaults = TASK_DEFAULTS
        kw = {}
        for k in TASK_VECTORS:
            v = doc.get(k, defaults.get(k))
            if not (isinstance(v, (list, tuple)) and len(v) == 3 and all(
                    _finite(x) for x in v)):
                raise TaskError(f"task {k}: {v!r} is not three finite numbers")
            kw[k] = np.array([float(x) for x in v])
        for k in TASK_NUMBERS:
            v = doc.get(k, defaults.get(k))
            if not _finite(v):
                raise TaskError(f"task {k}: {v!r} is not a finite number")
            kw[k] = float(v)
        for k in TASK_OPTIONAL:
            v = doc.get(k)
            if v is not None and not (_finite(v) and v > 0):
                raise TaskError(f"task {k}: {v!r} is not a positive number or null")
            kw[k] = None if v is None else float(v)
        observe = doc.get("observe_approach", False)
        if not isinstance(observe, bool):
            raise TaskError(f"task observe_approach: {observe!r} is not true or false")
        try:
            limits = Limits(**{k: doc[k] for k in limit_keys if k in doc})
        except ValueError as exc:
            raise TaskError(f"task {exc}") from None
        return cls(limits=limits, seed=doc.get("seed", 0), observe_approach=observe, **kw)


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


#: what a task document may leave out: a flight volume of 2 km x 2 km x 100 m around the
#: origin, a 0.3 m vehicle with the indicators of a middling platform
TASK_DEFAULTS = {"bounds_min": [-1e3, -1e3, 0.0], "bounds_max": [1e3, 1e3, 100.0],
                 "origin": [0.0, 0.0, 0.0], "collision_radius_m": 0.3, "twr_max": 2.0,
                 "alpha_xy_max": 50.0, "alpha_z_max": 5.0}


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
    def camera_for(cls, settings: dict):
        """The depth camera this navigator asks for with these resolved settings (None:
        none): the one its camera parameters name (``scenarios.camera.CAMERA_PARAMS``),
        else the class's ``camera``. The trial plan reads it before the navigator exists;
        a navigator whose camera depends on anything else overrides this."""
        if "camera" in settings and "camera_rate_hz" in settings:
            from ft_sitl.scenarios.camera import camera_of  # (the protocol loads no camera)
            return camera_of(settings)
        return cls.camera

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

