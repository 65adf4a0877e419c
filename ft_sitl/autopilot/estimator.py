"""The estimator stage: what the flight controller believes the state is.

PX4 does not fly on the truth: its controllers read EKF2's estimates, which are noisy,
biased and late. This stage sits between the plant and the cascade (the block
docs/architecture.md draws between them) and makes the estimate imperfect in the ways
that matter for control, per group of states, from settings declared once in
:data:`SCHEMA`:

- **latency:** the estimate of a group is the true value ``<group>_latency_s`` ago
  (rounded to whole physics steps: the delay is exact at the physics rate);
- **bias:** a constant error added to it (position and velocity in the world frame,
  east/north/up; attitude as roll/pitch/yaw; body rates about the body axes);
- **noise:** a first-order Gauss-Markov error with standard deviation
  ``<group>_noise_*`` per component and correlation time ``noise_correlation_s``
  (0: white, a new draw every physics step), counter-based
  (:func:`ft_sitl.physics.noise.gauss`): a pure function of the seed, the step and the
  component, so a trial reruns bit for bit however its steps are batched.

The groups are position, velocity, attitude (roll, pitch and yaw of the estimate are the
true ones, delayed, plus bias and noise) and body rates. Defaults are the truth: a
vehicle without an estimator (or with every setting at its default) skips the stage and
flies exactly as before.

Everything that acts as PX4's modules act on the estimate sees it: the cascade, the
commander (takeoff, landing, hold), the MAVLink telemetry (LOCAL_POSITION_NED, ATTITUDE
and the rest report the estimate, as PX4 reports EKF2's) and the in-process navigator's
state. The truth stays the plant's: collisions, the trial's judges and the scoring use
it, and the MQTT bus publishes it as the ground truth a simulator publishes.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ft_sitl.physics.dynamics import X_OMEGA, X_POS, X_QUAT, X_ROTOR, X_VEL
from ft_sitl.physics.noise import gauss_pair
from ft_sitl.schema import Param, Schema, SchemaError

#: the longest latency a group may have (s): the history every estimating vehicle keeps
MAX_LATENCY_S = 1.0

SCHEMA = Schema((
    Param("position_noise_m", 0.0, "m", (0.0, 10.0),
          doc="position error, standard deviation per axis"),
    Param("position_bias_m", (0.0, 0.0, 0.0), "m", (-100.0, 100.0),
          doc="constant position error (east, north, up)"),
    Param("position_latency_s", 0.0, "s", (0.0, MAX_LATENCY_S),
          doc="age of the position estimate"),
    Param("velocity_noise_m_s", 0.0, "m/s", (0.0, 10.0),
          doc="velocity error, standard deviation per axis"),
    Param("velocity_bias_m_s", (0.0, 0.0, 0.0), "m/s", (-10.0, 10.0),
          doc="constant velocity error (east, north, up)"),
    Param("velocity_latency_s", 0.0, "s", (0.0, MAX_LATENCY_S),
          doc="age of the velocity estimate"),
    Param("attitude_noise_deg", 0.0, "deg", (0.0, 30.0),
          doc="roll, pitch and yaw error, standard deviation each"),
    Param("attitude_bias_deg", (0.0, 0.0, 0.0), "deg", (-45.0, 45.0),
          doc="constant roll, pitch, yaw error"),
    Param("attitude_latency_s", 0.0, "s", (0.0, MAX_LATENCY_S),
          doc="age of the attitude estimate"),
    Param("rate_noise_deg_s", 0.0, "deg/s", (0.0, 200.0),
          doc="body-rate error, standard deviation per axis"),
    Param("rate_bias_deg_s", (0.0, 0.0, 0.0), "deg/s", (-100.0, 100.0),
          doc="constant body-rate error (gyro bias), roll/pitch/yaw axes"),
    Param("rate_latency_s", 0.0, "s", (0.0, MAX_LATENCY_S),
          doc="age of the body-rate estimate"),
    Param("noise_correlation_s", 0.0, "s", (0.0, 100.0),
          doc="correlation time of every noise (first-order Gauss-Markov; 0: white)"),
))

GROUPS = ("position", "velocity", "attitude", "rate")
_NOISE = ("position_noise_m", "velocity_noise_m_s", "attitude_noise_deg", "rate_noise_deg_s")
_BIAS = ("position_bias_m", "velocity_bias_m_s", "attitude_bias_deg", "rate_bias_deg_s")
_ANGULAR = (False, False, True, True)  # settings in degrees, the kernel in radians

# --- the kernel's row ---------------------------------------------------------------------
E_ON, E_SEED, E_A = 0, 1, 2
E_S = 3  # 4 noise drive scales (sigma * sqrt(1 - a^2)): position, velocity, attitude, rate
E_LAT = 7  # 4 latencies, whole physics steps
E_BIAS = 11  # 12 biases
E_N = 23  # 12 noise states
E_ATT = 35  # 1.0 when the attitude differs from the truth (else copied, bit for bit)
N_EST = 36
#: the states a history keeps (the ones the cascade reads)
N_HIST = X_ROTOR


class Estimator:
    """A vehicle's estimator settings (validated by :data:`SCHEMA`)."""

    def __init__(self, values: dict | None = None, owner: str = "estimator"):
        self.values = SCHEMA.resolve(values, owner)
        self.owner = owner

    @property
    def ideal(self) -> bool:
        """True when the estimate is the truth."""
        return self.values == SCHEMA.defaults()

    def latency_steps(self, dt: float) -> list[int]:
        return [round(self.values[f"{g}_latency_s"] / dt) for g in GROUPS]

    def row(self, dt: float, seed: int) -> np.ndarray:
        """The kernel's row (off when ideal), noise states at zero."""
        if not (isinstance(seed, (int, np.integer)) and 0 <= seed < 2**53):
            raise SchemaError(f"{self.owner}: seed {seed!r} must be an integer in 0..2^53-1")
        v = self.values
        e = np.zeros(N_EST)
        tau = v["noise_correlation_s"]
        a = math.exp(-dt / tau) if tau > 0.0 else 0.0
        e[E_SEED] = float(seed)
        e[E_A] = a
        for g, (noise, bias, angular) in enumerate(zip(_NOISE, _BIAS, _ANGULAR)):
            unit = math.radians(1.0) if angular else 1.0
            e[E_S + g] = v[noise] * unit * math.sqrt(1.0 - a * a)
            e[E_BIAS + 3 * g:E_BIAS + 3 * g + 3] = np.asarray(v[bias], dtype=float) * unit
        e[E_LAT:E_LAT + 4] = self.latency_steps(dt)
        e[E_ATT] = 1.0 if (e[E_S + 2] > 0.0 or e[E_LAT + 2] > 0.0
                           or any(v["attitude_bias_deg"])) else 0.0
        e[E_ON] = 0.0 if self.ideal else 1.0
        return e


def history_length(dt: float) -> int:
    """Slots of the ring of past states: the longest latency, plus now."""
    return round(MAX_LATENCY_S / dt) + 1


@njit(cache=True, inline="always")
def _perturbed_attitude(xs, xe, d_roll, d_pitch, d_yaw):
    """xe's attitude: xs's Z-Y-X Euler angles plus the errors. The conversions of
    :mod:`ft_sitl.physics.quaternion` (qto_euler, qfrom_euler) written out in scalars:
    theirs return arrays, an allocation every physics step that tripled this stage's cost
    (bench/bench_stages.py)."""
    w, x, y, z = xs[X_QUAT], xs[X_QUAT + 1], xs[X_QUAT + 2], xs[X_QUAT + 3]
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y)) + d_roll
    pitch = math.asin(min(1.0, max(-1.0, 2.0 * (w * y - z * x)))) + d_pitch
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z)) + d_yaw
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    xe[X_QUAT] = cr * cp * cy + sr * sp * sy
    xe[X_QUAT + 1] = sr * cp * cy - cr * sp * sy
    xe[X_QUAT + 2] = cr * sp * cy + sr * cp * sy
    xe[X_QUAT + 3] = cr * cp * sy - sr * sp * cy


@njit(cache=True)
def estimate_step_one(er, hist, x, xe, k):
    """Write the estimate of one vehicle at physics step ``k`` (counted since the
    simulation started) into ``xe`` from its true state ``x``; ``hist`` (slots x N_HIST)
    is its ring of past true states, ``er`` its row (noise states advanced here)."""
    h = hist.shape[0]
    slot = k % h
    for j in range(N_HIST):
        hist[slot, j] = x[j]
    seed = np.int64(er[E_SEED])
    a = er[E_A]
    for g in range(4):
        s = er[E_S + g]
        if s > 0.0:  # (3 draws: a pair and half of another; component j = 2g, 2g + 1)
            n0, n1 = gauss_pair(seed, k, 2 * g)
            n2, _ = gauss_pair(seed, k, 2 * g + 1)
            m = E_N + 3 * g
            er[m] = a * er[m] + s * n0
            er[m + 1] = a * er[m + 1] + s * n1
            er[m + 2] = a * er[m + 2] + s * n2
    rp = (k - np.int64(er[E_LAT])) % h
    rv = (k - np.int64(er[E_LAT + 1])) % h
    rq = (k - np.int64(er[E_LAT + 2])) % h
    rw = (k - np.int64(er[E_LAT + 3])) % h
    for c in range(3):
        xe[X_POS + c] = hist[rp, X_POS + c] + er[E_BIAS + c] + er[E_N + c]
        xe[X_VEL + c] = hist[rv, X_VEL + c] + er[E_BIAS + 3 + c] + er[E_N + 3 + c]
        xe[X_OMEGA + c] = hist[rw, X_OMEGA + c] + er[E_BIAS + 9 + c] + er[E_N + 9 + c]
    if er[E_ATT] != 0.0:
        _perturbed_attitude(hist[rq], xe, er[E_BIAS + 6] + er[E_N + 6],
                            er[E_BIAS + 7] + er[E_N + 7], er[E_BIAS + 8] + er[E_N + 8])
    else:
        for c in range(4):
            xe[X_QUAT + c] = x[X_QUAT + c]
    for j in range(X_ROTOR, x.shape[0]):
        xe[j] = x[j]
