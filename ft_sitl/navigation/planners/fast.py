"""Fast-Planner as a navigator: local map and ESDF from the depth camera, kinodynamic A*,
ESDF-based B-spline optimisation, time re-allocation, yaw B-spline, replanning.

Fast-Planner (Zhou et al., RA-L 2019) in its ``kino_replan`` configuration; behaviours and
defaults from the facts (/work/shared/docs/planner-facts.md), the code is our own. The
navigator's skeleton (perception, FSM, latency, retries, output) is the EGO navigator's
(:mod:`ft_sitl.navigation.planners.ego`), so the two differ only where the algorithms do.

What it does each call (``rate_hz`` 100, the command rate of the original's
``traj_server``), in simulated time:

1. **Perception.** A depth frame (when the camera is due) is fused into the
   :class:`~ft_sitl.navigation.maps.mapping.LocalMap` (unknown space is free; the scenario
   ceiling and the floor are virtual obstacles).
2. **Replanning** (``kino_replan_fsm``):

   * the first plan is made at once, from the observed position at rest (see below);
   * a new plan when the current trajectory, at the present time, is more than
     ``replan_threshold_m`` (1.5 m) from its start, unless it is within
     ``no_replan_threshold_m`` (2 m) of the goal (both measured on the trajectory, as the
     original; the vehicle's own position can lag it), and when it has ended short of the
     goal;
   * a safety check at 20 Hz walks the current trajectory from now, every 0.02 s, until
     6 m (straight-line) from the current point: a sample in a planning-occupied voxel
     (the original's coarse ESDF < 0.1 m; see below) triggers a replan at once. When the
     collision is less than ``emergency_time_s`` (0.8 s) ahead and that replan fails, the
     vehicle stops (hovers where it is, then plans from rest there);
   * a plan (``kinodynamicReplan``): the ESDF over ``+-(planning_horizon_m + 1)`` m around
     the start (clipped to the map's window); the kinodynamic A*
     (:mod:`~ft_sitl.navigation.planners.kino_astar`) from the current trajectory's state toward
     the goal (speed cap: the benchmark's, per axis; ``max_acc_m_s2`` 2; horizon 7 m;
     retried from hover with the full input set when the first search fails); its samples
     every ``ts = 0.5 m / v_max`` (spans of ``max(8, floor(T / ts))``) fitted to a uniform
     cubic B-spline with the start/end velocity and acceleration; the ESDF optimisation
     (:class:`~ft_sitl.navigation.optimisers.fast.FastOptimizer`; free end when the search did
     not reach the goal); the time re-allocation (up to 3 passes, the speed cap on the
     velocity control points' norm, the start state kept); a collision check of the
     result over the safety check's stretch (its first 6 m); the yaw B-spline.

   A plan fails when the search finds no path, or when the result collides within the
   checked stretch and does not improve on the current trajectory (a result colliding
   later than the current trajectory, and not within ``emergency_time_s``, is taken: the
   safety check replans it as the map grows, as the original, which takes every result).
   A failed plan is retried after 0.05 s, doubling with each failure in a row up to 1 s;
   after ``GIVE_UP_AFTER`` (8) failures in a row from the same state with the same map the
   planner gives up ("no plan": the trial ends as a timeout, as it would after 90 s of
   identical failures).

3. **Latency.** A plan is computed from the trajectory's state ``latency_s`` ahead and
   replaces the current trajectory ``latency_s`` later (simulated time); the default is a
   fixed estimate of the original's compute time per replan (:data:`DEFAULT_LATENCY_S`),
   ``measured_latency=True`` uses this process's measured compute time instead.
4. **Output.** Position + velocity + acceleration from the (non-uniform) B-spline; yaw and
   yaw rate from the yaw B-spline (headings toward the trajectory 2 s ahead), continuous
   inside, wrapped to [-pi, pi) in the setpoint. Past the trajectory's end: its end point,
   velocity and acceleration 0.

The first plan starts at rest. The original's first plan uses the odometry velocity;
the trial hands over a vehicle that may still be settling (up to 0.3 m/s). The search's
coarse inputs (the smallest non-zero acceleration is a/2 = 1 m/s^2 for 0.6 s) make a slow
vertical drift cheaper to keep than to cancel, and every later plan inherits it from the
trajectory: a 0.15 m/s sink at hand-over took the vehicle from 1.5 m to 0.6 m over 25 m of
Forest. (The same inheritance keeps a climb over an Urban wall going, as the original's.)

The emergency stop. The original's kinodynamic FSM never stops: a colliding trajectory is
replanned, a failed replan retried from the odometry at 100 Hz. The EGO navigator hovers
when a collision is less than 0.8 s ahead; here that rule fires on nearly every tree on
the path: an obstacle becomes occupied only within the 4.5 m ray length and after 6
frames (0.4 s at 15 Hz), i.e. ~2.9 m ahead, 0.7 s at 4 m/s, and the hover from 4 m/s
overshoots by ~2.5 m into it (Forest 2 collided that way). So the stop is the fallback
when the replan for such a collision fails.

The safety check. The original samples ``evaluateCoarseEDT`` (the ESDF at the voxel that
holds the point, no interpolation) and replans below 0.1 m. Its ESDF is computed from the
inflated occupancy, free voxels hold multiples of the 0.1 m resolution, so "below 0.1 m"
is exactly "the point's voxel is planning-occupied": we ask the map's planning occupancy,
which is always current (the ESDF is recomputed only when a plan is made).

Camera: as the EGO navigator (:func:`~ft_sitl.scenarios.camera.camera_config`): 160 x 120 @
15 Hz by default, ``camera="d435"`` for the originals' 320 x 240 @ 30 Hz rays.
"""

from __future__ import annotations

import math
import time

import numpy as np

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.frames import wrap_pi
from ft_sitl.navigation.base import Observation, Task
from ft_sitl.navigation.maps.esdf import EsdfGrid
from ft_sitl.navigation.optimisers.fast import (
    FastOptimizer,
    FastParams,
    plan_yaw,
)
from ft_sitl.navigation.planners.kino_astar import (
    KinoAstarParams,
    KinodynamicAstar,
    KinoStatus,
    VoxelOccupancy,
)
from ft_sitl.navigation.planners.skeleton import HorizonPlanner, checked_setpoint
from ft_sitl.navigation.trajectories.base import SplineTrajectory
from ft_sitl.navigation.trajectories.bspline import BSpline, Evaluation

#: estimated time from state to command of one Fast-Planner replan in the original C++ on
#: a desktop CPU: kinodynamic search a few ms, B-spline optimisation <= 300 evaluations
#: under a 5 ms cap, time adjustment and yaw < 1 ms (~10 ms), plus the ESDF the plan needs,
#: which the original recomputes over its local box in the map's 20 Hz timer (~10 ms an
#: update); twice EGO's 10 ms, which needs no ESDF
DEFAULT_LATENCY_S = 0.02
#: half width (m) of the ESDF box around a plan's start: the originals' local update range
ESDF_HALF_EXTENT_M = 5.5
#: the original's trajectory check: every 0.02 s of the trajectory up to 6 m ahead
CHECK_STEP_S = 0.02
CHECK_RADIUS_M = 6.0
#: Fast-Planner's control-point spacing (manager/control_points_distance, m)
CTRL_PT_DIST_M = 0.5
#: no plan when the goal is this close to the start state (the original: "Close goal")
CLOSE_GOAL_M = 0.2


def first_collision(pos, tau0: float, occupied, step_s: float = CHECK_STEP_S,
                    radius_m: float = CHECK_RADIUS_M) -> float | None:
    """Fast-Planner's ``checkTrajCollision``: sample the trajectory ``pos`` at ``tau0 +
    step_s k`` (k >= 1, before its end) until a sample is ``radius_m`` or farther from
    ``pos(tau0)`` (that sample included); the time after ``tau0`` of the first sample
    ``occupied`` says is occupied, or None."""
    dur = pos.duration
    if tau0 + step_s >= dur:
        return None
    k = np.arange(1, int(math.floor((dur - tau0) / step_s - 1e-9)) + 1)
    t = tau0 + step_s * k
    t = t[t < dur]
    if t.size == 0:
        return None
    pts = pos.position(t)
    far = np.flatnonzero(np.linalg.norm(pts - pos.position(tau0), axis=1) >= radius_m)
    if far.size:
        t, pts = t[:far[0] + 1], pts[:far[0] + 1]
    hit = np.flatnonzero(np.asarray(occupied(pts), dtype=bool))
    return float(t[hit[0]] - tau0) if hit.size else None


class FastPlanner(HorizonPlanner):
    """Fast-Planner (Zhou et al. 2019): kinodynamic A* + ESDF B-spline optimisation."""

    name = "fast"

    schema = HorizonPlanner.schema.with_defaults(max_acc_m_s2=2.0, planning_horizon_m=7.0,
                                                  latency_s=DEFAULT_LATENCY_S)

    # --- set-up ---------------------------------------------------------------------------
    def reset(self, task: Task) -> None:
        super().reset(task)  # yaw: continuous (unwrapped) here
        self.kino_params = KinoAstarParams(max_vel=self.vmax, max_acc=self.max_acc,
                                           horizon=self.horizon)
        self.optimizer = FastOptimizer(FastParams(max_vel=self.vmax, max_acc=self.max_acc))
        self.emergency = False
        self.stops = 0
        self.plan_log: list[dict] = []

    # --- planning ---------------------------------------------------------------------------
    def _occupied(self, pts: np.ndarray) -> np.ndarray:
        return self.map.occupied_inflated(pts)

    def _plan(self, obs: Observation) -> None:
        t_start = time.perf_counter()
        t_eff = obs.time_s + self.latency
        if self.traj is None or self.from_rest:
            p0 = np.array(obs.position if self.stop_at is None else self.stop_at, dtype=float)
            v0 = np.zeros(3)
            a0 = np.zeros(3)
            yaw0 = np.array([self.yaw, 0.0, 0.0])
        else:
            p0, v0, a0 = self.traj.state(t_eff)
            yaw0 = self.traj.yaw_state(t_eff)
        goal = np.asarray(self.task.goal, dtype=float)
        self.replans += 1
        if float(np.linalg.norm(goal - p0)) < CLOSE_GOAL_M:  # there already: hold it
            self._adopt(None, obs, t_start)
            return
        log: dict = {"t": obs.time_s}
        # perception for this plan: the ESDF box and the search's voxel grid
        t0 = time.perf_counter()
        # the originals' local update box: +-5.5 m around the start, +-4.5 m in height
        esdf = EsdfGrid.from_map(self.map, p0, ESDF_HALF_EXTENT_M)
        res_m = self.map.resolution_m
        grid = VoxelOccupancy(self.map.planning_grid(), self.map.origin_index * res_m, res_m)
        log["map_s"] = time.perf_counter() - t0
        # front end
        t0 = time.perf_counter()
        search = KinodynamicAstar(grid, res_m, bounds=self.bounds, params=self.kino_params)
        found = search.search(p0, v0, a0, goal, np.zeros(3), keep_start_acc=True)
        log["search_s"] = time.perf_counter() - t0
        log["status"] = found.status.value
        if not found.found:
            self._fail(obs, p0, "no path", log, t_start)
            return
        # back end
        t0 = time.perf_counter()
        ts, pts, sv, ev, sa, ea = found.bspline_samples(CTRL_PT_DIST_M / self.vmax)
        spline = BSpline.fit(pts, ts, sv, ev, sa, ea)
        opt = self.optimizer.optimize(spline, esdf,
                                      free_end=found.status is not KinoStatus.REACHED_GOAL)
        # flown evaluated by de Boor, as the original's NonUniformBspline
        pos, passes = opt.spline.with_evaluation(Evaluation.DE_BOOR).retimed(
            self.vmax, self.max_acc, self.optimizer.params.limit_ratio,
            self.optimizer.params.realloc_passes, vel_norm=True)
        log.update(opt_s=time.perf_counter() - t0, evaluations=opt.evaluations,
                   realloc_passes=passes)
        if not np.all(np.isfinite(pos.control_points)):
            self._fail(obs, p0, "non-finite trajectory", log, t_start)
            return
        hit = first_collision(pos, 0.0, self._occupied)
        if hit is not None:
            # a plan colliding within the checked stretch is still taken when it improves
            # on the current trajectory (collides later, and not within emergency_time_s):
            # the safety check replans it as the map grows, as the original's would
            cur = None
            if self.traj is not None and not self.from_rest:
                tau = min(max(t_eff - self.traj.t0, 0.0), self.traj.duration)
                cur = first_collision(self.traj.spline, tau, self._occupied)
            if cur is None or hit <= cur or hit < self.emergency_time:
                self._fail(obs, p0, f"collision {hit:.2f} s ahead", log, t_start)
                return
            log["collides_s"] = hit
        yaw = plan_yaw(pos, yaw0)
        self._succeeded()
        self._adopt(SplineTrajectory(pos, 0.0, yaw), obs, t_start, log)

    def _fail(self, obs: Observation, p0: np.ndarray, why: str, log: dict,
              t_start: float) -> None:
        if self.emergency and self.traj is not None:
            # no way around a collision less than emergency_time_s ahead: hover where it
            # is, then plan from rest there
            self._stop(np.array(obs.position, dtype=float))
            self.stops += 1
        self.emergency = False
        log.update(total_s=time.perf_counter() - t_start, failed=why)
        self.plan_log.append(log)
        self._failed(obs, p0, why, t_start)

    def _adopt(self, traj: SplineTrajectory | None, obs: Observation, t_start: float,
               log: dict | None = None) -> None:
        latency = self._compute_time(t_start)
        if log is not None:
            log["total_s"] = self.compute_s[-1]
            self.plan_log.append(log)
        self.emergency = False
        self._adopt_plan(traj, obs, latency)

    # --- the replanning loop's hooks ----------------------------------------------------------
    def _replan_due(self, obs: Observation) -> bool:
        """The trajectory (the original measures along it, not at the vehicle) more than
        ``replan_threshold_m`` from its start, or ended, and the goal farther than
        ``no_replan_threshold_m`` from it."""
        p_traj = self.traj.state(obs.time_s)[0]
        moved = float(np.linalg.norm(p_traj - self.traj.start))
        to_goal = float(np.linalg.norm(self.task.goal - p_traj))
        return to_goal > self.no_replan_threshold and (
            moved > self.replan_threshold or obs.time_s >= self.traj.end_time)

    def _collision_ahead(self, t: float) -> float | None:
        """Seconds until the current trajectory (checked as the original: 6 m ahead) meets
        a planning-occupied voxel."""
        tr = self.traj
        tau = min(max(t - tr.t0, 0.0), tr.duration)
        return first_collision(tr.spline, tau, self._occupied)

    def _emergency(self, obs: Observation, ahead: float) -> None:
        """A collision less than ``emergency_time_s`` ahead: replan now (whatever the retry
        back-off); stop if that fails (:meth:`_fail`)."""
        if ahead < self.emergency_time:
            self.emergency = True
            self.retry_at = obs.time_s

    def _setpoint(self, obs: Observation) -> Setpoint:
        t = obs.time_s
        if self.traj is None:
            if not math.isfinite(self.yaw):
                raise FloatingPointError(f"non-finite yaw at t = {t:.2f} s")
            return self._hold(obs, wrap_pi(self.yaw))
        p, v, a = self.traj.state(t)
        y = self.traj.yaw_state(t)
        yaw, yaw_rate = float(y[0]), float(y[1])
        if t > self.traj.end_time:
            v = np.zeros(3)
            a = np.zeros(3)
            yaw_rate = 0.0
        sp = checked_setpoint(t, p, v, a, wrap_pi(yaw), yaw_rate)
        self.yaw = yaw
        return sp
