"""Lockstep simulation of a batch of vehicles: the virtual flight controller's cascade and
the plant, stepped together on one integer-microsecond clock.

This is what the in-process mission runner and the MAVLink layer build on: the
controller computes rotor commands from the current state, the plant advances by one
physics step, and nothing else runs in between. A single vehicle is a batch of one.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from ft_sitl.autopilot import cascade as c
from ft_sitl.autopilot.estimator import (
    E_N,
    E_ON,
    N_EST,
    N_HIST,
    Estimator,
    estimate_step_one,
    history_length,
)
from ft_sitl.autopilot.gains import build_gains, mixer
from ft_sitl.autopilot.params import ParamSet
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.physics import dynamics as d
from ft_sitl.physics.actuators import (
    A_ON,
    N_ACT,
    Actuators,
    actuator_step_one,
    apply_constant,
)
from ft_sitl.physics.platform import Platform
from ft_sitl.physics.quaternion import qfrom_euler, qto_euler
from ft_sitl.physics.wind import N_WIND, W_ON, Wind, apply_mean, wind_step_one
from ft_sitl.scenarios.distance_grid import GM_H
from ft_sitl.sim.guard import (
    G_BMODE,
    G_BOUNDS,
    G_BQW,
    G_BQX,
    G_BQY,
    G_BQZ,
    G_BX,
    G_BY,
    G_BZ,
    G_DOT2,
    G_N,
    G_ON,
    G_RR,
    G_TRIP,
    M_N,
    guard_step,
)


@njit(cache=True)
def run_steps(n_steps, dt, x, sp, gn, a, cs, prm, alloc, env, status, w_cmd, rec, rec_every,
              k_done, gd, grid, meta, wind, act, est, hist, xe, k0):
    """Advance every vehicle to step n_steps from step k_done[i]; record the state every
    rec_every steps. A vehicle whose guard row trips (see guard_step) stops after that step
    with its G_TRIP set, for the caller to resolve and resume. ``wind``: each vehicle's
    wind row (ft_sitl.physics.wind), advanced before the plant; ``act``: its actuator row
    (ft_sitl.physics.actuators: command noise, a failed motor), applied to the controller's
    commands; ``est``: its estimator row (ft_sitl.autopilot.estimator), ``hist`` its ring
    of past states and ``xe`` its estimate, which the controller then flies on; ``k0``:
    the simulation's step count when this call started (their clock)."""
    for i in range(x.shape[0]):
        # per-vehicle rows sliced once, not every step
        xi, spi, gni, ai, csi, wi = x[i], sp[i], gn[i], a[i], cs[i], w_cmd[i]
        prmi, alloci, envi, sti, gi = prm[i], alloc[i], env[i], status[i], gd[i]
        wdi = wind[i]
        windy = wdi[W_ON] != 0.0
        adi = act[i]
        imperfect = adi[A_ON] != 0.0
        ei = est[i]
        estimating = ei[E_ON] != 0.0
        hi = hist[i] if estimating else hist[0]
        xei = xe[i]
        guarded = gi[G_ON] > 0.0 or gi[G_BOUNDS] > 0.0
        bx, by, bz, rr = gi[G_BX], gi[G_BY], gi[G_BZ], gi[G_RR]
        body = gi[G_BMODE] > 0.0
        k = k_done[i]
        while k < n_steps:
            px, py, pz = xi[0], xi[1], xi[2]
            if estimating:
                estimate_step_one(ei, hi, xi, xei, k0 + k)
                c.controller_step_one(xei, spi, gni, ai, csi, dt, wi)
            else:
                c.controller_step_one(xi, spi, gni, ai, csi, dt, wi)
            if imperfect:
                actuator_step_one(adi, wi, k0 + k)
            if windy:
                wind_step_one(wdi, envi, k0 + k, dt)
            d.plant_step_one(xi, wi, prmi, alloci, envi, sti, dt)
            k += 1
            if guarded:
                ex, ey, ez = xi[0] - bx, xi[1] - by, xi[2] - bz
                # inside the (convex) free ball: the whole step is, too
                inside = ex * ex + ey * ey + ez * ez < rr
                if inside and body:  # and a body within its rotation budget
                    dot = (gi[G_BQW] * xi[d.X_QUAT] + gi[G_BQX] * xi[d.X_QUAT + 1]
                           + gi[G_BQY] * xi[d.X_QUAT + 2]
                           + gi[G_BQZ] * xi[d.X_QUAT + 3])
                    inside = dot * dot > gi[G_DOT2]
                if not inside:
                    trip = guard_step(gi, grid, meta, px, py, pz, xi[0], xi[1], xi[2], xi)
                    bx, by, bz, rr = gi[G_BX], gi[G_BY], gi[G_BZ], gi[G_RR]
                    body = gi[G_BMODE] > 0.0
                    if trip:
                        break  # (the caller records this step once it is resolved)
            if rec_every > 0 and k % rec_every == 0:
                rec[k // rec_every - 1, i, :] = xi
        k_done[i] = k


@dataclass
class Recording:
    """States sampled during a run: t_s (K,), x (K, N, nx)."""

    t_s: np.ndarray
    x: np.ndarray

    def positions(self, i: int = 0) -> np.ndarray:
        return self.x[:, i, d.X_POS : d.X_POS + 3]

    def eulers(self, i: int = 0) -> np.ndarray:
        return np.array([qto_euler(q) for q in self.x[:, i, d.X_QUAT : d.X_QUAT + 4]])

    def omegas(self, i: int = 0) -> np.ndarray:
        return self.x[:, i, d.X_OMEGA : d.X_OMEGA + 3]


class Simulation:
    """N vehicles (any catalog or user platforms of one rotor count) flown in lockstep."""

    def __init__(
        self,
        platforms: Platform | Sequence[Platform],
        *,
        params: ParamSet | Sequence[ParamSet] | None = None,
        physics_hz: int = 1000,
    ):
        if isinstance(platforms, Platform):
            platforms = [platforms]
        self.platforms = list(platforms)
        if not isinstance(physics_hz, int) or physics_hz <= 0 or 1_000_000 % physics_hz:
            raise ValueError(
                f"physics_hz: {physics_hz!r} must be a positive integer dividing 1,000,000 "
                "(the clock counts whole microseconds)"
            )
        self.dt_us = 1_000_000 // physics_hz
        self.dt = self.dt_us * 1e-6
        n = len(self.platforms)
        if params is None:
            params = ParamSet()
        self.params = [params] * n if isinstance(params, ParamSet) else list(params)
        if len(self.params) != n:
            raise ValueError(f"params: {len(self.params)} parameter sets for {n} vehicles")
        self.plant = d.PlantBatch.from_platforms(self.platforms)
        self.n_rotors = self.platforms[0].n_rotors
        self.mix = np.stack([mixer(p) for p in self.platforms])
        self.sp = np.stack([Setpoint.off().row for _ in range(n)])
        self.ctrl = np.zeros((n, c.N_CTRL))
        self.w_cmd = np.zeros((n, self.n_rotors))
        self.gains = np.zeros((n, c.N_GAINS))
        self.refresh_gains()
        self.time_us = 0
        self.steps = 0
        # collision guard (attach_guard): the kernel reads its rows, grid and meta; without
        # one, these unguarded rows (G_ON = G_BOUNDS = 0)
        self.guard = None
        self._gd = np.zeros((n, G_N))
        self._grid = np.zeros((1, 1, 1), dtype=np.float32)
        self._meta = np.zeros(M_N)
        self._meta[GM_H] = 1.0
        self._k_done = np.zeros(n, dtype=np.int64)
        self.wind = np.zeros((n, N_WIND))  # no wind: the kernel skips the stage
        self.act = np.zeros((n, N_ACT))  # nominal actuators: likewise
        self.actuator_settings: list[dict | None] = [None] * n  # (as last set)
        self.est = np.zeros((n, N_EST))  # the truth as estimate: likewise
        # the estimates and the rings of past states, allocated by the first set_estimator
        self.xe = np.zeros((n, self.plant.x.shape[1]))
        self.est_hist = np.zeros((1, 1, N_HIST))
        self._nominal = (self.plant.prm.copy(), self.plant.alloc.copy())
        self._no_rec = np.empty((0, n, self.x.shape[1]))

    # --- configuration ------------------------------------------------------------
    def refresh_gains(self) -> None:
        """Rebuild gain rows after parameters changed."""
        for i, (p, ps) in enumerate(zip(self.platforms, self.params)):
            self.gains[i] = build_gains(p, ps, self.dt)

    def set_platform(self, i: int, platform: Platform, params: ParamSet | None = None) -> None:
        """Fly vehicle i as ``platform`` (same rotor count as the batch) with ``params``
        (None: its present parameter set) from now on: its plant rows, mixer and gains are
        rebuilt, its actuators nominal again. The other vehicles are untouched. Follow with
        :meth:`place` (and, with a guard attached, give the guard the new body first:
        ``CollisionGuard.set_vehicle``)."""
        if not isinstance(platform, Platform):
            raise TypeError(f"platform: a Platform, got {type(platform).__name__}")
        if platform.n_rotors != self.n_rotors:
            raise ValueError(f"platform {platform.name!r} has {platform.n_rotors} rotors; this "
                             f"batch flies {self.n_rotors}-rotor vehicles")
        params = self.params[i] if params is None else params
        gains = build_gains(platform, params, self.dt)  # refuses a platform it cannot fly
        self.platforms[i] = platform
        self.params[i] = params
        self.gains[i] = gains
        self.plant.prm[i] = d.plant_params(platform)
        self.plant.alloc[i] = platform.allocation()
        self._nominal[0][i] = self.plant.prm[i]
        self._nominal[1][i] = self.plant.alloc[i]
        self.mix[i] = mixer(platform)
        self.act[i] = 0.0
        self.actuator_settings[i] = None

    def attach_guard(self, guard, handler=None) -> None:
        """Check every physics step of every vehicle with ``guard`` (a
        :class:`~ft_sitl.sim.guard.CollisionGuard` with one radius per vehicle);
        ``handler(event)`` is called for each of its events while the simulation steps.
        The one place a guard is wired: :meth:`place` resets its rows from then on."""
        guard.bind(self)
        guard.handler = handler
        self.guard = guard
        self._gd, self._grid, self._meta = guard.rows, guard.grid_data, guard.meta

    @property
    def n(self) -> int:
        return len(self.platforms)

    @property
    def x(self) -> np.ndarray:
        return self.plant.x

    def place(self, i: int, position, yaw: float = 0.0, *, ground_z: float | None = None,
              on_ground: bool = False):
        """Put vehicle i at rest at a position (ENU, m) and heading (rad); ``on_ground``:
        standing on the floor (in ground contact from the first step). An attached guard
        forgets the vehicle's history."""
        x = self.plant.x[i]
        x[:] = 0.0
        x[d.X_POS : d.X_POS + 3] = position
        x[d.X_QUAT : d.X_QUAT + 4] = qfrom_euler(0.0, 0.0, yaw)
        x[d.X_ROTOR :] = 0.0
        if ground_z is not None:
            self.plant.env[i, d.E_GROUND_Z] = ground_z
        self.ctrl[i] = 0.0
        self.plant.status[i] = 0.0
        if on_ground:
            self.plant.status[i, d.S_CONTACT] = 1.0
        if self.guard is not None:
            self.guard.reset(i)
        if self.est[i, E_ON]:  # the estimator forgets, too
            self._reset_estimate(i)

    def start_hovering(self, i: int, position, yaw: float = 0.0) -> None:
        """Put vehicle i in the air at hover (rotors at hover speed) holding position."""
        self.place(i, position, yaw)
        self.plant.x[i, d.X_ROTOR :] = self.platforms[i].hover_rotor_speed_rad_s
        self.set_setpoint(i, Setpoint.position(position, yaw=yaw))

    def set_wind(self, i: int, wind: Wind | dict | None, seed: int = 0) -> None:
        """Fly vehicle i in ``wind`` (a :class:`~ft_sitl.physics.wind.Wind`, its settings
        as a dict, or None for calm air) from now on; ``seed`` seeds its turbulence. The
        gust is timed from now."""
        if wind is None:
            self.wind[i] = 0.0
            self.plant.env[i, d.E_WIND_X:d.E_WIND_Z + 1] = 0.0
            return
        if not isinstance(wind, Wind):
            wind = Wind(wind)
        self.wind[i] = wind.row(self.dt, seed, self.steps)
        apply_mean(self.wind[i], self.plant.env[i])

    def set_actuators(self, i: int, actuators: Actuators | dict | None,
                      seed: int = 0) -> None:
        """Give vehicle i imperfect actuators (an :class:`~ft_sitl.physics.actuators.
        Actuators`, its settings as a dict, or None for nominal ones) from now on; ``seed``
        seeds the command noise; a failure is timed from now."""
        n_rot = self.platforms[i].n_rotors
        if actuators is None:
            actuators = Actuators(n_rotors=n_rot)
        elif not isinstance(actuators, Actuators):
            actuators = Actuators(actuators, n_rotors=n_rot)
        apply_constant(actuators, self.plant.prm[i], self.plant.alloc[i],
                       self._nominal[0][i], self._nominal[1][i])
        self.actuator_settings[i] = dict(actuators.values)
        self.act[i] = actuators.row(self.dt, self.platforms[i].rotor_speed_max_rad_s, seed,
                                    self.steps)

    def set_estimator(self, i: int, estimator: Estimator | dict | None,
                      seed: int = 0) -> None:
        """Fly vehicle i's controller on an imperfect estimate of its state (an
        :class:`~ft_sitl.autopilot.estimator.Estimator`, its settings as a dict, or None for
        the truth) from now on; ``seed`` seeds the noise. The estimate starts from the
        vehicle holding its present state for the longest latency."""
        if estimator is None:
            estimator = Estimator()
        elif not isinstance(estimator, Estimator):
            estimator = Estimator(estimator)
        self.est[i] = estimator.row(self.dt, seed)
        if not self.est[i, E_ON]:
            return
        if self.est_hist.shape[1] == 1:  # the first estimating vehicle: the rings
            self.est_hist = np.zeros((self.n, history_length(self.dt), N_HIST))
        self._reset_estimate(i)

    def _reset_estimate(self, i: int) -> None:
        """A ring full of the present state, no noise yet: the estimate now (with its
        biases, as read-outs before the next step see it)."""
        self.est_hist[i, :, :] = self.plant.x[i, :N_HIST]
        self.est[i, E_N:E_N + 12] = 0.0
        estimate_step_one(self.est[i], self.est_hist[i], self.plant.x[i], self.xe[i],
                          self.steps)
        self.est[i, E_N:E_N + 12] = 0.0  # (the step's own draw comes when it is flown)

    def estimating(self, i: int = 0) -> bool:
        """True when vehicle i's controller flies on an imperfect estimate."""
        return bool(self.est[i, E_ON])

    def estimated(self, i: int = 0) -> np.ndarray:
        """Vehicle i's state as its flight controller last estimated it (a view: the
        true state itself without an estimator)."""
        return self.xe[i] if self.est[i, E_ON] else self.plant.x[i]

    def wind_velocity(self, i: int = 0) -> np.ndarray:
        """The air's velocity at vehicle i in the last physics step (ENU, m/s)."""
        return self.plant.env[i, d.E_WIND_X:d.E_WIND_Z + 1].copy()

    def set_setpoint(self, i: int, sp: Setpoint) -> None:
        self.sp[i] = sp.row

    # --- running -----------------------------------------------------------------
    def step(self, n_steps: int = 1, record_every: int = 0) -> np.ndarray | None:
        if n_steps < 0:
            raise ValueError("n_steps must be >= 0")
        if record_every:
            rec = np.empty((n_steps // record_every, self.n, self.x.shape[1]))
        else:  # nothing recorded: one empty array for every call
            rec = self._no_rec
        k_done = self._k_done
        k_done[:] = 0
        # moving obstacles: advance in chunks within which no vehicle can reach one, and
        # check them after each (CollisionGuard.mover_horizon / check_movers)
        movers = self.guard is not None and self.guard.movers is not None
        target = min(n_steps, self.guard.mover_horizon(self, self.time_us)) if movers \
            else n_steps
        while True:
            run_steps(
                target, self.dt, self.plant.x, self.sp, self.gains, self.mix, self.ctrl,
                self.plant.prm, self.plant.alloc, self.plant.env, self.plant.status,
                self.w_cmd, rec, record_every, k_done, self._gd, self._grid, self._meta,
                self.wind, self.act, self.est, self.est_hist, self.xe, self.steps,
            )
            trip = self._gd[:, G_TRIP]
            if trip.any():
                tripped = np.flatnonzero(trip != 0.0)
                for i in tripped:  # the guard resolves each stopped vehicle, then all resume
                    k = int(k_done[i])
                    self.guard.resolve(self, int(i), self.time_us + k * self.dt_us)
                    if record_every and k % record_every == 0:
                        rec[k // record_every - 1, i, :] = self.plant.x[i]
                continue
            if not movers:
                break
            t_us = self.time_us + target * self.dt_us
            self.guard.check_movers(self, t_us)
            if target == n_steps:
                break
            target = min(n_steps, target + self.guard.mover_horizon(self, t_us))
        self.time_us += n_steps * self.dt_us
        self.steps += n_steps
        return rec if record_every else None

    def run(self, duration_s: float, record_hz: float = 0.0) -> Recording | None:
        """Run for duration_s of simulated time, optionally sampling the state."""
        n_steps = round(duration_s / self.dt)
        every = round(1.0 / (record_hz * self.dt)) if record_hz > 0 else 0
        t0 = self.time_us * 1e-6
        rec = self.step(n_steps, every)
        if rec is None:
            return None
        t = t0 + self.dt * every * np.arange(1, rec.shape[0] + 1)
        return Recording(t, rec)

    # --- read-outs ----------------------------------------------------------------
    def position(self, i: int = 0) -> np.ndarray:
        return self.plant.x[i, d.X_POS : d.X_POS + 3].copy()

    def velocity(self, i: int = 0) -> np.ndarray:
        return self.plant.x[i, d.X_VEL : d.X_VEL + 3].copy()

    def attitude(self, i: int = 0) -> np.ndarray:
        return self.plant.x[i, d.X_QUAT : d.X_QUAT + 4].copy()

    def body_rates(self, i: int = 0) -> np.ndarray:
        """Angular velocity, body FLU (rad/s)."""
        return self.plant.x[i, d.X_OMEGA : d.X_OMEGA + 3].copy()

    def euler(self, i: int = 0) -> np.ndarray:
        return qto_euler(self.attitude(i))

    def rotor_speeds(self, i: int = 0) -> np.ndarray:
        return self.plant.x[i, d.X_ROTOR :].copy()

    def saturation_fraction(self, i: int = 0) -> float:
        """Fraction of controller steps so far in which any rotor sat at a limit."""
        return float(self.ctrl[i, c.C_SAT_STEPS] / self.steps) if self.steps else 0.0

    def on_ground(self, i: int = 0) -> bool:
        return bool(self.plant.status[i, d.S_CONTACT])

    def max_impact_speed(self, i: int = 0) -> float:
        return float(self.plant.status[i, d.S_IMPACT_MAX])

    def hard_impact(self, i: int = 0) -> bool:
        """True once vehicle i has hit the ground faster than HARD_IMPACT_SPEED_M_S."""
        return self.max_impact_speed(i) > d.HARD_IMPACT_SPEED_M_S

    def energy_j(self, i: int = 0) -> float:
        return float(self.plant.status[i, d.S_ENERGY])
