"""The engine of both environments: N vehicles in one world, flown by one
:class:`~ft_sitl.sim.lockstep.Simulation` (every vehicle's physics in one compiled call),
judged by the benchmark's own rules, observed and rewarded with numpy over the batch.

The single environment is a batch of one; the vector environment a batch of N. Nothing
here depends on N, so vehicle i of a batch flies, is judged and is observed exactly as
the only vehicle of a batch of one would be (tests/gym/test_vector.py).

**Acting.** An action (normalised, in [-1, 1]) becomes an offboard setpoint row of the
kind the configuration names (:func:`~ft_sitl.autopilot.setpoints.velocity_rows` and its
siblings, the rows ``Setpoint.velocity(...).offboard()`` makes), written into the cascade's
setpoint rows as a navigator's setpoint is in OFFBOARD mode (the commander passes an
offboard setpoint through unchanged in the air), held for ``physics_hz / control_hz``
physics steps.

**Judging.** After each action, every vehicle still in its episode is judged with the
referee's rules (:mod:`ft_sitl.missions.protocol`): its collision guard events
(:func:`~ft_sitl.missions.protocol.event_failure`: collision, mover collision, leaving the
flight volume), its true state (:func:`~ft_sitl.missions.protocol.flight_failure`:
non-finite, tilt beyond 90 deg, touching the floor), the goal sphere with its hold and the
time limit (:class:`~ft_sitl.missions.protocol.GoalRule`; without ``goal_rule`` only the
time limit). A timeout truncates the episode; every other outcome terminates it.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace

import numpy as np

from ft_sitl.autopilot.estimator import E_ON, Estimator
from ft_sitl.autopilot.params import DEFAULT_GAINS, ParamSet
from ft_sitl.autopilot.setpoints import (
    Setpoint,
    SetpointError,
    acceleration_rows,
    body_rate_rows,
    motor_rows,
    velocity_rows,
)
from ft_sitl.gym.config import ARENA, EnvConfig, EnvError
from ft_sitl.gym.kernels import measure, shaped_rewards
from ft_sitl.gym.worlds import BASE_CAMERA, World
from ft_sitl.missions.plan import flight_params, vehicle_collision
from ft_sitl.missions.protocol import GoalRule, TrialFailure, event_failure, flight_failure
from ft_sitl.missions.results import Outcome
from ft_sitl.missions.spec import PROTOCOLS, vehicle_half_span_m
from ft_sitl.navigation.learned.policy_io import (
    N_STATE,
    PLATFORM_NAMES,
    STATE_HIGH,
    STATE_LOW,
    edge_distances,
    goal_frame,
    normalise_platform,
    observe_state,
    ray_directions,
    velocity_action,
)
from ft_sitl.physics import dynamics as d
from ft_sitl.physics.catalog import PlatformRegistry, catalog
from ft_sitl.physics.platform import Platform
from ft_sitl.physics.synthesis import generate_virtual
from ft_sitl.physics.wind import Wind
from ft_sitl.scenarios.movers import NOT_STARTED
from ft_sitl.schema import SchemaError
from ft_sitl.sim.guard import CollisionGuard
from ft_sitl.sim.lockstep import Simulation

#: outcomes a collision penalty answers (the others but success and timeout: the failure
#: penalty)
COLLISIONS = (Outcome.COLLISION, Outcome.MOVER_COLLISION)


def platform_features(platform: Platform, protocol: int) -> np.ndarray:
    """TWR_max, alpha_xy_max, alpha_z_max and the body's half span (what navigators
    inflate by), raw."""
    ind = platform.indicators()
    return np.array([ind.twr_max, ind.alpha_xy_max_rad_s2, ind.alpha_z_max_rad_s2,
                     vehicle_half_span_m(protocol, platform)])


@functools.cache
def catalog_range(protocol: int) -> tuple[np.ndarray, np.ndarray]:
    """The catalog's smallest and largest of each :func:`platform_features` (log)."""
    f = np.log(np.array([platform_features(p, protocol) for p in catalog().values()]))
    return f.min(axis=0), f.max(axis=0)


@functools.cache
def catalog_rotors() -> int:
    """The rotor count of every catalog platform (and of those generated from them)."""
    (n,) = {p.n_rotors for p in catalog().values()}
    return n


def platform_vector(platform: Platform, protocol: int) -> np.ndarray:
    """The observation's platform vector: each feature's log, 0 at the catalog's smallest
    and 1 at its largest (a platform outside the catalog's range lies outside [0, 1];
    clipped to [-1, 2])."""
    lo, hi = catalog_range(protocol)
    return normalise_platform(platform_features(platform, protocol), lo, hi)


class FlightBatch:
    """N vehicles of one configuration in one world (see the module docstring)."""

    def __init__(self, cfg: EnvConfig, n: int):
        self.cfg = cfg
        self.n = n
        v = cfg.values
        self.k = cfg.steps_per_action
        self.dt_action = self.k / v["physics_hz"]
        self.n_rotors = catalog_rotors()  # a batch flies one rotor count: the catalog's
        self.action_dim = self.n_rotors if v["action"] == "motors" else 4
        self.sensor = v["sensor"]
        self.rays_local = ray_directions(v["ray_columns"], v["ray_rows"],
                                         v["ray_elevation_deg"])
        self.depth_config = BASE_CAMERA.subsampled(v["depth_step"])
        self.registry = PlatformRegistry()
        self.pool = self._pool(v["platform"])
        self.world: World | None = None
        self.sim: Simulation | None = None
        self.guard: CollisionGuard | None = None
        self.movers = None
        self.params = ParamSet(flight_params(None, cfg.limits, PROTOCOLS[cfg.protocol],
                                             DEFAULT_GAINS))
        # per vehicle
        self.goal = np.zeros((n, 3))
        self.start = np.zeros((n, 3))
        self.frame = np.tile(np.eye(3), (n, 1, 1))
        self.platform_obs = np.zeros((n, len(PLATFORM_NAMES)))
        self.t0_us = np.zeros(n, np.int64)
        self.prev_dist = np.zeros(n)
        self.last_action = np.zeros((n, self.action_dim))
        self.rules: list[GoalRule | None] = [None] * n
        self.done = np.ones(n, bool)
        self.outcome = np.full(n, "", dtype=object)
        self.detail = np.full(n, "", dtype=object)
        self.events: list[list] = [[] for _ in range(n)]
        #: per vehicle, its positions this episode (kept only when ``trails`` is set)
        self.trails = False
        self.trail: list[list] = [[] for _ in range(n)]

    # --- the world -----------------------------------------------------------------------
    def _pool(self, choice: str) -> list[Platform] | None:
        """The platforms an episode draws from (None: a generated one each episode)."""
        if choice == "generated":
            return None
        if choice == "catalog":
            return list(catalog().values())
        if choice in ("real", "virtual"):
            return [p for p in catalog().values() if p.category == choice]
        return [self.registry.get(choice)]

    def set_world(self, world: World) -> None:
        """A new simulation (clock at 0) of the batch's vehicles in ``world``; every
        vehicle waits for :meth:`reset_vehicle`."""
        p0 = next(iter(catalog().values()))
        radius, body = vehicle_collision(PROTOCOLS[self.cfg.protocol], p0)
        sim = Simulation([p0] * self.n, params=self.params, physics_hz=self.cfg["physics_hz"])
        guard = CollisionGuard(world.collision, [radius] * self.n, grid=world.grid,
                               names=world.scenario.obstacle_name,
                               bodies=[body] * self.n if body is not None else None)
        sim.attach_guard(guard, self._on_event)
        self.world, self.sim, self.guard, self.movers = world, sim, guard, None
        self.done[:] = True
        for ev in self.events:
            ev.clear()

    def set_movers(self, settings: dict | None, seed: int) -> None:
        """Moving obstacles of ``settings`` (None: none) placed in the world for ``seed``;
        they wait until :meth:`start_movers`."""
        if not settings:
            self.guard.set_movers(None)
            self.movers = None
            return
        placed = self.world.movers(settings, seed)
        self.guard.set_movers(replace(placed, clock=np.array([NOT_STARTED])))
        self.movers = self.guard.movers

    def start_movers(self) -> None:
        """The movers set off now."""
        if self.movers is not None:
            self.movers.start(self.sim.time_us)

    def _on_event(self, ev) -> None:
        self.events[ev.vehicle].append(ev)

    # --- an episode's vehicle --------------------------------------------------------------
    def draw_platform(self, rng: np.random.Generator) -> Platform:
        if self.pool is None:
            base = list(catalog().values())
            return generate_virtual(1, int(rng.integers(2**31)), base)[0]
        return self.pool[int(rng.integers(len(self.pool)))] if len(self.pool) > 1 \
            else self.pool[0]

    def platform_option(self, value) -> Platform:
        if isinstance(value, Platform):
            return value
        if isinstance(value, str):
            return self.registry.get(value)
        raise EnvError(f"option platform: a platform's name or a Platform, got "
                       f"{type(value).__name__}")

    def draw_wind(self, rng: np.random.Generator) -> tuple[dict | None, int]:
        v = self.cfg.values
        speed = rng.uniform(*v["wind_speed_m_s"])
        from_deg = rng.uniform(0.0, 360.0)
        seed = int(rng.integers(2**31))
        if speed == 0.0 and v["turbulence"] == "none":
            return None, seed
        return {"speed_m_s": float(speed), "from_deg": float(from_deg),
                "turbulence": v["turbulence"]}, seed

    def draw_estimator(self, rng: np.random.Generator) -> tuple[dict | None, int]:
        v = self.cfg.values
        p = rng.uniform(*v["position_noise_m"])
        vel = rng.uniform(*v["velocity_noise_m_s"])
        att = rng.uniform(*v["attitude_noise_deg"])
        seed = int(rng.integers(2**31))
        if p == 0.0 and vel == 0.0 and att == 0.0:
            return None, seed
        return {"position_noise_m": float(p), "velocity_noise_m_s": float(vel),
                "attitude_noise_deg": float(att)}, seed

    def draw_goal(self, rng: np.random.Generator) -> np.ndarray:
        """The episode's goal: the scenario's, or in the arena one drawn near the start."""
        sc = self.world.scenario
        if sc.family != ARENA:
            return sc.goal.copy()
        u = rng.standard_normal(3)
        u /= max(float(np.linalg.norm(u)), 1e-12)
        dist = rng.uniform(*self.cfg["arena_goal_distance_m"])
        lo = sc.bounds_min + 0.5
        hi = sc.bounds_max - 0.5
        return np.clip(sc.start + dist * u, lo, hi)

    def reset_vehicle(self, i: int, rng: np.random.Generator, options: dict) -> None:
        """Vehicle i starts an episode: its platform, wind, estimator and goal drawn from
        ``rng`` (or taken from ``options``), hovering at the start facing the goal."""
        sim = self.sim
        platform = (self.platform_option(options["platform"]) if "platform" in options
                    else self.draw_platform(rng))
        if platform.n_rotors != self.n_rotors:
            raise EnvError(f"option platform: {platform.name!r} has {platform.n_rotors} "
                           f"rotors; environments fly {self.n_rotors}-rotor platforms")
        wind, wind_seed = ((options["wind"], 0) if "wind" in options
                           else self.draw_wind(rng))
        est, est_seed = ((options["estimator"], 0) if "estimator" in options
                         else self.draw_estimator(rng))
        goal = self.draw_goal(rng)
        start = self.world.scenario.start.copy()
        try:
            wind = Wind(wind, "option wind") if wind is not None else None
            est = Estimator(est, "option estimator") if est is not None else None
        except SchemaError as exc:
            raise EnvError(str(exc)) from None
        frame = goal_frame(goal - start)
        yaw = math.atan2(frame[0, 1], frame[0, 0])
        sim.set_platform(i, platform)
        radius, body = vehicle_collision(PROTOCOLS[self.cfg.protocol], platform)
        self.guard.set_vehicle(i, radius, body)
        sim.start_hovering(i, start, yaw)
        sim.set_estimator(i, est, seed=est_seed)
        sim.set_wind(i, wind, seed=wind_seed)
        self.goal[i] = goal
        self.start[i] = start
        self.frame[i] = frame
        self.platform_obs[i] = platform_vector(platform, self.cfg.protocol)
        self.t0_us[i] = sim.time_us
        self.prev_dist[i] = float(np.linalg.norm(start - goal))
        self.last_action[i] = 0.0
        self.rules[i] = GoalRule(self.cfg.limits) if self.cfg["goal_rule"] else None
        self.done[i] = False
        self.outcome[i] = ""
        self.detail[i] = ""
        self.events[i].clear()
        self.trail[i] = [start.copy()] if self.trails else []

    def platform(self, i: int) -> Platform:
        return self.sim.platforms[i]

    # --- acting and judging ----------------------------------------------------------------
    def setpoint_rows(self, actions: np.ndarray) -> np.ndarray:
        """The offboard setpoint rows of normalised actions (N, action_dim)."""
        v = self.cfg.values
        a = actions
        try:
            if v["action"] in ("velocity", "acceleration"):
                rate = a[:, 3] * v["max_yaw_rate_rad_s"]
                if v["action"] == "velocity":
                    world = velocity_action(self.frame, a, v["max_speed_m_s"],
                                            v["max_climb_m_s"])
                    return velocity_rows(world, rate)
                # goal frame -> world: frame rows are the goal axes, so world = F^T g
                world = np.einsum("nji,nj->ni", self.frame, a[:, :3] * v["max_acc_m_s2"])
                return acceleration_rows(world, rate)
            if v["action"] == "attitude_rate":
                return body_rate_rows(a[:, :3] * v["max_body_rate_rad_s"],
                                      (a[:, 3] + 1.0) / 2.0)
            return motor_rows((a + 1.0) / 2.0)
        except SetpointError as exc:  # (the actions were checked against the space)
            raise EnvError(f"action: {exc}") from None

    def step(self, actions: np.ndarray):
        """Fly every vehicle still in its episode for one action (vehicles that are done
        have their motors stopped) and judge them. Returns (reward, terminated,
        truncated) arrays; outcomes in :attr:`outcome` and :attr:`detail`."""
        sim = self.sim
        live = ~self.done
        rows = self.setpoint_rows(actions)
        rows[~live] = Setpoint.off().row
        sim.sp[:] = rows
        sim.step(self.k)
        now = sim.time_us
        x = sim.x
        n = self.n
        finite, ground = np.empty(n, bool), np.empty(n, bool)
        tilt, dist = np.empty(n), np.empty(n)
        measure(x, sim.plant.status[:, d.S_CONTACT], self.goal, finite, tilt, ground, dist)
        terminated = np.zeros(self.n, bool)
        truncated = np.zeros(self.n, bool)
        success = np.zeros(self.n, bool)
        collided = np.zeros(self.n, bool)
        failed = np.zeros(self.n, bool)
        timeout_us = round(self.cfg["timeout_s"] * 1e6)
        for i in np.flatnonzero(live):
            failure = None
            for ev in self.events[i]:
                failure = event_failure(ev)
                if failure is not None:
                    break
            if failure is None:
                failure = flight_failure(bool(finite[i]), float(tilt[i]), bool(ground[i]))
            t_ep_us = int(now - self.t0_us[i])
            if failure is None:
                rule = self.rules[i]
                if rule is not None:
                    try:
                        success[i] = rule.update(float(dist[i]), t_ep_us)
                    except TrialFailure as f:
                        failure = f
                elif t_ep_us >= timeout_us:
                    failure = TrialFailure(Outcome.TIMEOUT,
                                           f"time limit {self.cfg['timeout_s']:g} s")
            if success[i]:
                self.outcome[i], self.detail[i] = Outcome.SUCCESS.value, ""
                terminated[i] = True
            elif failure is not None:
                self.outcome[i], self.detail[i] = failure.reason.value, failure.detail
                if failure.reason == Outcome.TIMEOUT:
                    truncated[i] = True
                else:
                    terminated[i] = True
                    if failure.reason in COLLISIONS:
                        collided[i] = True
                    else:
                        failed[i] = True
            if self.trails:
                self.trail[i].append(x[i, d.X_POS:d.X_POS + 3].copy())
        for ev in self.events:
            ev.clear()
        self.guard.events.clear()  # (judged above: the guard's log would only grow)
        reward = self.rewards(actions, dist, success, collided, failed)
        self.prev_dist[live] = dist[live]
        self.last_action[live] = actions[live]
        self.done |= terminated | truncated
        reward[~live] = 0.0
        return reward, terminated, truncated

    def rewards(self, actions, dist, success, collided, failed) -> np.ndarray:
        """The reward of the step (docs/gym.md, "Rewards")."""
        w = self.cfg.reward
        r = np.empty(self.n)
        shaped_rewards(actions, self.last_action, self.prev_dist, dist, self.dt_action,
                       self.cfg["goal_radius_m"], w["progress"], w["distance"], w["time"],
                       w["in_goal"], w["smoothness"], r)
        r += w["success_bonus"] * success
        r -= w["collision_penalty"] * collided
        r -= w["failure_penalty"] * failed
        return r

    # --- observing -----------------------------------------------------------------------
    def observe(self, idx: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """The observations of vehicles ``idx`` (None: all), keys as the observation
        space's: state and platform, plus rays or depth."""
        sim = self.sim
        idx = np.arange(self.n) if idx is None else np.asarray(idx)
        est = sim.est[idx, E_ON] != 0.0
        xs = np.where(est[:, None], sim.xe[idx], sim.x[idx])
        sc = self.world.scenario
        state = np.empty((len(idx), N_STATE), np.float32)
        observe_state(xs, self.goal[idx], self.frame[idx], sc.floor, sc.ceiling, STATE_LOW,
                      STATE_HIGH, state)
        obs = {"state": state,
               "edges": edge_distances(xs[:, d.X_POS:d.X_POS + 3], self.frame[idx],
                                       sc.bounds_min, sc.bounds_max),
               "platform": self.platform_obs[idx].astype(np.float32),
               "last_action": self.last_action[idx].astype(np.float32)}
        if self.sensor == "rays":
            obs["rays"] = self.rays(idx)
        elif self.sensor == "depth":
            obs["depth"] = self.depths(idx, self.depth_config)[:, None]
        return obs

    def rays(self, idx: np.ndarray) -> np.ndarray:
        """(len(idx), rays) float32: each ray's hit distance over the range, 1 for nothing
        within it, cast from the true positions in the episode's goal frame."""
        rng_m = self.cfg["ray_range_m"]
        cam = self.world.any_camera()
        if cam is None:
            return np.ones((len(idx), len(self.rays_local)), np.float32)
        x = self.sim.x[idx]
        lengths = cam.cast_fans(x[:, d.X_POS:d.X_POS + 3], np.transpose(self.frame[idx],
                                                                          (0, 2, 1)),
                                self.rays_local, max_range_m=rng_m, movers=self.movers,
                                movers_time_us=self.sim.time_us)
        # (a vehicle touching a surface may read a hair below 0: the float64 plane length)
        return (np.clip(lengths, 0.0, rng_m) / rng_m).astype(np.float32)

    def depths(self, idx: np.ndarray, config, metres: bool = False) -> np.ndarray:
        """(len(idx), H, W) float32 depth images at the true poses: z-depth over the range
        (NaN, no return, as 1), or in metres (NaN kept) when ``metres``."""
        cam = self.world.camera(config)
        h, w = config.height, config.width
        if cam is None:
            fill = np.nan if metres else 1.0
            return np.full((len(idx), h, w), fill, np.float32)
        x = self.sim.x[idx]
        depth = cam.capture_depths(x[:, d.X_POS:d.X_POS + 3], x[:, d.X_QUAT:d.X_QUAT + 4],
                                   movers=self.movers, movers_time_us=self.sim.time_us)
        if metres:
            return depth
        return np.nan_to_num(depth / np.float32(config.max_range_m), nan=1.0)

    #: the info keys (docs/gym.md, "Info") and their array types
    INFO_KEYS = (("outcome", object), ("detail", object), ("time_s", np.float64),
                 ("distance_m", np.float64), ("platform", object), ("scenario", object))

    def infos(self, idx: np.ndarray) -> dict[str, np.ndarray]:
        """The infos of vehicles ``idx``, one array per key: outcome ("" while flying) and
        its detail, the episode's time (s), the true distance to the goal (m), the
        platform's and the scenario's names."""
        x = self.sim.x[idx]
        names = self.sim.platforms
        return {
            "outcome": self.outcome[idx].copy(),
            "detail": self.detail[idx].copy(),
            "time_s": (self.sim.time_us - self.t0_us[idx]) * 1e-6,
            "distance_m": np.linalg.norm(x[:, d.X_POS:d.X_POS + 3] - self.goal[idx], axis=1),
            "platform": np.array([names[i].name for i in idx], dtype=object),
            "scenario": np.full(len(idx), self.world.name, dtype=object),
        }

    def info(self, i: int) -> dict:
        """Vehicle i's info (:meth:`infos`) as plain Python values."""
        return {k: v[0].item() if isinstance(v[0], np.generic) else v[0]
                for k, v in self.infos(np.array([i])).items()}
