"""The worlds environments fly in: a scenario with its collision world, distance grid,
depth cameras and top view, built once per configuration and kept for the next episode.

A world is what one :class:`~ft_sitl.sim.guard.CollisionGuard` checks against: every
vehicle of a batch flies in the same world (docs/gym.md, "One world per batch").
"""

from __future__ import annotations

import json
from collections import OrderedDict

import numpy as np
import trimesh

from ft_sitl.gym.config import ARENA, EnvError
from ft_sitl.missions.resources import RESOURCES, scenario_key
from ft_sitl.scenarios.camera import CameraConfig, DepthCamera
from ft_sitl.scenarios.families import (
    REGISTRY,
    build_scenario,
    resolve_family,
    start_altitude,
)
from ft_sitl.scenarios.movers import MoverError, with_movers
from ft_sitl.scenarios.scenario import Scenario, ScenarioError

#: worlds kept per process (the newest): one family's ten configurations (a grid is up to
#: 32 MB)
WORLD_CACHE_MAX = 10
#: mover placements kept per world
MOVER_CACHE_MAX = 256
#: the depth camera the observations and the depth render are cut from: the benchmark
#: camera's optics (D435 depth stream) and range
BASE_CAMERA = CameraConfig(max_range_m=10.0)
#: the depth render's resolution step (160 x 120: the planners' benchmark camera)
RENDER_DEPTH_STEP = 4

# top view colours (RGB)
FLOOR_RGB = (236, 236, 232)
ABOVE_CEILING_RGB = (70, 70, 78)
START_RGB = (40, 90, 220)
GOAL_RGB = (30, 160, 60)
VEHICLE_RGB = (220, 40, 40)
TRAIL_RGB = (240, 140, 140)
MOVER_RGB = (240, 150, 20)


class World:
    """One scenario and what flying in it needs (built on first use, kept)."""

    def __init__(self, scenario: Scenario, key: tuple):
        self.scenario = scenario
        self.key = key
        self.collision, self.grid = RESOURCES.world_and_grid(scenario)
        #: nothing to hit or see (the arena): rays and depth read "nothing in range"
        self.empty = len(scenario.mesh.faces) == 0
        self._cameras: dict = {}
        self._top: dict = {}
        self._movers: OrderedDict = OrderedDict()

    @property
    def name(self) -> str:
        return self.scenario.name

    def movers(self, settings: dict, seed: int):
        """The moving obstacles ``settings`` ask for, placed for ``seed`` (placed once,
        kept: the :data:`MOVER_CACHE_MAX` newest; a placement takes ~0.1 s)."""
        key = (json.dumps(settings, sort_keys=True), int(seed))
        if key in self._movers:
            self._movers.move_to_end(key)
            return self._movers[key]
        try:
            placed = with_movers(self.scenario, settings, int(seed)).movers
        except MoverError as exc:
            raise EnvError(str(exc)) from None
        self._movers[key] = placed
        while len(self._movers) > MOVER_CACHE_MAX:
            self._movers.popitem(last=False)
        return placed

    def camera(self, config: CameraConfig) -> DepthCamera | None:
        """A depth camera of ``config`` in this world (None in an empty one)."""
        if self.empty:
            return None
        if config not in self._cameras:
            self._cameras[config] = DepthCamera(config, self.scenario.mesh)
        return self._cameras[config]

    def any_camera(self) -> DepthCamera | None:
        """A camera for casting rays (any configuration: its mesh is what counts)."""
        if self.empty:
            return None
        if not self._cameras:
            return self.camera(BASE_CAMERA.subsampled(RENDER_DEPTH_STEP))
        return next(iter(self._cameras.values()))

    def top_view(self, px: int) -> tuple[np.ndarray, float]:
        """The background of the rgb_array render: (H, W, 3) uint8 seen from above, north
        up, the longer side ``px`` pixels; obstacles shaded by height (dark: above the
        ceiling); and the metres per pixel."""
        if px not in self._top:
            self._top[px] = self._render_top(px)
        return self._top[px]

    def _render_top(self, px: int) -> tuple[np.ndarray, float]:
        sc = self.scenario
        lo, hi = sc.bounds_min, sc.bounds_max
        size = hi[:2] - lo[:2]
        scale = float(max(size)) / px  # metres per pixel
        w = max(1, int(round(size[0] / scale)))
        h = max(1, int(round(size[1] / scale)))
        img = np.empty((h, w, 3), np.uint8)
        img[:] = FLOOR_RGB
        cam = self.any_camera()
        if cam is None:
            return img, scale
        top = float(max(sc.mesh.bounds[1][2], hi[2])) + 1.0
        cols = lo[0] + (np.arange(w) + 0.5) * scale
        rows = hi[1] - (np.arange(h) + 0.5) * scale
        origins = np.empty((h * w, 3))
        origins[:, 0] = np.tile(cols, h)
        origins[:, 1] = np.repeat(rows, w)
        origins[:, 2] = top
        rots = np.broadcast_to(np.eye(3), (h * w, 3, 3))
        length = cam.cast_fans(origins, rots, np.array([[0.0, 0.0, -1.0]]))[:, 0]
        height = (top - length).reshape(h, w)
        hit = np.isfinite(height) & (height > lo[2] + 1e-3)
        ceiling = float(hi[2])
        shade = 200.0 - 120.0 * np.clip(height / ceiling, 0.0, 1.0)
        for c in range(3):
            layer = img[:, :, c]
            layer[hit] = shade[hit].astype(np.uint8)
            layer[hit & (height > ceiling)] = ABOVE_CEILING_RGB[c]
        return img, scale


def arena(size) -> Scenario:
    """The hover task's world: an empty box of ``size`` (width, length, ceiling; m), the
    start above its centre at min(2 m, ceiling / 2)."""
    w, length, ceiling = (float(v) for v in size)
    z = start_altitude(ceiling)
    empty = trimesh.Trimesh(vertices=np.zeros((0, 3)), faces=np.zeros((0, 3), np.int64))
    centre = (w / 2.0, length / 2.0)
    return Scenario(ARENA, 1, 0, "user", empty, (0.0, 0.0, 0.0), (w, length, ceiling),
                    (*centre, 0.0), (*centre, z), 0.0, (*centre, z),
                    provenance={"generator": "ft_sitl.gym.worlds.arena", "size_m": [w, length,
                                                                                  ceiling]})


class WorldCache:
    """The :data:`WORLD_CACHE_MAX` newest worlds of this process, by configuration."""

    def __init__(self, size: int = WORLD_CACHE_MAX):
        self.size = size
        self._worlds: OrderedDict = OrderedDict()

    def _get(self, key: tuple, make) -> World:
        if key in self._worlds:
            self._worlds.move_to_end(key)
            return self._worlds[key]
        world = World(make(), key)
        self._worlds[key] = world
        while len(self._worlds) > self.size:
            self._worlds.popitem(last=False)
        return world

    def family(self, family: str, index: int, seed: int, params: dict | None,
               version: int | None = None) -> World:
        """Configuration ``index`` of ``family`` for ``seed`` (generator ``params``), built
        by the family's generator ``version`` (None: the newest)."""
        try:
            version = REGISTRY[resolve_family(family)].check_version(version)
            key = ("family", family, index, seed,
                   json.dumps(params, sort_keys=True) if params else "", version)
            return self._get(key, lambda: build_scenario(family, index, seed, params,
                                                         version))
        except (ScenarioError, TypeError) as exc:  # (TypeError: params not JSON data)
            raise EnvError(f"scenario: {exc}") from None

    def arena(self, size) -> World:
        key = ("arena", *(float(v) for v in size))
        return self._get(key, lambda: arena(size))

    def scenario(self, scenario: Scenario) -> World:
        """A world for a Scenario object (a user mesh, or one built elsewhere)."""
        return self._get(("scenario", *scenario_key(scenario)), lambda: scenario)


#: this process's worlds
WORLDS = WorldCache()


def disc(img: np.ndarray, cx: float, cy: float, r: float, rgb) -> None:
    """Fill the disc of radius ``r`` px about pixel (column ``cx``, row ``cy``)."""
    h, w = img.shape[:2]
    x0, x1 = max(0, int(cx - r)), min(w, int(cx + r) + 2)
    y0, y1 = max(0, int(cy - r)), min(h, int(cy + r) + 2)
    if x0 >= x1 or y0 >= y1:
        return
    yy, xx = np.mgrid[y0:y1, x0:x1]
    inside = (xx + 0.5 - cx) ** 2 + (yy + 0.5 - cy) ** 2 <= r * r
    img[y0:y1, x0:x1][inside] = rgb


def ring(img: np.ndarray, cx: float, cy: float, r: float, rgb, width: float = 1.5) -> None:
    """Draw the circle of radius ``r`` px about (``cx``, ``cy``)."""
    h, w = img.shape[:2]
    x0, x1 = max(0, int(cx - r - width)), min(w, int(cx + r + width) + 2)
    y0, y1 = max(0, int(cy - r - width)), min(h, int(cy + r + width) + 2)
    if x0 >= x1 or y0 >= y1:
        return
    yy, xx = np.mgrid[y0:y1, x0:x1]
    d = np.sqrt((xx + 0.5 - cx) ** 2 + (yy + 0.5 - cy) ** 2)
    img[y0:y1, x0:x1][np.abs(d - r) <= width / 2] = rgb
