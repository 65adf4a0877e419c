"""The Gymnasium environments: :class:`NavigateEnv` (one vehicle) and
:class:`NavigateVectorEnv` (N vehicles in one compiled physics call), both over
:class:`~ft_sitl.gym.batch.FlightBatch` (docs/gym.md).

Randomness: every draw of an episode (platform, wind, estimator, the arena's goal) comes
from the (sub-)environment's ``np_random``, seeded by ``reset(seed=...)`` (the vector
environment seeds sub-environment i with seed + i, as Gymnasium's SyncVectorEnv does).
The world (scenario configuration, mover placement) is drawn from a second stream of the
same seed, so that a vector environment, whose vehicles share one world, and its single
counterparts draw their vehicles alike. A reset with a seed starts a new simulation (its
clock at 0); a reset without one continues the simulation's clock, as a vector
environment's autoreset does.
"""

from __future__ import annotations

import numpy as np
from gymnasium import Env, spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from ft_sitl.gym.batch import FlightBatch
from ft_sitl.gym.config import (
    ANY,
    ARENA,
    RESET_OPTIONS,
    ActionError,
    EnvConfig,
    EnvError,
    check_movers,
    check_options,
    make_config,
)
from ft_sitl.gym.worlds import (
    BASE_CAMERA,
    GOAL_RGB,
    MOVER_RGB,
    RENDER_DEPTH_STEP,
    START_RGB,
    TRAIL_RGB,
    VEHICLE_RGB,
    WORLDS,
    World,
    disc,
    ring,
)
from ft_sitl.navigation.learned.policy_io import (
    EDGE_NAMES,
    EDGE_RANGE_M,
    PLATFORM_HIGH,
    PLATFORM_LOW,
    PLATFORM_NAMES,
    STATE_HIGH,
    STATE_LOW,
)
from ft_sitl.scenarios.families import REGISTRY, resolve_family
from ft_sitl.scenarios.scenario import Scenario, ScenarioError

#: the world stream of a seed (see the module docstring)
WORLD_STREAM = 0x776F726C64
RENDER_MODES = ("rgb_array", "depth_array", "depth")
#: vector reset option: which sub-environments to reset (Gymnasium's partial reset)
RESET_MASK = "reset_mask"


def observation_space(cfg: EnvConfig, action_dim: int) -> spaces.Dict:
    """The observation space of one vehicle (docs/gym.md, "Observations")."""
    items = {
        "state": spaces.Box(STATE_LOW, STATE_HIGH, dtype=np.float32),
        "edges": spaces.Box(0.0, EDGE_RANGE_M, (len(EDGE_NAMES),), np.float32),
        "platform": spaces.Box(PLATFORM_LOW, PLATFORM_HIGH, (len(PLATFORM_NAMES),),
                               np.float32),
        "last_action": spaces.Box(-1.0, 1.0, (action_dim,), np.float32),
    }
    if cfg["sensor"] == "rays":
        items["rays"] = spaces.Box(0.0, 1.0, (cfg["ray_columns"] * cfg["ray_rows"],),
                                   np.float32)
    elif cfg["sensor"] == "depth":
        c = BASE_CAMERA.subsampled(cfg["depth_step"])
        items["depth"] = spaces.Box(0.0, 1.0, (1, c.height, c.width), np.float32)
    return spaces.Dict(items)


def check_actions(actions, space: spaces.Box, n: int | None) -> np.ndarray:
    """``actions`` as a float64 array (n, dim) after checking them against ``space``
    (a single action when ``n`` is None): ActionError names what is wrong. Actions are
    refused, not clipped."""
    shape = space.shape if n is None else (n, *space.shape)
    try:
        a = np.asarray(actions, dtype=np.float64)
    except (TypeError, ValueError):
        raise ActionError(f"action: {actions!r} is not an array of numbers "
                          f"(expected shape {shape})") from None
    if a.shape != shape:
        raise ActionError(f"action: shape {a.shape}, expected {shape}")
    a2 = a.reshape(-1, *space.shape)
    bad = ~np.isfinite(a2) | (a2 < space.low) | (a2 > space.high)
    if bad.any():
        i, j = (int(k[0]) for k in np.nonzero(bad))
        where = f"action[{j}]" if n is None else f"sub-environment {i}: action[{j}]"
        raise ActionError(f"{where} = {float(a2[i, j])!r} is outside the action space "
                          f"[{space.low[j]:g}, {space.high[j]:g}] (actions are refused, "
                          "not clipped: clip them in the agent or wrap the environment in "
                          "gymnasium.wrappers.ClipAction)")
    return a2


class _WorldDraw:
    """Draws the world of a (vector) environment's episode: from the reset options, else
    from the settings' distribution with the world stream."""

    def __init__(self, cfg: EnvConfig):
        self.cfg = cfg
        self.rng: np.random.Generator | None = None

    def seed(self, seed: int | None) -> None:
        if seed is not None:
            self.rng = np.random.default_rng(np.random.SeedSequence([int(seed),
                                                                     WORLD_STREAM]))
        elif self.rng is None:
            self.rng = np.random.default_rng()

    def draw(self, options: dict) -> tuple[World, dict | None, int]:
        """(world, mover settings, mover seed)."""
        cfg, rng = self.cfg, self.rng
        if "scenario" in options:
            world = scenario_option(options["scenario"], cfg)
        elif cfg["family"] == ARENA:
            world = WORLDS.arena(cfg["arena_size_m"])
        else:
            fam = cfg["family"]
            if fam == ANY:
                names = list(REGISTRY)
                fam = names[int(rng.integers(len(names)))]
            lo, hi = cfg["scenario_index"]
            index = int(rng.integers(lo, hi + 1))
            slo, shi = cfg["scenario_seed"]
            seed = int(rng.integers(slo, shi + 1))
            world = WORLDS.family(fam, index, seed, cfg.scenario_params, cfg.version_of(fam))
        movers = (check_movers(options["movers"], "option movers") if "movers" in options
                  else cfg.movers)
        return world, movers, int(rng.integers(cfg["mover_layouts"]))


def scenario_option(value, cfg: EnvConfig | None = None) -> World:
    """The world of a ``scenario`` reset option: a Scenario, or {family, index, seed,
    params, version} (version: the family's generator version; by default the one the
    environment's ``scenario_versions`` names, else the newest)."""
    if isinstance(value, Scenario):
        return WORLDS.scenario(value)
    if not isinstance(value, dict):
        raise EnvError(f"option scenario: a Scenario or a mapping with family, index, seed "
                       f"(and params, version), got {type(value).__name__}")
    unknown = set(value) - {"family", "index", "seed", "params", "version"}
    if unknown or "family" not in value:
        raise EnvError(f"option scenario: keys family (required), index, seed, params, "
                       f"version; got {sorted(value)}")
    if value["family"] == ARENA:
        raise EnvError("option scenario: the arena is the 'family' setting's, not an option")
    version = value.get("version")
    if version is None and cfg is not None:
        try:
            version = cfg.version_of(resolve_family(value["family"]))
        except ScenarioError as exc:
            raise EnvError(f"option scenario: {exc}") from None
    return WORLDS.family(value["family"], value.get("index", 1), value.get("seed", 0),
                         value.get("params"), version)


def render_rgb(batch: FlightBatch, i: int, px: int) -> np.ndarray:
    """Vehicle i's world from above (north up): obstacles shaded by height, the start
    (blue), the goal sphere (green ring), moving obstacles (orange), the episode's trail
    and the vehicle (red)."""
    world = batch.world
    bg, scale = world.top_view(px)
    img = bg.copy()
    lo, hi = world.scenario.bounds_min, world.scenario.bounds_max

    def to_px(p):
        return (p[0] - lo[0]) / scale, (hi[1] - p[1]) / scale

    gx, gy = to_px(batch.goal[i])
    ring(img, gx, gy, batch.cfg["goal_radius_m"] / scale, GOAL_RGB)
    sx, sy = to_px(batch.start[i])
    disc(img, sx, sy, max(2.0, 0.3 / scale), START_RGB)
    if batch.movers is not None:
        poses = batch.movers.poses(batch.sim.time_us)
        for k in range(batch.movers.count):
            mx, my = to_px(poses[k])
            disc(img, mx, my, max(2.0, float(batch.movers.bounding[k]) / scale), MOVER_RGB)
    for p in batch.trail[i]:
        tx, ty = to_px(p)
        disc(img, tx, ty, 1.0, TRAIL_RGB)
    vx, vy = to_px(batch.sim.x[i, :3])
    disc(img, vx, vy, max(2.0, batch.sim.platforms[i].body().half_span_m / scale),
         VEHICLE_RGB)
    return img


class NavigateEnv(Env):
    """One vehicle flying to a goal in a benchmark scenario (or hovering at one in the
    arena), through the flight controller's cascade. Settings: :data:`~ft_sitl.gym.config.
    ENV_SCHEMA` as keyword arguments, ``reward`` (:data:`~ft_sitl.gym.config.
    REWARD_SCHEMA`), ``scenario_params`` (the family generator's), ``movers`` and
    ``scenario_versions`` (``{family: generator version}``; unnamed families: the newest);
    ``render_mode`` one of ``rgb_array``, ``depth_array`` (``depth``: the same)."""

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 50}

    def __init__(self, render_mode: str | None = None, *, reward: dict | None = None,
                 scenario_params: dict | None = None, movers: dict | None = None,
                 scenario_versions: dict | None = None, **settings):
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise EnvError(f"render_mode: {render_mode!r} is not one of "
                           f"{', '.join(RENDER_MODES)} (or None)")
        self.cfg = make_config(settings, reward, scenario_params, movers, scenario_versions)
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": self.cfg["control_hz"]}
        self.batch = FlightBatch(self.cfg, 1)
        self.batch.trails = render_mode == "rgb_array"
        self.action_space = spaces.Box(-1.0, 1.0, (self.batch.action_dim,), np.float32)
        self.observation_space = observation_space(self.cfg, self.batch.action_dim)
        self._world = _WorldDraw(self.cfg)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        opts = check_options(options, RESET_OPTIONS, "reset")
        self._world.seed(seed)
        world, movers, mover_seed = self._world.draw(opts)
        batch = self.batch
        if seed is not None or batch.world is not world:
            batch.set_world(world)
        batch.set_movers(movers, mover_seed)
        batch.reset_vehicle(0, self.np_random, opts)
        batch.start_movers()
        return self._obs(), batch.info(0)

    def step(self, action):
        batch = self.batch
        if batch.sim is None:
            raise EnvError("step() before reset(): call reset() first")
        if batch.done[0]:
            raise EnvError("step() after the episode ended (terminated or truncated): call "
                           "reset()")
        a = check_actions(action, self.action_space, None)
        reward, terminated, truncated = batch.step(a)
        return (self._obs(), float(reward[0]), bool(terminated[0]), bool(truncated[0]),
                batch.info(0))

    def _obs(self) -> dict:
        return {k: v[0] for k, v in self.batch.observe().items()}

    def render(self):
        if self.render_mode is None or self.batch.sim is None:
            return None
        if self.render_mode == "rgb_array":
            return render_rgb(self.batch, 0, self.cfg["render_px"])
        return self.batch.depths(np.array([0]), BASE_CAMERA.subsampled(RENDER_DEPTH_STEP),
                                 metres=True)[0]

    def close(self):
        self.batch.sim = self.batch.guard = None
        super().close()


class NavigateVectorEnv(VectorEnv):
    """``num_envs`` vehicles of one configuration flown in one compiled physics call, each
    in its own episode, all in one world (docs/gym.md, "The vector environment").
    Settings as :class:`NavigateEnv`'s; ``autoreset_mode``: Gymnasium's
    (:class:`~gymnasium.vector.AutoresetMode` or its value; next step by default)."""

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 50,
                "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(self, num_envs: int, render_mode: str | None = None, *,
                 autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
                 reward: dict | None = None, scenario_params: dict | None = None,
                 movers: dict | None = None, scenario_versions: dict | None = None,
                 **settings):
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) \
                or num_envs < 1:
            raise EnvError(f"num_envs: a positive integer, got {num_envs!r}")
        if render_mode is not None and render_mode not in RENDER_MODES:
            raise EnvError(f"render_mode: {render_mode!r} is not one of "
                           f"{', '.join(RENDER_MODES)} (or None)")
        try:
            mode = AutoresetMode(autoreset_mode)
        except ValueError:
            raise EnvError(f"autoreset_mode: {autoreset_mode!r} is not one of "
                           f"{', '.join(m.value for m in AutoresetMode)}") from None
        self.cfg = make_config(settings, reward, scenario_params, movers, scenario_versions)
        self.num_envs = int(num_envs)
        self.render_mode = render_mode
        self.autoreset_mode = mode
        self.metadata = {**self.metadata, "render_fps": self.cfg["control_hz"],
                         "autoreset_mode": mode}
        self.batch = FlightBatch(self.cfg, self.num_envs)
        self.batch.trails = render_mode == "rgb_array"
        self.single_action_space = spaces.Box(-1.0, 1.0, (self.batch.action_dim,),
                                              np.float32)
        self.single_observation_space = observation_space(self.cfg, self.batch.action_dim)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self._world = _WorldDraw(self.cfg)
        self._rngs: list[np.random.Generator | None] = [None] * self.num_envs
        self._autoreset = np.zeros(self.num_envs, bool)

    def reset(self, *, seed: int | list | None = None, options: dict | None = None):
        n = self.num_envs
        opts = check_options(options, {**RESET_OPTIONS, RESET_MASK: "which sub-environments"},
                             "reset")
        mask = opts.pop(RESET_MASK, None)
        mask = np.ones(n, bool) if mask is None else np.asarray(mask)
        if mask.shape != (n,) or mask.dtype != bool or not mask.any():
            raise EnvError(f"option {RESET_MASK}: a boolean array of shape ({n},) with at "
                           "least one True")
        if seed is None:
            seeds = [None] * n
        elif isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            seeds = [int(seed) + i for i in range(n)]
        else:
            seeds = list(seed)
            if len(seeds) != n:
                raise EnvError(f"seed: {len(seeds)} seeds for {n} sub-environments")
        super().reset(seed=seeds[0] if mask.all() else None)
        batch = self.batch
        full = bool(mask.all())
        if not full and ("scenario" in opts or "movers" in opts):
            raise EnvError("options scenario and movers change the world every vehicle "
                           f"flies in: only when all of them reset ({RESET_MASK} all True)")
        if not full and batch.sim is None:
            raise EnvError(f"the first reset resets every sub-environment ({RESET_MASK} "
                           "all True)")
        for i in np.flatnonzero(mask):
            if seeds[i] is not None:
                self._rngs[i] = seeding.np_random(int(seeds[i]))[0]
            elif self._rngs[i] is None:
                self._rngs[i] = seeding.np_random()[0]
        if full:
            self._world.seed(seeds[0])
            world, movers, mover_seed = self._world.draw(opts)
            if any(s is not None for s in seeds) or batch.world is not world:
                batch.set_world(world)
            batch.set_movers(movers, mover_seed)
        for i in np.flatnonzero(mask):
            batch.reset_vehicle(int(i), self._rngs[i], opts)
        if full:
            batch.start_movers()
        self._autoreset[mask] = False
        return batch.observe(), self._infos(np.flatnonzero(mask))

    def step(self, actions):
        batch = self.batch
        if batch.sim is None:
            raise EnvError("step() before reset(): call reset() first")
        a = check_actions(actions, self.single_action_space, self.num_envs)
        if self.autoreset_mode == AutoresetMode.DISABLED and batch.done.any():
            i = int(np.flatnonzero(batch.done)[0])
            raise EnvError(f"sub-environment {i}'s episode ended: reset it (option "
                           f"{RESET_MASK}) before stepping (autoreset is disabled)")
        pending = np.flatnonzero(self._autoreset)  # NEXT_STEP: reset in this call
        reward, terminated, truncated = batch.step(a)
        for i in pending:
            batch.reset_vehicle(int(i), self._rngs[i], {})
        obs = batch.observe()
        infos = self._infos(np.arange(self.num_envs))
        ended = np.flatnonzero(terminated | truncated)
        if self.autoreset_mode == AutoresetMode.SAME_STEP and len(ended):
            final_obs = np.full(self.num_envs, None, dtype=object)
            for i in ended:
                final_obs[i] = {k: v[i].copy() for k, v in obs.items()}
            final_info = self._infos(ended)
            for i in ended:
                batch.reset_vehicle(int(i), self._rngs[i], {})
            fresh = batch.observe(ended)
            for k in obs:
                obs[k][ended] = fresh[k]
            infos["final_obs"] = final_obs
            infos["_final_obs"] = terminated | truncated
            infos["final_info"] = final_info
            infos["_final_info"] = terminated | truncated
            reset_info = self._infos(ended)
            for k in ("outcome", "detail", "time_s", "distance_m", "platform"):
                infos[k][ended] = reset_info[k][ended]
        elif self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self._autoreset = terminated | truncated
        return obs, reward, terminated, truncated, infos

    def _infos(self, idx) -> dict:
        """Gymnasium's vector info: each key an array over the sub-environments and a
        ``_key`` mask of those it is given for (``idx``)."""
        n = self.num_envs
        idx = np.asarray(idx, dtype=np.int64)
        mask = np.zeros(n, bool)
        mask[idx] = True
        given = self.batch.infos(idx)
        out: dict = {}
        for key, kind in FlightBatch.INFO_KEYS:
            out[key] = np.full(n, "" if kind is object else 0.0, dtype=kind)
            out[key][idx] = given[key]
            out["_" + key] = mask.copy()
        return out

    def render(self):
        if self.render_mode is None or self.batch.sim is None:
            return None
        if self.render_mode == "rgb_array":
            return tuple(render_rgb(self.batch, i, self.cfg["render_px"])
                         for i in range(self.num_envs))
        depth = self.batch.depths(np.arange(self.num_envs),
                                  BASE_CAMERA.subsampled(RENDER_DEPTH_STEP), metres=True)
        return tuple(depth)

    def close_extras(self, **kwargs):
        self.batch.sim = self.batch.guard = None
