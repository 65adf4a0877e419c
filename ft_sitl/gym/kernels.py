"""The per-step arithmetic of a batch over its vehicles, compiled: what the judges measure
and the shaped reward (the observation's state vector is
:func:`ft_sitl.navigation.learned.policy_io.observe_state`, shared with the learned navigator).
One pass each over the vehicles, so a batch of one does not pay numpy's per-call
overhead a dozen times per step."""

from __future__ import annotations

import math

from numba import njit

from ft_sitl.physics.dynamics import X_POS, X_QUAT
from ft_sitl.physics.quaternion import tilt_angle


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
