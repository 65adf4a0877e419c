"""What an environment is made of, declared once: its settings (:data:`ENV_SCHEMA`), its
reward's terms (:data:`REWARD_SCHEMA`) and the reset options (:data:`RESET_OPTIONS`).

Every setting is a :class:`~ft_sitl.schema.Param` (name, default, unit, allowed range,
one line of documentation); docs/gym.md's tables are generated from these declarations
and tested against them. A setting given as an interval ``[lo, hi]`` is a distribution:
each episode draws its value uniformly from it (``[x, x]``: always x).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

from ft_sitl.config import did_you_mean
from ft_sitl.missions.spec import PROTOCOL_VERSION
from ft_sitl.navigation.base import LIMITS, Limits
from ft_sitl.physics.catalog import PlatformRegistry
from ft_sitl.physics.platform import PlatformError
from ft_sitl.physics.wind import SCHEMA as WIND_SCHEMA
from ft_sitl.scenarios import movers as mv
from ft_sitl.scenarios.families import REGISTRY, resolve_family
from ft_sitl.scenarios.scenario import ScenarioError
from ft_sitl.schema import Param, Schema, SchemaError

#: how an action is flown (docs/gym.md, "Actions")
ACTIONS = ("velocity", "acceleration", "attitude_rate", "motors")
#: what the vehicle perceives besides its state
SENSORS = ("rays", "depth", "none")
#: the obstacle-free family of the hover task: an empty box, a goal near the start
ARENA = "arena"
#: a family drawn per world from the seven benchmark families
ANY = "any"
#: platform pools an episode's platform is drawn from (or a platform's name)
PLATFORM_POOLS = ("catalog", "real", "virtual", "generated")

ENV_SCHEMA = Schema((
    # --- the world ------------------------------------------------------------------------
    Param("family", "forest", choices=(*REGISTRY, ANY, ARENA),
          doc="scenario family: one of the seven benchmark families, 'any' (drawn "
              "uniformly per world) or 'arena' (an empty box, the hover task's)"),
    Param("scenario_index", (1, 10), "-", (1, 10), kind="interval",
          doc="the family's configuration, an integer drawn uniformly from [lo, hi]"),
    Param("scenario_seed", (0, 0), "-", (0, 2**31 - 1), kind="interval",
          doc="the generator's seed, an integer drawn uniformly from [lo, hi] (0: the "
              "benchmark's configurations)"),
    Param("arena_size_m", (20.0, 20.0, 6.0), "m", (2.0, 500.0),
          doc="family 'arena': width (x), length (y) and ceiling of the empty box"),
    Param("arena_goal_distance_m", (0.5, 3.0), "m", (0.0, 100.0), kind="interval",
          doc="family 'arena': the goal's distance from the start (the box's centre at "
              "min(2 m, ceiling / 2)), in a uniformly drawn direction, kept 0.5 m inside"),
    Param("mover_layouts", 16, "-", (1, 2**31 - 1),
          doc="with movers: how many placements of them episodes draw from (each placed "
              "once per process, ~0.1 s, and kept)"),
    # --- the vehicle ----------------------------------------------------------------------
    Param("platform", "catalog",
          doc="'catalog' (one of the 36 platforms, uniformly), 'real' or 'virtual' (one of "
              "the catalog's 18 of that category), 'generated' (a new virtual platform "
              "interpolated in the catalog's design space, physics.synthesis."
              "generate_virtual), or a platform's name"),
    Param("wind_speed_m_s", (0.0, 0.0), "m/s", (0.0, 40.0), kind="interval",
          doc="mean wind speed, drawn uniformly; its direction uniformly from all around"),
    Param("turbulence", "none", choices=WIND_SCHEMA["turbulence"].choices,
          doc="Dryden turbulence intensity of every episode's wind (physics.wind)"),
    Param("position_noise_m", (0.0, 0.0), "m", (0.0, 10.0), kind="interval",
          doc="the flight controller's position estimate: noise standard deviation, drawn "
              "uniformly (autopilot.estimator)"),
    Param("velocity_noise_m_s", (0.0, 0.0), "m/s", (0.0, 10.0), kind="interval",
          doc="likewise for the velocity estimate"),
    Param("attitude_noise_deg", (0.0, 0.0), "deg", (0.0, 30.0), kind="interval",
          doc="likewise for roll, pitch and yaw"),
    # --- acting ---------------------------------------------------------------------------
    Param("action", "velocity", choices=ACTIONS,
          doc="what an action commands: 'velocity' or 'acceleration' (goal frame) with a "
              "yaw rate, 'attitude_rate' (body rates and collective thrust), 'motors' "
              "(each rotor's command)"),
    Param("control_hz", 50, "Hz", (1, 1000),
          doc="actions per simulated second; must divide physics_hz"),
    Param("physics_hz", 1000, "Hz", (100, 10000),
          doc="physics and flight-controller rate; must divide 1,000,000"),
    replace(LIMITS["max_speed_m_s"],
            doc="velocity action: the horizontal speed of an action of 1 (also the flight "
                "controller's MPC_XY_VEL_MAX, the benchmark's speed cap)"),
    Param("max_climb_m_s", 1.0, "m/s", (0.1, 10.0),
          doc="velocity action: the vertical speed of an action of 1"),
    Param("max_acc_m_s2", 5.0, "m/s^2", (0.1, 50.0),
          doc="acceleration action: the acceleration of an action of 1"),
    Param("max_yaw_rate_rad_s", math.pi / 2, "rad/s", (0.0, 10.0),
          doc="velocity and acceleration actions: the yaw rate of an action of 1"),
    Param("max_body_rate_rad_s", 3.0, "rad/s", (0.1, 20.0),
          doc="attitude_rate action: the body rate of an action of 1"),
    # --- perceiving -----------------------------------------------------------------------
    Param("sensor", "rays", choices=SENSORS,
          doc="'rays': a ray scan in the goal frame; 'depth': the depth camera's image, "
              "down-sampled; 'none': state and platform only"),
    Param("ray_columns", 36, "-", (1, 720),
          doc="rays: horizontal directions, evenly spaced counter-clockwise from the goal "
              "direction (NavRL's 36)"),
    Param("ray_rows", 4, "-", (1, 90),
          doc="rays: elevations, evenly spaced over ray_elevation_deg (NavRL's 4)"),
    Param("ray_elevation_deg", (-10.0, 20.0), "deg", (-89.0, 89.0), kind="interval",
          doc="rays: the lowest and highest elevation"),
    Param("ray_range_m", 4.0, "m", (0.1, 100.0),
          doc="rays: the range; a ray reads its hit distance over this (1: nothing)"),
    Param("depth_step", 20, "px", (1, 480),
          doc="depth: the 640 x 480 benchmark camera (D435 optics, 10 m range) at 1/step "
              "resolution (20: 32 x 24)"),
    # --- episodes -------------------------------------------------------------------------
    replace(LIMITS["timeout_s"],
            doc="the time limit: an episode not yet in the goal sphere then is truncated "
                "(the benchmark's timeout)"),
    LIMITS["goal_radius_m"],
    LIMITS["hold_s"],
    Param("goal_rule", True,
          doc="end episodes on the goal as the benchmark does (success after the hold, "
              "'unstable' on leaving during it); false: only crashes and the time limit "
              "end them (the hover task)"),
    Param("render_px", 256, "px", (16, 4096),
          doc="rgb_array: the longer side of the top view"),
))

REWARD_SCHEMA = Schema((
    Param("progress", 1.0, "1/m", (0.0, 1000.0),
          doc="per metre the goal distance shrank during the step (negative when it grew)"),
    Param("distance", 0.0, "1/(m s)", (0.0, 1000.0),
          doc="penalty per metre of goal distance per second"),
    Param("in_goal", 0.0, "1/s", (0.0, 1000.0),
          doc="per second inside the goal sphere"),
    Param("time", 0.0, "1/s", (0.0, 1000.0),
          doc="penalty per second of flight"),
    Param("smoothness", 0.0, "-", (0.0, 1000.0),
          doc="penalty per unit of the mean squared change of the (normalised) action "
              "since the previous step"),
    Param("success_bonus", 10.0, "-", (0.0, 1e6),
          doc="when the episode ends in success"),
    Param("collision_penalty", 10.0, "-", (0.0, 1e6),
          doc="when it ends in a collision, with an obstacle or a moving one"),
    Param("failure_penalty", 10.0, "-", (0.0, 1e6),
          doc="when it ends out of bounds (the floor included), out of control or "
              "unstable"),
))

#: what ``reset(options=...)`` takes (all optional); each replaces that episode's draw
RESET_OPTIONS = {
    "platform": "a platform's name or a Platform (same rotor count)",
    "scenario": "a Scenario, or {family, index, seed, params, version} (the vector "
                "environment: only when all its vehicles reset)",
    "wind": "wind settings (physics.wind.SCHEMA) or None (calm)",
    "estimator": "estimator settings (autopilot.estimator.SCHEMA) or None (the truth)",
    "movers": "moving-obstacle settings (scenarios.movers.SCHEMA) or None (the vector "
              "environment: only when all its vehicles reset)",
}


class EnvError(ValueError):
    """A setting or reset option an environment refuses; the message names it and what is
    allowed."""


class ActionError(ValueError):
    """An action outside the action space (wrong shape, a non-finite or out-of-range
    component); the message names the component, its value and the allowed interval."""


@dataclass(frozen=True)
class EnvConfig:
    """An environment's validated settings: ``values`` (:data:`ENV_SCHEMA`, every key),
    ``reward`` (:data:`REWARD_SCHEMA`), the scenario generator's ``scenario_params``, the
    ``movers`` settings (None: none) and ``scenario_versions``, the generator version of
    each family named there (the others: their newest)."""

    values: dict
    reward: dict
    scenario_params: dict | None
    movers: dict | None
    protocol: int = PROTOCOL_VERSION
    scenario_versions: dict | None = None

    def __getitem__(self, key: str):
        return self.values[key]

    def version_of(self, family: str) -> int | None:
        """The generator version the worlds of ``family`` (a registry key) are built with
        (None: the newest)."""
        return (self.scenario_versions or {}).get(family)

    @property
    def steps_per_action(self) -> int:
        return self.values["physics_hz"] // self.values["control_hz"]

    @property
    def limits(self) -> Limits:
        """The benchmark's limits these settings fly under (the referee's)."""
        v = self.values
        return Limits(max_speed_m_s=v["max_speed_m_s"], timeout_s=v["timeout_s"],
                      goal_radius_m=v["goal_radius_m"], hold_s=v["hold_s"])


def make_config(settings: Mapping, reward: Mapping | None = None,
                scenario_params: Mapping | None = None,
                movers: Mapping | None = None,
                scenario_versions: Mapping | None = None) -> EnvConfig:
    """The settings checked (EnvError naming the key, the value and what is allowed)."""
    owner = "ft-sitl gym environment"
    try:
        values = ENV_SCHEMA.resolve(settings, owner)
        rewards = REWARD_SCHEMA.resolve(reward, "ft-sitl gym reward")
    except SchemaError as exc:
        raise EnvError(str(exc)) from None
    phys, ctrl = values["physics_hz"], values["control_hz"]
    if 1_000_000 % phys:
        raise EnvError(f"{owner}: physics_hz {phys} must divide 1,000,000 (the clock counts "
                       "whole microseconds)")
    if phys % ctrl:
        raise EnvError(f"{owner}: control_hz {ctrl} must divide physics_hz {phys} (an action "
                       "lasts whole physics steps)")
    platform_choice(values["platform"])
    scenario_versions = check_versions(scenario_versions, f"{owner}: scenario_versions")
    if scenario_params is not None:
        if values["family"] in (ANY, ARENA):
            raise EnvError(f"{owner}: scenario_params need one benchmark family, not "
                           f"{values['family']!r}")
        if not isinstance(scenario_params, Mapping):
            raise EnvError(f"{owner}: scenario_params must be a mapping, got "
                           f"{type(scenario_params).__name__}")
        try:
            REGISTRY[values["family"]].resolve(
                scenario_params, (scenario_versions or {}).get(values["family"]))
        except ScenarioError as exc:
            raise EnvError(f"{owner}: scenario_params: {exc}") from None
        scenario_params = json.loads(json.dumps(dict(scenario_params)))
    if movers is not None:
        movers = check_movers(movers, f"{owner}: movers")
    return EnvConfig(values, rewards, scenario_params, movers,
                     scenario_versions=scenario_versions)


def check_versions(versions, owner: str) -> dict | None:
    """Generator versions by family, ``{family: version}`` (the paper's family names are
    accepted), as ``{registry key: version}``; None or empty: every family's newest. An
    unknown family or version is an EnvError naming it and what there is."""
    if versions is None:
        return None
    if not isinstance(versions, Mapping):
        raise EnvError(f"{owner}: a mapping of family to generator version, got "
                       f"{type(versions).__name__}")
    out: dict = {}
    for name, version in versions.items():
        try:
            key = resolve_family(name)
            out[key] = REGISTRY[key].check_version(version)
        except ScenarioError as exc:
            raise EnvError(f"{owner}: {exc}") from None
    return out or None


def check_movers(movers, owner: str) -> dict | None:
    """Mover settings checked (None or an empty count: none)."""
    if movers is None:
        return None
    if not isinstance(movers, Mapping):
        raise EnvError(f"{owner}: a mapping of mover settings or None, got "
                       f"{type(movers).__name__}")
    try:
        mv.settings(movers, owner)
    except SchemaError as exc:
        raise EnvError(str(exc)) from None
    return dict(movers)


def platform_choice(value: str) -> str:
    """``value`` if it is a pool (:data:`PLATFORM_POOLS`) or a catalog platform's name."""
    if value in PLATFORM_POOLS:
        return value
    try:
        PlatformRegistry().get(value)
    except PlatformError as exc:
        raise EnvError(f"platform: {value!r} is neither a pool ({', '.join(PLATFORM_POOLS)}) "
                       f"nor a platform: {exc}") from None
    return value


def check_options(options, allowed: Mapping[str, str], owner: str) -> dict:
    """Reset options checked for unknown keys (values are checked where they are used)."""
    if options is None:
        return {}
    if not isinstance(options, Mapping):
        raise EnvError(f"{owner}: options must be a mapping, got {type(options).__name__}")
    for key in options:
        if key not in allowed:
            raise EnvError(f"{owner}: no reset option {key!r}"
                           f"{did_you_mean(str(key), list(allowed))} (options: "
                           f"{', '.join(allowed)})")
    return dict(options)
