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
   * a collision check of the trajectory ahead against the map at 20 Hz, every 0.01 s of
     it from now to 2/3 of its duration, or to its end once past 2/3. A collision is
     replanned from the current trajectory at once, whatever the back-off (the
     original's "make a chance"); only when that plan fails and the collision is
     less than ``emergency_time_s`` (1.0 s, the original's ``fsm/emergency_time_``)
     ahead is it an emergency stop: hover where the vehicle is, and once it is slower than
     :data:`STILL_M_S` plan anew from its position and velocity (the original's
     EMERGENCY_STOP state, ego_replan_fsm.cpp);
   * a plan: the local target ``planning_horizon_m`` (7.5 m) ahead on the reference (at
     rest when the goal is that close), a one-segment polynomial to it from the current
     trajectory's state, fitted to a uniform cubic B-spline, optimised by
     :class:`~ft_sitl.navigation.optimisers.ego.EgoOptimizer` (rebound + refinement).
     A plan from the trajectory tries three initial paths in turn, as the original's
     planFromCurrentTraj: the rest of the trajectory and a polynomial, a polynomial from
     the state, a minimum-snap path through a random point beside the midpoint (the
     task's random stream). A plan from rest tries a polynomial, and on every retry a
     random path.

   ``replan_rule = "single"`` is the rule of protocols 1-10: the check covers the first
   2/3 of the trajectory from its start (what has been flown included, never its last
   third), one initial path (the rest of the trajectory and a polynomial, or a polynomial
   from rest), and a collision less than ``emergency_time_s`` (0.8 s then) ahead stops at
   once and plans from rest at the stop point in the same step.

   A plan from the trajectory that fails is tried again at the next call (100 Hz, the
   original's REPLAN_TRAJ) while the vehicle flies on. A plan from rest that fails is
   retried after 0.05 s, doubling with each failure in a row up to 1 s; after
   ``GIVE_UP_AFTER`` (8) failures in a row from the same state with the same map the
   planner gives up ("no plan": the trial ends as a timeout). Both are ours: the original
   retries at 100 Hz until the time limit, each retry from rest with a new random path. (Up
   to protocol 10, ``single``, every failure backs off, and the give-up stood for 90 s of
   identical failures of a deterministic optimiser.)

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
from ft_sitl.schema import Param

#: estimated compute time of one EGO replan in the original C++ (optimisation ~1 ms, plus
#: A* and map work; the paper's authors report a few ms on a desktop CPU)
DEFAULT_LATENCY_S = 0.01
#: EGO's control-point spacing of the initial path (m)
CTRL_PT_DIST_M = 0.4
#: after an emergency stop, the original plans again once the vehicle is slower than this
#: (m/s; ego_replan_fsm.cpp, EMERGENCY_STOP: ``odom_vel_.norm() < 0.1``)
STILL_M_S = 0.1
#: the original's safety check samples the trajectory ahead this often (s; time_step)
CHECK_STEP_S = 0.01


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

    schema = HorizonPlanner.schema.extend(
        Param("replan_rule", "original", choices=("original", "single"),
              doc="original: a plan tries the rest of the trajectory, then a polynomial, "
                  "then a random one; a collision is replanned before any stop, which waits "
                  "for standstill (ego_replan_fsm.cpp); single (protocols 1-10): one try, "
                  "and a collision less than emergency_time_s ahead stops at once"),
    ).with_defaults(max_acc_m_s2=3.0, planning_horizon_m=7.5, latency_s=DEFAULT_LATENCY_S,
                    emergency_time_s=1.0)

    def __init__(self, **params):
        super().__init__(**params)
        self.original = self.settings["replan_rule"] == "original"

    # --- set-up ---------------------------------------------------------------------------
    def reset(self, task: Task) -> None:
        super().reset(task)
        self.grid = OccupancyView.from_map(self.map, bounds=self.bounds)
        self.optimizer = EgoOptimizer(self.grid, EgoParams(max_vel=self.vmax,
                                                           max_acc=self.max_acc))
        self.reference = global_reference(task.start, task.goal, self.vmax)
        self.progress_t = 0.0
        self.emergency = False  # the pending replan answers a collision within emergency_time_s
        self.await_still = False  # stopped: the next plan waits until the vehicle is still
        self.failed_inits = 0  # initial paths whose optimisation failed, in a row
        self.rest_tries = 0  # plans from rest since the last success or stop

    # --- planning ---------------------------------------------------------------------------
    def _plan(self, obs: Observation) -> None:
        if self.await_still:
            if float(np.linalg.norm(obs.velocity)) >= STILL_M_S:
                return  # (hovering at the stop point; the plan stays asked for)
            self.await_still = False
            self.stop_at = None  # plan from the vehicle's own state, as the original
            self.rest_tries = 0
        t_start = time.perf_counter()
        t_eff = obs.time_s + self.latency
        vmax = self.vmax
        flying = not (self.traj is None or self.from_rest)
        if flying:
            p0, v0, a0 = self.traj.state(t_eff)
        else:
            p0 = np.array(obs.position if self.stop_at is None else self.stop_at)
            v0 = np.zeros(3) if self.stop_at is not None else np.array(obs.velocity)
            a0 = np.zeros(3)
        target = self.reference.local_target(p0, self.progress_t, self.horizon, vmax,
                                             self.max_acc)
        self.progress_t = target.progress_time_s
        self.replans += 1
        if float(np.linalg.norm(target.point - p0)) < 0.1:  # there already: hold it
            self._adopt(None, obs, t_start)
            return
        if not self.original:
            inits = ("previous",) if flying else ("polynomial",)
        elif flying:  # planFromCurrentTraj: three initial paths, in turn
            inits = ("previous", "polynomial", "random")
        else:  # GEN_NEW_TRAJ: a polynomial first, then a random one on every retry
            inits = ("random",) if self.rest_tries else ("polynomial",)
            self.rest_tries += 1
        for init in inits:
            points = _resample(self._initial_path(init, p0, v0, a0, t_eff, target),
                               CTRL_PT_DIST_M)
            dt = CTRL_PT_DIST_M / vmax * (1.2 if len(points) > 2 else 5.0)
            spline = BSpline.fit(points, dt, v0, target.velocity, a0, np.zeros(3))
            res = self.optimizer.optimize(spline, v0, target.velocity, a0, np.zeros(3))
            if res.success:
                break
            self.failed_inits += 1
        if not res.success:
            if self.emergency and self.traj is not None:
                # no way around a collision less than emergency_time_s ahead: hover where
                # the vehicle is, then plan once it is still
                self._stop(np.array(obs.position, dtype=float))
                self.await_still = True
            self.emergency = False
            self._failed(obs, p0, res.status.value, t_start)
            return
        self.failed_inits = self.rest_tries = 0
        self._succeeded()
        self._adopt(SplineTrajectory(res.spline, 0.0), obs, t_start)

    def _initial_path(self, init: str, p0, v0, a0, t_eff: float, target) -> np.ndarray:
        """The initial path of a plan from the state ``p0, v0, a0`` to the local target,
        sampled every ``ts`` (EGO's reboundReplan, STEP 1): ``previous``, the rest of the
        current trajectory and a polynomial from its end (a polynomial alone when nothing
        of it is left); ``polynomial``, one polynomial from the state; ``random``, a
        minimum-snap path through a random point beside the midpoint, farther out the more
        initial paths have failed in a row (the original's ``flag_randomPolyTraj``)."""
        vmax = self.vmax
        ts = CTRL_PT_DIST_M / vmax * 1.5  # EGO's sampling step of the initial path
        prefix = np.zeros((0, 3))
        if init == "previous":
            tau = np.arange(t_eff - self.traj.t0, self.traj.spline.duration, ts)
            if len(tau):
                prefix = self.traj.spline.position(tau)
        dist = float(np.linalg.norm(target.point - p0))
        if init == "random":
            poly_t = one_segment_time(dist, vmax, self.max_acc)
            mid = self._random_point(p0, target.point)
            poly = min_snap(np.array([p0, mid, target.point]),
                            np.array([poly_t / 2, poly_t / 2]), v0=v0, a0=a0,
                            v1=target.velocity, a1=np.zeros(3), order=4)
            return np.vstack([poly.position(np.arange(0.0, poly_t, ts)), target.point])
        if len(prefix):
            pe, ve, ae = self.traj.state(self.traj.end_time)
            poly_t = float(np.linalg.norm(target.point - pe)) / vmax * 2.0
        else:
            pe, ve, ae = p0, v0, a0
            poly_t = one_segment_time(dist, vmax, self.max_acc)
        if poly_t > ts:
            poly = min_snap(np.array([pe, target.point]), np.array([poly_t]), v0=ve, a0=ae,
                            v1=target.velocity, a1=np.zeros(3), order=3)
            return np.vstack([prefix, poly.position(np.arange(0.0, poly_t, ts)),
                              target.point])
        return np.vstack([prefix, target.point]) if len(prefix) else np.array([p0,
                                                                               target.point])

    def _random_point(self, p0: np.ndarray, p1: np.ndarray) -> np.ndarray:
        """The original's random inserted point: the midpoint of ``p0 p1`` moved by
        U(-0.5, 0.5) x 0.8 x the distance sideways and U(-0.5, 0.5) x 0.4 x the distance
        across (perpendicular to the line and to the sideways direction), both scaled by
        ``0.989 - 0.978 / (n + 0.989)`` for n initial paths failed in a row (drawn from the
        task's random stream)."""
        d = p0 - p1
        dist = float(np.linalg.norm(d))
        side = np.cross(d, [0.0, 0.0, 1.0])
        side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-9 else \
            np.array([1.0, 0.0, 0.0])
        up = np.cross(d, side)
        up = up / np.linalg.norm(up) if np.linalg.norm(up) > 1e-9 else np.array([0.0, 0.0,
                                                                                  1.0])
        scale = 0.989 - 0.978 / (self.failed_inits + 0.989)
        u = self.task.rng.random(2) - 0.5
        return (p0 + p1) / 2 + u[0] * dist * side * 0.8 * scale + u[1] * dist * up * 0.4 * scale

    def _failed(self, obs: Observation, p0: np.ndarray, why: str, t_start: float) -> None:
        """original, flying a trajectory: try again at the next call, as the original's
        REPLAN_TRAJ state does at its 100 Hz FSM rate, while the vehicle flies on (the
        safety check stops it when the trajectory ahead collides); no back-off and no giving
        up, since the start moves. Otherwise (and holding: GEN_NEW_TRAJ) the skeleton's
        back-off and giving up, ours rather than the original's endless retries."""
        if not (self.original and self.traj is not None and not self.from_rest):
            super()._failed(obs, p0, why, t_start)
            return
        self.failures += 1
        self.fail_sig, self.same_failures = None, 0
        self._compute_time(t_start)
        self.plan_now = True
        self.retry_at = obs.time_s

    def _adopt(self, traj: SplineTrajectory | None, obs: Observation, t_start: float) -> None:
        self.emergency = False
        self._adopt_plan(traj, obs, self._compute_time(t_start))

    # --- the replanning loop's hooks ----------------------------------------------------------
    def _replan_due(self, obs: Observation) -> bool:
        """More than ``replan_threshold_m`` from the trajectory's start, the goal farther
        than ``no_replan_threshold_m`` (both measured at the vehicle)."""
        goal_dist = float(np.linalg.norm(self.task.goal - obs.position))
        moved = float(np.linalg.norm(obs.position - self.traj.start))
        return moved > self.replan_threshold and goal_dist > self.no_replan_threshold

    def _collision_ahead(self, t: float) -> float | None:
        """Seconds until the trajectory ahead meets an occupied voxel. original: from now,
        every :data:`CHECK_STEP_S`, to 2/3 of its duration while short of it, else to its
        end (checkCollisionCallback). single: its first 2/3 from its start, flown or not."""
        spline = self.traj.spline
        if not self.original:
            hit = first_collision_time(spline, self.grid)
            return None if hit is None else self.traj.t0 + hit - t
        now = t - self.traj.t0
        two_thirds = spline.duration * 2.0 / 3.0
        end = two_thirds if now < two_thirds else spline.duration
        tau = np.arange(max(now, 0.0), end, CHECK_STEP_S)
        if not len(tau):
            return None
        hit = np.flatnonzero(self.grid.is_occupied(spline.position(tau)))
        return float(tau[hit[0]] - now) if hit.size else None

    def _emergency(self, obs: Observation, ahead: float) -> None:
        """A collision ``ahead`` s on the trajectory (a plan is asked for). original: plan
        now, whatever the back-off; a failure then stops when ``ahead`` is less than
        ``emergency_time_s`` (:meth:`_plan`). single: less than ``emergency_time_s`` ahead,
        stop at once (then plan from rest)."""
        if self.original:
            self.emergency = ahead < self.emergency_time
            self.retry_at = obs.time_s
        elif ahead < self.emergency_time:
            self._stop(np.array(obs.position))
