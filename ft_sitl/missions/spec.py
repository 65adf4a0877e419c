"""What decides a trial: :class:`TrialSpec`, its canonical JSON and its id.

The spec is everything a trial is a pure function of (with the code version): navigator
and parameters, platform, scenario, repetition, seed, limits. Its SHA-256 is the trial id,
the campaign's key; ``ft-sitl trial rerun`` rebuilds a trial from the spec stored in its
row.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field, replace

from ft_sitl.autopilot import geofence
from ft_sitl.autopilot.estimator import SCHEMA as ESTIMATOR_SCHEMA
from ft_sitl.autopilot.estimator import Estimator
from ft_sitl.autopilot.failures import SCHEDULE_SCHEMA as FAILURE_SCHEMA
from ft_sitl.autopilot.params import DEFAULT_GAINS, GAIN_MODES, PARAMS, ParamError, ParamSet
from ft_sitl.config import Table
from ft_sitl.missions.perception import SCHEMA as PERCEPTION_SCHEMA
from ft_sitl.missions.perception import Perception
from ft_sitl.navigation.base import Limits
from ft_sitl.physics.actuators import SCHEMA as ACTUATOR_SCHEMA
from ft_sitl.physics.actuators import Actuators
from ft_sitl.physics.catalog import get_platform, platform_from_mapping
from ft_sitl.physics.platform import Platform
from ft_sitl.physics.wind import SCHEMA as WIND_SCHEMA
from ft_sitl.physics.wind import Wind
from ft_sitl.scenarios.difficulty import FlightBudget
from ft_sitl.scenarios.families import describe_family
from ft_sitl.scenarios.movers import SCHEMA as MOVER_SCHEMA
from ft_sitl.scenarios.movers import MoverSettings
from ft_sitl.scenarios.scenario import ScenarioError
from ft_sitl.schema import SchemaError


@dataclass(frozen=True)
class ProtocolRules:
    """What one version of the trial protocol decides (docs/missions.md, "Protocol
    versions")."""

    version: int
    summary: str
    #: MPC_ACC_* also clamp the navigator's offboard setpoints (FT_OFFB_ACC_LIM = 1)
    offboard_acc_clamp: bool
    #: the benchmark depth camera's frame rate when a navigator does not set its own (Hz;
    #: None: the camera's current one, scenarios.camera.BENCHMARK_CAMERA_HZ)
    benchmark_camera_hz: float | None
    #: the navigator is reset before arming and observes the approach (Navigator.observe)
    observe_approach: bool
    #: the acceleration limit planners plan with when the spec's limits set none (m/s^2;
    #: None: each planner's own max_acc_m_s2, the rule before protocol 3)
    max_acc_m_s2: float | None
    #: navigators keep obstacles the platform's footprint away (Task.footprint_m)
    footprint_inflation: bool = False
    #: the vehicle is its body (central box and rotor disks posed by its attitude), not
    #: its collision sphere, and its footprint is the body's half span
    vehicle_body: bool = False
    #: a navigation that has not come STALL_PROGRESS_M closer to the goal than it had
    #: been for this long (simulated s) ends as a timeout at once (None: only
    #: limits.timeout_s ends it). It changes results: a stalled flight's row ends early
    #: (nav_time_s, path, energy), and a flight that would have got going again later
    #: and reached the goal is a timeout (docs/benchmarks.md, "Stalled flights")
    stall_timeout_s: float | None = None
    #: the navigator's map takes the latest camera frame at this rate (Hz), as the
    #: originals' grid maps do on their 0.05 s update timer; frames no update takes are not
    #: rendered (None: every frame goes to the navigator as it is captured)
    map_fusion_hz: float | None = None
    #: navigators perceive moving obstacles as their deployments do (NavRL: its detector
    #: and tracker feed its dynamic-obstacle input, its shield and its map's free regions,
    #: ``dynamic_obstacles = "tracked"``); before, NavRL flew with that input off
    moving_obstacles: bool = False
    #: the flight controller refuses to arm a vehicle that breaches its geofence where it
    #: stands (GF_ACTION not 0), as PX4 does (Commander.arm_fence_check); before, it armed
    #: and the breach acted once in the air
    arm_fence_check: bool = False
    #: NavRL's shield clusters its ray hits within this radius (m) when the spec does not
    #: set ``shield_cluster_radius_m`` (None: the navigator's default, the deployment's
    #: sqrt(0.2) m: its DBSCAN compares squared distances with 0.2)
    navrl_shield_cluster_m: float | None = 0.2
    #: over MAVLink, the navigator's random stream and the bus camera's noise are the
    #: in-process trial's (streams.trial_streams); before, the wire seeded both its own
    #: way (streams.legacy_wire_streams). In-process trials fly as before.
    wire_streams_shared: bool = False
    #: in-process, every navigator setpoint reaches the flight controller as a MAVSDK
    #: client's does over MAVLink (autopilot.wire_setpoint: local NED, float32, yaw through
    #: degrees), so that a lockstep wire trial flies the same numbers; before, in full
    #: float64 precision
    setpoints_as_on_the_wire: bool = False
    #: EGO's replanning rule and emergency time (``replan_rule``, ``emergency_time_s``)
    #: where the spec does not set them; None: the navigator's defaults, the original's
    #: (three initial paths per plan; a collision replanned before any stop, which waits
    #: for standstill; 1.0 s)
    ego_replan: tuple[str, float] | None = ("single", 0.8)


def _versions(first: ProtocolRules, *changes: tuple[str, dict]) -> dict[int, ProtocolRules]:
    """The versions of the protocol, each declared as what it changes in the one before it
    (``(summary, {field: new value})``), numbered from ``first``'s on."""
    out = {first.version: first}
    rules = first
    for summary, changed in changes:
        rules = replace(rules, version=rules.version + 1, summary=summary, **changed)
        out[rules.version] = rules
    return out


#: the versions of the trial protocol this code flies; a trial's spec names its version
#: (absent: 1, the rules of every row written before versions were recorded), its row says
#: which version made it, and ``ft-sitl trial rerun`` flies an old row by its own rules
PROTOCOLS = _versions(
    ProtocolRules(1, "the rules of the first paper run and docs/results/paper-sample "
                     "(campaigns up to 2026-11-26)",
                  offboard_acc_clamp=True, benchmark_camera_hz=15.0, observe_approach=False,
                  max_acc_m_s2=None),
    ("PX4's offboard rule: MPC_ACC_* no longer clamp the navigator's setpoints (the tilt and "
     "thrust limits bound them)",
     {"offboard_acc_clamp": False}),
    ("perception as the originals run it (the depth camera at 30 Hz, the navigator observing "
     "from arming) and one acceleration limit every planner plans with "
     "(limits.max_acc_m_s2, default 3 m/s^2); PX4's offboard rule as in 2",
     {"benchmark_camera_hz": None, "observe_approach": True, "max_acc_m_s2": 3.0}),
    ("navigators know their vehicle: each inflates its map (NavRL: its shield's agent "
     "radius) by the platform's footprint, its collision radius; the rest as in 3",
     {"footprint_inflation": True}),
    ("the vehicle is its body: the central body and the rotor disks, posed by the full "
     "attitude, are what touches obstacles and what the clearance measures; the footprint "
     "navigators inflate by is the body's half span; the rest as in 4",
     {"vehicle_body": True}),
    ("the navigator's map takes the latest frame of the 30 Hz camera on its own 20 Hz timer, "
     "as the originals' grid maps do (frames it would never fuse are not rendered); the "
     "rest as in 5",
     {"map_fusion_hz": 20.0}),
    ("navigators perceive moving obstacles as their deployments do: NavRL's depth detector "
     "and tracker feed its dynamic-obstacle input, its shield and its map's free regions "
     "(before, that input was zero); the rest as in 6",
     {"moving_obstacles": True}),
    ("PX4's arming check on the geofence: a vehicle that breaches the trial's fence on the "
     "ground (GF_ACTION not none) is refused arming, \"Preflight Fail: Geofence "
     "violation\", and the trial ends as geofence (before, it armed and the breach acted "
     "after take-off); NavRL's shield clusters its ray hits as the deployment does, within "
     "sqrt(0.2) = 0.447 m (0.2 m before); the rest as in 7",
     {"arm_fence_check": True, "navrl_shield_cluster_m": None}),
    ("one trial plan for both transports: a navigator flown over MAVLink draws from the "
     "in-process trial's random stream and its bus camera from the in-process camera's "
     "noise stream (before, the wire seeded each its own way: PGO's topological sampling "
     "and noisy depth frames differed between the transports); trials flown in-process are "
     "as in 8",
     {"wire_streams_shared": True}),
    ("in-process setpoints reach the flight controller as a MAVSDK client's do over MAVLink "
     "(local NED relative to the take-off point, every field a float32, the yaw through "
     "degrees), so that a navigator flown over MAVLink in lockstep gives the in-process "
     "row column for column but the wall times; observations and depth frames are as in 9",
     {"setpoints_as_on_the_wire": True}),
    ("EGO replans as the original (ego_replan_fsm.cpp, planner_manager.cpp): a plan from "
     "the trajectory tries three initial paths in turn (the rest of the trajectory, a "
     "polynomial, a random one), a plan from rest a polynomial and then random ones; a "
     "collision on the trajectory is replanned at once, and only when that plan fails less "
     "than emergency_time 1.0 s before the collision does the vehicle stop, planning anew "
     "from its own state once slower than 0.1 m/s (before: one initial path, and a "
     "collision less than 0.8 s ahead stopped it at once, planning from rest at the stop "
     "point in the same step); the rest as in 10",
     {"ego_replan": None}),
)
#: the version new trials and campaigns fly unless they name another
PROTOCOL_VERSION = max(PROTOCOLS)


def flight_budget() -> FlightBudget:
    """What the current protocol gives a navigation: the default limits' top speed and
    time limit, and the acceleration limit every planner plans with (scenario difficulty
    times its routes under it; :mod:`ft_sitl.scenarios.difficulty`)."""
    limits = Limits()
    return FlightBudget(limits.max_speed_m_s, PROTOCOLS[PROTOCOL_VERSION].max_acc_m_s2,
                        limits.timeout_s)


class TrialSpecError(ValueError):
    """A trial spec is invalid; the message names the field."""


def _check_int(name, v, lo=0):
    if isinstance(v, bool) or not isinstance(v, int) or v < lo:
        raise TrialSpecError(f"{name}: must be an integer >= {lo}, got {v!r}")
    return v


@dataclass(frozen=True)
class TrialSpec:
    """Everything that decides a trial. ``platform_def`` (the platform's physical fields)
    and ``scenario_file`` make user platforms and scenarios rerunnable on their own."""

    algorithm: str
    platform: str
    family: str
    scenario_index: int = 1
    scenario_seed: int = 0
    trial: int = 0
    seed: int = 0
    algorithm_params: dict = field(default_factory=dict)
    limits: Limits = field(default_factory=Limits)
    campaign: str = ""
    label: str = ""  # the algorithm's name in the results (default: the navigator's name)
    platform_def: dict | None = None
    scenario_file: str | None = None
    physics_hz: int = 1000
    protocol: int = PROTOCOL_VERSION
    gains: str = DEFAULT_GAINS  # the controller-gain mode (GAIN_MODES: FT_GAIN_MODE)
    #: the family generator's version (scenarios.families.Family.versions; None: the
    #: newest, written into the spec; absent from a stored spec: 1). None for a file.
    scenario_version: int | None = None
    #: the wind the trial flies in (ft_sitl.physics.wind settings; None: calm air),
    #: kept as its settings that differ from the defaults
    wind: dict | None = None
    #: PX4 parameters the trial's flight controller sets (autopilot.params; None: the
    #: defaults), kept sorted by name
    params: dict | None = None
    #: imperfect actuators (ft_sitl.physics.actuators settings; None: as built), kept as
    #: the settings that differ from the defaults
    actuators: dict | None = None
    #: what the navigator perceives, made imperfect (missions.perception settings: latency,
    #: state noise, dropped frames; None: ideal), the settings that differ from the defaults
    perception: dict | None = None
    #: the flight controller's estimate of the state, made imperfect (autopilot.estimator
    #: settings: noise, bias, latency per group; None: the truth), the non-default settings
    estimator: dict | None = None
    #: failures injected during the trial, PX4's way (autopilot.failures: at_s, unit, type,
    #: instance each), in time order; None: none
    failures: list | None = None
    #: moving obstacles added to the scenario (scenarios.movers settings: count or
    #: density, speed, shapes, paths; None: a static world), the non-default settings
    movers: dict | None = None
    #: the geofence the trial's flight controller keeps (:func:`fence_setting`: action,
    #: max_hor_dist_m, max_ver_dist_m, polygons, circles; the scenario's ENU frame, m), every
    #: key kept; None: none
    fence: dict | None = None
    #: the name of the aggressiveness level whose speed cap and acceleration limit are
    #: ``limits``' (missions.aggressiveness; a label for the rows: the limits are what the
    #: trial flies); None: the campaign has no aggressiveness axis
    aggressiveness: str | None = None

    def __post_init__(self):
        for name in ("algorithm", "platform", "family"):
            v = getattr(self, name)
            if not isinstance(v, str) or not v:
                raise TrialSpecError(f"{name}: must be a non-empty string, got {v!r}")
        _check_int("scenario_index", self.scenario_index, 1)
        _check_int("scenario_seed", self.scenario_seed)
        _check_int("trial", self.trial)
        _check_int("seed", self.seed)
        _check_int("physics_hz", self.physics_hz, 1)
        if not isinstance(self.algorithm_params, dict):
            raise TrialSpecError("algorithm_params: must be a table of parameters")
        if not isinstance(self.limits, Limits):
            raise TrialSpecError("limits: must be a Limits")
        check_protocol(self.protocol)
        check_gains(self.gains)
        object.__setattr__(self, "wind", wind_settings(self.wind))
        object.__setattr__(self, "params", px4_params(self.params))
        object.__setattr__(self, "actuators", actuator_settings(self.actuators))
        object.__setattr__(self, "perception", perception_settings(self.perception))
        object.__setattr__(self, "estimator", estimator_settings(self.estimator))
        object.__setattr__(self, "failures", failure_schedule(self.failures))
        object.__setattr__(self, "movers", mover_settings(self.movers))
        object.__setattr__(self, "fence", fence_setting(self.fence))
        if self.aggressiveness is not None and (not isinstance(self.aggressiveness, str)
                                                or not self.aggressiveness.strip()):
            raise TrialSpecError(f"aggressiveness: must be a level's name (a non-empty "
                                 f"string) or None, got {self.aggressiveness!r}")
        if self.scenario_file is None:
            try:
                fam = describe_family(self.family)
                object.__setattr__(self, "scenario_version",
                                   fam.check_version(self.scenario_version))
            except ScenarioError as exc:
                raise TrialSpecError(f"family / scenario_version: {exc}") from None
        elif self.scenario_version is not None:
            raise TrialSpecError("scenario_version: a scenario file has no generator version "
                                 f"(got {self.scenario_version!r})")
        default_acc = PROTOCOLS[self.protocol].max_acc_m_s2
        if self.limits.max_acc_m_s2 is not None and default_acc is None:
            raise TrialSpecError(f"limits.max_acc_m_s2: protocol version {self.protocol} has "
                                 f"no protocol acceleration limit (each planner used its own "
                                 f"max_acc_m_s2); it came with version 3")
        if self.limits.max_acc_m_s2 is None and default_acc is not None:
            # the protocol's default, written into the spec (and so into its id and row)
            object.__setattr__(self, "limits", replace(self.limits, max_acc_m_s2=default_acc))

    # --- serialisation -------------------------------------------------------------------
    def to_dict(self) -> dict:
        """The canonical spec. ``protocol`` and ``scenario_version`` are left out at
        version 1 and ``gains`` at the default, so the specs (and trial ids) of rows
        written before any of them existed stay what they were."""
        d = {
            "algorithm": self.algorithm, "algorithm_params": self.algorithm_params,
            "platform": self.platform, "platform_def": self.platform_def,
            "family": self.family, "scenario_index": self.scenario_index,
            "scenario_seed": self.scenario_seed, "scenario_file": self.scenario_file,
            "trial": self.trial, "seed": self.seed, "limits": self.limits.as_dict(),
            "campaign": self.campaign, "label": self.label, "physics_hz": self.physics_hz,
        }
        if self.protocol != 1:
            d["protocol"] = self.protocol
        if self.gains != DEFAULT_GAINS:
            d["gains"] = self.gains
        if self.scenario_version not in (None, 1):
            d["scenario_version"] = self.scenario_version
        if self.wind is not None:  # (calm air left out: ids of calm trials unchanged)
            d["wind"] = self.wind
        if self.params is not None:  # (likewise: the default parameters)
            d["params"] = self.params
        if self.actuators is not None:  # (likewise: nominal actuators)
            d["actuators"] = self.actuators
        if self.perception is not None:  # (likewise: ideal perception)
            d["perception"] = self.perception
        if self.estimator is not None:  # (likewise: the truth as estimate)
            d["estimator"] = self.estimator
        if self.failures is not None:  # (likewise: no failures)
            d["failures"] = self.failures
        if self.movers is not None:  # (likewise: a static world)
            d["movers"] = self.movers
        if self.fence is not None:  # (likewise: no fence)
            d["fence"] = self.fence
        if self.aggressiveness is not None:  # (likewise: no aggressiveness axis)
            d["aggressiveness"] = self.aggressiveness
        return d

    @classmethod
    def from_dict(cls, d: dict) -> TrialSpec:
        if not isinstance(d, dict):
            raise TrialSpecError("a trial spec must be a table")
        d = dict(d)
        d.pop("code_version", None)
        d.setdefault("protocol", 1)  # a spec written before versions were recorded
        if not d.get("scenario_file"):  # likewise: the family's first generator
            d.setdefault("scenario_version", 1)
        try:
            limits = Limits(**d.pop("limits", {}))
        except TypeError as exc:
            raise TrialSpecError(f"limits: {exc}") from None
        except ValueError as exc:
            raise TrialSpecError(str(exc)) from None
        try:
            return cls(limits=limits, **d)
        except TypeError as exc:
            raise TrialSpecError(f"trial spec: {exc}") from None

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))

    @property
    def trial_id(self) -> str:
        """16 hex digits of the SHA-256 of the canonical spec (the campaign's key)."""
        return hashlib.sha256(self.to_json().encode()).hexdigest()[:16]


def _non_default(values, owner: str, schema, model, what: str) -> dict | None:
    """``values`` checked by ``model(values, owner)`` and reduced to the settings that
    differ from ``schema``'s defaults (floats for numbers given as integers where the
    parameter is a float); None when none differ."""
    if values is None:
        return None
    if not isinstance(values, dict):
        raise TrialSpecError(f"{owner}: must be a table of {what} "
                             f"({', '.join(schema.names())}), got {values!r}")
    try:
        resolved = model(values, owner).values
    except SchemaError as exc:
        raise TrialSpecError(str(exc)) from None
    defaults = schema.defaults()
    out = {}
    for k, v in resolved.items():
        kind = schema[k].kind
        if kind == "float" and isinstance(v, int) and not isinstance(v, bool):
            v = float(v)
        elif kind == "vector":  # (a list of floats, as JSON gives it back)
            v = [float(x) for x in v]
            if v == [float(x) for x in defaults[k]]:
                continue
        if v != defaults[k]:
            out[k] = v
    return out or None


def actuator_settings(values, owner: str = "actuators") -> dict | None:
    """A trial's actuators as their canonical settings (those that differ from the
    defaults); None for actuators as built. TrialSpecError naming ``owner`` and the key."""
    return _non_default(values, owner, ACTUATOR_SCHEMA, Actuators, "actuator settings")


def perception_settings(values, owner: str = "perception") -> dict | None:
    """A trial's perception as its canonical settings (those that differ from the
    defaults); None for ideal perception. TrialSpecError naming ``owner`` and the key."""
    return _non_default(values, owner, PERCEPTION_SCHEMA, Perception, "perception settings")


def estimator_settings(values, owner: str = "estimator") -> dict | None:
    """A trial's flight-controller estimator as its canonical settings (those that differ
    from the defaults); None for the truth. TrialSpecError naming ``owner`` and the key."""
    return _non_default(values, owner, ESTIMATOR_SCHEMA, Estimator, "estimator settings")


def mover_settings(values, owner: str = "movers") -> dict | None:
    """A trial's moving obstacles as their canonical settings (those that differ from the
    defaults); None for a static world. TrialSpecError naming ``owner`` and the key."""
    return _non_default(values, owner, MOVER_SCHEMA, MoverSettings, "mover settings")


def failure_setting(values, owner: str = "failures") -> dict | None:
    """One scheduled failure (autopilot.failures.SCHEDULE_SCHEMA: at_s, unit, type,
    instance), every key kept; None for an empty table (no failure). TrialSpecError naming
    ``owner`` and the key."""
    if values is None or values == {}:
        return None
    if not isinstance(values, dict):
        raise TrialSpecError(f"{owner}: must be a table of failure settings "
                             f"({', '.join(FAILURE_SCHEMA.names())}), got {values!r}")
    try:
        v = FAILURE_SCHEMA.resolve(values, owner)
    except SchemaError as exc:
        raise TrialSpecError(str(exc)) from None
    return {"at_s": float(v["at_s"]), "unit": v["unit"], "type": v["type"],
            "instance": int(v["instance"])}


def failure_schedule(values, owner: str = "failures") -> list | None:
    """A trial's failures: a list of scheduled failures (or one), in time order; None
    for none."""
    if values is None:
        return None
    items = [values] if isinstance(values, dict) else values
    if not isinstance(items, list):
        raise TrialSpecError(f"{owner}: must be a list of failure tables, got {values!r}")
    out = [f for k, item in enumerate(items)
           if (f := failure_setting(item, f"{owner}[{k}]")) is not None]
    return sorted(out, key=lambda f: f["at_s"]) or None


#: a trial fence's keys; the ones that are a PX4 parameter, and which (its unit the key's)
FENCE_KEYS = ("action", "max_hor_dist_m", "max_ver_dist_m", "polygons", "circles")
FENCE_PARAMS = {"action": "GF_ACTION", "max_hor_dist_m": "GF_MAX_HOR_DIST",
                "max_ver_dist_m": "GF_MAX_VER_DIST"}
POLYGON_KEYS = ("inclusion", "vertices")
CIRCLE_KEYS = ("inclusion", "center", "radius_m")


def fence_setting(values, owner: str = "fence") -> dict | None:
    """A trial's geofence as its canonical table; None for an empty table (no fence).

    ``action`` (GF_ACTION: a name of ``geofence.GF_ACTIONS`` or its number; default PX4's,
    hold), ``max_hor_dist_m`` / ``max_ver_dist_m`` (GF_MAX_HOR_DIST / GF_MAX_VER_DIST,
    from home; 0, the default, is off), ``polygons`` (``{inclusion, vertices}``, vertices
    ``[x, y]``) and ``circles`` (``{inclusion, center, radius_m}``), in the scenario's
    local ENU frame (m). The areas are checked by the geofence's own rules (vertex counts,
    crossing edges, finite positions, radii, the item limit) and the numbers by the
    parameter table; the canonical table keeps every key, the action by name and numbers
    as floats. TrialSpecError naming ``owner`` and the key."""
    if values is None or values == {}:
        return None
    if not isinstance(values, dict):
        raise TrialSpecError(f"{owner}: must be a table of fence settings "
                             f"({', '.join(FENCE_KEYS)}), got {values!r}")
    t = Table(values, owner, error=TrialSpecError)
    t.check_keys(FENCE_KEYS)
    out: dict = {"action": fence_action(t.get("action", PARAMS["GF_ACTION"].default),
                                        f"{owner}: action")}
    for key in ("max_hor_dist_m", "max_ver_dist_m"):
        name = FENCE_PARAMS[key]
        v = t.get(key, PARAMS[name].default)
        try:
            ParamSet({name: v})
        except ParamError as exc:
            raise t.fail(key, str(exc)) from None
        out[key] = float(v)
    areas = []
    for key, keys, build in (("polygons", POLYGON_KEYS,
                              lambda a, w: geofence.polygon(a["vertices"], a["inclusion"], w)),
                             ("circles", CIRCLE_KEYS,
                              lambda a, w: geofence.circle(a["center"], a["radius_m"],
                                                           a["inclusion"], w))):
        items = t.get(key, [])
        if not isinstance(items, list):
            raise t.fail(key, f"must be a list of tables ({', '.join(keys)}), got {items!r}")
        for k, item in enumerate(items):
            where = f"{owner}.{key}[{k}]"
            if not isinstance(item, dict):
                raise TrialSpecError(f"{where}: must be a table ({', '.join(keys)}), got "
                                     f"{item!r}")
            a = Table(item, where, error=TrialSpecError)
            a.check_keys(keys)
            a.require(keys)
            if not isinstance(item["inclusion"], bool):
                raise a.fail("inclusion", f"must be true (keep inside) or false (keep out), "
                                          f"got {item['inclusion']!r}")
            try:
                areas.append(build(item, where))
            except geofence.FenceError as exc:
                raise TrialSpecError(str(exc)) from None
    fence = geofence.Fence(areas)
    try:
        geofence.check_items(fence.n_items, owner)
    except geofence.FenceError as exc:
        raise TrialSpecError(str(exc)) from None
    if fence.empty and not (out["max_hor_dist_m"] or out["max_ver_dist_m"]):
        raise TrialSpecError(f"{owner}: fences nothing (no polygon, no circle, no maximum "
                             f"distance); leave it out (or {{}}) for no fence")
    out["polygons"] = [{"inclusion": a.inclusion, "vertices": a.vertices.tolist()}
                       for a in fence.areas if isinstance(a, geofence.Polygon)]
    out["circles"] = [{"inclusion": a.inclusion, "center": a.center.tolist(),
                       "radius_m": a.radius_m}
                      for a in fence.areas if isinstance(a, geofence.Circle)]
    return out


def fence_action(v, owner: str = "fence: action") -> str:
    """A GF_ACTION given by name or number, as its name; TrialSpecError naming ``owner``."""
    names = geofence.GF_ACTIONS
    if isinstance(v, str) and v in names.values():
        return v
    if not isinstance(v, bool) and isinstance(v, int) and v in names:
        return names[v]
    known = ", ".join(f"{name!r} ({code})" for code, name in names.items())
    raise TrialSpecError(f"{owner}: must be a GF_ACTION, by name or number: {known}; "
                         f"got {v!r}")


def fence_of(setting: dict) -> geofence.Fence:
    """The :class:`~ft_sitl.autopilot.geofence.Fence` of a canonical fence table (its areas;
    the action and the distances are parameters: :func:`fence_params`)."""
    return geofence.Fence(
        [geofence.polygon(p["vertices"], p["inclusion"], "fence") for p in setting["polygons"]]
        + [geofence.circle(c["center"], c["radius_m"], c["inclusion"], "fence")
           for c in setting["circles"]])


def fence_params(setting: dict) -> dict:
    """The PX4 parameters of a canonical fence table: GF_ACTION, GF_MAX_HOR_DIST,
    GF_MAX_VER_DIST."""
    codes = {name: code for code, name in geofence.GF_ACTIONS.items()}
    return {"GF_ACTION": codes[setting["action"]],
            "GF_MAX_HOR_DIST": setting["max_hor_dist_m"],
            "GF_MAX_VER_DIST": setting["max_ver_dist_m"]}


def wind_settings(values, owner: str = "wind") -> dict | None:
    """A trial's wind as its canonical settings: those that differ from the defaults, in
    declaration order; None for calm air (no settings, or only defaults). TrialSpecError
    naming ``owner``, the key and the allowed range for a bad one."""
    return _non_default(values, owner, WIND_SCHEMA, Wind, "wind settings")


#: parameters the trial protocol sets itself, and the campaign key that sets each
PROTOCOL_PARAMS = {"MPC_XY_VEL_MAX": "limits.max_speed_m_s",
                   "FT_OFFB_ACC_LIM": "protocol (its version decides it)",
                   "FT_GAIN_MODE": "gains",
                   **{name: f"fence.{key}" for key, name in FENCE_PARAMS.items()}}


def px4_params(values, owner: str = "params") -> dict | None:
    """A trial's PX4 parameter overrides, checked against the parameter table (names,
    bounds, integers) and sorted by name; None for none. TrialSpecError naming ``owner``
    and the parameter; the parameters the protocol sets are refused with the key that
    sets them, and the stored ones (no effect on the flight) as such."""
    if values is None:
        return None
    if not isinstance(values, dict):
        raise TrialSpecError(f"{owner}: must be a table of PX4 parameters "
                             f"(e.g. {{MPC_XY_P = 1.2}}), got {values!r}")
    for name in values:
        if name in PROTOCOL_PARAMS:
            raise TrialSpecError(f"{owner}: {name} is set by the trial protocol: use "
                                 f"{PROTOCOL_PARAMS[name]} instead")
        if name in PARAMS and not PARAMS[name].honoured:
            raise TrialSpecError(f"{owner}: {name} is a stored PX4 parameter that ft-sitl "
                                 f"does not act on, so a trial cannot vary it (see "
                                 f"'ft-sitl params list --honoured')")
    try:
        ps = ParamSet({k: values[k] for k in values})
    except ParamError as exc:
        raise TrialSpecError(f"{owner}: {exc}") from None
    out = {k: ps[k] for k in sorted(values)}
    return out or None


def check_protocol(version) -> int:
    """``version`` if this code flies it, else TrialSpecError saying which versions it
    flies (a row from a newer ft-sitl needs that one)."""
    if isinstance(version, bool) or not isinstance(version, int) or version not in PROTOCOLS:
        known = ", ".join(map(str, sorted(PROTOCOLS)))
        raise TrialSpecError(f"protocol: version {version!r} is not one this ft-sitl flies "
                             f"({known}); a trial written under another version needs the "
                             f"ft-sitl that wrote it (its row's code_version)")
    return version


def check_gains(name) -> str:
    """``name`` if it names a controller-gain mode, else TrialSpecError naming the key and
    the modes."""
    if not isinstance(name, str) or name not in GAIN_MODES:
        known = ", ".join(repr(k) for k in GAIN_MODES)
        raise TrialSpecError(f"gains: {name!r} is not a controller-gain mode ({known}: "
                             f"FT_GAIN_MODE {', '.join(map(str, GAIN_MODES.values()))})")
    return name


def vehicle_half_span_m(protocol: int, platform: Platform) -> float:
    """The vehicle's horizontal half size in a trial of this protocol version (m): what
    its collision check takes to be the vehicle, seen from above. From protocol 5
    (``vehicle_body``) the body's half span; before, its collision sphere's radius."""
    if PROTOCOLS[check_protocol(protocol)].vehicle_body:
        return platform.body().half_span_m
    return platform.collision_radius_m


def platform_for(spec: TrialSpec) -> Platform:
    """The spec's platform: its stored physical fields, else the catalog entry."""
    if spec.platform_def is not None:
        return platform_from_mapping(dict(spec.platform_def), f"trial spec platform "
                                                               f"{spec.platform!r}")
    return get_platform(spec.platform)
