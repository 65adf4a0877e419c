"""What a learned policy sees and what its action means: one definition shared by the
Gymnasium environments that train it (:mod:`ft_sitl.gym`, above the mission runner) and
the navigator that flies it in trials (:mod:`ft_sitl.navigation.learned.learned`, below it).

- the **goal frame** (NavRL's): x the horizontal start -> goal direction, z up, y left;
- the **state vector** (:data:`STATE_NAMES`) of a flight-controller state, compiled
  (:func:`observe_state`, one pass over a batch);
- the **platform vector**: TWR_max, alpha_xy_max, alpha_z_max and the body's half span,
  each log-normalised to a range (the catalog's, :func:`normalise_platform`);
- the **ray scan** layout (:func:`ray_directions`);
- the **policy input** (:func:`policy_input`): those, scaled, in one flat vector;
- a velocity action in the goal frame -> a world velocity (:func:`velocity_action`);
- a small multilayer perceptron evaluated with numpy (:class:`MlpPolicy`): how a trained
  policy is flown without the training stack (PyTorch, Stable-Baselines3).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from numba import njit

from ft_sitl.physics.dynamics import X_OMEGA, X_POS, X_QUAT, X_VEL
from ft_sitl.physics.quaternion import qrotate

#: the state vector's components, in order (docs/gym.md, "Observations")
STATE_NAMES = (
    "goal_dir_x", "goal_dir_y", "goal_dir_z",  # unit vector to the goal, goal frame
    "goal_horizontal_m", "goal_vertical_m",  # horizontal distance, height difference
    "vel_x", "vel_y", "vel_z",  # velocity, goal frame (m/s)
    "body_z_x", "body_z_y", "body_z_z",  # the body's up axis, goal frame
    "body_x_x", "body_x_y", "body_x_z",  # the body's forward axis, goal frame
    "rate_roll", "rate_pitch", "rate_yaw",  # body rates (rad/s, FLU)
    "height_m", "below_ceiling_m",  # above the floor, below the ceiling
)
N_STATE = len(STATE_NAMES)
_UNIT = 1.0
_METRES = 1000.0
_SPEED = 100.0
STATE_HIGH = np.array([_UNIT] * 3 + [_METRES] * 2 + [_SPEED] * 3 + [_UNIT] * 6
                      + [_SPEED] * 3 + [_METRES] * 2, np.float32)
STATE_LOW = -STATE_HIGH

#: the edges vector's components: how far the flight volume's sides are from the vehicle
#: along the goal frame's horizontal axes (m), capped at EDGE_RANGE_M
EDGE_NAMES = ("edge_ahead_m", "edge_left_m", "edge_behind_m", "edge_right_m")
EDGE_RANGE_M = 20.0

#: the platform vector's components: the catalog's indicators and size, each
#: log-normalised to a range (0: its smallest, 1: its largest)
PLATFORM_NAMES = ("twr_max", "alpha_xy_max", "alpha_z_max", "half_span")
PLATFORM_LOW, PLATFORM_HIGH = -1.0, 2.0


def goal_frame(direction) -> np.ndarray:
    """Rows x, y, z of the goal frame (NavRL's): x the horizontal direction, z up."""
    dx, dy = float(direction[0]), float(direction[1])
    n = math.hypot(dx, dy)
    x = np.array([dx / n, dy / n, 0.0]) if n > 1e-9 else np.array([1.0, 0.0, 0.0])
    return np.array([x, [-x[1], x[0], 0.0], [0.0, 0.0, 1.0]])


def ray_directions(columns: int, rows: int, elevation_deg) -> np.ndarray:
    """(columns * rows, 3) unit rays of the scan in the goal frame: column-major, column j
    at ``360 j / columns`` deg counter-clockwise from the goal direction, row k at the
    k-th of ``rows`` elevations evenly spaced over ``elevation_deg`` (lo, hi)."""
    h = np.deg2rad(360.0 / columns) * np.arange(columns)
    lo, hi = elevation_deg
    v = np.deg2rad(np.linspace(lo, hi, rows) if rows > 1 else np.array([(lo + hi) / 2.0]))
    dirs = np.empty((columns, rows, 3))
    dirs[..., 0] = np.cos(h)[:, None] * np.cos(v)[None, :]
    dirs[..., 1] = np.sin(h)[:, None] * np.cos(v)[None, :]
    dirs[..., 2] = np.sin(v)[None, :]
    return dirs.reshape(-1, 3)


def normalise_platform(features, lo, hi) -> np.ndarray:
    """The platform vector of raw features (TWR_max, alpha_xy_max (rad/s^2), alpha_z_max
    (rad/s^2), half span (m)): ``(log f - lo) / (hi - lo)`` per component, ``lo`` and
    ``hi`` the logs of a range's smallest and largest (the catalog's: 0 at its smallest, 1
    at its largest), clipped to [PLATFORM_LOW, PLATFORM_HIGH]."""
    f = np.asarray(features, dtype=float)
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    return np.clip((np.log(f) - lo) / (hi - lo), PLATFORM_LOW, PLATFORM_HIGH)


# a compiled kernel indexes the plant's state layout (X_*) directly: it is the gym's batch
# observation (rows of the batched plant's state), and a named read-out per row would
# leave numba's loop
@njit(cache=True)
def observe_state(xs, goal, frame, floor, ceiling, low, high, out):
    """The state vectors (:data:`STATE_NAMES`) of the states ``xs`` (rows of the
    dynamics' state: the flight controller's estimates) into ``out`` (float32): goal-frame
    rows ``frame``; a NaN component becomes 0, and every component is clipped to
    [low, high]."""
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


def edge_distances(position, frame, bounds_min, bounds_max,
                   cap: float = EDGE_RANGE_M) -> np.ndarray:
    """(N, 4) float32: from each position (N, 3) the distance to the flight volume's side
    (the box ``bounds_min``..``bounds_max``, seen from above) along its goal frame's +x,
    +y, -x and -y (``frame`` (N, 3, 3), rows the goal axes), capped at ``cap``; 0 from a
    position outside."""
    p = np.asarray(position, dtype=float)[:, :2]
    axes = np.asarray(frame, dtype=float)[:, :2, :2]  # goal x and y, horizontal parts
    dirs = np.concatenate([axes, -axes], axis=1)  # (N, 4, 2): +x, +y, -x, -y
    lo = np.asarray(bounds_min, dtype=float)[:2]
    hi = np.asarray(bounds_max, dtype=float)[:2]
    with np.errstate(divide="ignore", invalid="ignore"):
        to_hi = (hi - p)[:, None, :] / dirs
        to_lo = (lo - p)[:, None, :] / dirs
    exit_t = np.where(dirs > 0, to_hi, np.where(dirs < 0, to_lo, np.inf)).min(axis=2)
    inside = np.all((p >= lo) & (p <= hi), axis=1)
    out = np.clip(np.nan_to_num(exit_t, nan=0.0, posinf=cap), 0.0, cap)
    out[~inside] = 0.0
    return out.astype(np.float32)


# --- the policy's input ------------------------------------------------------------------

#: how the policy input scales the state vector: per component (scale, lo, hi), the
#: component divided by the scale and clipped; the horizontal goal distance is squashed
#: (tanh of it over the scale) so that far goals do not swamp the rest
_STATE_SCALE = np.array([1.0] * 3 + [10.0, 2.0] + [4.0] * 3 + [1.0] * 6 + [3.0] * 3
                        + [3.0, 3.0])
_STATE_CLIP = 2.0


#: the edge distances' scale in the policy input (m)
_EDGE_SCALE = 10.0


def policy_input(state, edges, platform, last_action, rays) -> np.ndarray:
    """(N, N_STATE + 4 + 4 + action + rays) float32: what a policy is fed, from batched
    observation parts (the gym's ``state``, ``edges``, ``platform``, ``last_action`` and
    ``rays``): the state scaled (distances in units of 10 m squashed with tanh, the height
    difference over 2 m, velocities over 4 m/s, rates over 3 rad/s, heights over 3 m,
    each clipped to +-2), the edges over 10 m, the rest as they are."""
    s = np.asarray(state, dtype=np.float64) / _STATE_SCALE
    s[:, 3] = np.tanh(s[:, 3])
    s = np.clip(s, -_STATE_CLIP, _STATE_CLIP)
    return np.concatenate([s, np.asarray(edges, dtype=np.float64) / _EDGE_SCALE,
                           np.asarray(platform, dtype=np.float64),
                           np.asarray(last_action, dtype=np.float64),
                           np.asarray(rays, dtype=np.float64)], axis=1).astype(np.float32)


def input_size(rays: int, action: int = 4) -> int:
    """The length of :func:`policy_input`'s rows."""
    return N_STATE + len(EDGE_NAMES) + len(PLATFORM_NAMES) + action + rays


def velocity_action(frame, action, max_speed_m_s: float, max_climb_m_s: float):
    """World velocities (N, 3) of normalised goal-frame velocity actions (N, >= 3): x and
    y times ``max_speed_m_s``, z times ``max_climb_m_s``, rotated by the goal frames
    ``frame`` (N, 3, 3; rows the goal axes, so world = F^T g)."""
    a = np.asarray(action, dtype=float)
    scale = np.array([max_speed_m_s, max_speed_m_s, max_climb_m_s])
    return np.einsum("nji,nj->ni", np.asarray(frame, dtype=float), a[:, :3] * scale)


# --- a trained policy, flown with numpy ----------------------------------------------------

class PolicyFileError(ValueError):
    """A policy file that cannot be read, or is not a policy this version flies."""


#: the policy file's format version (the ``format`` of its metadata)
POLICY_FORMAT = 1
_ACTIVATIONS = {"tanh": np.tanh, "relu": lambda z: np.maximum(z, 0.0)}


class MlpPolicy:
    """A deterministic policy: a multilayer perceptron (weights ``layers``, a list of (W
    (out, in), b (out,)), the activation between layers, none after the last) whose output
    is the action's mean, clipped to [-1, 1]. ``meta`` is the file's metadata: how the
    policy was trained and what its input and output mean (docs/planners.md, "learned").

    Stored as one ``.npz`` (``W0, b0, W1, b1, ...`` and ``meta``, a JSON text): read with
    numpy alone, so a trained policy flies without PyTorch or Stable-Baselines3."""

    def __init__(self, layers, activation: str, meta: dict):
        if activation not in _ACTIVATIONS:
            raise PolicyFileError(f"activation {activation!r} is not one of "
                                  f"{', '.join(_ACTIVATIONS)}")
        if not layers:
            raise PolicyFileError("a policy needs at least one layer")
        self.layers = [(np.asarray(w, dtype=np.float64), np.asarray(b, dtype=np.float64))
                       for w, b in layers]
        for i, (w, b) in enumerate(self.layers):
            if w.ndim != 2 or b.shape != (w.shape[0],):
                raise PolicyFileError(f"layer {i}: weights {w.shape} and bias {b.shape} "
                                      "do not fit")
            if i and w.shape[1] != self.layers[i - 1][0].shape[0]:
                raise PolicyFileError(f"layer {i} takes {w.shape[1]} inputs; layer {i - 1} "
                                      f"gives {self.layers[i - 1][0].shape[0]}")
            if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
                raise PolicyFileError(f"layer {i} has non-finite weights")
        self.activation = activation
        self.meta = dict(meta)

    @property
    def input_size(self) -> int:
        return self.layers[0][0].shape[1]

    @property
    def output_size(self) -> int:
        return self.layers[-1][0].shape[0]

    def act(self, x) -> np.ndarray:
        """Actions (N, output) in [-1, 1] of inputs (N, input)."""
        z = np.asarray(x, dtype=np.float64)
        if z.ndim != 2 or z.shape[1] != self.input_size:
            raise ValueError(f"policy input: shape (N, {self.input_size}) needed, got "
                             f"{z.shape}")
        f = _ACTIVATIONS[self.activation]
        for w, b in self.layers[:-1]:
            z = f(z @ w.T + b)
        w, b = self.layers[-1]
        return np.clip(z @ w.T + b, -1.0, 1.0)

    def save(self, path) -> None:
        arrays = {}
        for i, (w, b) in enumerate(self.layers):
            arrays[f"W{i}"] = w.astype(np.float32)
            arrays[f"b{i}"] = b.astype(np.float32)
        meta = {**self.meta, "format": POLICY_FORMAT, "activation": self.activation}
        np.savez_compressed(path, meta=np.array(json.dumps(meta, sort_keys=True)), **arrays)

    @classmethod
    def load(cls, path) -> MlpPolicy:
        p = Path(path)
        try:
            with np.load(p, allow_pickle=False) as z:
                meta = json.loads(str(z["meta"]))
                n = sum(1 for k in z.files if k.startswith("W"))
                layers = [(z[f"W{i}"], z[f"b{i}"]) for i in range(n)]
        except (OSError, KeyError, ValueError) as exc:
            raise PolicyFileError(f"{p}: not a policy file ({type(exc).__name__}: "
                                  f"{exc})") from None
        if meta.get("format") != POLICY_FORMAT:
            raise PolicyFileError(f"{p}: policy file format {meta.get('format')!r}; this "
                                  f"version reads format {POLICY_FORMAT}")
        try:
            return cls(layers, meta.get("activation", ""), meta)
        except PolicyFileError as exc:
            raise PolicyFileError(f"{p}: {exc}") from None
