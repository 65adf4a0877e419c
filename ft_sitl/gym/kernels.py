"""The per-step arithmetic of a batch over its vehicles, compiled: what the judges measure,
the observation's state vector and the shaped reward. One pass each over the vehicles,
so a batch of one does not pay numpy's per-call overhead a dozen times per step."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ft_sitl.physics.dynamics import X_OMEGA, X_POS, X_QUAT, X_VEL
from ft_sitl.physics.quaternion import qrotate, tilt_angle

#: the state vector's length (ft_sitl.gym.batch.STATE_NAMES)
N_STATE = 19


@njit(cache=True)
def measure(x, contact, goal, finite, tilt, ground, dist):
    """Per vehicle (rows of the true states ``x``): all components finite, the tilt (rad,
    as :func:`~ft_sitl.physics.quaternion.tilt_angle`), in ground contact (the plant's
    ``contact`` flags), the distance to its goal (m)."""
    for n in range(x.shape[0]):
        ok = True
        for k in range(x.shape[1]):
            if not math.isfinite(x[n, k]):
                ok = False
                break
        finite[n] = ok
        tilt[n] = tilt_angle(x[n, X_QUAT:X_QUAT + 4])
        ground[n] = contact[n] != 0.0
        dx = x[n, X_POS] - goal[n, 0]
        dy = x[n, X_POS + 1] - goal[n, 1]
        dz = x[n, X_POS + 2] - goal[n, 2]
        dist[n] = math.sqrt(dx * dx + dy * dy + dz * dz)


@njit(cache=True)
def observe_state(xs, goal, frame, floor, ceiling, low, high, out):
    """The state vectors (ft_sitl.gym.batch.STATE_NAMES) of the states ``xs`` (the flight
    controller's estimates) into ``out`` (float32): goal-frame rows ``frame``; a NaN
    component becomes 0, and every component is clipped to [low, high]."""
    ex = np.array([1.0, 0.0, 0.0])
    ez = np.array([0.0, 0.0, 1.0])
    vals = np.empty(N_STATE)
    for n in range(xs.shape[0]):
        x = xs[n]
        f = frame[n]
        rx = goal[n, 0] - x[X_POS]
        ry = goal[n, 1] - x[X_POS + 1]
        rz = goal[n, 2] - x[X_POS + 2]
        s = max(math.sqrt(rx * rx + ry * ry + rz * rz), 1e-6)
        q = x[X_QUAT:X_QUAT + 4]
        bz = qrotate(q, ez)
        bx = qrotate(q, ex)
        for a in range(3):
            vals[a] = (f[a, 0] * rx + f[a, 1] * ry + f[a, 2] * rz) / s
            vals[5 + a] = f[a, 0] * x[X_VEL] + f[a, 1] * x[X_VEL + 1] + f[a, 2] * x[X_VEL + 2]
            vals[8 + a] = f[a, 0] * bz[0] + f[a, 1] * bz[1] + f[a, 2] * bz[2]
            vals[11 + a] = f[a, 0] * bx[0] + f[a, 1] * bx[1] + f[a, 2] * bx[2]
            vals[14 + a] = x[X_OMEGA + a]
        vals[3] = math.sqrt(rx * rx + ry * ry)
        vals[4] = rz
        vals[17] = x[X_POS + 2] - floor
        vals[18] = ceiling - x[X_POS + 2]
        for k in range(N_STATE):
            v = vals[k]
            if math.isnan(v):
                v = 0.0
            out[n, k] = min(max(v, low[k]), high[k])


@njit(cache=True)
def shaped_rewards(actions, last, prev_dist, dist, dt, radius, w_progress, w_distance,
                   w_time, w_in_goal, w_smooth, out):
    """The shaped part of each vehicle's reward (docs/gym.md, "Rewards"): progress,
    distance, time, time in the goal sphere and smoothness; 0 where it is not finite (a
    vehicle whose state is)."""
    m = actions.shape[1]
    for n in range(actions.shape[0]):
        change = 0.0
        for k in range(m):
            c = actions[n, k] - last[n, k]
            change += c * c
        r = (w_progress * (prev_dist[n] - dist[n]) - w_distance * dist[n] * dt
             - w_time * dt - w_smooth * change / m)
        if dist[n] <= radius:
            r += w_in_goal * dt
        out[n] = r if math.isfinite(r) else 0.0
