"""NavRL as a navigator: the authors' released PPO policy with its velocity-obstacle shield.

NavRL (Xu et al. 2025) is the learned method of the FLYINGTRUST comparison. The paper flew
the authors' pre-trained model without fine tuning; so does this navigator. The weights are
NOT part of ft-sitl: the user supplies the released checkpoint (``navrl_checkpoint.pt``, MIT
licence, from the authors' repository), found in this order:

1. the ``checkpoint`` parameter (a path),
2. the environment variable ``FT_SITL_NAVRL_CHECKPOINT``,
3. ``$XDG_DATA_HOME/ft-sitl/navrl/navrl_checkpoint.pt`` (``~/.local/share/...``), where
   ``ft-sitl navigators install navrl PATH`` copies a checkpoint after checking it.

Without one, naming ``navrl`` in a campaign is an error that says this, and ``algorithms =
"all"`` leaves it out with a note. The checkpoint is read without PyTorch
(:mod:`ft_sitl.navigation.learned.navrl_policy`).

What it does, as the authors' ROS deployment does (control at 20 Hz, simulated time):

1. **Perception.** Depth frames are fused into the same
   :class:`~ft_sitl.navigation.maps.mapping.LocalMap` the planners use (0.1 m voxels, one-voxel
   inflation, unknown = free). Each control step casts the 36 x 4 "lidar" into the inflated
   map from the vehicle: 10 deg horizontal steps counter-clockwise from the start -> goal
   direction, elevations -10, 0, 10, 20 deg, 4 m range; the policy sees 4 m minus the hit
   distance. Moving obstacles (``dynamic_obstacles``): "tracked" (default) runs the
   deployment's detector and tracker on every frame the navigator gets
   (:mod:`ft_sitl.navigation.learned.navrl_detector`), "truth" takes the simulator's ground truth
   (``Observation.movers``, as the original's simulation launch takes Gazebo's through its
   ``fake_detector``), "off" none. As the deployment's map does, the boxes of those within
   5 m of the camera (grown by 0.3 m, not below z = 0) are set free after each update, and
   the depth points in the boxes of the last 6 updates are left out of it.
2. **Heading.** It first yaws in place toward the goal direction (until within 0.1 rad),
   waits 10 control periods, then holds that yaw.
3. **Policy.** If anything is within ~3.8 m in the half-space toward the goal (the original's
   check of the first and last quarter of the beams, ignoring the -10 deg row), the policy
   runs, and also whenever a moving obstacle is in its dynamic input: state = unit vector
   to the goal and velocity in the goal frame, horizontal and vertical distance; dynamic
   obstacles = the nearest 5 moving obstacles within 4 m horizontally, each as the
   deployment encodes it (:func:`dynamic_obstacle_input`; zeros with "off" or none near);
   the action is ``(2 mean - 1) L`` per goal-frame axis with the Beta mean, rotated to the
   world.
   Otherwise it flies straight at the goal at ``L``. ``L`` = ``action_limit_m_s`` = 1.0 m/s,
   the released deployment's value (why the paper saw NavRL capped near 1 m/s).
4. **Safety shield.** The ray end points are clustered (DBSCAN, 2 points, neighbours within
   sqrt(0.2) m: the deployment squares its 0.2; ``shield_cluster_radius_m``); each cluster
   becomes a sphere (1.5 x its largest horizontal extent, pushed that extent away
   from the vehicle); ORCA half-spaces with a 2 s horizon (0.05 s inside an obstacle) are
   built around the command, and only if the command lies in a velocity obstacle the
   closest velocity satisfying all of them (speed <= sqrt(3) L) replaces it; when none
   does, the one violating them least. The moving obstacles of the dynamic input are
   there too, each a column of spheres moving with its velocity (:func:`dynamic_spheres`),
   kept the vehicle's radius plus 0.3 m away.
5. **Goal approach.** Within 3 m of the goal the command is rescaled to 0.5 m/s.
6. **Output.** PX4 offboard: horizontal velocity, the start altitude as a position, yaw
   toward the goal (altitude is held: the deployment's ``height_control`` is off).

A command takes effect ``latency_s`` (default 10 ms: ray casting and inference through the
ROS services) after the observation it was computed from. Simplified: the shield's
linear programs are solved as a small quadratic program (scipy SLSQP) instead of RVO2's
incremental LP; its fixed 0.7-1.3 m height band is left out (altitude is held anyway); a
ray inside an obstacle sphere counts as "in the velocity obstacle" (the original reads an
uninitialised flag there).
"""

from __future__ import annotations

import functools
import math
import os
import time
from collections import deque
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.frames import wrap_pi
from ft_sitl.navigation.base import Navigator, Observation, ObstacleStates, Task
from ft_sitl.navigation.latency import LATENCY, MEASURED_LATENCY, DelayedCommands
from ft_sitl.navigation.learned import navrl_detector
from ft_sitl.navigation.learned.navrl_detector import DynamicObstacleTracker, in_range
from ft_sitl.navigation.learned.navrl_policy import DYN_DIM, DYN_OBS, CheckpointError, NavRLPolicy
from ft_sitl.navigation.learned.policy_io import goal_frame
from ft_sitl.navigation.maps.mapping import local_map_for
from ft_sitl.scenarios.camera import CAMERA_PARAMS, camera_of
from ft_sitl.schema import Param, Schema

ENV_VAR = "FT_SITL_NAVRL_CHECKPOINT"
CHECKPOINT_NAME = "navrl_checkpoint.pt"
CONTROL_HZ = 20.0
LIDAR_RANGE_M = 4.0
LIDAR_HRES_DEG = 10.0
LIDAR_ELEVATIONS_DEG = (-10.0, 0.0, 10.0, 20.0)
RAY_STEP_M = 0.05
DEFAULT_LATENCY_S = 0.01
ROBOT_RADIUS_M = 0.3
SHIELD_HORIZON_S = 2.0
SHIELD_STEP_S = 0.05
#: the shield's clustering radius (m): the deployment's ``DBSCAN(2, 0.2, points)``
#: (safeAction.cpp, getClusters) compares the *squared* distance with 0.2, so points up to
#: sqrt(0.2) = 0.447 m apart are neighbours (trial protocols before 8 flew 0.2 m)
DBSCAN_EPS_M = math.sqrt(0.2)
DBSCAN_MIN_POINTS = 2
YAW_TOLERANCE_RAD = 0.1
SETTLE_PERIODS = 10
APPROACH_RADIUS_M = 3.0
APPROACH_SPEED_M_S = 0.5
#: the policy gets the moving obstacles within this horizontal distance (the deployment's
#: ``distance_range``), the nearest DYN_OBS of them
DYNAMIC_RANGE_M = 4.0
#: the bin (m) of the obstacle width category (the width plus the robot's diameter)
WIDTH_BIN_M = 0.25
#: an obstacle taller than this (m) is "2-D": only its horizontal offset is given
TALL_M = 1.0
#: the shield's extra distance to moving obstacles (``safety_distance``)
SHIELD_SAFETY_DISTANCE_M = 0.3
#: NavRL's map frees the boxes of the moving obstacles within this horizontal distance of
#: the camera (its ``raycast_max_length``), grown by FREE_MARGIN_M, and keeps leaving out
#: the points in those of the last FREE_HISTORY updates
MAP_FREE_RANGE_M = 5.0
FREE_MARGIN_M = 0.3
FREE_HISTORY = 6
DYNAMIC_MODES = ("tracked", "truth", "off")


def data_dir() -> Path:
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "ft-sitl" / "navrl"


def find_checkpoint(explicit: str | None = None) -> Path | None:
    """The checkpoint to use (see the module docstring), or None when there is none.
    An explicit path or the environment variable that names a missing file is an error."""
    if explicit is not None:
        p = Path(explicit).expanduser()
        if not p.is_file():
            raise FileNotFoundError(f"checkpoint: {p}: no such file")
        return p
    env = os.environ.get(ENV_VAR)
    if env:
        p = Path(env).expanduser()
        if not p.is_file():
            raise FileNotFoundError(f"{ENV_VAR}={env}: no such file")
        return p
    p = data_dir() / CHECKPOINT_NAME
    return p if p.is_file() else None


NO_CHECKPOINT = (f"NavRL needs the authors' released policy checkpoint, which ft-sitl does "
                 f"not ship: give params.checkpoint, set {ENV_VAR}, or run `ft-sitl "
                 f"navigators install navrl PATH`")


@functools.lru_cache(maxsize=4)
def _policy(path: str, mtime_ns: int):
    return NavRLPolicy.from_checkpoint(path)


def load_policy(path: Path):
    """The policy in ``path``, loaded once per process (and again if the file changes)."""
    return _policy(str(path.resolve()), path.stat().st_mtime_ns)


# --- geometry of the goal frame (policy_io.goal_frame: NavRL's) -----------------------------

def lidar_directions(start_angle: float) -> np.ndarray:
    """(36, 4, 3) unit ray directions: horizontal beams counter-clockwise from
    ``start_angle``, elevations -10..20 deg (a direction (cos h, sin h, tan v), normalised)."""
    h = start_angle + np.deg2rad(LIDAR_HRES_DEG) * np.arange(int(360 / LIDAR_HRES_DEG))
    v = np.deg2rad(np.array(LIDAR_ELEVATIONS_DEG))
    d = np.empty((len(h), len(v), 3))
    d[..., 0] = np.cos(h)[:, None]
    d[..., 1] = np.sin(h)[:, None]
    d[..., 2] = np.tan(v)[None, :]
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def cast_lidar(occupied, position, directions, max_range=LIDAR_RANGE_M, step=RAY_STEP_M):
    """Hit distance of each ray (clamped to ``max_range``): the first sample along the ray,
    every ``step`` metres, that ``occupied`` (points (..., 3) -> bool) reports. (The
    navigator uses the map's compiled :meth:`LocalMap.first_occupied`, the same march.)"""
    d = np.arange(step, max_range + 1e-9, step)
    pts = position[None, None, None, :] + directions[:, :, None, :] * d[None, None, :, None]
    hit = occupied(pts)
    first = np.argmax(hit, axis=-1)
    any_hit = hit.any(axis=-1)
    return np.where(any_hit, d[first], max_range)


def obstacle_in_range(lidar_deficit: np.ndarray) -> bool:
    """The original's test: something is within ~3.8 m in the first or last quarter of the
    beams (the half toward the goal), elevations 0..20 deg."""
    q = lidar_deficit.shape[0] // 4
    return bool(np.any(lidar_deficit[:q, 1:] >= 0.2) or np.any(lidar_deficit[-q:, 1:] >= 0.2))


# --- the safety shield ---------------------------------------------------------------------

def dbscan(points: np.ndarray, eps: float = DBSCAN_EPS_M,
           min_points: int = DBSCAN_MIN_POINTS) -> list[np.ndarray]:
    """The shield's clustering of the ray end points (N, 3): sorted index arrays of the
    clusters, noise left out (:func:`ft_sitl.navigation.learned.navrl_detector.dbscan`, the
    detector's DBSCAN with the shield's eps and minimum)."""
    return navrl_detector.dbscan(points, eps, min_points)


def cluster_spheres(points: np.ndarray, position: np.ndarray,
                    eps: float = DBSCAN_EPS_M) -> list[tuple[np.ndarray, float]]:
    """NavRL's static obstacles: per cluster of ray end points (neighbours within
    ``eps``) a sphere of radius 1.5 x the largest horizontal distance from the cluster's
    box centre, centred that distance beyond the box centre (seen from the vehicle)."""
    out = []
    for idx in dbscan(points, eps):
        c = points[idx]
        centre = 0.5 * (c.min(axis=0) + c.max(axis=0))
        extent = float(np.max(np.linalg.norm((c - centre)[:, :2], axis=1)))
        away = centre - position
        n = float(np.linalg.norm(away))
        if n > 1e-9:
            centre = centre + away / n * extent
        out.append((centre, 1.5 * extent))
    return out


def _perpendicular(v: np.ndarray) -> np.ndarray:
    """A unit vector perpendicular to v, horizontal (to its left) when v is not vertical."""
    n = np.cross([0.0, 0.0, 1.0], v)
    if float(np.linalg.norm(n)) < 1e-9:
        n = np.cross([1.0, 0.0, 0.0], v)
    return n / float(np.linalg.norm(n))


def orca_plane(agent_pos, agent_vel, agent_radius, obs_pos, obs_vel, obs_radius,
               horizon=SHIELD_HORIZON_S, step=SHIELD_STEP_S):
    """ORCA half-space (point, normal, in_vo) for one obstacle with the cut-off circle, the
    agent taking full responsibility; None when it is degenerate (zero relative velocity
    inside the obstacle). A relative velocity exactly on the cone's axis, where RVO2's
    projection divides zero by zero, passes on the left. Velocities v with
    (v - point) . normal >= 0 are safe for ``horizon`` seconds."""
    rp = np.asarray(obs_pos, float) - agent_pos
    rv = np.asarray(agent_vel, float) - obs_vel
    dist_sq = float(rp @ rp)
    r = agent_radius + obs_radius
    if dist_sq > r * r:
        w = rv - rp / horizon
        w_sq = float(w @ w)
        dot = float(w @ rp)
        if dot < 0.0 and dot * dot > r * r * w_sq:  # the cut-off circle is closest
            in_vo = float(np.linalg.norm(rv * horizon - rp)) < r
            wl = math.sqrt(w_sq)
            n = w / wl if wl > 1e-12 else -rp / math.sqrt(dist_sq)
            u = (r / horizon - wl) * n
        else:  # the cone's side
            rv_n = float(np.linalg.norm(rv))
            ang_vo = math.asin(min(1.0, r / math.sqrt(dist_sq)))
            in_vo = rv_n > 1e-12 and math.acos(max(-1.0, min(1.0, float(rp @ rv) / (
                math.sqrt(dist_sq) * rv_n)))) < ang_vo
            b = float(rp @ rv)
            c = float(rv @ rv) - float(np.sum(np.cross(rp, rv) ** 2)) / (dist_sq - r * r)
            disc = b * b - dist_sq * c
            if disc < 0.0:
                return None
            t = (b + math.sqrt(disc)) / dist_sq
            w = rv - t * rp
            wl = float(np.linalg.norm(w))
            if wl > 1e-12:
                n = w / wl
                u = (r * t - wl) * n
            else:  # on the cone's axis (head-on): the nearest side is the left one
                axis = rp / math.sqrt(dist_sq)
                sin_a = min(1.0, r / math.sqrt(dist_sq))
                n = math.sqrt(1.0 - sin_a * sin_a) * _perpendicular(rp) - sin_a * axis
                u = float(np.linalg.norm(rv)) * sin_a * n
    else:  # inside: leave within one time step
        w = rv - rp / step
        wl = float(np.linalg.norm(w))
        if wl < 1e-12:
            return None
        n = w / wl
        u = (r / step - wl) * n
        in_vo = True
    return np.asarray(agent_vel, float) + u, n, in_vo


def safe_velocity(preferred: np.ndarray, planes, max_speed: float) -> np.ndarray:
    """The velocity closest to ``preferred`` in every half-space (v - p) . n >= 0 with
    |v| <= max_speed; when there is none, the one whose worst violation is smallest."""

    if not planes:
        return preferred
    P = np.array([p for p, _, _ in planes])
    N = np.array([n for _, n, _ in planes])
    off = np.einsum("ij,ij->i", P, N)
    x0 = preferred * min(1.0, max_speed / max(float(np.linalg.norm(preferred)), 1e-12))
    cons = [{"type": "ineq", "fun": lambda v: N @ v - off, "jac": lambda v: N},
            {"type": "ineq", "fun": lambda v: max_speed ** 2 - v @ v,
             "jac": lambda v: -2.0 * v}]
    res = minimize(lambda v: float((v - preferred) @ (v - preferred)), x0,
                   jac=lambda v: 2.0 * (v - preferred), constraints=cons, method="SLSQP",
                   options={"maxiter": 100, "ftol": 1e-10})
    v = res.x
    if res.success and np.all(N @ v - off >= -1e-6) and v @ v <= max_speed ** 2 + 1e-6:
        return v
    # infeasible: minimise the largest violation t (variables v, t)
    cons = [{"type": "ineq", "fun": lambda z: N @ z[:3] - off + z[3],
             "jac": lambda z: np.hstack([N, np.ones((len(N), 1))])},
            {"type": "ineq", "fun": lambda z: max_speed ** 2 - z[:3] @ z[:3],
             "jac": lambda z: np.hstack([-2.0 * z[:3], [0.0]])}]
    z0 = np.append(np.zeros(3), float(np.max(off)) + 1.0)
    res = minimize(lambda z: z[3], z0, jac=lambda z: np.array([0.0, 0.0, 0.0, 1.0]),
                   constraints=cons, method="SLSQP", options={"maxiter": 100})
    v = res.x[:3]
    return v if np.all(np.isfinite(v)) else np.zeros(3)


def dynamic_spheres(obstacles: ObstacleStates) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """The shield's moving obstacles: each box as a column of spheres (centre, velocity,
    radius) as the original's ``getSafeAction`` builds it: radius half the box's
    horizontal diagonal, ceil(height / side) spheres a side apart (side: the larger
    horizontal edge), the lowest one half the remainder above the box's bottom."""
    out = []
    for c, v, s in zip(obstacles.position, obstacles.velocity, obstacles.size):
        side = max(s[0], s[1])
        if side <= 0.0 or s[2] <= 0.0:
            continue
        n = math.ceil(s[2] / side)
        z0 = c[2] - s[2] / 2 + (s[2] - (n - 1) * side) / 2
        r = 0.5 * math.hypot(s[0], s[1])
        out += [(np.array([c[0], c[1], z0 + k * side]), v, r) for k in range(n)]
    return out


def shield(position, preferred, ray_points, max_speed, agent_radius: float = 0.0,
           dynamic: ObstacleStates | None = None, dynamic_radius: float = 0.0,
           cluster_radius: float = DBSCAN_EPS_M):
    """NavRL's safe action for the static ray hits and the moving obstacles ``dynamic``;
    returns (velocity, whether it solved). ``agent_radius``: the vehicle's radius in the
    static velocity obstacles (m); ``dynamic_radius``: in the moving ones (the original's
    robot size plus its safety distance); ``cluster_radius``: the hits' DBSCAN radius."""
    planes = []
    need = False
    obstacles = [] if dynamic is None else [
        (c, v, r, dynamic_radius) for c, v, r in dynamic_spheres(dynamic)]
    obstacles += [(c, np.zeros(3), r, agent_radius)
                  for c, r in cluster_spheres(ray_points, position, cluster_radius)]
    for centre, vel, radius, mine in obstacles:
        pl = orca_plane(position, preferred, mine, centre, vel, radius)
        if pl is None:
            continue
        planes.append(pl)
        need = need or pl[2]
    if not need:
        return preferred, False
    return safe_velocity(preferred, planes, max_speed), True


def dynamic_obstacle_input(obstacles: ObstacleStates, position, frame: np.ndarray,
                           robot_radius: float = ROBOT_RADIUS_M) -> np.ndarray:
    """The policy's dynamic-obstacle input (DYN_OBS x DYN_DIM) from the first DYN_OBS of
    ``obstacles`` (nearest first), as the released deployment computes it (``get_action``
    of navigation.py): per obstacle the unit vector to it in the goal frame, its horizontal
    and vertical distance, its velocity in the goal frame, its width category
    ceil((max(x, y size) + 2 robot_radius) / 0.25) - 1 clipped to 0..3, and 1 if it is at
    most 1 m tall, else 0 (a tall obstacle's vertical offset is zeroed); rows without an
    obstacle, and the position terms of one without height, are zeros."""
    out = np.zeros((DYN_OBS, DYN_DIM))
    n = min(obstacles.count, DYN_OBS)
    if n == 0:
        return out
    size = obstacles.size[:n]
    rpos = obstacles.position[:n] - np.asarray(position, dtype=float).reshape(3)
    flat = size[:, 2] == 0.0
    rpos[flat] = 0.0
    rpos[size[:, 2] > TALL_M, 2] = 0.0
    rg = rpos @ frame.T
    dist = np.linalg.norm(rpos, axis=1)
    out[:n, 0:3] = rg / np.maximum(dist, 1e-6)[:, None]
    out[:n, 3] = np.hypot(rg[:, 0], rg[:, 1])
    out[:n, 4] = rg[:, 2]
    out[:n, 5:8] = obstacles.velocity[:n] @ frame.T
    width = np.maximum(size[:, 0], size[:, 1]) + 2.0 * robot_radius
    out[:n, 8] = np.where(flat, 0.0, np.clip(np.ceil(width / WIDTH_BIN_M) - 1.0, 0.0,
                                             1.0 / WIDTH_BIN_M - 1.0))
    out[:n, 9] = np.where((size[:, 2] <= TALL_M) & ~flat, 1.0, 0.0)
    return out


def free_boxes(obstacles: ObstacleStates, camera_position) -> tuple[np.ndarray, np.ndarray]:
    """The boxes NavRL's map frees for the moving obstacles: those within MAP_FREE_RANGE_M
    of the camera horizontally, grown by FREE_MARGIN_M on every side but not below z = 0
    (lower corners, upper corners)."""
    near = in_range(obstacles, camera_position, MAP_FREE_RANGE_M)
    lo = near.position - near.size / 2 - FREE_MARGIN_M
    lo[:, 2] = np.maximum(lo[:, 2], 0.0)
    return lo, near.position + near.size / 2 + FREE_MARGIN_M


class NavRL(Navigator):
    """NavRL (Xu et al. 2025): learned velocity policy + ORCA safety shield."""

    name = "navrl"
    rate_hz = 100.0

    schema = Schema((
        Param("checkpoint", None, "path", kind="str",
              doc=f"the policy checkpoint file (none: ${ENV_VAR}, then the installed one)"),
        Param("action_limit_m_s", 1.0, "m/s", (0.1, 10.0),
              doc="speed limit L of the policy's action (per axis)"),
        LATENCY,
        MEASURED_LATENCY,
        Param("use_shield", True, doc="correct the policy's action with the ORCA safety shield"),
        Param("shield_cluster_radius_m", DBSCAN_EPS_M, "m", (0.05, 2.0),
              doc="the shield's DBSCAN neighbour radius for the ray hits (the deployment's "
                  "squared-distance 0.2; trials before protocol 8 fly 0.2 m)"),
        Param("dynamic_obstacles", "tracked", choices=DYNAMIC_MODES,
              doc="moving obstacles for the policy's dynamic input, the shield and the map's "
                  "free regions: 'tracked' by the deployment's depth detector and tracker, "
                  "'truth' the simulator's ground truth (in-process trials only), 'off' "
                  "none (the input stays zero; what trials before protocol 7 fly)"),
        *CAMERA_PARAMS,
    )).with_defaults(latency_s=DEFAULT_LATENCY_S)

    def __init__(self, **params):
        super().__init__(**params)
        p = self.settings
        checkpoint = p["checkpoint"]
        path = find_checkpoint(checkpoint)
        if path is None:
            raise FileNotFoundError(NO_CHECKPOINT)
        try:
            self.policy = load_policy(path)
        except CheckpointError as exc:
            env = os.environ.get(ENV_VAR)
            if checkpoint is None and env:  # find_checkpoint took the variable's file
                raise CheckpointError(f"{ENV_VAR}={env}: {exc}") from None
            raise
        self.checkpoint_path = path
        self.limit = float(p["action_limit_m_s"])
        self.latency = float(p["latency_s"])
        self.measured_latency = bool(p["measured_latency"])
        self.use_shield = bool(p["use_shield"])
        self.cluster_radius = float(p["shield_cluster_radius_m"])
        self.dynamic_mode = p["dynamic_obstacles"]
        self.needs_mover_truth = self.dynamic_mode == "truth"
        self.camera = camera_of(p)

    @classmethod
    def unavailable(cls) -> str | None:
        try:
            found = find_checkpoint()
        except FileNotFoundError as exc:
            return str(exc)
        return None if found is not None else NO_CHECKPOINT

    def reset(self, task: Task) -> None:
        super().reset(task)
        self.map = local_map_for(task, self.camera)
        # the shield's agent radius: the platform's footprint (protocol 4 on; the
        # original's deployment uses 0.3 m), else 0 as before; toward moving obstacles
        # the deployment's robot size (0.3 m) plus its safety distance, the footprint
        # taking the robot size's place when there is one
        self.agent_radius = task.footprint_m if task.footprint_m is not None else 0.0
        self.dynamic_radius = (task.footprint_m if task.footprint_m is not None
                               else ROBOT_RADIUS_M) + SHIELD_SAFETY_DISTANCE_M
        self.hold_z = float(task.start[2])
        self.goal = np.array([task.goal[0], task.goal[1], self.hold_z])
        direction = self.goal - task.start
        self.frame = goal_frame(direction)
        self.goal_yaw = math.atan2(direction[1], direction[0])
        self.rays = lidar_directions(self.goal_yaw)
        # the moving obstacles: the detector (tracked), the policy's last dynamic input,
        # the obstacles the shield last saw, and the map's free regions of the last updates
        self.tracker = (DynamicObstacleTracker(self.camera) if self.dynamic_mode == "tracked"
                        else None)
        self.dynamic = np.zeros((DYN_OBS, DYN_DIM))
        self.dynamic_seen = ObstacleStates.empty()
        self.free_history: deque = deque(maxlen=FREE_HISTORY)
        self.clock_offset_us = 0
        self.perception_s: list[float] = []  # wall-clock time of each frame's perception
        self.settled = 0
        self.commands = DelayedCommands(CONTROL_HZ, self.latency, self.measured_latency)
        self.policy_calls = 0
        self.shield_solves = 0
        self.dynamic_steps = 0  # control periods with a moving obstacle in the input

    def state_vector(self, position, velocity) -> np.ndarray:
        rpos = self.goal - position
        dist = max(float(np.linalg.norm(rpos)), 1e-6)
        return np.concatenate([self.frame @ (rpos / dist), [np.hypot(rpos[0], rpos[1])],
                               [rpos[2]], self.frame @ velocity])

    def command(self, obs: Observation) -> Setpoint | None:
        """One control period; None keeps the previous command (the settling wait)."""
        pos = np.asarray(obs.position, dtype=float)
        if abs(wrap_pi(self.goal_yaw - obs.yaw)) >= YAW_TOLERANCE_RAD:
            return Setpoint.position(pos, yaw=self.goal_yaw)
        self.settled += 1
        if self.settled <= SETTLE_PERIODS:
            return None
        dist = self.map.first_occupied(pos, self.rays, RAY_STEP_M, LIDAR_RANGE_M)
        deficit = LIDAR_RANGE_M - dist
        vel = np.asarray(obs.velocity, dtype=float)
        if self.dynamic_mode != "off":
            near = in_range(self._moving(obs), pos, DYNAMIC_RANGE_M)
            self.dynamic_seen = near.take(slice(0, DYN_OBS))
            self.dynamic = dynamic_obstacle_input(self.dynamic_seen, pos, self.frame)
            self.dynamic_steps += int(self.dynamic_seen.count > 0)
        if obstacle_in_range(deficit) or np.any(self.dynamic != 0.0):
            mean = self.policy.mean_action(self.state_vector(pos, vel), deficit, self.dynamic)
            cmd = self.frame.T @ ((2.0 * mean - 1.0) * self.limit)
            self.policy_calls += 1
        else:
            to_goal = self.goal - pos
            n = float(np.linalg.norm(to_goal))
            cmd = to_goal / n * self.limit if n > 1e-9 else np.zeros(3)
        if self.use_shield:
            ends = pos + self.rays * dist[..., None]
            cmd, solved = shield(pos, cmd, ends.reshape(-1, 3), math.sqrt(3.0) * self.limit,
                                 self.agent_radius, self.dynamic_seen, self.dynamic_radius,
                                 self.cluster_radius)
            self.shield_solves += int(solved)
        goal_dist = float(np.linalg.norm(pos - self.goal))
        speed = float(np.linalg.norm(cmd))
        if 0.3 < goal_dist <= APPROACH_RADIUS_M and speed > 0.0:
            cmd = cmd / speed * APPROACH_SPEED_M_S
        if not np.all(np.isfinite(cmd)):
            raise FloatingPointError(f"non-finite NavRL command {cmd} at t = {obs.time_s:.2f}")
        return Setpoint.trajectory(position=[math.nan, math.nan, self.hold_z],
                                   velocity=[cmd[0], cmd[1], math.nan], yaw=self.goal_yaw)

    def _moving(self, obs: Observation) -> ObstacleStates:
        """The moving obstacles now: the tracker's, or the ground truth."""
        if self.tracker is not None:
            return self.tracker.obstacles()
        if obs.movers is None:
            raise ValueError("dynamic_obstacles = 'truth' needs the moving obstacles' ground "
                             "truth (Observation.movers), which only the in-process trial "
                             "driver supplies; use 'tracked' or 'off' here")
        return obs.movers

    def _perceive(self, obs: Observation) -> None:
        """A depth frame, if any: the detector takes it (tracked), and it is fused into the
        map the lidar is cast in, leaving out the points in the moving obstacles' boxes of
        the last FREE_HISTORY updates and then freeing the current boxes, as the
        deployment's map does (not with 'off')."""
        frame = obs.depth
        if self.dynamic_mode == "off":
            if frame is not None:
                self.map.fuse(frame)
            return
        moving = self._moving(obs)  # (truth: checked at every step)
        if frame is None:
            return
        t0 = time.perf_counter()
        if self.tracker is not None:
            # the navigator's clock starts again at 0 when navigation starts (it counted
            # from arming before): the tracker's time goes on one frame period later
            t_us = int(frame.t_us) + self.clock_offset_us
            last = self.tracker.last_t_us
            if last is not None and t_us <= last:
                self.clock_offset_us += last + round(self.camera.period_us) - t_us
                t_us = int(frame.t_us) + self.clock_offset_us
            self.tracker.update(frame, t_us)
            moving = self.tracker.obstacles()
        boxes = free_boxes(moving, frame.p_world_camera)
        if self.free_history:
            self.map.fuse(frame, exclude_boxes=(np.vstack([b[0] for b in self.free_history]),
                                                np.vstack([b[1] for b in self.free_history])))
        else:
            self.map.fuse(frame)
        self.map.set_free(boxes)
        self.free_history.append(boxes)
        self.perception_s.append(time.perf_counter() - t0)

    def observe(self, obs: Observation) -> None:
        """Before navigation: the depth frame goes to the detector and the map."""
        self._perceive(obs)

    def step(self, obs: Observation) -> Setpoint:
        t = obs.time_s
        self._perceive(obs)
        sp = self.commands.step(t, lambda: self.command(obs))
        if sp is None:  # before the first command: hold the start
            return Setpoint.position(self.task.start, yaw=obs.yaw)
        return sp
