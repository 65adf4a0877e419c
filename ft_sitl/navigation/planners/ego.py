"""EGO-Planner as a navigator: local map from the depth camera, min-snap global reference,
rebound B-spline optimisation, replanning, emergency stop, yaw toward the path ahead.

What it does each call (``rate_hz`` 100, the original's command rate), in simulated time:

1. **Perception.** A depth frame (when the camera is due) is fused into the
   :class:`~ft_sitl.navigation.maps.mapping.LocalMap`; the planner only knows what the camera
   saw. Unknown space counts as free, the scenario ceiling is a virtual ceiling.
2. **Global reference.** Once, at the start: a min-snap polynomial start -> goal through a
   point every 4 m (:func:`~ft_sitl.navigation.trajectories.minsnap.global_reference`).
3. **Replanning** (EGO's FSM):

   * the first plan is made at once;
   * a new plan when the vehicle is more than ``replan_threshold_m`` (1.5 m) from the
     current trajectory's start, unless the goal is within ``no_replan_threshold_m`` (2 m);
   * a collision check of the remaining trajectory's first 2/3 against the map at 20 Hz:
     a collision triggers a replan, and an emergency stop (hover where it is, then plan
     from rest) when it is less than ``emergency_time_s`` (0.8 s) ahead;
   * a plan: the local target ``planning_horizon_m`` (7.5 m) ahead on the reference (at
     rest when the goal is that close), a one-segment polynomial to it from the current
     trajectory's state, fitted to a uniform cubic B-spline, optimised by
     :class:`~ft_sitl.navigation.optimisers.ego.EgoOptimizer` (rebound + refinement).

   A plan that fails is retried after 0.05 s, doubling with each failure in a row up to
   1 s; after ``GIVE_UP_AFTER`` (8) failures in a row from the same state with the same
   map the planner gives up ("no plan": the trial ends as a timeout, as it would after 90 s
   of identical failures, since the optimiser is deterministic).

4. **Latency.** A plan does not act at once: it is computed from the trajectory's state
   ``latency_s`` ahead and replaces the current trajectory ``latency_s`` later (simulated
   time). The default is a fixed estimate of the original's compute time per replan on a
   desktop CPU (:data:`DEFAULT_LATENCY_S`), so a fast or slow host CPU does not change how
   the planner flies; ``measured_latency=True`` uses this process's measured compute time
   instead.
5. **Output.** Position + velocity + acceleration + yaw from the current trajectory; yaw
   points at the trajectory 1 s ahead, rate-limited to pi rad/s, low-pass 0.5.

Camera. The originals fuse a 640 x 480 RealSense stream at 30 Hz with every second pixel
(320 x 240 rays). Ray casting that here costs ~0.5 CPU-s per simulated second, more than
everything else together, so the benchmark default is a 160 x 120 frame (the same field of
view) at 15 Hz; ``camera="d435"`` selects the faithful 320 x 240 @ 30 Hz rays
(``camera_width``/``camera_height``/``camera_rate_hz`` set any other).
"""

from __future__ import annotations

import time

import numpy as np

from ft_sitl.navigation.base import Observation, Task
from ft_sitl.navigation.optimisers.ego import EgoOptimizer, EgoParams, first_collision_time
from ft_sitl.navigation.planners.astar import OccupancyView
from ft_sitl.navigation.planners.skeleton import HorizonPlanner
from ft_sitl.navigation.trajectories.base import SplineTrajectory
from ft_sitl.navigation.trajectories.bspline import BSpline
from ft_sitl.navigation.trajectories.minsnap import global_reference, min_snap, one_segment_time

#: estimated compute time of one EGO replan in the original C++ (optimisation ~1 ms, plus
#: A* and map work; the paper's authors report a few ms on a desktop CPU)
DEFAULT_LATENCY_S = 0.01
#: EGO's control-point spacing of the initial path (m)
CTRL_PT_DIST_M = 0.4


def _resample(path: np.ndarray, spacing: float, min_points: int = 7) -> np.ndarray:
    """Points every ``spacing`` metres of arc length along the polyline ``path`` (its last
    point included); the spacing shrinks by 1.5 until there are ``min_points`` (EGO)."""
    seg = np.linalg.norm(np.diff(path, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    total = float(cum[-1])
    if total <= 0.0:
        return np.repeat(path[:1], min_points, axis=0)
    while True:
        s = np.arange(0.0, total, spacing)
        if len(s) + 1 >= min_points or spacing < 1e-3:
            break
        spacing /= 1.5
    s = np.append(s[s < total - 1e-6], total)
    return np.column_stack([np.interp(s, cum, path[:, k]) for k in range(3)])


class EgoPlanner(HorizonPlanner):
    """EGO-Planner (Zhou et al. 2021): ESDF-free gradient-based local planning."""

    name = "ego"

    schema = HorizonPlanner.schema.with_defaults(max_acc_m_s2=3.0, planning_horizon_m=7.5,
                                                  latency_s=DEFAULT_LATENCY_S)

    # --- set-up ---------------------------------------------------------------------------
    def reset(self, task: Task) -> None:
        super().reset(task)
        self.grid = OccupancyView.from_map(self.map, bounds=self.bounds)
        self.optimizer = EgoOptimizer(self.grid, EgoParams(max_vel=self.vmax,
                                                           max_acc=self.max_acc))
        self.reference = global_reference(task.start, task.goal, self.vmax)
        self.progress_t = 0.0

    # --- planning ---------------------------------------------------------------------------
    def _plan(self, obs: Observation) -> None:
        t_start = time.perf_counter()
        t_eff = obs.time_s + self.latency
        vmax = self.vmax
        ts = CTRL_PT_DIST_M / vmax * 1.5  # EGO's sampling step of the initial path
        if self.traj is None or self.from_rest:
            p0 = np.array(obs.position if self.stop_at is None else self.stop_at)
            v0 = np.zeros(3) if self.stop_at is not None else np.array(obs.velocity)
            a0 = np.zeros(3)
            prefix = np.zeros((0, 3))
        else:
            p0, v0, a0 = self.traj.state(t_eff)
            # the rest of the current trajectory, then a polynomial to the new target
            tau = np.arange(t_eff - self.traj.t0, self.traj.spline.duration, ts)
            prefix = self.traj.spline.position(tau) if len(tau) else np.zeros((0, 3))
        target = self.reference.local_target(p0, self.progress_t, self.horizon, vmax,
                                             self.max_acc)
        self.progress_t = target.progress_time_s
        self.replans += 1
        if float(np.linalg.norm(target.point - p0)) < 0.1:  # there already: hold it
            self._adopt(None, obs, t_start)
            return
        if len(prefix):
            pe, ve, ae = self.traj.state(self.traj.end_time)
            poly_t = float(np.linalg.norm(target.point - pe)) / vmax * 2.0
        else:
            pe, ve, ae = p0, v0, a0
            dist = float(np.linalg.norm(target.point - p0))
            poly_t = one_segment_time(dist, vmax, self.max_acc)
        path = prefix
        if poly_t > ts:
            poly = min_snap(np.array([pe, target.point]), np.array([poly_t]), v0=ve, a0=ae,
                            v1=target.velocity, a1=np.zeros(3), order=3)
            path = np.vstack([prefix, poly.position(np.arange(0.0, poly_t, ts)),
                              target.point])
        else:
            path = np.vstack([prefix, target.point]) if len(prefix) else np.array([p0,
                                                                                   target.point])
        points = _resample(path, CTRL_PT_DIST_M)
        dt = CTRL_PT_DIST_M / vmax * 1.2 if len(points) > 2 else CTRL_PT_DIST_M / vmax * 5
        spline = BSpline.fit(points, dt, v0, target.velocity, a0, np.zeros(3))
        res = self.optimizer.optimize(spline, v0, target.velocity, a0, np.zeros(3))
        if not res.success:
            self._failed(obs, p0, res.status.value, t_start)
            return
        self._succeeded()
        self._adopt(SplineTrajectory(res.spline, 0.0), obs, t_start)

    def _adopt(self, traj: SplineTrajectory | None, obs: Observation, t_start: float) -> None:
        self._adopt_plan(traj, obs, self._compute_time(t_start))

    # --- the replanning loop's hooks ----------------------------------------------------------
    def _replan_due(self, obs: Observation) -> bool:
        """More than ``replan_threshold_m`` from the trajectory's start, the goal farther
        than ``no_replan_threshold_m`` (both measured at the vehicle)."""
        goal_dist = float(np.linalg.norm(self.task.goal - obs.position))
        moved = float(np.linalg.norm(obs.position - self.traj.start))
        return moved > self.replan_threshold and goal_dist > self.no_replan_threshold

    def _collision_ahead(self, t: float) -> float | None:
        """Seconds until the current trajectory's first 2/3 meets an occupied voxel."""
        hit = first_collision_time(self.traj.spline, self.grid)
        if hit is None:
            return None
        return self.traj.t0 + hit - t

    def _emergency(self, obs: Observation, ahead: float) -> None:
        """A collision less than ``emergency_time_s`` ahead: stop (then plan from rest)."""
        if ahead < self.emergency_time:
            self._stop(np.array(obs.position))
