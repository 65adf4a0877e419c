"""The platform: a quadrotor's physical parameters, their schema and its indicators.

A :class:`Platform` is frozen data. Every field has a unit, an allowed range and a line
saying what it is (:data:`SCHEMA`); :func:`validate` enforces the ranges and the
physical-consistency rules (inertia triangle inequalities, hover inside the rotor speed
range). The FLYINGTRUST indicators (paper eqs. 2, 4/5, 9) are recomputed from the
physical parameters by :meth:`Platform.indicators`, never stored.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from ft_sitl import G
from ft_sitl.physics.body import BODY_FIELDS, VehicleBody, build_body
from ft_sitl.physics.layouts import LAYOUTS, allocation_matrix, get_layout, max_axis_torques

#: real and virtual: the paper's Table 1; user: from platform files; series: the controlled
#: series (ft_sitl.physics.series), one catalog body with one indicator changed
CATEGORIES = ("real", "virtual", "user", "series")


class PlatformError(ValueError):
    """A platform definition is invalid. The message names the source, the key and the range."""


@dataclass(frozen=True)
class FieldSpec:
    unit: str
    lo: float
    hi: float
    doc: str


# Ranges are generous physical bounds for 0.05-50 kg multirotors: they catch unit mistakes
# (grams for kilograms, rpm for rad/s) and impossible values, not unusual designs.
SCHEMA: dict[str, FieldSpec] = {
    "mass_kg": FieldSpec("kg", 0.05, 50.0, "take-off mass including battery and payload"),
    "arm_length_m": FieldSpec(
        "m", 0.02, 1.5, "distance from the centre of mass to each rotor hub (the paper's d)"
    ),
    "inertia_kg_m2": FieldSpec(
        "kg m^2", 1e-6, 50.0, "principal moments of inertia [Jxx, Jyy, Jzz] about body FLU axes"
    ),
    "prop_diameter_m": FieldSpec("m", 0.02, 1.5, "propeller diameter"),
    "thrust_coefficient": FieldSpec(
        "N/(rad/s)^2", 1e-10, 1e-2, "c_T in T = c_T w^2 (per rotor, static thrust)"
    ),
    "torque_thrust_ratio_m": FieldSpec(
        "m", 1e-4, 0.2, "c_M / c_T: rotor drag torque per newton of thrust"
    ),
    "rotor_speed_min_rad_s": FieldSpec("rad/s", 0.0, 1e4, "idle rotor speed while armed"),
    "rotor_speed_max_rad_s": FieldSpec(
        "rad/s", 10.0, 1e4, "maximum sustained rotor speed (the paper's w_max)"
    ),
    "motor_tau_up_s": FieldSpec("s", 1e-3, 0.5, "first-order time constant when speeding up"),
    "motor_tau_down_s": FieldSpec("s", 1e-3, 0.5, "first-order time constant when slowing down"),
    "rotor_drag_coefficient": FieldSpec(
        "N s/m per rad/s",
        0.0,
        1e-2,
        "in-plane rotor (induced) drag: force = -k * sum(w_i) * in-plane air velocity",
    ),
    "body_drag_coefficient": FieldSpec(
        "kg/m", 0.0, 10.0, "quadratic body drag 0.5*rho*Cd*A per body axis [x, y, z]"
    ),
    "collision_radius_m": FieldSpec(
        "m", 0.02, 3.0, "radius of the collision sphere of trial protocols 1-4 (from "
        "protocol 5 the vehicle's body touches the world: BODY_SCHEMA)"
    ),
}

#: optional fields: the collision body's dimensions (ft_sitl.physics.body; omitted: its
#: rules from the arm length and the propeller)
BODY_SCHEMA: dict[str, FieldSpec] = {k: FieldSpec(*v) for k, v in BODY_FIELDS.items()}

VECTOR_FIELDS = ("inertia_kg_m2", "body_drag_coefficient", "body_size_m")


@dataclass(frozen=True)
class Indicators:
    """The FLYINGTRUST kinodynamic indicators (paper eq. 11) plus pitch for reference."""

    twr_max: float
    alpha_xy_max_rad_s2: float  # roll, as the paper uses for alpha_xy
    alpha_pitch_max_rad_s2: float
    alpha_z_max_rad_s2: float

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


@dataclass(frozen=True)
class Platform:
    name: str
    category: str
    layout: str
    mass_kg: float
    arm_length_m: float
    inertia_kg_m2: tuple[float, float, float]
    prop_diameter_m: float
    thrust_coefficient: float
    torque_thrust_ratio_m: float
    rotor_speed_min_rad_s: float
    rotor_speed_max_rad_s: float
    motor_tau_up_s: float
    motor_tau_down_s: float
    rotor_drag_coefficient: float
    body_drag_coefficient: tuple[float, float, float]
    collision_radius_m: float
    source: str = ""
    body_size_m: tuple[float, float, float] | None = None
    rotor_disk_thickness_m: float | None = None
    rotor_height_m: float | None = None

    # --- derived quantities -------------------------------------------------------
    @property
    def n_rotors(self) -> int:
        return get_layout(self.layout).n_rotors

    @property
    def rotor_thrust_max_n(self) -> float:
        return self.thrust_coefficient * self.rotor_speed_max_rad_s**2

    @property
    def rotor_thrust_min_n(self) -> float:
        return self.thrust_coefficient * self.rotor_speed_min_rad_s**2

    @property
    def thrust_max_n(self) -> float:
        return self.n_rotors * self.rotor_thrust_max_n

    @property
    def hover_rotor_speed_rad_s(self) -> float:
        return math.sqrt(self.mass_kg * G / (self.n_rotors * self.thrust_coefficient))

    def body(self) -> VehicleBody:
        """The collision body: central box and rotor disks (ft_sitl.physics.body)."""
        return build_body(self.layout, self.arm_length_m, self.prop_diameter_m,
                          self.body_size_m, self.rotor_disk_thickness_m, self.rotor_height_m)

    def allocation(self) -> np.ndarray:
        """B (4 x n) mapping rotor thrusts to [collective, tau_x, tau_y, tau_z]."""
        return allocation_matrix(
            get_layout(self.layout), self.arm_length_m, self.torque_thrust_ratio_m
        )

    def max_torques(self) -> np.ndarray:
        """Full-authority torque about body x, y, z (N m), opposing rotors at idle."""
        return max_axis_torques(
            self.allocation(), self.rotor_thrust_min_n, self.rotor_thrust_max_n
        )

    def indicators(self) -> Indicators:
        """TWR_max (eq. 2) and alpha_max = J^-1 tau_max (eqs. 4/5, 9)."""
        tau = self.max_torques()
        j = self.inertia_kg_m2
        return Indicators(
            twr_max=self.thrust_max_n / (self.mass_kg * G),
            alpha_xy_max_rad_s2=tau[0] / j[0],
            alpha_pitch_max_rad_s2=tau[1] / j[1],
            alpha_z_max_rad_s2=tau[2] / j[2],
        )

    def physical_dict(self) -> dict:
        """The fields as plain data (tuples as lists), for files and --json; body
        dimensions left to their rules are left out (so specs written before bodies
        existed keep their ids)."""
        d = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None and f.name in BODY_SCHEMA:
                continue
            d[f.name] = list(v) if isinstance(v, tuple) else v
        return d


def _where(source: str, key: str) -> str:
    return f"{source}: {key}" if source else key


def validate(p: Platform, source: str = "") -> Platform:
    """Check ranges and physical consistency; raise PlatformError naming what is wrong."""
    where = source or f"platform {p.name!r}"
    if not isinstance(p.name, str) or not p.name.strip():
        raise PlatformError(f"{_where(where, 'name')}: must be a non-empty string")
    if p.category not in CATEGORIES:
        raise PlatformError(
            f"{_where(where, 'category')}: {p.category!r} is not one of {', '.join(CATEGORIES)}"
        )
    if p.layout not in LAYOUTS:
        raise PlatformError(
            f"{_where(where, 'layout')}: {p.layout!r} is not one of {', '.join(sorted(LAYOUTS))}"
        )
    for key, spec in (SCHEMA | BODY_SCHEMA).items():
        value = getattr(p, key)
        if value is None and key in BODY_SCHEMA:
            continue
        values = value if key in VECTOR_FIELDS else (value,)
        if key in VECTOR_FIELDS and len(values) != 3:
            raise PlatformError(f"{_where(where, key)}: needs 3 values [x, y, z], got {value!r}")
        for v in values:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                raise PlatformError(
                    f"{_where(where, key)}: {v!r} is not a finite number ({spec.unit})"
                )
            if not (spec.lo <= v <= spec.hi):
                raise PlatformError(
                    f"{_where(where, key)}: {v!r} {spec.unit} is outside the allowed range "
                    f"[{spec.lo:g}, {spec.hi:g}] {spec.unit} ({spec.doc})"
                )
    jxx, jyy, jzz = p.inertia_kg_m2
    for a, b, c, label in (
        (jzz, jxx, jyy, "Jzz <= Jxx + Jyy"),
        (jxx, jyy, jzz, "Jxx <= Jyy + Jzz"),
        (jyy, jxx, jzz, "Jyy <= Jxx + Jzz"),
    ):
        if a > (b + c) * (1.0 + 1e-9):
            raise PlatformError(
                f"{_where(where, 'inertia_kg_m2')}: {list(p.inertia_kg_m2)} violates the "
                f"triangle inequality {label}: no rigid body has these principal moments"
            )
    if p.rotor_speed_min_rad_s >= p.rotor_speed_max_rad_s:
        raise PlatformError(
            f"{_where(where, 'rotor_speed_min_rad_s')}: {p.rotor_speed_min_rad_s} must be "
            f"below rotor_speed_max_rad_s ({p.rotor_speed_max_rad_s})"
        )
    weight = p.mass_kg * G
    if p.thrust_max_n < 1.05 * weight:
        raise PlatformError(
            f"{_where(where, 'rotor_speed_max_rad_s')}: maximum thrust "
            f"{p.thrust_max_n:.3f} N gives TWR_max {p.thrust_max_n / weight:.3f}; "
            "a platform needs TWR_max >= 1.05 to hover with any control margin"
        )
    if p.n_rotors * p.rotor_thrust_min_n > 0.5 * weight:
        raise PlatformError(
            f"{_where(where, 'rotor_speed_min_rad_s')}: idle thrust "
            f"{p.n_rotors * p.rotor_thrust_min_n:.3f} N exceeds half the weight "
            f"({0.5 * weight:.3f} N): the vehicle could not descend or land"
        )
    if p.collision_radius_m < p.arm_length_m:
        raise PlatformError(
            f"{_where(where, 'collision_radius_m')}: {p.collision_radius_m} m is smaller than "
            f"the arm length ({p.arm_length_m} m): the rotors would sit outside the "
            "collision shape"
        )
    return p
