"""Campaign files: a :class:`Campaign` (what to run) from a TOML or YAML file or a preset
(``quick``, ``paper``); running it is :mod:`ft_sitl.missions.campaign`.

A campaign file (TOML or YAML) names what to run; every key is optional except
``algorithms``::

    name = "my-campaign"
    trials = 10                      # per (algorithm, platform, scenario family)
    seed = 0                         # trial seeds derive from it
    scenario_seed = 0                # seed of the scenario configurations
    platforms = ["real"]             # names, categories (real, virtual, user) or "all"
    platform_files = ["mine.toml"]   # user platforms (relative to this file)
    scenarios = "all"                # families (paper names work), {family, indices,
                                     # version} (version: an older generator of the
                                     # family, default the newest), {file = "yard.yaml"}
                                     # (a user scenario), or "all"
    indices = "all"                  # default configurations of each family (1..10)
    physics_hz = 1000
    protocol = 1                     # the trial protocol's version (default: the newest)
    gains = "bandwidth"              # controller-gain mode: "bandwidth" (FT_GAIN_MODE 0,
                                     # default) or "px4" (1: PX4's normalised rate gains)
    thrust_floor = "px4"             # each trial's MPC_THR_MIN: "px4" (the parameters',
                                     # default) or "weight" (per platform, at most 0.36
                                     # of its weight: missions.thrust_floor)
    # axes, each one table or a list of them crossed with the matrix ({}: the default):
    # wind, params, actuators, perception, estimator, failures, fence (docs/missions.md)
    aggressiveness = ["gentle", "paper", {name = "fast", max_speed_m_s = 6.0,
                      max_acc_m_s2 = 3.0}]  # an axis of levels (names or tables): each
                                     # sets limits.max_speed_m_s and max_acc_m_s2

    [[algorithms]]                   # or: algorithms = "all" / ["straight", ...]
    name = "straight"                # a registered navigator
    label = "straight-3"             # optional: its name in the results
    params = { speed_m_s = 3.0 }

    [limits]                         # the protocol's defaults
    max_speed_m_s = 4.0
    timeout_s = 90.0
    goal_radius_m = 2.0
    hold_s = 3.0
    max_acc_m_s2 = 3.0               # what planners plan with (protocol 3 on; default 3)

    [weights]                        # composite score (paper defaults)
    scenarios = { classic = 1.2, theoretical = 1.0 }
    platforms = { real = 1.5, virtual = 1.0 }
    beta = 0.3

Trial ``t`` (0-based) of a combination flies configuration ``indices[t % len(indices)]``,
so 10 trials over the ten configurations fly each once, as in the paper. Its seed is
derived from the campaign seed, the combination and ``t``.

Every mistake is one :class:`CampaignError` naming the file and the key path; the file is
read by :mod:`ft_sitl.config`, and the composite-score weights are checked here, when the
file is read, by the scorer's own rule (:mod:`ft_sitl.missions.scoring`).
"""

from __future__ import annotations

import hashlib
import json
import shlex
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from ft_sitl.autopilot.params import DEFAULT_GAINS, GAIN_MODES
from ft_sitl.config import Table, integer, read_document
from ft_sitl.missions import scoring
from ft_sitl.missions.aggressiveness import LEVEL_LIMITS, Level, level_of
from ft_sitl.missions.spec import (
    PROTOCOL_VERSION,
    PROTOCOLS,
    TrialSpec,
    TrialSpecError,
    actuator_settings,
    estimator_settings,
    failure_setting,
    fence_setting,
    mover_settings,
    perception_settings,
    px4_params,
    wind_settings,
)
from ft_sitl.missions.thrust_floor import PX4, THRUST_FLOOR, thrust_min_override
from ft_sitl.navigation.base import LIMITS, Limits
from ft_sitl.navigation.registry import NavigatorError, available, create
from ft_sitl.physics.catalog import PlatformRegistry
from ft_sitl.physics.platform import CATEGORIES, PlatformError
from ft_sitl.scenarios.families import CATEGORY, FAMILIES, REGISTRY, resolve_family
from ft_sitl.scenarios.io import load_scenario
from ft_sitl.scenarios.scenario import ScenarioError
from ft_sitl.schema import SchemaError

PRESETS = ("quick", "paper", "gains")
TOP_KEYS = ("name", "trials", "seed", "scenario_seed", "platforms", "platform_files",
            "scenarios", "indices", "physics_hz", "protocol", "gains", "algorithms", "limits",
            "weights", "description", "wind", "params", "actuators", "perception",
            "estimator", "failures", "movers", "fence", "aggressiveness", "thrust_floor")
LIMIT_KEYS = tuple(LIMITS.names())
WEIGHT_KEYS = ("scenarios", "platforms", "beta")


class CampaignError(ValueError):
    """A campaign file or request is invalid; the message names the file and the key."""


#: the pseudo-navigator of a campaign's ``command`` entry: a user's program, which always
#: flies over MAVLink
COMMAND = "command"


@dataclass(frozen=True)
class AlgorithmEntry:
    name: str
    label: str
    params: dict


@dataclass(frozen=True)
class ScenarioEntry:
    family: str
    indices: tuple[int, ...]
    file: str | None = None
    #: the family generator's version (None for a file)
    version: int | None = None


@dataclass
class Campaign:
    name: str
    algorithms: list[AlgorithmEntry]
    platforms: list  # Platform objects
    scenarios: list[ScenarioEntry]
    trials: int = 10
    seed: int = 0
    scenario_seed: int = 0
    limits: Limits = field(default_factory=Limits)
    weights: dict = field(default_factory=dict)
    physics_hz: int = 1000
    protocol: int = PROTOCOL_VERSION
    gains: str = DEFAULT_GAINS
    #: whose MPC_THR_MIN the trials fly (missions.thrust_floor): "px4" or "weight"
    thrust_floor: str = PX4
    source: str = ""
    doc: dict = field(default_factory=dict)
    #: what "all" left out and why (e.g. a navigator without its model weights)
    notes: list[str] = field(default_factory=list)
    #: the wind axis: every trial of the matrix flies in each (None: calm air)
    winds: list = field(default_factory=lambda: [None])
    #: the controller-gain axis: every trial flies with each mode ([gains] when one)
    gain_modes: list = field(default_factory=list)
    #: the PX4-parameter axis: every trial flies with each set (None: the defaults)
    param_sets: list = field(default_factory=lambda: [None])
    #: the actuator axis: every trial flies with each (None: actuators as built)
    actuator_sets: list = field(default_factory=lambda: [None])
    #: the perception axis: every trial flies with each (None: ideal perception)
    perceptions: list = field(default_factory=lambda: [None])
    #: the estimator axis: every trial flies with each (None: the truth as estimate)
    estimators: list = field(default_factory=lambda: [None])
    #: the failure axis: every trial flies with each (None: no failure injected)
    failure_sets: list = field(default_factory=lambda: [None])
    #: the moving-obstacle axis: every trial flies with each (None: a static world)
    mover_sets: list = field(default_factory=lambda: [None])
    #: the geofence axis: every trial flies with each (None: no fence)
    fences: list = field(default_factory=lambda: [None])
    #: the aggressiveness axis: every trial flies at each Level, which sets its speed cap
    #: and acceleration limit (None: the campaign's limits)
    levels: list = field(default_factory=lambda: [None])

    def spec_dict(self) -> dict:
        """The campaign as data: what resuming compares, what reports print."""
        return {
            "name": self.name, "trials": self.trials, "seed": self.seed,
            "scenario_seed": self.scenario_seed, "physics_hz": self.physics_hz,
            "algorithms": [{"name": a.name, "label": a.label, "params": a.params}
                           for a in self.algorithms],
            "platforms": [p.name for p in self.platforms],
            "scenarios": [{"family": s.family, "indices": list(s.indices),
                           **({"file": s.file} if s.file else {}),
                           # (left out at 1: directories written before versions resume)
                           **({"version": s.version} if s.version not in (None, 1) else {})}
                          for s in self.scenarios],
            "limits": self.limits.as_dict(), "weights": self.weights,
            # (left out at version 1: directories written before versions resume)
            **({"protocol": self.protocol} if self.protocol != 1 else {}),
            # (left out at the default: directories written before the key existed resume)
            **({"gains": self.gains} if self.gains != DEFAULT_GAINS else {}),
            **({"thrust_floor": self.thrust_floor} if self.thrust_floor != PX4 else {}),
            **({"wind": [w or {} for w in self.winds]} if self.winds != [None] else {}),
            **({"gains": self.modes()} if len(self.modes()) > 1 else {}),
            **({"params": [p or {} for p in self.param_sets]}
               if self.param_sets != [None] else {}),
            **({"actuators": [a or {} for a in self.actuator_sets]}
               if self.actuator_sets != [None] else {}),
            **({"perception": [p or {} for p in self.perceptions]}
               if self.perceptions != [None] else {}),
            **({"estimator": [e or {} for e in self.estimators]}
               if self.estimators != [None] else {}),
            **({"failures": [f or {} for f in self.failure_sets]}
               if self.failure_sets != [None] else {}),
            **({"movers": [m or {} for m in self.mover_sets]}
               if self.mover_sets != [None] else {}),
            **({"fence": [f or {} for f in self.fences]} if self.fences != [None] else {}),
            **({"aggressiveness": [lv.as_dict() for lv in self.levels]}
               if self.levels != [None] else {}),
        }

    def modes(self) -> list[str]:
        """The controller-gain modes the matrix flies (the axis, or the one mode)."""
        return list(self.gain_modes) or [self.gains]

    def trial_params(self, platform, params: dict | None) -> dict | None:
        """A trial's PX4 parameters: ``params`` (a set of the axis), with the MPC_THR_MIN
        the campaign's ``thrust_floor`` gives ``platform`` when it differs from theirs."""
        floor = thrust_min_override(self.thrust_floor, platform, params)
        return params if floor is None else {**(params or {}), "MPC_THR_MIN": floor}

    def trial_specs(self) -> list[TrialSpec]:
        """Every trial of the matrix, grouped by scenario configuration."""
        out = []
        for sc in self.scenarios:
            for a in self.algorithms:
                for p in self.platforms:
                    # (the axis's parameter sets as this platform flies them)
                    param_sets = [self.trial_params(p, ps) for ps in self.param_sets]
                    for t in range(self.trials):
                        index = sc.indices[t % len(sc.indices)]
                        # (the same seed in every wind: the axis compares like with like)
                        key = f"{self.seed}|{a.label}|{p.name}|{sc.family}|{t}".encode()
                        seed = int.from_bytes(hashlib.sha256(key).digest()[:4], "little")
                        out.extend(TrialSpec(
                            algorithm=a.name, label=a.label, algorithm_params=a.params,
                            platform=p.name,
                            platform_def=p.physical_dict() if p.category == "user" else None,
                            family=sc.family, scenario_index=index,
                            scenario_seed=self.scenario_seed, scenario_file=sc.file,
                            trial=t, seed=seed,
                            limits=lv.limits(self.limits) if lv else self.limits,
                            aggressiveness=lv.name if lv else None, campaign=self.name,
                            physics_hz=self.physics_hz, protocol=self.protocol,
                            gains=g, scenario_version=sc.version, wind=w, params=ps,
                            actuators=ac, perception=pe, estimator=es,
                            failures=[fa] if fa else None, movers=mo, fence=fe)
                            for lv in self.levels
                            for g in self.modes() for ps in param_sets
                            for ac in self.actuator_sets for pe in self.perceptions
                            for es in self.estimators for fa in self.failure_sets
                            for mo in self.mover_sets for fe in self.fences
                            for w in self.winds)
        out.sort(key=lambda s: (s.scenario_file or "", s.family, s.scenario_index))
        return out


def preset_path(name: str) -> Path:
    return Path(str(resources.files("ft_sitl.missions") / "presets" / f"{name}.toml"))


def load_campaign(source: str | Path) -> Campaign:
    """A campaign from a file, or a preset by name (``quick``, ``paper``)."""
    text = str(source)
    path = Path(text)
    if text in PRESETS:  # a bare preset name (a campaign file always has a suffix)
        path = preset_path(text)
    doc = read_document(path, what="campaign file", hint=f" (presets: {', '.join(PRESETS)})",
                        expected="algorithms, ...", error=CampaignError)
    return parse_campaign(doc, path)


def parse_campaign(doc: dict, path: Path | None = None) -> Campaign:
    """A campaign from the top-level table of a campaign file (``path`` names it in
    messages and anchors relative file names)."""
    where = str(path) if path is not None else "campaign"
    base = path.parent if path is not None else Path(".")
    t = Table(doc, where, error=CampaignError)
    t.check_keys(TOP_KEYS)
    if "algorithms" not in doc:
        raise CampaignError(f"{where}: missing key 'algorithms' (which navigators to run)")
    name = t.string("name", path.stem if path is not None else "campaign")
    trials = t.integer("trials", 10, lo=1, hi=10_000)
    seed = t.integer("seed", 0)
    scenario_seed = t.integer("scenario_seed", 0)
    physics_hz = t.integer("physics_hz", 1000, lo=100, hi=10_000)
    if 1_000_000 % physics_hz:
        raise t.fail("physics_hz", f"{physics_hz} must divide 1,000,000")
    protocol = t.integer("protocol", PROTOCOL_VERSION, lo=min(PROTOCOLS), hi=max(PROTOCOLS))
    gains = t.get("gains", DEFAULT_GAINS)
    modes = gains if isinstance(gains, list) else [gains]
    if not modes or len(set(map(str, modes))) != len(modes) or any(
            not isinstance(m, str) or m not in GAIN_MODES for m in modes):
        raise t.fail("gains", f"must be one of {', '.join(map(repr, GAIN_MODES))} (the "
                              f"controller-gain mode, docs/missions.md) or a list of "
                              f"different ones, got {gains!r}")
    gain_modes = modes if isinstance(gains, list) else []
    gains = modes[0]
    thrust_floor = t.get("thrust_floor", THRUST_FLOOR.default)
    try:
        THRUST_FLOOR.check(thrust_floor, where)
    except SchemaError as exc:
        raise CampaignError(f"{exc} (docs/missions.md, \"Thrust floor\")") from None
    limits_t = t.table("limits", {})
    limits_t.check_keys(LIMIT_KEYS)
    try:
        limits = Limits(**limits_t.data)
    except ValueError as exc:
        raise CampaignError(f"{where}: {exc}") from None
    platforms = _platforms(t, base)
    scenarios = _scenarios(t, base)
    weights = _weights(t, platforms, scenarios)
    winds = _winds(t)
    param_sets = _param_sets(t)
    _check_floor_not_set_twice(t, thrust_floor, param_sets)
    actuator_sets = _table_axis(t, "actuators", "actuator settings", actuator_settings)
    _check_motors(t, actuator_sets, platforms)
    perceptions = _table_axis(t, "perception", "perception settings", perception_settings)
    estimators = _table_axis(t, "estimator", "estimator settings", estimator_settings)
    failure_sets = _table_axis(t, "failures", "failure settings", failure_setting)
    _check_motors(t, failure_sets, platforms, "failures", ("instance",))
    mover_sets = _table_axis(t, "movers", "mover settings", mover_settings)
    fences = _table_axis(t, "fence", "fence settings", fence_setting)
    levels = _levels(t, limits_t, protocol)
    notes: list[str] = []
    return Campaign(winds=winds, gain_modes=gain_modes, param_sets=param_sets,
                    actuator_sets=actuator_sets, perceptions=perceptions,
                    estimators=estimators, failure_sets=failure_sets, mover_sets=mover_sets,
                    fences=fences, levels=levels,
        name=name, algorithms=parse_algorithms(where, doc["algorithms"], notes),
        platforms=platforms, scenarios=scenarios, trials=trials, seed=seed,
        scenario_seed=scenario_seed, limits=limits, weights=weights, physics_hz=physics_hz,
        protocol=protocol, gains=gains, thrust_floor=thrust_floor,
        source=str(path) if path is not None else "", doc=doc, notes=notes)


def _table_axis(t: Table, key: str, what: str, check) -> list:
    """An axis of tables: ``key`` is one table (``what``) or a non-empty list of different
    ones, each checked by ``check(value, owner)`` (a TrialSpecError naming the entry);
    absent: [None], the default alone."""
    raw = t.get(key, None)
    if raw is None:
        return [None]
    items = [raw] if isinstance(raw, dict) else raw
    if not isinstance(items, list) or not items:
        raise t.fail(key, f"must be a table of {what} or a non-empty list of them, "
                          f"got {raw!r}")
    out, seen = [], set()
    for k, item in enumerate(items):
        owner = key if isinstance(raw, dict) else f"{key}[{k}]"
        try:
            value = check(item, f"{t.where}: {owner}")
        except TrialSpecError as exc:
            raise CampaignError(str(exc)) from None
        canonical = json.dumps(value, sort_keys=True)
        if canonical in seen:
            raise t.fail(owner, f"the same {what} twice ({item!r})")
        seen.add(canonical)
        out.append(value)
    return out


def _levels(t: Table, limits_t: Table, protocol: int) -> list:
    """The ``aggressiveness`` axis: one level (a declared level's name or a table) or a
    non-empty list of different ones (missions.aggressiveness), each flown by every trial
    of the matrix; absent: [None], the campaign's limits. A level sets the speed cap and
    the acceleration limit, so ``[limits]`` may not set them too."""
    raw = t.get("aggressiveness", None)
    if raw is None:
        return [None]
    items = raw if isinstance(raw, list) else [raw]
    if not items:
        raise t.fail("aggressiveness", "must be a level (a name or a table) or a non-empty "
                                       "list of them, got []")
    both = [k for k in LEVEL_LIMITS if k in limits_t]
    if both:
        raise limits_t.fail(both[0], "the aggressiveness axis sets it for each level; leave "
                                     "it out of [limits] (or drop the axis)")
    if PROTOCOLS[protocol].max_acc_m_s2 is None:
        raise t.fail("aggressiveness", f"protocol version {protocol} has no acceleration "
                                       f"limit (each planner used its own; it came with "
                                       f"version 3), so its trials cannot fly a level")
    out: list[Level] = []
    for k, item in enumerate(items):
        owner = "aggressiveness" if not isinstance(raw, list) else f"aggressiveness[{k}]"
        try:
            level = level_of(item, f"{t.where}: {owner}")
        except TrialSpecError as exc:
            raise CampaignError(str(exc)) from None
        for j, other in enumerate(out):
            if other.name == level.name:
                raise t.fail(owner, f"the level name {level.name!r} twice (also "
                                    f"aggressiveness[{j}])")
            if (other.max_speed_m_s, other.max_acc_m_s2) == (level.max_speed_m_s,
                                                             level.max_acc_m_s2):
                raise t.fail(owner, f"{level.summary()} flies the same limits as "
                                    f"aggressiveness[{j}], {other.summary()}")
        out.append(level)
    return out


def _winds(t: Table) -> list:
    """The ``wind`` axis: wind settings (ft_sitl.physics.wind, docs/platforms.md), each
    flown by every trial of the matrix; absent: calm air."""
    return _table_axis(t, "wind", "wind settings", wind_settings)


def _param_sets(t: Table) -> list:
    """The ``params`` axis: PX4 parameters (autopilot.params: name = value), each set flown
    by every trial of the matrix; absent: the defaults."""
    return _table_axis(t, "params", "PX4 parameters", px4_params)


def _check_floor_not_set_twice(t: Table, thrust_floor: str, param_sets: list) -> None:
    """A ``thrust_floor`` mode that sets MPC_THR_MIN and a ``params`` set that sets it too
    is a conflict, refused rather than one silently winning."""
    if thrust_floor == PX4:
        return
    for k, ps in enumerate(param_sets):
        if "MPC_THR_MIN" in (ps or {}):
            owner = "params" if len(param_sets) == 1 else f"params[{k}]"
            raise t.fail(owner, f"MPC_THR_MIN is set by thrust_floor = {thrust_floor!r} "
                                f"(per platform); drop one of the two")


def _check_motors(t: Table, actuator_sets: list, platforms, axis: str = "actuators",
                  keys=("degraded_motor", "fail_motor", "stuck_motor")) -> None:
    """The motors an actuator (or failure) setting names exist on every platform of the
    campaign."""
    fewest = min((p.n_rotors for p in platforms), default=0)
    for k, a in enumerate(actuator_sets):
        for key in keys:
            m = (a or {}).get(key, 0)
            if key == "instance" and (a or {}).get("unit") != "motor":
                continue
            if m > fewest:
                owner = axis if len(actuator_sets) == 1 else f"{axis}[{k}]"
                raise t.fail(owner,
                             f"{key}: {m} must be within 0..{fewest} (the fewest motors of "
                             f"the campaign's platforms)")


def _weights(t: Table, platforms, scenarios) -> dict:
    """The ``weights`` table, checked now by the scorer's rules (what the score would refuse
    after every trial has flown)."""

    w = t.table("weights", {})
    w.check_keys(WEIGHT_KEYS)
    out: dict = {}
    if "beta" in w:
        try:
            scoring.check_beta(w.data["beta"], what=f"{w.prefix}beta")
        except ValueError as exc:
            raise CampaignError(f"{w.where}: {exc}") from None
        out["beta"] = float(w.data["beta"])
    fam = {s.family: ("user" if s.file else CATEGORY.get(s.family, "user")) for s in scenarios}
    plat = {p.name: p.category for p in platforms}
    for key, defaults, names in (("scenarios", scoring.DEFAULT_SCENARIO_WEIGHTS, fam),
                                 ("platforms", scoring.DEFAULT_PLATFORM_WEIGHTS, plat)):
        if key not in w:
            continue
        given = w.data[key]
        if not isinstance(given, dict):
            raise w.fail(key, f"must be a table of weights, got {given!r}")
        try:
            scoring.resolve_weights(given, defaults, names, names, f"{w.prefix}{key}")
        except ValueError as exc:
            raise CampaignError(f"{w.where}: {exc}") from None
        out[key] = {str(k): float(v) for k, v in given.items()}
    return out


def parse_algorithms(where: str, v, notes: list[str] | None = None) -> list[AlgorithmEntry]:
    """The ``algorithms`` entries (``where`` names them in messages); what ``"all"`` leaves
    out is appended to ``notes``."""

    if v == "all":
        v = []
        for n, c in sorted(available().items()):
            why = c if isinstance(c, str) else c.unavailable()
            if why is None:
                v.append(n)
            elif notes is not None:
                notes.append(f"algorithms = \"all\" leaves out {n!r}: {why}")
    out, labels = [], set()
    for k, item in enumerate(Table({"algorithms": v}, where, error=CampaignError)
                             .items("algorithms")):
        w = f"{where}: algorithms[{k}]"
        if isinstance(item, str):
            item = {"name": item}
        if not isinstance(item, dict):
            raise CampaignError(f"{w}: must be a navigator name or a table with 'name'")
        Table(item, w, error=CampaignError).check_keys(("name", "label", "params", "command"))
        if "command" in item:
            out.append(_command_entry(w, item, labels))
            continue
        name = item.get("name")
        if not isinstance(name, str):
            raise CampaignError(f"{w}: missing 'name' (a registered navigator)")
        params = item.get("params", {})
        if not isinstance(params, dict):
            raise CampaignError(f"{w}: params: must be a table of parameters")
        try:
            create(name, params)  # validates the name and the parameters now
        except NavigatorError as exc:
            raise CampaignError(f"{w}: {exc}") from None
        label = item.get("label", name)
        if not isinstance(label, str) or not label:
            raise CampaignError(f"{w}: label: must be a non-empty string")
        if label in labels:
            raise CampaignError(f"{w}: label {label!r} is used twice; give each entry its "
                                "own label")
        labels.add(label)
        out.append(AlgorithmEntry(name, label, dict(params)))
    return out


def _command_entry(w: str, item: dict, labels: set) -> AlgorithmEntry:
    """A user program as the navigator: ``{label = "mine", command = "python nav.py"}``."""

    if "name" in item or "params" in item:
        raise CampaignError(f"{w}: a 'command' entry takes only 'label' and 'command'")
    cmd = item["command"]
    if isinstance(cmd, str):
        try:
            argv = shlex.split(cmd)
        except ValueError as exc:
            raise CampaignError(f"{w}: command: {exc}") from None
    elif isinstance(cmd, list) and all(isinstance(a, str) for a in cmd):
        argv = list(cmd)
    else:
        raise CampaignError(f"{w}: command: must be a command line (a string or a list of "
                            "strings)")
    if not argv:
        raise CampaignError(f"{w}: command: is empty")
    label = item.get("label")
    if not isinstance(label, str) or not label:
        raise CampaignError(f"{w}: a 'command' entry needs a 'label' (its name in the "
                            "results)")
    if label in labels:
        raise CampaignError(f"{w}: label {label!r} is used twice; give each entry its "
                            "own label")
    labels.add(label)
    return AlgorithmEntry(COMMAND, label, {"argv": argv})


def _platforms(t: Table, base: Path) -> list:
    where = t.where
    files = t.items("platform_files") if t.get("platform_files", []) else []
    try:
        reg = PlatformRegistry([base / f for f in files])
    except (PlatformError, OSError, ValueError) as exc:
        raise CampaignError(f"{where}: platform_files: {exc}") from None
    everything = reg.all()
    chosen: list = []
    for k, item in enumerate(t.items("platforms", "all")):
        if not isinstance(item, str):
            raise CampaignError(f"{where}: platforms[{k}]: must be a platform name or a "
                                f"category, got {item!r}")
        if item == "all":
            picked = everything
        elif item in CATEGORIES:
            picked = reg.category(item)
            if not picked:
                raise CampaignError(f"{where}: platforms: no {item} platforms "
                                    f"(user platforms come from platform_files)")
        else:
            try:
                picked = [reg.get(item)]
            except (PlatformError, KeyError, ValueError) as exc:
                raise CampaignError(f"{where}: platforms[{k}]: {exc}") from None
        for p in picked:
            if p.name not in {q.name for q in chosen}:
                chosen.append(p)
    return chosen


def _indices(t: Table, default="all") -> tuple[int, ...]:
    """The configurations ``t["indices"]`` names: "all", one index or a list (1..10)."""
    v = t.get("indices", default)
    if v == "all":
        return tuple(range(1, 11))
    items = [v] if isinstance(v, int) else t.items("indices", default)
    return tuple(integer(i, t.fail, "indices", lo=1, hi=10) for i in items)


def _scenarios(t: Table, base: Path) -> list[ScenarioEntry]:
    where = t.where
    indices = _indices(t)
    if t.get("scenarios", "all") == "all":
        return [ScenarioEntry(f, indices, version=REGISTRY[f].version) for f in FAMILIES]
    out = []
    for k, item in enumerate(t.items("scenarios")):
        w = f"{where}: scenarios[{k}]"
        if isinstance(item, str):
            item = {"family": item}
        if not isinstance(item, dict):
            raise CampaignError(f"{w}: must be a family name or a table")
        entry = Table(item, w, error=CampaignError)
        entry.check_keys(("family", "indices", "file", "version"))
        if "file" in item:

            if "version" in item:
                raise CampaignError(f"{w}: version does not apply to a scenario file (its "
                                    "geometry is the file)")
            if "indices" in item:
                raise CampaignError(f"{w}: indices do not apply to a scenario file (it is "
                                    "one configuration)")
            f = base / str(item["file"])
            try:
                sc = load_scenario(f)
            except ScenarioError as exc:
                raise CampaignError(f"{w}: {exc}") from None
            out.append(ScenarioEntry(sc.family, (1,), str(f.resolve())))
            continue
        try:
            fam = resolve_family(item.get("family"))
        except ScenarioError as exc:
            raise CampaignError(f"{w}: {exc}") from None
        idx = _indices(entry) if "indices" in item else indices
        try:
            version = REGISTRY[fam].check_version(item.get("version"))
        except ScenarioError as exc:
            raise CampaignError(f"{w}: version: {exc}") from None
        out.append(ScenarioEntry(fam, idx, version=version))
    seen: dict = {}
    for k, e in enumerate(out):
        key = e.file or e.family
        if key in seen:
            raise CampaignError(f"{where}: scenarios[{k}]: {key!r} is listed twice (also "
                                f"scenarios[{seen[key]}]); give each family once, with all "
                                "its indices")
        seen[key] = k
    return out
