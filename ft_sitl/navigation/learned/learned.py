"""The learned navigator: a velocity policy trained here with PPO over generated platforms
and the seven scenario families (``ft-sitl train``, :mod:`ft_sitl.gym.train`), flown from
a numpy policy file without the training stack.

The shipped policy (``ft_sitl/navigation/learned/data/learned-v1.npz``; its training and results:
docs/planners.md, "learned", and docs/results/learned/) or any other file ``ft-sitl
train`` wrote (parameter ``policy``). The file records how its input is built and its
action scaled (:mod:`ft_sitl.navigation.learned.policy_io`), and the navigator reproduces exactly
what the policy saw in training except for one thing, the obstacles:

1. **Perception.** In training the policy's ray scan is cast into the true world. Here, as
   for NavRL (whose authors trained on the simulator's truth too and deploy on a map), the
   rays are cast into the planners' :class:`~ft_sitl.navigation.maps.mapping.LocalMap` built
   from the depth camera's frames (0.1 m voxels, from take-off on), without inflation: the
   scan reads the distance to the nearest seen surface (to the 0.05 m march step) as the
   training scan does, and what the camera has not seen reads as free.
2. **Heading.** It first yaws in place toward the goal (as the training episodes start:
   facing the goal), then holds that heading; the policy was trained without yaw actions,
   so the camera keeps looking along the start -> goal direction.
3. **Policy.** Every 1 / ``control_hz`` s (the file's, 10 Hz for the shipped one): the state
   vector of the flight controller's estimate in the goal frame, the distances to the
   flight volume's sides along the goal frame's axes (the task's bounds), the platform vector
   (TWR_max, alpha_xy_max, alpha_z_max and the footprint the task gives, normalised to
   the catalog's range stored in the file), the previous action and the scan go through
   the network; its deterministic action (the Gaussian's mean, clipped to [-1, 1]) is a
   goal-frame velocity (x, y times ``max_speed_m_s``, z times ``max_climb_m_s``), sent as
   a PX4 velocity setpoint with the heading held.

A command takes effect ``latency_s`` (default 10 ms) after the observation it came from.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.frames import wrap_pi
from ft_sitl.navigation.base import Navigator, Observation, Task
from ft_sitl.navigation.latency import LATENCY, MEASURED_LATENCY, DelayedCommands
from ft_sitl.navigation.learned.policy_io import (
    N_STATE,
    STATE_HIGH,
    STATE_LOW,
    MlpPolicy,
    PolicyFileError,
    edge_distances,
    goal_frame,
    input_size,
    normalise_platform,
    observe_state,
    policy_input,
    ray_directions,
    velocity_action,
)
from ft_sitl.navigation.maps.mapping import LocalMap, MapConfig
from ft_sitl.physics import dynamics as d
from ft_sitl.scenarios.camera import CAMERA_PARAMS, camera_of
from ft_sitl.schema import Param, Schema

#: the policies shipped with ft-sitl: ``learned-<name>.npz`` here, named by ``<name>``; a
#: new one is added beside the old (rows flown with ``v1`` keep re-running bit for bit)
SHIPPED_DIR = Path(__file__).with_name("data")
DEFAULT_POLICY = "v1"
#: the scan's march step (m): NavRL's
RAY_STEP_M = 0.05
YAW_TOLERANCE_RAD = 0.1
#: the metadata a policy file must carry for this navigator
REQUIRED_META = ("control_hz", "max_speed_m_s", "max_climb_m_s", "ray_columns", "ray_rows",
                 "ray_elevation_deg", "ray_range_m", "platform_log_lo", "platform_log_hi")


@functools.lru_cache(maxsize=4)
def _load(path: str, mtime_ns: int) -> MlpPolicy:
    policy = MlpPolicy.load(path)
    missing = [k for k in REQUIRED_META if k not in policy.meta]
    if missing:
        raise PolicyFileError(f"{path}: not a navigation policy (its metadata lacks "
                              f"{', '.join(missing)})")
    m = policy.meta
    n_in = input_size(int(m["ray_columns"]) * int(m["ray_rows"]))
    if policy.input_size != n_in or policy.output_size != 4:
        raise PolicyFileError(f"{path}: the network maps {policy.input_size} inputs to "
                              f"{policy.output_size} outputs; a navigation policy with "
                              f"{m['ray_columns']} x {m['ray_rows']} rays maps {n_in} to 4")
    return policy


def shipped() -> list[str]:
    """The names of the shipped policies."""
    return sorted(p.stem.removeprefix("learned-") for p in SHIPPED_DIR.glob("learned-*.npz"))


def policy_path(policy: str = DEFAULT_POLICY) -> Path:
    """A shipped policy's file (``policy`` one of :func:`shipped`), else ``policy`` as a
    path; FileNotFoundError naming both readings if neither exists."""
    own = SHIPPED_DIR / f"learned-{policy}.npz"
    if own.is_file():
        return own
    p = Path(policy).expanduser()
    if p.is_file():
        return p
    names = ", ".join(shipped()) or "none installed"
    raise FileNotFoundError(f"policy {policy!r}: neither a shipped policy ({names}) nor a "
                            "file")


def load_policy(policy: str = DEFAULT_POLICY) -> MlpPolicy:
    """The policy ``policy`` (:func:`policy_path`), read once per process (again if the
    file changes); PolicyFileError (a ValueError) if it is not one."""
    p = policy_path(policy)
    return _load(str(p.resolve()), p.stat().st_mtime_ns)


class Learned(Navigator):
    """A PPO velocity policy trained here on generated platforms (module docstring)."""

    name = "learned"
    rate_hz = 100.0

    schema = Schema((
        Param("policy", DEFAULT_POLICY, kind="str",
              doc="a shipped policy's name (v1: trained by ft_sitl/gym/presets/learned.toml) "
                  "or the path of a policy file `ft-sitl train` wrote"),
        LATENCY,
        MEASURED_LATENCY,
        *CAMERA_PARAMS,
    ))

    @classmethod
    def unavailable(cls) -> str | None:
        try:
            policy_path(DEFAULT_POLICY)
        except FileNotFoundError as exc:
            return f"{exc} (the installation lacks ft_sitl/navigation/learned/data)"
        return None

    def __init__(self, **params):
        super().__init__(**params)
        p = self.settings
        self.policy = load_policy(p["policy"])
        m = self.policy.meta
        self.control_hz = float(m["control_hz"])
        self.max_speed = float(m["max_speed_m_s"])
        self.max_climb = float(m["max_climb_m_s"])
        self.ray_range = float(m["ray_range_m"])
        self.rays_local = ray_directions(int(m["ray_columns"]), int(m["ray_rows"]),
                                         tuple(m["ray_elevation_deg"]))
        self.platform_range = (np.array(m["platform_log_lo"]), np.array(m["platform_log_hi"]))
        self.latency = float(p["latency_s"])
        self.measured_latency = bool(p["measured_latency"])
        self.camera = camera_of(p)

    def reset(self, task: Task) -> None:
        super().reset(task)
        self.map = LocalMap(MapConfig(skip_pixel=1, inflation_voxels=0), task.ceiling,
                            float(task.bounds_min[2]), camera=self.camera,
                            center_m=tuple(task.start[:2]))
        direction = task.goal - task.start
        self.frame = goal_frame(direction)
        self.goal_yaw = math.atan2(self.frame[0, 1], self.frame[0, 0])
        self.rays_world = self.rays_local @ self.frame  # world = F^T g, row-wise
        footprint = (task.footprint_m if task.footprint_m is not None
                     else task.collision_radius_m)
        self.platform_vec = normalise_platform(
            [task.twr_max, task.alpha_xy_max, task.alpha_z_max, footprint],
            *self.platform_range)[None]
        self.last_action = np.zeros((1, 4))
        # the input of the compiled kernel observe_state, in the plant's state layout (the
        # rotor speeds are not observed)
        self.x = np.zeros((1, d.X_ROTOR))
        self.state = np.empty((1, N_STATE), np.float32)
        self.facing = False
        self.commands = DelayedCommands(self.control_hz, self.latency, self.measured_latency)

    def observe(self, obs: Observation) -> None:
        """Before navigation: the depth frames go into the map (from take-off on)."""
        if obs.depth is not None:
            self.map.fuse(obs.depth)

    def inputs(self, obs: Observation) -> np.ndarray:
        """The policy's input (1, size) for an observation: the gym's observation parts,
        the scan cast into the map."""
        # observe_state is the gym's compiled kernel (policy_io), which reads the plant's
        # state layout: x is its input and nothing else indexes it
        x = self.x
        x[0, d.X_POS:d.X_POS + 3] = obs.position
        x[0, d.X_VEL:d.X_VEL + 3] = obs.velocity
        x[0, d.X_QUAT:d.X_QUAT + 4] = obs.attitude
        x[0, d.X_OMEGA:d.X_OMEGA + 3] = obs.angular_velocity
        task = self.task
        observe_state(x, task.goal[None], self.frame[None], float(task.bounds_min[2]),
                      task.ceiling, STATE_LOW, STATE_HIGH, self.state)
        hits = self.map.first_occupied(np.asarray(obs.position, dtype=float), self.rays_world,
                                       RAY_STEP_M, self.ray_range)
        rays = (np.clip(hits, 0.0, self.ray_range) / self.ray_range)[None]
        edges = edge_distances(np.array(obs.position, dtype=float)[None], self.frame[None],
                               task.bounds_min, task.bounds_max)
        return policy_input(self.state, edges, self.platform_vec, self.last_action, rays)

    def command(self, obs: Observation) -> Setpoint:
        """One control period: turn to the goal first, then the policy's velocity."""
        if not self.facing:
            if abs(wrap_pi(self.goal_yaw - obs.yaw)) >= YAW_TOLERANCE_RAD:
                return Setpoint.position(self.task.start, yaw=self.goal_yaw)
            self.facing = True
        action = self.policy.act(self.inputs(obs))
        self.replans += 1  # (each policy call counts as a plan)
        self.last_action = action.astype(np.float32).astype(np.float64)
        v = velocity_action(self.frame[None], action, self.max_speed, self.max_climb)[0]
        if not np.all(np.isfinite(v)):
            raise FloatingPointError(f"non-finite learned command {v} at t = {obs.time_s:.2f}")
        return Setpoint.velocity(v, yaw=self.goal_yaw)

    def step(self, obs: Observation) -> Setpoint:
        t = obs.time_s
        if obs.depth is not None:
            self.map.fuse(obs.depth)
        sp = self.commands.step(t, lambda: self.command(obs))
        if sp is None:  # before the first command: hold the start
            return Setpoint.position(self.task.start, yaw=obs.yaw)
        return sp
