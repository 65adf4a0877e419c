"""What a worker process keeps between trials: scenarios, collision worlds with their
distance grids, and the navigators' depth cameras, each built once per scenario.

A campaign flies its trials scenario by scenario, so a small cache (the
:data:`CACHE_MAX` newest entries per kind) saves rebuilding them for every trial. Campaign
workers also share distance grids through a directory (:meth:`TrialResources.share_grids`):
the first process to need a scenario's grid builds it and saves it there, the others load
it (a grid is deterministic, so every process gets the same array it would have built).
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os

import numpy as np

from ft_sitl.missions.durable import durable_replace
from ft_sitl.missions.spec import TrialSpec, TrialSpecError
from ft_sitl.missions.streams import mover_seed
from ft_sitl.scenarios.camera import DepthCamera
from ft_sitl.scenarios.collision import CollisionWorld
from ft_sitl.scenarios.distance_grid import DistanceGrid
from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.io import load_scenario
from ft_sitl.scenarios.movers import MoverError, with_movers

#: entries kept per cache
CACHE_MAX = 8
#: mover placements kept (a few kB each): one per configuration and trial number, which a
#: campaign cycles through for every algorithm and platform
MOVER_CACHE_MAX = 256
#: shared grids kept on disk (the newest; up to ~30 MB each): a campaign's chunks come
#: scenario by scenario, so an older grid is rarely asked for again (it is rebuilt if so)
GRID_CACHE_KEEP = 8


def scenario_key(sc) -> tuple:
    """What identifies a scenario's geometry (not its id(): ids are reused)."""
    return (sc.name, sc.mesh_digest(), tuple(sc.bounds_min), tuple(sc.bounds_max))


class TrialResources:
    """Per-process caches of the things trials are built from."""

    def __init__(self, grid_dir: str | None = None):
        self.grid_dir = grid_dir
        self._scenarios: dict = {}
        self._worlds: dict = {}
        self._cameras: dict = {}
        self._movers: dict = {}

    def share_grids(self, path: str | None) -> None:
        """Share distance grids with other processes through ``path`` (None: build here)."""
        self.grid_dir = path

    @staticmethod
    def _cached(cache: dict, key, make, size: int = CACHE_MAX):
        if key not in cache:
            if len(cache) >= size:
                cache.pop(next(iter(cache)))
            cache[key] = make()
        return cache[key]

    def scenario(self, spec: TrialSpec):
        """The spec's scenario: from its file, or built from (family, index, seed); with
        the spec's moving obstacles placed in it (scenarios.movers, for the trial's
        mover seed: every algorithm and platform of a configuration's trial k meets the same
        movers), or a
        scenario file's own (its ``movers`` table or list)."""
        if spec.scenario_file:
            sc = self._cached(self._scenarios, ("file", spec.scenario_file),
                              lambda: load_scenario(spec.scenario_file))
        else:
            key = (spec.family, spec.scenario_index, spec.scenario_seed, None,
                   spec.scenario_version)
            sc = self._cached(self._scenarios, key, lambda: build_scenario(*key))
        if spec.movers is None:
            return sc  # (a scenario file's own movers, if it has any)
        if sc.movers is not None:
            raise TrialSpecError(f"movers: the scenario file {spec.scenario_file} has movers "
                                 "of its own; give them in the file or in the trial's "
                                 "movers, not both")
        seed = mover_seed(spec.scenario_file or spec.family, spec.scenario_seed,
                          spec.scenario_index, spec.trial)
        mkey = (scenario_key(sc), json.dumps(spec.movers, sort_keys=True), seed)
        try:
            return self._cached(self._movers, mkey, lambda: with_movers(sc, spec.movers, seed),
                                MOVER_CACHE_MAX)
        except MoverError as exc:
            raise TrialSpecError(str(exc)) from None

    def world_and_grid(self, scenario) -> tuple[CollisionWorld, DistanceGrid]:
        """The scenario's collision world and distance grid."""
        key = scenario_key(scenario)

        def make():
            return (CollisionWorld(scenario.mesh, scenario.bounds_min, scenario.bounds_max),
                    self._distance_grid(scenario, key))
        return self._cached(self._worlds, key, make)

    def camera(self, config, scenario) -> DepthCamera:
        """A depth camera of ``config`` in ``scenario`` (its ray-casting BVH built once)."""
        return self._cached(self._cameras, (scenario_key(scenario), config),
                            lambda: DepthCamera(config, scenario.mesh))

    # --- grids shared between processes -------------------------------------------------
    def _distance_grid(self, scenario, key: tuple) -> DistanceGrid:
        def build():
            return DistanceGrid.build(scenario.mesh, scenario.bounds_min, scenario.bounds_max)

        if self.grid_dir is None:
            return build()
        name = hashlib.sha256(repr(key).encode()).hexdigest()[:32]
        path = os.path.join(self.grid_dir, name + ".npz")
        try:
            lock = open(os.path.join(self.grid_dir, name + ".lock"), "a")  # noqa: SIM115
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
                durable_replace(tmp, path)
                prune_grids(self.grid_dir)
            except OSError:
                pass  # sharing is an optimisation only
            return grid


def prune_grids(directory: str) -> None:
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


#: this process's resources (campaign workers set its grid directory when they start)
RESOURCES = TrialResources()
