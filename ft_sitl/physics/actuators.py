"""Actuator imperfection: degraded motors, added motor lag, command noise, a motor failure.

What a vehicle's motors do differently from their datasheet, set per vehicle
(:meth:`ft_sitl.sim.lockstep.Simulation.set_actuators`) from settings declared once in
:data:`SCHEMA`:

- **degradation:** every motor's thrust (and with it its drag torque) scaled by
  ``efficiency``, and one motor (``degraded_motor``, 1-based in the platform's layout
  order) by ``degraded_efficiency`` instead: a worn propeller, a weak ESC. Applied to the
  plant's allocation matrix, so the controller, which allocates for the nominal motors,
  does not know;
- **lag:** ``lag_s`` added to the motors' spin-up and spin-down time constants;
- **command noise:** each rotor speed command gets Gaussian noise of ``noise`` x the
  maximum rotor speed (standard deviation), every physics step, while it is armed; the
  noise is counter-based (:func:`ft_sitl.physics.noise.gauss`): a pure function of the
  seed, the step and the motor;
- **failure:** motor ``fail_motor`` (1-based; 0: none) stops ``fail_at_s`` after the
  settings were applied (its command is cut: the rotor spins down with its own lag and
  produces nothing after). The controller keeps allocating for it: the others saturate
  as they try to make up (the row's ``saturation_fraction``), and a quadrotor losing a
  motor tumbles and falls;
- **stuck motor:** motor ``stuck_motor`` (1-based; 0: none) keeps the speed command it
  had ``stuck_at_s`` after the settings were applied, whatever the controller asks
  (PX4's failure injection type "stuck").

Degradation and lag are applied once, to the plant's rows; noise and failure by
:func:`actuator_step_one` in the lockstep kernel between the controller and the plant.
A vehicle without them skips the stage.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ft_sitl.physics import dynamics as d
from ft_sitl.physics.noise import gauss
from ft_sitl.schema import Param, Schema, SchemaError

SCHEMA = Schema((
    Param("efficiency", 1.0, "-", (0.05, 1.0),
          doc="thrust efficiency of every motor (1: as built)"),
    Param("degraded_motor", 0, "-", (0, 16),
          doc="one motor (1-based, layout order) with its own efficiency (0: none)"),
    Param("degraded_efficiency", 1.0, "-", (0.0, 1.0),
          doc="that motor's thrust efficiency"),
    Param("lag_s", 0.0, "s", (0.0, 1.0), doc="added to the motors' time constants"),
    Param("noise", 0.0, "-", (0.0, 0.2),
          doc="rotor speed command noise, standard deviation as a fraction of the maximum"),
    Param("fail_motor", 0, "-", (0, 16), doc="a motor that stops (1-based; 0: none)"),
    Param("fail_at_s", 0.0, "s", (0.0, 3600.0),
          doc="when it stops, after the settings were applied"),
    Param("stuck_motor", 0, "-", (0, 16),
          doc="a motor whose command freezes (1-based; 0: none)"),
    Param("stuck_at_s", 0.0, "s", (0.0, 3600.0),
          doc="when it freezes, after the settings were applied"),
))

(A_ON, A_SEED, A_NOISE, A_WMAX, A_FAIL, A_FAIL_K, A_STUCK, A_STUCK_K, A_STUCK_W) = range(9)
N_ACT = 9


class Actuators:
    """A vehicle's actuator settings (validated by :data:`SCHEMA` and against the
    platform's motor count)."""

    def __init__(self, values: dict | None = None, owner: str = "actuators",
                 n_rotors: int | None = None):
        self.values = SCHEMA.resolve(values, owner)
        self.owner = owner
        v = self.values
        for key in ("degraded_motor", "fail_motor", "stuck_motor"):
            if n_rotors is not None and v[key] > n_rotors:
                raise SchemaError(f"{owner}: {key}: {v[key]} must be within 0..{n_rotors} "
                                  f"(the platform's motors)")

    @property
    def nominal(self) -> bool:
        v = self.values
        return (v["efficiency"] == 1.0 and (v["degraded_motor"] == 0 or
                                           v["degraded_efficiency"] == 1.0)
                and v["lag_s"] == 0.0 and v["noise"] == 0.0 and v["fail_motor"] == 0
                and v["stuck_motor"] == 0)

    def efficiencies(self, n_rotors: int) -> np.ndarray:
        v = self.values
        e = np.full(n_rotors, v["efficiency"])
        if v["degraded_motor"]:
            e[v["degraded_motor"] - 1] = v["degraded_efficiency"]
        return e

    def row(self, dt: float, w_max: float, seed: int, k0: int = 0) -> np.ndarray:
        """The kernel's row: noise and failure (off when neither is set)."""
        if not (isinstance(seed, (int, np.integer)) and 0 <= seed < 2**53):
            raise SchemaError(f"{self.owner}: seed {seed!r} must be an integer in 0..2^53-1")
        v = self.values
        a = np.zeros(N_ACT)
        a[A_SEED] = float(seed)
        a[A_NOISE] = v["noise"]
        a[A_WMAX] = w_max
        a[A_FAIL] = float(v["fail_motor"] - 1)
        a[A_FAIL_K] = float(k0 + round(v["fail_at_s"] / dt))
        a[A_STUCK] = float(v["stuck_motor"] - 1)
        a[A_STUCK_K] = float(k0 + round(v["stuck_at_s"] / dt))
        a[A_STUCK_W] = -1.0  # (the frozen command, once it froze)
        a[A_ON] = 1.0 if (v["noise"] > 0 or v["fail_motor"] or v["stuck_motor"]) else 0.0
        return a


@njit(cache=True)
def actuator_step_one(ad, w_cmd, k):
    """Apply command noise and a failed motor to one vehicle's rotor speed commands at
    physics step ``k`` (counted since the simulation started)."""
    if ad[A_ON] == 0.0:
        return
    sigma = ad[A_NOISE] * ad[A_WMAX]
    if sigma > 0.0:
        seed = np.int64(ad[A_SEED])
        for j in range(w_cmd.shape[0]):
            if w_cmd[j] > 0.0:  # armed (a zero command stops the motor: left alone)
                w_cmd[j] = max(w_cmd[j] + sigma * gauss(seed, k, j), 1e-9)
    stuck = np.int64(ad[A_STUCK])
    if stuck >= 0 and k >= np.int64(ad[A_STUCK_K]):
        if ad[A_STUCK_W] < 0.0:
            ad[A_STUCK_W] = w_cmd[stuck]
        w_cmd[stuck] = ad[A_STUCK_W]
    fail = np.int64(ad[A_FAIL])
    if fail >= 0 and k >= np.int64(ad[A_FAIL_K]):
        w_cmd[fail] = 0.0


def apply_constant(act: Actuators, prm: np.ndarray, alloc: np.ndarray,
                   nominal_prm: np.ndarray, nominal_alloc: np.ndarray) -> None:
    """Write degradation and lag into one vehicle's plant rows, from its nominal rows."""
    e = act.efficiencies(alloc.shape[1])
    alloc[:] = nominal_alloc * e[None, :]
    prm[:] = nominal_prm
    prm[d.P_TAU_UP] += act.values["lag_s"]
    prm[d.P_TAU_DN] += act.values["lag_s"]
