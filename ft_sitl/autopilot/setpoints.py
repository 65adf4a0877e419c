"""Offboard setpoints in the forms PX4 accepts, validated before they reach the cascade.

Every constructor takes world ENU / body FLU values in SI units (the MAVLink layer
converts from NED/FRD in :mod:`ft_sitl.frames`). A value that is required and not finite
raises :class:`SetpointError`; the caller keeps flying its last valid setpoint.
Optional feed-forward terms left out (None) are "not controlled", PX4's NaN.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ft_sitl.autopilot import cascade as c


class SetpointError(ValueError):
    """A setpoint with a missing, non-finite or out-of-range value."""


def _vec(name: str, v, *, required: bool, allow_nan: bool = False) -> np.ndarray:
    if v is None:
        if required:
            raise SetpointError(f"{name}: required")
        return np.full(3, np.nan)
    try:
        arr = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise SetpointError(f"{name}: {v!r} is not a 3-vector of numbers") from None
    if arr.shape != (3,):
        raise SetpointError(f"{name}: needs 3 components, got {arr.size}")
    bad = np.isinf(arr) | (np.isnan(arr) if not allow_nan else np.zeros(3, bool))
    if bad.any():
        raise SetpointError(f"{name}: {arr.tolist()} has non-finite component(s)")
    if required and np.isnan(arr).all():
        raise SetpointError(f"{name}: all components are NaN")
    return arr


def _scalar(name: str, v, *, lo: float = -math.inf, hi: float = math.inf) -> float:
    if v is None:
        return math.nan
    if isinstance(v, bool):
        raise SetpointError(f"{name}: {v!r} is not a number")
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise SetpointError(f"{name}: {v!r} is not a number") from None
    if not math.isfinite(f):
        raise SetpointError(f"{name}: {f} is not finite")
    if not lo <= f <= hi:
        raise SetpointError(f"{name}: {f} is outside [{lo}, {hi}]")
    return f


@dataclass(frozen=True)
class Setpoint:
    """A packed, validated setpoint row for the cascade (see cascade.SP_*)."""

    row: np.ndarray

    @property
    def kind(self) -> int:
        return int(self.row[c.SP_KIND])

    @property
    def is_offboard(self) -> bool:
        """Whether the setpoint came from outside the flight controller (see
        :meth:`offboard`)."""
        return bool(self.row[c.SP_OFFBOARD] == 1.0)

    def offboard(self) -> Setpoint:
        """This setpoint marked as coming from outside (an offboard client): the cascade
        then bounds its acceleration only by the tilt and thrust limits, as PX4 does,
        not by MPC_ACC_* (which shape the flight controller's own trajectories)."""
        row = self.row.copy()
        row[c.SP_OFFBOARD] = 1.0
        return Setpoint(row)

    # --- constructors --------------------------------------------------------------
    @staticmethod
    def _base(kind: int) -> np.ndarray:
        row = np.full(c.N_SP, np.nan)
        row[c.SP_KIND] = kind
        return row

    @classmethod
    def off(cls) -> Setpoint:
        """Motors stopped (disarmed)."""
        return cls(cls._base(c.KIND_OFF))

    @classmethod
    def idle(cls) -> Setpoint:
        """Armed on the ground: rotors at idle speed."""
        return cls(cls._base(c.KIND_IDLE))

    @classmethod
    def trajectory(cls, position=None, velocity=None, acceleration=None, yaw=None,
                   yaw_rate=None) -> Setpoint:
        """PX4 trajectory setpoint: per axis, position wins, then velocity, then acceleration.

        Components may be NaN individually (that axis not controlled at that level), as
        in PX4's trajectory_setpoint; at least one of the three must control each axis.
        """
        row = cls._base(c.KIND_TRAJECTORY)
        pos = _vec("position", position, required=False, allow_nan=True)
        vel = _vec("velocity", velocity, required=False, allow_nan=True)
        acc = _vec("acceleration", acceleration, required=False, allow_nan=True)
        uncontrolled = np.isnan(pos) & np.isnan(vel) & np.isnan(acc)
        if uncontrolled.any():
            axes = ", ".join("xyz"[i] for i in np.flatnonzero(uncontrolled))
            raise SetpointError(f"trajectory: axis {axes} has no position, velocity or "
                                "acceleration setpoint")
        row[c.SP_POS : c.SP_POS + 3] = pos
        row[c.SP_VEL : c.SP_VEL + 3] = vel
        row[c.SP_ACC : c.SP_ACC + 3] = acc
        row[c.SP_YAW] = _scalar("yaw", yaw)
        row[c.SP_YAWRATE] = _scalar("yaw_rate", yaw_rate)
        return cls(row)

    @classmethod
    def position(cls, position, velocity=None, acceleration=None, yaw=None,
                 yaw_rate=None) -> Setpoint:
        """Position with optional velocity / acceleration feed-forward."""
        _vec("position", position, required=True)
        return cls.trajectory(position, velocity, acceleration, yaw, yaw_rate)

    @classmethod
    def velocity(cls, velocity, acceleration=None, yaw=None, yaw_rate=None) -> Setpoint:
        _vec("velocity", velocity, required=True)
        return cls.trajectory(None, velocity, acceleration, yaw, yaw_rate)

    @classmethod
    def acceleration(cls, acceleration, yaw=None, yaw_rate=None) -> Setpoint:
        _vec("acceleration", acceleration, required=True)
        return cls.trajectory(None, None, acceleration, yaw, yaw_rate)

    @classmethod
    def attitude(cls, q_world_body, thrust: float) -> Setpoint:
        """Attitude quaternion (w, x, y, z; ENU/FLU) and normalised collective thrust 0..1."""
        row = cls._base(c.KIND_ATTITUDE)
        try:
            q = np.asarray(q_world_body, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise SetpointError(f"attitude: {q_world_body!r} is not a quaternion") from None
        if q.shape != (4,) or not np.isfinite(q).all():
            raise SetpointError(f"attitude: {q.tolist()} is not a finite quaternion (w, x, y, z)")
        nq = float(np.linalg.norm(q))
        if abs(nq - 1.0) > 1e-3:
            raise SetpointError(f"attitude: quaternion norm {nq:.6f} is not 1")
        row[c.SP_Q : c.SP_Q + 4] = q / nq
        row[c.SP_THRUST] = _scalar("thrust", thrust, lo=0.0, hi=1.0)
        if math.isnan(row[c.SP_THRUST]):
            raise SetpointError("thrust: required")
        return cls(row)

    @classmethod
    def motors(cls, commands) -> Setpoint:
        """Direct motor commands in [0, 1] per rotor (in the platform's rotor order), as an
        external autopilot outputs them: rotor speed command u * w_max."""
        u = np.asarray(commands, dtype=float).reshape(-1)
        if not 1 <= len(u) <= c.MAX_SP_MOTORS:
            raise SetpointError(f"motors: {len(u)} commands, 1..{c.MAX_SP_MOTORS} expected")
        if not np.all(np.isfinite(u)) or np.any(u < 0.0) or np.any(u > 1.0):
            raise SetpointError(f"motors: commands must be within 0..1, got {u}")
        row = cls._base(c.KIND_MOTORS)
        row[c.SP_MOTORS:c.SP_MOTORS + len(u)] = u
        return cls(row)

    @classmethod
    def body_rates(cls, rates_body, thrust: float) -> Setpoint:
        """Body rates (rad/s, FLU) and normalised collective thrust 0..1."""
        row = cls._base(c.KIND_RATES)
        row[c.SP_RATES : c.SP_RATES + 3] = _vec("rates", rates_body, required=True)
        row[c.SP_THRUST] = _scalar("thrust", thrust, lo=0.0, hi=1.0)
        if math.isnan(row[c.SP_THRUST]):
            raise SetpointError("thrust: required")
        return cls(row)


# --- checking a setpoint that came from elsewhere ------------------------------------------
def offboard_problem(sp) -> str:
    """Why ``sp`` is not an offboard setpoint the flight controller can fly ("" if it is
    one): what a navigator returns is checked with this before it reaches the cascade.
    The constructors of :class:`Setpoint` only make flyable rows; this catches rows built
    by other means (``Setpoint(row)`` by hand, a row edited in place) and the kinds that
    are not offboard setpoints (off, idle, motors)."""
    if not isinstance(sp, Setpoint):
        return f"{type(sp).__name__}, not a Setpoint"
    row = sp.row
    if not isinstance(row, np.ndarray) or row.shape != (c.N_SP,) or row.dtype.kind != "f":
        return "a malformed setpoint"
    why = _row_problem(row if row.dtype == np.float64 else row.astype(np.float64))
    if why == 0:
        return ""
    if why == 2:
        kind = row[c.SP_KIND]
        if kind in (c.KIND_OFF, c.KIND_IDLE):
            return "a motors-off/idle setpoint"
        return f"a setpoint of unknown kind {kind!r}"
    return _ROW_PROBLEMS[why]


_ROW_PROBLEMS = {1: "a setpoint with an infinite value",
             3: "a trajectory setpoint with an uncontrolled axis",
             4: "an attitude setpoint with NaN", 5: "a rates setpoint with NaN"}


@njit(cache=True)
def _row_problem(row) -> int:
    """0 when the offboard setpoint row is flyable, else the code of the first problem
    (1 infinite value, 2 not an offboard kind, 3 a trajectory axis with no position,
    velocity or acceleration, 4 / 5 NaN in an attitude / rates setpoint): the rules the
    constructors enforce, in one compiled pass instead of a dozen numpy calls per
    navigator step."""
    for k in range(row.shape[0]):
        if math.isinf(row[k]):
            return 1
    kind = row[c.SP_KIND]
    if not (kind == c.KIND_TRAJECTORY or kind == c.KIND_ATTITUDE or kind == c.KIND_RATES):
        return 2
    if kind == c.KIND_TRAJECTORY:
        for a in range(3):
            if (math.isnan(row[c.SP_POS + a]) and math.isnan(row[c.SP_VEL + a])
                    and math.isnan(row[c.SP_ACC + a])):
                return 3
    elif kind == c.KIND_ATTITUDE:
        for a in range(4):
            if math.isnan(row[c.SP_Q + a]):
                return 4
        if math.isnan(row[c.SP_THRUST]):
            return 4
    else:
        for a in range(3):
            if math.isnan(row[c.SP_RATES + a]):
                return 5
        if math.isnan(row[c.SP_THRUST]):
            return 5
    return 0


# --- many vehicles at once -----------------------------------------------------------------
# The rows of N offboard setpoints of one kind in one call (a vectorised environment sets
# a batch's setpoints every control period): each row is the row of the Setpoint
# constructor named in the docstring, value for value, and the same values are refused.
def _batch(name: str, values, width: int) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise SetpointError(f"{name}: not an array of numbers") from None
    if arr.ndim != 2 or arr.shape[1] != width:
        raise SetpointError(f"{name}: needs shape (N, {width}), got {arr.shape}")
    bad = ~np.isfinite(arr)
    if bad.any():
        i = int(np.flatnonzero(bad.any(axis=1))[0])
        raise SetpointError(f"{name}: row {i} {arr[i].tolist()} has non-finite component(s)")
    return arr


def _batch_rows(kind: int, n: int) -> np.ndarray:
    rows = np.full((n, c.N_SP), np.nan)
    rows[:, c.SP_KIND] = kind
    return rows


def _unit_interval(name: str, arr: np.ndarray) -> None:
    out = (arr < 0.0) | (arr > 1.0)
    if out.any():
        i = int(np.flatnonzero(out.reshape(len(arr), -1).any(axis=1))[0])
        raise SetpointError(f"{name}: row {i} {np.atleast_1d(arr[i]).tolist()} is outside "
                            "[0, 1]")


def _trajectory_rows(name: str, slot: int, vectors, yaw_rate) -> np.ndarray:
    """Offboard trajectory rows controlling one level (``slot``: SP_VEL or SP_ACC) of
    every axis, with a yaw rate (the heading held)."""
    v = _batch(name, vectors, 3)
    r = _batch("yaw_rate", np.reshape(yaw_rate, (-1, 1)), 1)
    rows = _batch_rows(c.KIND_TRAJECTORY, len(v))
    rows[:, slot:slot + 3] = v
    rows[:, c.SP_YAWRATE] = r[:, 0]
    rows[:, c.SP_OFFBOARD] = 1.0
    return rows


def velocity_rows(velocity, yaw_rate) -> np.ndarray:
    """(N, N_SP): row i is ``Setpoint.velocity(velocity[i], yaw_rate=yaw_rate[i])
    .offboard().row`` (yaw held: NaN)."""
    return _trajectory_rows("velocity", c.SP_VEL, velocity, yaw_rate)


def acceleration_rows(acceleration, yaw_rate) -> np.ndarray:
    """(N, N_SP): row i is ``Setpoint.acceleration(acceleration[i], yaw_rate=yaw_rate[i])
    .offboard().row``."""
    return _trajectory_rows("acceleration", c.SP_ACC, acceleration, yaw_rate)


def body_rate_rows(rates_body, thrust) -> np.ndarray:
    """(N, N_SP): row i is ``Setpoint.body_rates(rates_body[i], thrust[i]).offboard().row``
    (rad/s FLU, normalised collective thrust 0..1)."""
    w = _batch("rates", rates_body, 3)
    f = _batch("thrust", np.reshape(thrust, (-1, 1)), 1)
    _unit_interval("thrust", f)
    rows = _batch_rows(c.KIND_RATES, len(w))
    rows[:, c.SP_RATES:c.SP_RATES + 3] = w
    rows[:, c.SP_THRUST] = f[:, 0]
    rows[:, c.SP_OFFBOARD] = 1.0
    return rows


def motor_rows(commands) -> np.ndarray:
    """(N, N_SP): row i is ``Setpoint.motors(commands[i]).row`` (0..1 per rotor, in the
    platform's rotor order)."""
    width = np.shape(commands)[-1] if np.ndim(commands) == 2 else 0
    if not 1 <= width <= c.MAX_SP_MOTORS:
        raise SetpointError(f"motors: needs shape (N, 1..{c.MAX_SP_MOTORS}), got "
                            f"{np.shape(commands)}")
    u = _batch("motors", commands, width)
    _unit_interval("motors", u)
    rows = _batch_rows(c.KIND_MOTORS, len(u))
    rows[:, c.SP_MOTORS:c.SP_MOTORS + u.shape[1]] = u
    return rows
