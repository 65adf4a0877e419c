"""A trial's plan: its spec resolved once, for every transport.

A :class:`~ft_sitl.missions.spec.TrialSpec` says what decides a trial; :func:`plan_trial`
resolves it into a :class:`TrialPlan`, once: the protocol version's rules, the platform,
the scenario (with its moving obstacles), what touches obstacles (the collision sphere or
the body) and how far navigators keep them away, the flight controller's parameters, the
navigator's parameters and depth camera, and the seed of every random stream
(:mod:`ft_sitl.missions.streams`). The in-process driver (:mod:`ft_sitl.missions.trial`),
the MAVLink transport and the referee (:mod:`ft_sitl.missions.protocol`) read the plan;
none of them derives any of it again.

The navigator's :class:`~ft_sitl.navigation.base.Task` is the plan's face towards the
navigator (:meth:`TrialPlan.task`), the same object in-process and over MAVLink, where it
travels as ``Task.to_dict``.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

from ft_sitl.autopilot.params import GAIN_MODES, ParamSet
from ft_sitl.missions.perception import Perception
from ft_sitl.missions.resources import RESOURCES, TrialResources
from ft_sitl.missions.spec import (
    PROTOCOLS,
    ProtocolRules,
    TrialSpec,
    fence_params,
    platform_for,
    vehicle_half_span_m,
)
from ft_sitl.missions.streams import RandomStreams, legacy_wire_streams, trial_streams
from ft_sitl.navigation.base import Task
from ft_sitl.navigation.registry import available
from ft_sitl.physics.platform import Platform

#: why a trial with perception settings does not fly over MAVLink
PERCEPTION_WIRE = ("perception: latency, state noise and dropped frames are applied by the "
                   "in-process driver; over MAVLink the navigator runs in its own process "
                   "with the transport's own timing (fly this campaign in-process)")


@dataclass(frozen=True, eq=False)
class TrialPlan:
    """One trial, resolved (module docstring). Build it with :func:`plan_trial`."""

    spec: TrialSpec
    rules: ProtocolRules
    platform: Platform
    scenario: object
    #: the collision guard's radius (m) and the body it checks (None: the sphere alone)
    guard_radius_m: float
    body: object | None
    #: how far the navigator keeps obstacles away (m; None: its own default, before 4)
    footprint_m: float | None
    #: the flight controller's parameters (the spec's, the fence's and the protocol's)
    flight_params: MappingProxyType
    #: the navigator's parameters (the spec's and what its protocol version fixed)
    navigator_params: MappingProxyType
    #: the navigator's depth camera (None: none), and the camera its frames are made
    #: with: that one with the spec's perception applied (dropped frames, latency)
    camera: object | None
    frame_camera: object | None
    #: the random streams in-process, and those a transport over MAVLink draws from
    streams: RandomStreams
    wire_streams: RandomStreams

    def task(self, *, wire: bool = False) -> Task:
        """What the navigator is told (a new Task each call: its random stream starts
        afresh). ``wire``: the task of the navigator flown over MAVLink (its stream is the
        in-process one from protocol 9, :attr:`ProtocolRules.wire_streams_shared`)."""
        sc, ind = self.scenario, self.platform.indicators()
        streams = self.wire_streams if wire else self.streams
        return Task(start=sc.start.copy(), start_yaw=float(sc.start_yaw),
                    goal=sc.goal.copy(), limits=self.spec.limits,
                    bounds_min=sc.bounds_min.copy(), bounds_max=sc.bounds_max.copy(),
                    collision_radius_m=self.platform.collision_radius_m,
                    twr_max=ind.twr_max, alpha_xy_max=ind.alpha_xy_max_rad_s2,
                    alpha_z_max=ind.alpha_z_max_rad_s2, seed=streams.entropy("navigator"),
                    footprint_m=self.footprint_m, origin=sc.takeoff.copy(),
                    observe_approach=self.rules.observe_approach,
                    map_fusion_hz=self.rules.map_fusion_hz)

    def param_set(self) -> ParamSet:
        """A fresh ParamSet of :attr:`flight_params` (the vehicle's, which it may change)."""
        return ParamSet(dict(self.flight_params))


def plan_trial(spec: TrialSpec, *, navigator=None,
               resources: TrialResources = RESOURCES) -> TrialPlan:
    """The plan of ``spec``. ``navigator``: an instance flying instead of the registry's
    (tests, tools): the plan's camera is then that instance's."""
    rules = PROTOCOLS[spec.protocol]
    platform = platform_for(spec)
    scenario = resources.scenario(spec)
    radius, body = vehicle_collision(rules, platform)
    cls = available().get(spec.algorithm)  # (the entry points scanned once a plan)
    nav_params = navigator_params(spec, cls)
    cam = (getattr(navigator, "camera", None) if navigator is not None
           else navigator_camera(spec.algorithm, nav_params, cls))
    seen = cam
    if cam is not None and spec.perception is not None:
        seen = Perception(spec.perception).camera_config(cam)
    streams = trial_streams(spec.seed, spec.trial)
    fence = fence_params(spec.fence) if spec.fence is not None else {}
    return TrialPlan(
        spec=spec, rules=rules, platform=platform, scenario=scenario,
        guard_radius_m=radius, body=body, footprint_m=footprint_m(rules, spec, platform),
        flight_params=MappingProxyType(flight_params({**(spec.params or {}), **fence},
                                                     spec.limits, rules, spec.gains)),
        navigator_params=MappingProxyType(nav_params), camera=cam, frame_camera=seen,
        streams=streams,
        wire_streams=streams if rules.wire_streams_shared
        else legacy_wire_streams(streams, spec.seed, spec.trial))


_LOOK_UP = object()


def navigator_camera(algorithm: str, params: dict, cls=_LOOK_UP):
    """The depth camera the registered navigator ``algorithm`` asks for with ``params``
    (None: none, or a navigator this process cannot load). ``cls``: the registry's entry
    for ``algorithm`` when the caller has it (else looked up)."""
    if cls is _LOOK_UP:
        cls = available().get(algorithm)
    if not isinstance(cls, type):
        return None
    return cls.camera_for(cls.schema.resolve(dict(params), f"navigator {algorithm!r}"))


def footprint_m(rules: ProtocolRules, spec: TrialSpec, platform: Platform) -> float | None:
    """How far the trial's navigator keeps obstacles away (m; None: not told): the body's
    half span from protocol 5, the collision radius in 4, nothing before."""
    if rules.footprint_inflation:
        return vehicle_half_span_m(spec.protocol, platform)
    return None


def navigator_params(spec: TrialSpec, cls=_LOOK_UP) -> dict:
    """The navigator's parameters in this trial: the spec's, plus what the trial's protocol
    version fixed that the navigator's defaults have changed since (versions 1 and 2 flew
    the benchmark camera at 15 Hz; before 7 NavRL saw no moving obstacles; before 8 its
    shield clustered within 0.2 m; before 11 EGO planned with one initial path and
    stopped at once on a collision less than 0.8 s ahead). ``cls`` as for
    :func:`navigator_camera`."""
    params = dict(spec.algorithm_params)
    rules = PROTOCOLS[spec.protocol]
    if cls is _LOOK_UP:
        cls = available().get(spec.algorithm)
    names = () if isinstance(cls, (str, type(None))) else cls.schema.names()
    rate = rules.benchmark_camera_hz
    if rate is not None and "camera_rate_hz" in names and "camera_rate_hz" not in params \
            and params.get("camera", "benchmark") == "benchmark":
        params["camera_rate_hz"] = rate
    if not rules.moving_obstacles and "dynamic_obstacles" in names and \
            "dynamic_obstacles" not in params:
        params["dynamic_obstacles"] = "off"
    if rules.navrl_shield_cluster_m is not None and "shield_cluster_radius_m" in names and \
            "shield_cluster_radius_m" not in params:
        params["shield_cluster_radius_m"] = rules.navrl_shield_cluster_m
    if rules.ego_replan is not None and "replan_rule" in names and \
            "replan_rule" not in params:
        params["replan_rule"] = rules.ego_replan[0]
        params.setdefault("emergency_time_s", rules.ego_replan[1])
    return params


def vehicle_collision(rules: ProtocolRules, platform: Platform):
    """What touches obstacles under these rules: (the collision guard's radius, the body
    or None). From protocol 5 (``vehicle_body``) the platform's body, its bounding radius
    the broad phase; before, its collision sphere."""
    if rules.vehicle_body:
        body = platform.body()
        return body.bounding_radius_m, body
    return platform.collision_radius_m, None


def flight_params(params: dict | None, limits, rules: ProtocolRules, gains: str) -> dict:
    """The flight controller's parameters under these rules: ``params`` (the spec's) with
    the speed cap as MPC_XY_VEL_MAX, the protocol's offboard rule as FT_OFFB_ACC_LIM and
    the controller-gain mode ``gains`` as FT_GAIN_MODE (checked: ParamError)."""
    values = {**(params or {}), "MPC_XY_VEL_MAX": limits.max_speed_m_s,
              "FT_OFFB_ACC_LIM": int(rules.offboard_acc_clamp),
              "FT_GAIN_MODE": GAIN_MODES[gains]}
    ParamSet(values)  # (a bad value is refused here, once)
    return values
