"""One trial of the FLYINGTRUST protocol, in-process and in lockstep.

``run_trial(spec)`` flies one :class:`TrialSpec` with the same flight-controller code the
MAVLink layer serves (a :class:`~ft_sitl.sim.fleet.Fleet` with its commander, cascade
and plant, and the scenario's collision guard) and returns the trial's row of the results
table (:mod:`ft_sitl.missions.results`).

Protocol (``../shared/docs/benchmark-protocol.md``, paper Sec. IV-B):

1. *Approach.* Spawn on the floor at the scenario's takeoff point facing the goal, arm,
   take off (PX4 AUTO.TAKEOFF) to the start altitude, then hold until the vehicle is
   stable at the start waypoint: within 0.3 m of it and slower than 0.3 m/s for 1 s
   (limit: 30 s, else the trial fails as ``loss_of_control`` "could not reach the start").
2. *Navigation.* Offboard mode; every ``1 / navigator.rate_hz`` s of simulated time the
   navigator gets an :class:`~ft_sitl.navigation.Observation` (and a depth frame when
   its camera is due) and returns a setpoint. ``MPC_XY_VEL_MAX`` is the speed cap (4 m/s).
3. *Outcome*, checked every 20 ms of simulated time (the commander's tick) and at every
   physics step for contacts (the guard): the first of

   - ``collision``: the collision sphere touched an obstacle (the guard's event);
   - ``out_of_bounds``: the centre left the flight volume (area sides, ceiling), or the
     vehicle touched the floor during navigation;
   - ``loss_of_control``: tilt beyond 90 deg or a non-finite state;
   - ``navigator_error``: the navigator raised, or returned something that is not a
     valid Setpoint;
   - ``timeout``: not in the goal sphere 90 s after navigation start, or the navigator
     gave up (``GiveUp``: "no plan");
   - ``unstable``: entered the goal sphere but left it within the 3 s hold window;
   - ``success``: entered the goal sphere (within 90 s) and stayed in it for 3 s.

Everything but ``wall_time_s`` and ``planner_time_s`` is a pure function of the spec:
the same spec gives the same row (``ft-sitl trial rerun`` checks this).
"""

from __future__ import annotations

import datetime
import hashlib
import json
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ft_sitl import __version__
from ft_sitl.autopilot import cascade as cs
from ft_sitl.autopilot.cascade import C_SAT_STEPS
from ft_sitl.autopilot.commander import MAIN_OFFBOARD
from ft_sitl.autopilot.params import ParamSet
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.navigation.base import GiveUp, Limits, Observation, Task
from ft_sitl.physics import dynamics as d
from ft_sitl.sim.fleet import Fleet

APPROACH_TIMEOUT_S = 30.0
STABLE_POS_M = 0.3
STABLE_SPEED_M_S = 0.3
STABLE_FOR_S = 1.0
TICK_S = 0.02
#: wall-clock budget of one in-process trial (s): a navigator that hangs (or is hundreds of
#: times slower than real time) fails its trial as a navigator error instead of stopping
#: the campaign; far above any legitimate trial (the slowest take ~10 s here)
TRIAL_WALL_BUDGET_S = 600.0
WALL_BUDGET_ENV = "FT_SITL_TRIAL_WALL_BUDGET_S"


def wall_budget_from_env() -> float | None:
    """The trial wall-clock budget campaigns use: ``$FT_SITL_TRIAL_WALL_BUDGET_S`` seconds
    ("none" for no limit), else :data:`TRIAL_WALL_BUDGET_S`. ValueError names the variable
    when it is not a positive number or "none"."""
    import os

    raw = os.environ.get(WALL_BUDGET_ENV)
    if raw is None or raw.strip() == "":
        return TRIAL_WALL_BUDGET_S
    if raw.strip().lower() == "none":
        return None
    try:
        v = float(raw)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise ValueError(f"{WALL_BUDGET_ENV}={raw!r}: must be a positive number of seconds "
                         f"or 'none'")
    return v
MAX_TILT_RAD = math.pi / 2


class TrialSpecError(ValueError):
    """A trial spec is invalid; the message names the field."""


def _int(name, v, lo=0):
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

    def __post_init__(self):
        for name in ("algorithm", "platform", "family"):
            v = getattr(self, name)
            if not isinstance(v, str) or not v:
                raise TrialSpecError(f"{name}: must be a non-empty string, got {v!r}")
        _int("scenario_index", self.scenario_index, 1)
        _int("scenario_seed", self.scenario_seed)
        _int("trial", self.trial)
        _int("seed", self.seed)
        _int("physics_hz", self.physics_hz, 1)
        if not isinstance(self.algorithm_params, dict):
            raise TrialSpecError("algorithm_params: must be a table of parameters")
        if not isinstance(self.limits, Limits):
            raise TrialSpecError("limits: must be a Limits")

    # --- serialisation -------------------------------------------------------------------
    def to_dict(self) -> dict:
        return {
            "algorithm": self.algorithm, "algorithm_params": self.algorithm_params,
            "platform": self.platform, "platform_def": self.platform_def,
            "family": self.family, "scenario_index": self.scenario_index,
            "scenario_seed": self.scenario_seed, "scenario_file": self.scenario_file,
            "trial": self.trial, "seed": self.seed, "limits": self.limits.as_dict(),
            "campaign": self.campaign, "label": self.label, "physics_hz": self.physics_hz,
        }

    @classmethod
    def from_dict(cls, d: dict) -> TrialSpec:
        if not isinstance(d, dict):
            raise TrialSpecError("a trial spec must be a table")
        d = dict(d)
        d.pop("code_version", None)
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


# --- per-process caches: scenarios, collision worlds and grids are reused across trials ---
_SCENARIOS: dict = {}
_GRIDS: dict = {}
_CACHE_MAX = 8


def _cached(cache: dict, key, make):
    if key not in cache:
        if len(cache) >= _CACHE_MAX:
            cache.pop(next(iter(cache)))
        cache[key] = make()
    return cache[key]


def load_scenario_for(spec: TrialSpec):
    if spec.scenario_file:
        from ft_sitl.scenarios.io import load_scenario

        return _cached(_SCENARIOS, ("file", spec.scenario_file),
                       lambda: load_scenario(spec.scenario_file))
    from ft_sitl.scenarios.families import build_scenario

    key = (spec.family, spec.scenario_index, spec.scenario_seed)
    return _cached(_SCENARIOS, key, lambda: build_scenario(*key))


def _scenario_key(sc) -> tuple:
    """What identifies a scenario's geometry (not its id(): ids are reused)."""
    return (sc.name, sc.mesh_digest(), tuple(sc.bounds_min), tuple(sc.bounds_max))


#: a directory where campaign workers share distance grids (None: each process builds its
#: own); set in each worker by the campaign's process pool (:func:`set_grid_dir`)
_GRID_DIR: str | None = None
#: shared grids kept on disk (the newest; up to ~30 MB each): a campaign's chunks come
#: scenario by scenario, so an older grid is rarely asked for again (it is rebuilt if so)
GRID_CACHE_KEEP = 8


def set_grid_dir(path: str | None) -> None:
    """Share distance grids through ``path``: the first process to need a scenario's grid
    builds it and saves it there, the others load it (a grid is deterministic, so every
    process gets the same array it would have built)."""
    global _GRID_DIR
    _GRID_DIR = path


def _distance_grid(scenario, key: tuple):
    from ft_sitl.scenarios.distance_grid import DistanceGrid

    def build():
        return DistanceGrid.build(scenario.mesh, scenario.bounds_min, scenario.bounds_max)

    if _GRID_DIR is None:
        return build()
    try:
        import fcntl
    except ImportError:  # no advisory locks (Windows): build here
        return build()
    name = hashlib.sha256(repr(key).encode()).hexdigest()[:32]
    path = os.path.join(_GRID_DIR, name + ".npz")
    try:
        lock = open(os.path.join(_GRID_DIR, name + ".lock"), "a")
    except OSError:  # the directory is gone (the campaign ended): build here
        return build()
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one process builds, the others wait and load
        if os.path.exists(path):
            try:
                with np.load(path) as z:
                    return DistanceGrid(z["data"], z["origin"], float(z["pitch"]))
            except (OSError, ValueError, KeyError):
                pass  # unreadable: build it again
        grid = build()
        tmp = f"{path}.{os.getpid()}.tmp.npz"
        try:
            np.savez(tmp, data=grid.data, origin=grid.origin, pitch=grid.pitch)
            os.replace(tmp, path)
            _prune_grids(_GRID_DIR)
        except OSError:
            pass  # sharing is an optimisation only
        return grid


def _prune_grids(directory: str) -> None:
    """Delete all but the GRID_CACHE_KEEP newest shared grids (their lock files stay: a
    process may be waiting on one)."""
    saved = []
    for name in os.listdir(directory):
        if name.endswith(".npz") and ".tmp." not in name:
            try:
                saved.append((os.stat(os.path.join(directory, name)).st_mtime_ns, name))
            except OSError:
                continue
    for _, name in sorted(saved)[:-GRID_CACHE_KEEP]:
        try:
            os.remove(os.path.join(directory, name))
        except OSError:
            pass


def _world_and_grid(scenario):
    from ft_sitl.scenarios.collision import CollisionWorld

    key = _scenario_key(scenario)

    def make():
        return (CollisionWorld(scenario.mesh, scenario.bounds_min, scenario.bounds_max),
                _distance_grid(scenario, key))
    return _cached(_GRIDS, key, make)


def platform_for(spec: TrialSpec):
    if spec.platform_def is not None:
        from ft_sitl.physics.catalog import platform_from_mapping

        return platform_from_mapping(dict(spec.platform_def), f"trial spec platform "
                                                               f"{spec.platform!r}")
    from ft_sitl.physics.catalog import get_platform

    return get_platform(spec.platform)


# --- the trial -----------------------------------------------------------------------------
@dataclass
class TrialOutcome:
    row: dict
    trajectory: np.ndarray | None = None  # (K, 4): t_s (from navigation start), x, y, z
    scenario: object = None


class _Fail(Exception):
    def __init__(self, reason: str, detail: str = ""):
        super().__init__(reason)
        self.reason, self.detail = reason, detail


class WallBudgetExceeded(BaseException):
    """Raised into a trial that overran its wall-clock budget (a BaseException, so the
    navigator's own ``except Exception`` does not swallow it)."""


class _WallWatchdog:
    """Interrupts the trial ``budget_s`` after it started: SIGALRM when the trial runs on
    the main thread of a POSIX process (a navigator stuck inside one step), plus a check
    between steps everywhere."""

    def __init__(self, wall0: float, budget_s: float | None):
        self.deadline = math.inf if budget_s is None else wall0 + budget_s
        self.budget_s = budget_s
        self._old = None

    def __enter__(self):
        import signal
        import threading

        if (self.budget_s is not None and hasattr(signal, "setitimer")
                and threading.current_thread() is threading.main_thread()
                and signal.getitimer(signal.ITIMER_REAL)[0] == 0.0):
            # (an alarm someone else armed, e.g. a test timeout, is left alone: then only
            # the check between steps applies)
            def fire(signum, frame):
                raise WallBudgetExceeded()
            self._old = signal.signal(signal.SIGALRM, fire)
            signal.setitimer(signal.ITIMER_REAL,
                             max(self.deadline - time.perf_counter(), 1e-3))
        return self

    def __exit__(self, *exc):
        if self._old is not None:
            import signal

            signal.setitimer(signal.ITIMER_REAL, 0.0)
            signal.signal(signal.SIGALRM, self._old)
            self._old = None
        return False

    def check(self) -> None:
        if time.perf_counter() > self.deadline:
            raise WallBudgetExceeded()

    def fail(self, t_nav_s: float) -> _Fail:
        return _Fail("navigator_error", f"the trial overran its wall-clock budget of "
                                        f"{self.budget_s:g} s at {t_nav_s:.1f} s of "
                                        f"navigation (a hung or far too slow navigator)")


def trial_vehicle(spec: TrialSpec, sc, platform):
    """The trial's collision guard and its one-vehicle Fleet, on the takeoff point facing
    the goal, the speed cap as MPC_XY_VEL_MAX (in-process and over the wire alike)."""
    from ft_sitl.sim.guard import CollisionGuard

    world, grid = _world_and_grid(sc)
    guard = CollisionGuard(world, [platform.collision_radius_m], grid=grid,
                           names=sc.obstacle_name)
    params = ParamSet({"MPC_XY_VEL_MAX": spec.limits.max_speed_m_s})
    fleet = Fleet([platform], params=[params], spawn=[sc.takeoff], spawn_yaw=[sc.start_yaw],
                  physics_hz=spec.physics_hz, guard=guard)
    return guard, fleet


def run_trial(spec: TrialSpec, *, record: bool = False, navigator=None,
              wall_budget_s: float | None = TRIAL_WALL_BUDGET_S) -> TrialOutcome:
    """Fly one trial; the row of the results table (and the trajectory when ``record``).
    ``navigator`` overrides the registry lookup (an instance; tests). A trial still running
    ``wall_budget_s`` of wall-clock time after it started (None: no limit) ends as a
    navigator error."""
    if wall_budget_s is not None and not (isinstance(wall_budget_s, (int, float))
                                          and not isinstance(wall_budget_s, bool)
                                          and wall_budget_s > 0):
        raise ValueError(f"wall_budget_s must be a positive number of seconds or None, got "
                         f"{wall_budget_s!r}")
    from ft_sitl.navigation.registry import create
    wall0 = time.perf_counter()
    sc, platform = load_scenario_for(spec), platform_for(spec)
    nav = navigator if navigator is not None else create(spec.algorithm,
                                                         spec.algorithm_params)
    guard, fleet = trial_vehicle(spec, sc, platform)
    cmd = fleet.commanders[0]
    ind = platform.indicators()
    row = _identity_row(spec, platform, ind, sc)
    m = _Metrics()
    traj: list = []
    reason, detail = "success", ""
    # navigation-phase baselines (the approach may fail before they are taken)
    t_nav0_us, sat0, steps0, e0 = None, 0.0, 0, math.nan
    watchdog = _WallWatchdog(wall0, wall_budget_s)
    try:
        with watchdog:
            _approach(fleet, sc)
            t_nav0_us = fleet.time_us
            sat0 = float(fleet.sim.ctrl[0, C_SAT_STEPS])
            steps0 = fleet.sim.steps
            e0 = fleet.sim.energy_j(0)
            n_events = len(fleet.events)
            task = Task(start=sc.start.copy(), start_yaw=sc.start_yaw, goal=sc.goal.copy(),
                        limits=spec.limits, bounds_min=sc.bounds_min.copy(),
                        bounds_max=sc.bounds_max.copy(),
                        collision_radius_m=platform.collision_radius_m, twr_max=ind.twr_max,
                        alpha_xy_max=ind.alpha_xy_max_rad_s2, alpha_z_max=ind.alpha_z_max_rad_s2,
                        rng=np.random.default_rng(np.random.SeedSequence(
                            [spec.seed, spec.trial])))
            camera = _camera(nav, sc)
            cam_rng = np.random.default_rng(np.random.SeedSequence([spec.seed, spec.trial, 1]))
            try:
                t = time.perf_counter()
                nav.reset(task)
                m.planner_s += time.perf_counter() - t
            except GiveUp as exc:
                raise _Fail("timeout", f"navigator gave up: {exc}") from None
            except (KeyboardInterrupt, WallBudgetExceeded):
                raise
            except BaseException as exc:  # noqa: BLE001 - even sys.exit() only fails the trial
                raise _Fail("navigator_error",
                            f"reset raised {type(exc).__name__}: {exc}") from None
            period_us = _period_us(nav, fleet.sim.dt_us)
            next_nav_us = t_nav0_us
            next_cam_us = t_nav0_us
            cam_period_us = round(1e6 / camera.config.rate_hz) if camera is not None else 0
            judge = NavigationJudge(fleet, guard, spec, sc, m, n_events, traj if record else None)
            tick_us = round(TICK_S * 1e6)
            while True:
                now = fleet.time_us
                t_nav_us = now - t_nav0_us
                if now >= next_nav_us:
                    s = judge.state_at(now)
                    depth = None
                    if camera is not None and now >= next_cam_us:
                        depth = camera.capture(t_nav_us, fleet.sim.position(0),
                                               fleet.sim.attitude(0), rng=cam_rng)
                        next_cam_us += cam_period_us
                    obs = Observation(time_s=t_nav_us * 1e-6, position=s.position,
                                      velocity=s.velocity, yaw=s.yaw,
                                      attitude=fleet.sim.attitude(0),
                                      angular_velocity=fleet.sim.x[
                                          0, d.X_OMEGA:d.X_OMEGA + 3].copy(),
                                      depth=depth)
                    sp = _ask(nav, obs, m)
                    fleet.offboard_setpoint(0, sp)
                    if cmd.main_mode != MAIN_OFFBOARD:  # PX4: a setpoint first, then the mode
                        res = cmd.set_mode(MAIN_OFFBOARD)
                        if res.name != "ACCEPTED" or cmd.main_mode != MAIN_OFFBOARD:
                            raise _Fail("navigator_error", "the flight controller refused "
                                                           "offboard mode")
                        fleet.offboard_setpoint(0, sp)
                    next_nav_us += period_us
                # to the next navigator step or commander tick, at least one physics step
                fleet.run_us(max(fleet.sim.dt_us, min(tick_us, next_nav_us - fleet.time_us)))
                if judge.after_step():
                    break
                watchdog.check()
    except _Fail as f:
        reason, detail = f.reason, f.detail
    except WallBudgetExceeded:
        t_nav_s = (fleet.time_us - t_nav0_us) * 1e-6 if t_nav0_us is not None else 0.0
        f = watchdog.fail(t_nav_s)
        reason, detail = f.reason, f.detail
    finish_row(row, spec, fleet, m, reason, detail, (t_nav0_us, sat0, steps0, e0),
               _count(getattr(nav, "replans", 0)), wall0)
    return TrialOutcome(row, np.array(traj) if record else None, sc)


def finish_row(row: dict, spec, fleet, m, reason: str, detail: str, baselines,
               replans: int, wall0: float) -> None:
    """Complete a trial's row: outcome, metrics, navigation-phase totals (``baselines`` =
    time, saturation steps, physics steps and energy at navigation start; time None when
    navigation never started)."""
    t_nav0_us, sat0, steps0, e0 = baselines
    if reason == "collision":
        m.min_clear = 0.0  # it touched (the contact response leaves it 1 mm off)
    navigated = t_nav0_us is not None
    nav_steps = fleet.sim.steps - steps0 if navigated else 0
    row.update(m.row())
    row.update({
        "success": reason == "success", "reason": reason, "detail": detail,
        "nav_time_s": (fleet.time_us - t_nav0_us) * 1e-6 if navigated else 0.0,
        "saturation_fraction": (float(fleet.sim.ctrl[0, C_SAT_STEPS] - sat0) / nav_steps
                                if nav_steps else math.nan),
        "energy_j": fleet.sim.energy_j(0) - e0 if navigated else math.nan,
        "replans": replans,
        "sim_time_s": fleet.time_us * 1e-6,
        "wall_time_s": time.perf_counter() - wall0,
        "code_version": __version__,
        "finished_utc": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "spec": spec.to_json(),
    })


def _count(v) -> int:
    """A navigator's replan counter as an integer (-1 if it is not a count)."""
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
        return -1
    return int(v)


def _identity_row(spec, platform, ind, sc) -> dict:
    return {
        "trial_id": spec.trial_id, "campaign": spec.campaign,
        "algorithm": spec.label or spec.algorithm,
        "algorithm_params": json.dumps(spec.algorithm_params, sort_keys=True),
        "platform": platform.name, "platform_category": platform.category,
        "mass_kg": platform.mass_kg, "twr_max": ind.twr_max,
        "alpha_xy_max": ind.alpha_xy_max_rad_s2, "alpha_z_max": ind.alpha_z_max_rad_s2,
        "family": sc.family, "scenario_category": sc.category,
        "scenario_index": sc.index, "scenario_seed": sc.seed, "scenario": sc.name,
        "trial": spec.trial, "seed": spec.seed,
    }


def _approach(fleet: Fleet, sc) -> None:
    """Arm, take off to the start altitude, settle at the start waypoint."""
    cmd = fleet.commanders[0]
    res = cmd.arm()
    if res.name != "ACCEPTED":
        texts = [t for _, t in cmd.statustexts]
        raise _Fail("loss_of_control", f"arming refused: {texts[-1] if texts else res.name}")
    cmd.takeoff(float(sc.start[2]))
    stable_us = 0
    tick_us = round(TICK_S * 1e6)
    t_end = fleet.time_us + round(APPROACH_TIMEOUT_S * 1e6)
    reposition = False
    while fleet.time_us < t_end:
        fleet.run_us(tick_us)
        s = fleet.state(0)
        if fleet.events and fleet.events[-1].kind == "collision":
            ev = fleet.events[-1]
            raise _Fail("collision", f"hit {ev.what} before navigation started")
        if not reposition and abs(s.position[2] - sc.start[2]) < STABLE_POS_M:
            cmd.reposition(sc.start.copy(), sc.start_yaw)
            reposition = True
        err = float(np.linalg.norm(s.position - sc.start))
        if reposition and err < STABLE_POS_M and float(np.linalg.norm(s.velocity)) \
                < STABLE_SPEED_M_S:
            stable_us += tick_us
            if stable_us >= round(STABLE_FOR_S * 1e6):
                return
        else:
            stable_us = 0
    s = fleet.state(0)
    raise _Fail("loss_of_control", f"could not reach the start in {APPROACH_TIMEOUT_S:g} s "
                                   f"({np.linalg.norm(s.position - sc.start):.2f} m off)")


_CAMERAS: dict = {}


def _camera(nav, sc):
    """The navigator's camera in this scenario (its ray-casting BVH cached per process)."""
    cfg = getattr(nav, "camera", None)
    if cfg is None:
        return None
    from ft_sitl.scenarios.camera import DepthCamera

    return _cached(_CAMERAS, (_scenario_key(sc), cfg), lambda: DepthCamera(cfg, sc.mesh))


def _period_us(nav, dt_us: int) -> int:
    """The navigator's step period, a whole number of physics steps (at least one)."""
    rate = getattr(nav, "rate_hz", None)
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not (
            math.isfinite(rate) and rate > 0):
        raise _Fail("navigator_error", f"rate_hz must be a positive number, got {rate!r}")
    return max(1, round(1e6 / float(rate) / dt_us)) * dt_us


def _ask(nav, obs, m) -> Setpoint:
    t = time.perf_counter()
    try:
        sp = nav.step(obs)
    except GiveUp as exc:
        raise _Fail("timeout", f"navigator gave up: {exc}") from None
    except (KeyboardInterrupt, WallBudgetExceeded):
        raise
    except BaseException as exc:  # noqa: BLE001 - even sys.exit() only fails the trial
        raise _Fail("navigator_error", f"step raised {type(exc).__name__}: {exc}") from None
    finally:
        m.planner_s += time.perf_counter() - t
        m.planner_calls += 1
    why = _invalid(sp)
    if why:
        raise _Fail("navigator_error", f"step returned {why}")
    return sp


def _invalid(sp) -> str:
    """Why sp is not a setpoint the flight controller can fly ("" if it is one)."""
    if not isinstance(sp, Setpoint):
        return f"{type(sp).__name__}, not a Setpoint"
    row = sp.row
    if not isinstance(row, np.ndarray) or row.shape != (cs.N_SP,) or row.dtype.kind != "f":
        return "a malformed setpoint"
    why = _setpoint_problem(row if row.dtype == np.float64 else row.astype(np.float64))
    if why == 0:
        return ""
    if why == 2:
        kind = row[cs.SP_KIND]
        if kind in (cs.KIND_OFF, cs.KIND_IDLE):
            return "a motors-off/idle setpoint"
        return f"a setpoint of unknown kind {kind!r}"
    return _PROBLEMS[why]


_PROBLEMS = {1: "a setpoint with an infinite value",
             3: "a trajectory setpoint with an uncontrolled axis",
             4: "an attitude setpoint with NaN", 5: "a rates setpoint with NaN"}


@njit(cache=True)
def _setpoint_problem(row) -> int:
    """0 when the offboard setpoint row is flyable, else the code of the first problem
    (1 infinite value, 2 not an offboard kind, 3 a trajectory axis with no position,
    velocity or acceleration, 4 / 5 NaN in an attitude / rates setpoint): one compiled pass
    instead of a dozen numpy calls per navigator step."""
    for k in range(row.shape[0]):
        if math.isinf(row[k]):
            return 1
    kind = row[cs.SP_KIND]
    if not (kind == cs.KIND_TRAJECTORY or kind == cs.KIND_ATTITUDE or kind == cs.KIND_RATES):
        return 2
    if kind == cs.KIND_TRAJECTORY:
        for a in range(3):
            if (math.isnan(row[cs.SP_POS + a]) and math.isnan(row[cs.SP_VEL + a])
                    and math.isnan(row[cs.SP_ACC + a])):
                return 3
    elif kind == cs.KIND_ATTITUDE:
        for a in range(4):
            if math.isnan(row[cs.SP_Q + a]):
                return 4
        if math.isnan(row[cs.SP_THRUST]):
            return 4
    else:
        for a in range(3):
            if math.isnan(row[cs.SP_RATES + a]):
                return 5
        if math.isnan(row[cs.SP_THRUST]):
            return 5
    return 0


def _check(fleet: Fleet, n_events: int, s, spec) -> None:
    for ev in fleet.events[n_events:]:
        if ev.kind == "collision":
            raise _Fail("collision", f"hit {ev.what} at {ev.speed_m_s:.1f} m/s")
        if ev.kind == "left_volume":
            raise _Fail("out_of_bounds", f"left the flight volume past the {ev.what}"
                        if ev.what != "ceiling" else "climbed above the ceiling")
    x = fleet.sim.x[0]
    if not np.all(np.isfinite(x)):
        raise _Fail("loss_of_control", "non-finite state")
    if s.tilt > MAX_TILT_RAD:
        raise _Fail("loss_of_control", f"tilt {math.degrees(s.tilt):.0f} deg")
    if s.on_ground:
        raise _Fail("out_of_bounds", "touched the floor")


class NavigationJudge:
    """The protocol's outcome checks during navigation, after every advance of the
    simulation (in-process and over the wire alike): metrics, the trajectory record,
    collision / bounds / control checks, the goal sphere with its hold, the timeout.
    :meth:`after_step` raises _Fail with the outcome, or returns True on success."""

    def __init__(self, fleet, guard, spec, sc, metrics, n_events: int, traj=None):
        self.fleet, self.guard, self.spec, self.sc = fleet, guard, spec, sc
        self.m = metrics
        self.n_events = n_events
        self.traj = traj
        self.t_nav0_us = fleet.time_us
        self.t_sample_us = fleet.time_us
        self._state = fleet.state(0)
        self._state_us = fleet.time_us
        self.prev = self._state.position.copy()
        self.entered_us = None
        self.timeout_us = round(spec.limits.timeout_s * 1e6)
        self.hold_us = round(spec.limits.hold_s * 1e6)

    def state_at(self, time_us: int):
        """The vehicle's state at ``time_us``: the one the last check read when the
        simulation has not moved since (it is used read-only here), else a fresh one."""
        if time_us == self._state_us:
            return self._state
        return self.fleet.state(0)

    def after_step(self) -> bool:
        fleet, spec, m = self.fleet, self.spec, self.m
        s = fleet.state(0)
        self._state, self._state_us = s, fleet.time_us
        m.sample(fleet, self.guard, self.prev, s, (fleet.time_us - self.t_sample_us) * 1e-6)
        self.t_sample_us = fleet.time_us
        self.prev = s.position.copy()
        t_nav_us = fleet.time_us - self.t_nav0_us
        if self.traj is not None:
            self.traj.append((t_nav_us * 1e-6, *s.position))
        _check(fleet, self.n_events, s, spec)
        dist = _norm(s.position - self.sc.goal)
        if dist <= spec.limits.goal_radius_m:
            if self.entered_us is None:
                self.entered_us = t_nav_us
                m.time_to_goal_s = t_nav_us * 1e-6
            elif t_nav_us - self.entered_us >= self.hold_us:
                return True
        elif self.entered_us is not None:
            raise _Fail("unstable", f"left the goal sphere "
                                    f"{(t_nav_us - self.entered_us) * 1e-6:.2f} s after "
                                    f"entering it (hold {spec.limits.hold_s:g} s)")
        if self.entered_us is None and t_nav_us >= self.timeout_us:
            raise _Fail("timeout", f"not in the goal sphere after {spec.limits.timeout_s:g}"
                                   f" s ({dist:.1f} m away)")
        return False


def _norm(v: np.ndarray) -> float:
    """np.linalg.norm of a float vector (it computes sqrt(v.dot(v)): the same bits) without
    its argument handling, which cost more than the arithmetic at every step."""
    return math.sqrt(v.dot(v))


class _Metrics:
    def __init__(self):
        self.path = 0.0
        self.speed_sum = 0.0
        self.time_s = 0.0
        self.n = 0
        self.max_speed = 0.0
        self.min_clear = math.inf
        self.max_tilt = 0.0
        self.planner_s = 0.0
        self.planner_calls = 0
        self.time_to_goal_s = math.nan

    def sample(self, fleet, guard, prev, s, dt_s: float) -> None:
        self.path += _norm(s.position - prev)
        v = _norm(s.velocity)
        self.speed_sum += v * dt_s  # time-weighted: samples are not evenly spaced
        self.time_s += dt_s
        self.n += 1
        self.max_speed = max(self.max_speed, v)
        self.max_tilt = max(self.max_tilt, s.tilt)
        # an exact (fcl) clearance only when the guard's lower bound does not rule out a
        # new minimum
        if not guard.clearance_bound(0) > self.min_clear:
            self.min_clear = min(self.min_clear, guard.clearance(0))

    def row(self) -> dict:
        return {
            "time_to_goal_s": self.time_to_goal_s,
            "path_length_m": self.path,
            "mean_speed_m_s": self.speed_sum / self.time_s if self.time_s > 0 else math.nan,
            "max_speed_m_s": self.max_speed if self.n else math.nan,
            "min_clearance_m": self.min_clear if math.isfinite(self.min_clear) else math.nan,
            "max_tilt_deg": math.degrees(self.max_tilt) if self.n else math.nan,
            "planner_time_s": self.planner_s,
            "planner_calls": self.planner_calls,
        }
