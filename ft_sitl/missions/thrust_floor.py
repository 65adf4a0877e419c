"""The campaign key ``thrust_floor``: which ``MPC_THR_MIN`` each trial's flight controller
flies (docs/missions.md, "Thrust floor").

``MPC_THR_MIN`` is the lowest collective thrust the position controller commands in the
air, a fraction of the platform's maximum thrust. Its floor caps the downward
acceleration a vehicle can be commanded to g (1 - MPC_THR_MIN * TWR_max), so PX4's one
default (0.12) on every airframe leaves a TWR-6 vehicle 2.75 m/s^2 where a TWR-3 vehicle
has 6.3 (docs/results/envelope/README.md, "Why TWR 6 fails in Random-Angle Cylinder").
A PX4 user tunes it per airframe; the ``"weight"`` mode does it for every trial with one
rule, :func:`weight_floor`:

* ``"px4"`` (the default): MPC_THR_MIN is whatever the trial's parameters say (PX4's
  0.12 unless the ``params`` axis sets it); nothing is added to any spec.
* ``"weight"``: MPC_THR_MIN = max(0.05, min(0.12, 0.36 / TWR_max)), rounded down to
  PX4's step of 0.01. The floor is then at most 0.36 of the vehicle's weight, so every
  vehicle keeps at least g (1 - 0.36) = 6.3 m/s^2 of downward acceleration: the TWR-3
  vehicle's under PX4's default. At TWR_max <= 3 the rule gives PX4's 0.12, so those
  trials are today's, with the same ids; above 7.2 PX4's lower bound 0.05 holds.

:func:`thrust_min_override` is where a campaign asks the rule: the value that goes into a
trial spec's ``params``, or None when the trial would fly that value anyway.
"""

from __future__ import annotations

import math

from ft_sitl.autopilot.params import PARAMS
from ft_sitl.physics.platform import Platform
from ft_sitl.schema import Param

PX4 = "px4"
WEIGHT = "weight"

#: the share of the vehicle's weight the "weight" mode's floor stays within: PX4's
#: default MPC_THR_MIN (0.12) on a TWR_max-3 vehicle (g (1 - 0.36) = 6.3 m/s^2 downward)
WEIGHT_FRACTION = 0.36

#: MPC_THR_MIN's resolution in PX4 (its metadata: @decimal 2, @increment 0.01); the rule
#: rounds down to it, so the floor never exceeds its share of the weight
DECIMALS = 2

#: the campaign key, declared once
THRUST_FLOOR = Param(
    "thrust_floor", PX4, choices=(PX4, WEIGHT),
    doc="which MPC_THR_MIN each trial flies: 'px4' (the parameters', PX4's 0.12 by "
        "default) or 'weight' (per platform: at most 0.36 of its weight, "
        "max(0.05, min(0.12, 0.36 / TWR_max)))")

_THR_MIN = PARAMS["MPC_THR_MIN"]


def weight_floor(twr_max: float) -> float:
    """The "weight" mode's MPC_THR_MIN for a vehicle of this TWR_max:
    max(PX4's lower bound, min(PX4's default, WEIGHT_FRACTION / twr_max)), rounded down to
    PX4's 0.01. (The rounding takes a millionth of a step of float noise: a TWR_max of
    3.000000000000001 still gets 0.12.)"""
    if not (isinstance(twr_max, (int, float)) and math.isfinite(twr_max) and twr_max > 0):
        raise ValueError(f"twr_max: must be a positive number, got {twr_max!r}")
    share = min(_THR_MIN.default, WEIGHT_FRACTION / twr_max)
    scale = 10**DECIMALS
    return max(_THR_MIN.lo, math.floor(share * scale + 1e-6) / scale)


def thrust_min_override(mode: str, platform: Platform, params: dict | None) -> float | None:
    """The MPC_THR_MIN that ``mode`` adds to a trial of ``platform`` whose PX4 parameters
    are ``params`` (None: the defaults); None when it adds none: in mode "px4", or when the
    rule's value is the one those parameters fly anyway (so the spec, and its id, stay
    what they were)."""
    THRUST_FLOOR.check(mode, "thrust_floor")
    if mode == PX4:
        return None
    value = weight_floor(platform.indicators().twr_max)
    flown = (params or {}).get("MPC_THR_MIN", _THR_MIN.default)
    return None if value == flown else value
