"""Wind in the plant: a mean wind, Dryden turbulence and a discrete 1-cosine gust.

The wind is the air's velocity in the world frame (ENU). The plant's rotor drag and body
drag act on the vehicle's velocity relative to the air (:mod:`ft_sitl.physics.dynamics`,
stage 2), so one wind moves a light, draggy platform more than a heavy one. The wind of
each vehicle is advanced by :func:`wind_step_one` inside the lockstep kernel, once per
physics step, before the plant; a vehicle without wind skips it, so its arithmetic (and
every result flown without wind) is unchanged.

**Mean wind.** ``speed_m_s`` blowing from ``from_deg`` (meteorological: the direction it
comes from, clockwise from north; 270 = from the west, blowing east), plus
``vertical_m_s`` (up positive).

**Turbulence: the Dryden model** of MIL-F-8785C for low altitude (below 1,000 ft):

- length scales ``L_w = h`` and ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2`` (h and L in
  feet; h is ``turbulence_altitude_m``, floored at 10 ft, where the formulas stop being
  meaningful);
- intensities ``sigma_w = 0.1 W20`` and ``sigma_u = sigma_v = sigma_w / (0.177 +
  0.000823 h)^0.4``, W20 being the wind speed at 20 ft: the standard's light, moderate
  and severe turbulence have W20 = 15, 30 and 45 kt; ``standard`` takes W20 = the mean
  wind speed; ``turbulence_sigma_m_s`` sets sigma_u (= sigma_v) directly instead, sigma_w
  keeping the standard's ratio;
- spectra (one-sided in rad/s, each integrating to sigma^2), with T = L / V:
  ``Phi_u = sigma_u^2 (2 T / pi) / (1 + (T w)^2)`` and
  ``Phi_v,w = sigma^2 (T / pi) (1 + 3 (T w)^2) / (1 + (T w)^2)^2``;
- u along the mean wind (east when there is none), v across it (horizontal), w vertical;
- the frozen-turbulence speed V at which the field passes the vehicle is the mean wind
  speed, at least :data:`MIN_PASSING_SPEED_M_S` (a hovering vehicle in calm air would
  otherwise see a field that never changes).

Each component is the exact discretisation of a linear filter driven by white noise
(first order for u, second order for v and w), sampled every :data:`TURBULENCE_DT_S`
(10 ms, or every physics step if that is longer) and held in between, so its variance and
spectrum hold whatever the physics rate. The noise is counter-based
(:func:`ft_sitl.physics.noise.gauss`), a pure function of the vehicle's wind seed, the
physics step and the component: a trial's wind does not depend on how its steps are
batched. A mean wind alone costs the kernel nothing (it is written once); turbulence and a
gust are advanced in the kernel (docs/benchmarks.md, "Wind").

**Gust:** a 1-cosine gust of ``gust_m_s`` from ``gust_from_deg`` (plus
``gust_vertical_m_s``), starting ``gust_start_s`` after the wind is set and lasting
``gust_duration_s``: ``(1 - cos(2 pi t / D)) / 2`` of its amplitude, peaking halfway.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit
from scipy.linalg import cholesky, expm, solve_discrete_lyapunov

from ft_sitl.physics import dynamics as d
from ft_sitl.physics.noise import gauss
from ft_sitl.schema import Param, Schema, SchemaError

FT = 0.3048  # m per foot
KNOT = 0.514444  # m/s per knot
#: W20 of the standard's light, moderate and severe turbulence (MIL-F-8785C), m/s
INTENSITY_W20_M_S = {"light": 15 * KNOT, "moderate": 30 * KNOT, "severe": 45 * KNOT}
#: lowest altitude the low-altitude formulas are evaluated at (10 ft)
MIN_ALTITUDE_FT = 10.0
#: lowest speed at which the frozen turbulence field passes the vehicle
MIN_PASSING_SPEED_M_S = 1.0

SCHEMA = Schema((
    Param("speed_m_s", 0.0, "m/s", (0.0, 40.0), doc="mean wind speed (horizontal)"),
    Param("from_deg", 270.0, "deg", (0.0, 360.0),
          doc="direction the mean wind comes from, clockwise from north (270: from the west)"),
    Param("vertical_m_s", 0.0, "m/s", (-10.0, 10.0), doc="mean vertical wind, up positive"),
    Param("turbulence", "none", choices=("none", "light", "moderate", "severe", "standard"),
          doc="Dryden turbulence intensity: MIL-F-8785C's W20 of 15, 30, 45 kt, or "
              "'standard' with W20 = the mean wind speed"),
    Param("turbulence_sigma_m_s", 0.0, "m/s", (0.0, 20.0),
          doc="when > 0: the longitudinal/lateral turbulence RMS directly (overrides the "
              "intensity; vertical keeps the standard's ratio)"),
    Param("turbulence_altitude_m", 2.0, "m", (0.1, 300.0),
          doc="altitude the length scales and intensities are evaluated at (floored at 10 ft)"),
    Param("gust_m_s", 0.0, "m/s", (0.0, 40.0), doc="1-cosine gust amplitude (horizontal)"),
    Param("gust_from_deg", 270.0, "deg", (0.0, 360.0),
          doc="direction the gust comes from, clockwise from north"),
    Param("gust_vertical_m_s", 0.0, "m/s", (-20.0, 20.0), doc="vertical gust amplitude"),
    Param("gust_start_s", 0.0, "s", (0.0, 3600.0), doc="gust start, after the wind is set"),
    Param("gust_duration_s", 2.0, "s", (0.05, 120.0), doc="gust length (peak halfway)"),
))

# --- the kernel's row per vehicle ---------------------------------------------------------
(W_ON, W_SEED, W_MX, W_MY, W_MZ, W_UX, W_UY, W_TURB, W_AU, W_BU) = range(10)
W_PHIV, W_LV, W_CV = 10, 14, 17      # 2x2 transition, lower Cholesky (3), output (2)
W_PHIW, W_LW, W_CW = 19, 23, 26
W_XU, W_XV, W_XW = 28, 29, 31        # filter states (1, 2, 2)
W_GX, W_GY, W_GZ, W_GT0, W_GDUR, W_K0 = 33, 34, 35, 36, 37, 38
W_EVERY, W_TX, W_TY, W_TZ = 39, 40, 41, 42  # turbulence update period (steps), held value
N_WIND = 43
#: the turbulence is sampled this often (s) and held in between: its spectra have fallen
#: by orders of magnitude at the 50 Hz this resolves, and the noise is most of its cost
TURBULENCE_DT_S = 0.01


def _to_vector(speed: float, from_deg: float) -> tuple[float, float]:
    """ENU components of a horizontal wind of ``speed`` coming from ``from_deg``."""
    to = math.radians(from_deg + 180.0)
    return speed * math.sin(to), speed * math.cos(to)


def dryden_scales(altitude_m: float, w20_m_s: float) -> dict:
    """MIL-F-8785C low-altitude length scales (m) and intensities (m/s)."""
    h = max(altitude_m / FT, MIN_ALTITUDE_FT)
    k = 0.177 + 0.000823 * h
    sigma_w = 0.1 * w20_m_s
    return {"L_u": h / k ** 1.2 * FT, "L_v": h / k ** 1.2 * FT, "L_w": h * FT,
            "sigma_u": sigma_w / k ** 0.4, "sigma_v": sigma_w / k ** 0.4, "sigma_w": sigma_w}


def _second_order(sigma: float, T: float, dt: float):
    """Exact discretisation of sigma sqrt(T) (1 + sqrt(3) T s) / (1 + T s)^2 driven by unit
    white noise: transition (2x2), Cholesky factor of the step's noise covariance, output."""
    A = np.array([[0.0, 1.0], [-1.0 / T**2, -2.0 / T]])
    B = np.array([[0.0], [1.0]])
    # Van Loan: the noise covariance accumulated over one step
    M = np.zeros((4, 4))
    M[:2, :2] = -A
    M[:2, 2:] = B @ B.T
    M[2:, 2:] = A.T
    E = expm(M * dt)
    phi = E[2:, 2:].T
    Q = phi @ E[:2, 2:]
    Q = 0.5 * (Q + Q.T)
    L = cholesky(Q + 1e-300 * np.eye(2), lower=True)
    C = np.array([sigma * math.sqrt(T) / T**2, sigma * math.sqrt(3.0 * T) / T])
    return phi, L, C


class Wind:
    """A wind model's settings (validated by :data:`SCHEMA`) and its kernel row."""

    def __init__(self, values: dict | None = None, owner: str = "wind"):
        self.values = SCHEMA.resolve(values, owner)
        self.owner = owner

    @property
    def calm(self) -> bool:
        v = self.values
        return (v["speed_m_s"] == 0 and v["vertical_m_s"] == 0 and v["gust_m_s"] == 0 and
                v["gust_vertical_m_s"] == 0 and self.sigmas()["sigma_u"] == 0)

    def mean(self) -> np.ndarray:
        v = self.values
        e, n = _to_vector(v["speed_m_s"], v["from_deg"])
        return np.array([e, n, v["vertical_m_s"]])

    def passing_speed(self) -> float:
        return max(self.values["speed_m_s"], MIN_PASSING_SPEED_M_S)

    def sigmas(self) -> dict:
        """Length scales and intensities of the turbulence (all 0 without it)."""
        v = self.values
        if v["turbulence_sigma_m_s"] > 0:
            s = dryden_scales(v["turbulence_altitude_m"], 1.0)
            ratio = s["sigma_w"] / s["sigma_u"]
            return {**s, "sigma_u": v["turbulence_sigma_m_s"],
                    "sigma_v": v["turbulence_sigma_m_s"],
                    "sigma_w": v["turbulence_sigma_m_s"] * ratio}
        if v["turbulence"] == "none":
            return {**dryden_scales(v["turbulence_altitude_m"], 0.0)}
        w20 = (v["speed_m_s"] if v["turbulence"] == "standard"
               else INTENSITY_W20_M_S[v["turbulence"]])
        return dryden_scales(v["turbulence_altitude_m"], w20)

    def row(self, dt: float, seed: int, k0: int = 0) -> np.ndarray:
        """The kernel's row for a vehicle whose physics step is ``dt`` s, with noise seed
        ``seed`` (0 <= seed < 2^53), the gust timed from physics step ``k0``. A row with
        neither turbulence nor gust is off (``W_ON`` 0): the mean wind is then constant,
        written into the plant's environment once (:func:`apply_mean`)."""
        if not (isinstance(seed, (int, np.integer)) and 0 <= seed < 2**53):
            raise SchemaError(f"{self.owner}: seed {seed!r} must be an integer in 0..2^53-1")
        w = np.zeros(N_WIND)
        if self.calm:
            return w
        v = self.values
        w[W_SEED] = float(seed)
        w[W_MX:W_MZ + 1] = self.mean()
        every = max(1, round(TURBULENCE_DT_S / dt))
        w[W_EVERY] = float(every)
        dt = every * dt  # the turbulence filters' step
        ux, uy = (_to_vector(1.0, v["from_deg"]) if v["speed_m_s"] > 0 else (1.0, 0.0))
        w[W_UX], w[W_UY] = ux, uy
        s = self.sigmas()
        if s["sigma_u"] > 0:
            V = self.passing_speed()
            w[W_ON] = w[W_TURB] = 1.0
            a = math.exp(-dt * V / s["L_u"])
            w[W_AU] = a
            w[W_BU] = s["sigma_u"] * math.sqrt(-math.expm1(-2.0 * dt * V / s["L_u"]))
            for sig, L, (iphi, il, ic) in ((s["sigma_v"], s["L_v"], (W_PHIV, W_LV, W_CV)),
                                            (s["sigma_w"], s["L_w"], (W_PHIW, W_LW, W_CW))):
                phi, chol, C = _second_order(sig, L / V, dt)
                w[iphi:iphi + 4] = phi.ravel()
                w[il], w[il + 1], w[il + 2] = chol[0, 0], chol[1, 0], chol[1, 1]
                w[ic:ic + 2] = C
            # start each filter in its stationary distribution, from the same noise stream
            w[W_XU] = s["sigma_u"] * gauss(seed, -1, 0)
            for (iphi, il, _ic), ix, j in (((W_PHIV, W_LV, W_CV), W_XV, 1),
                                          ((W_PHIW, W_LW, W_CW), W_XW, 3)):
                P = _stationary(w[iphi:iphi + 4].reshape(2, 2), w[il:il + 3])
                Lp = cholesky(P + 1e-300 * np.eye(2), lower=True)
                n = np.array([gauss(seed, -1, j), gauss(seed, -1, j + 1)])
                w[ix:ix + 2] = Lp @ n
        ge, gn = _to_vector(v["gust_m_s"], v["gust_from_deg"])
        w[W_GX], w[W_GY], w[W_GZ] = ge, gn, v["gust_vertical_m_s"]
        if w[W_GX] or w[W_GY] or w[W_GZ]:
            w[W_ON] = 1.0
        w[W_GT0] = v["gust_start_s"]
        w[W_GDUR] = v["gust_duration_s"]
        w[W_K0] = float(k0)
        return w


def _stationary(phi: np.ndarray, l3: np.ndarray) -> np.ndarray:
    """The stationary covariance of x <- phi x + L n (a discrete Lyapunov equation)."""
    L = np.array([[l3[0], 0.0], [l3[1], l3[2]]])
    return solve_discrete_lyapunov(phi, L @ L.T)


@njit(cache=True)
def wind_step_one(wd, env, k, dt):
    """Advance one vehicle's wind to physics step ``k`` (counted since the simulation
    started) and write it into the plant's environment row: the mean, the turbulence
    (sampled every ``W_EVERY`` steps from the gust's reference step, held in between) and
    the gust."""
    if wd[W_ON] == 0.0:
        return
    j = k - np.int64(wd[W_K0])
    if wd[W_TURB] != 0.0 and j % np.int64(wd[W_EVERY]) == 0:
        seed = np.int64(wd[W_SEED])
        xu = wd[W_AU] * wd[W_XU] + wd[W_BU] * gauss(seed, k, 0)
        wd[W_XU] = xu
        tv = 0.0
        tw = 0.0
        for c in range(2):
            iphi = W_PHIV if c == 0 else W_PHIW
            il = W_LV if c == 0 else W_LW
            ic = W_CV if c == 0 else W_CW
            ix = W_XV if c == 0 else W_XW
            n0 = gauss(seed, k, 1 + 2 * c)
            n1 = gauss(seed, k, 2 + 2 * c)
            x0 = wd[ix]
            x1 = wd[ix + 1]
            y0 = wd[iphi] * x0 + wd[iphi + 1] * x1 + wd[il] * n0
            y1 = wd[iphi + 2] * x0 + wd[iphi + 3] * x1 + wd[il + 1] * n0 + wd[il + 2] * n1
            wd[ix] = y0
            wd[ix + 1] = y1
            if c == 0:
                tv = wd[ic] * y0 + wd[ic + 1] * y1
            else:
                tw = wd[ic] * y0 + wd[ic + 1] * y1
        ux = wd[W_UX]
        uy = wd[W_UY]
        wd[W_TX] = ux * xu - uy * tv
        wd[W_TY] = uy * xu + ux * tv
        wd[W_TZ] = tw
    wx = wd[W_MX] + wd[W_TX]
    wy = wd[W_MY] + wd[W_TY]
    wz = wd[W_MZ] + wd[W_TZ]
    t = j * dt
    t0 = wd[W_GT0]
    dur = wd[W_GDUR]
    if t >= t0 and t <= t0 + dur and dur > 0.0:
        f = 0.5 * (1.0 - math.cos(2.0 * math.pi * (t - t0) / dur))
        wx += wd[W_GX] * f
        wy += wd[W_GY] * f
        wz += wd[W_GZ] * f
    env[d.E_WIND_X] = wx
    env[d.E_WIND_Y] = wy
    env[d.E_WIND_Z] = wz


def apply_mean(wd: np.ndarray, env: np.ndarray) -> None:
    """Write a row's mean wind into the plant's environment row (its value between
    kernel updates, and for good when the row has no turbulence or gust)."""
    env[d.E_WIND_X:d.E_WIND_Z + 1] = wd[W_MX:W_MZ + 1]


@njit(cache=True)
def wind_series(row, n, dt, k0=0):
    """The wind (n, 3) a vehicle with this row feels over physics steps k0 .. k0+n-1 (the
    row's filter states advance; pass a copy to keep it)."""
    env = np.zeros(d.N_ENV)
    env[d.E_WIND_X] = row[W_MX]
    env[d.E_WIND_Y] = row[W_MY]
    env[d.E_WIND_Z] = row[W_MZ]
    out = np.empty((n, 3))
    for k in range(n):
        wind_step_one(row, env, k0 + k, dt)
        out[k, 0] = env[d.E_WIND_X]
        out[k, 1] = env[d.E_WIND_Y]
        out[k, 2] = env[d.E_WIND_Z]
    return out
