"""Motor layouts as a named table, and the allocation matrix computed from geometry.

Each layout lists its rotors in PX4 / ArduPilot motor order (the order of
``actuator_motors`` and of HIL_ACTUATOR_CONTROLS). A rotor is an azimuth in the body
FLU frame (degrees, counter-clockwise from the nose, seen from above) and a spin
direction (+1 counter-clockwise seen from above, -1 clockwise). Nothing else in
ft-sitl types sign patterns by hand: mixing comes from :func:`allocation_matrix`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Rotor:
    azimuth_deg: float
    spin: int  # +1 CCW seen from above (reaction torque CW), -1 CW


@dataclass(frozen=True)
class Layout:
    name: str
    rotors: tuple[Rotor, ...]
    description: str

    @property
    def n_rotors(self) -> int:
        return len(self.rotors)

    def rotor_positions(self, arm_length_m: float) -> np.ndarray:
        """(n, 3) rotor hub positions in the body FLU frame (rotor plane z = 0)."""
        az = np.radians([r.azimuth_deg for r in self.rotors])
        return np.stack(
            [arm_length_m * np.cos(az), arm_length_m * np.sin(az), np.zeros_like(az)], axis=1
        )

    def spins(self) -> np.ndarray:
        return np.array([r.spin for r in self.rotors], dtype=float)


LAYOUTS: dict[str, Layout] = {
    layout.name: layout
    for layout in (
        Layout(
            "quad_x",
            (Rotor(-45.0, +1), Rotor(135.0, +1), Rotor(45.0, -1), Rotor(-135.0, -1)),
            "quadrotor, cross ('X') layout: arms at 45 deg to the body axes "
            "(PX4 order: front-right, rear-left, front-left, rear-right)",
        ),
        Layout(
            "quad_plus",
            (Rotor(-90.0, +1), Rotor(90.0, +1), Rotor(0.0, -1), Rotor(180.0, -1)),
            "quadrotor, plus ('+') layout: arms along the body axes "
            "(PX4 order: right, left, front, back)",
        ),
    )
}


def get_layout(name: str) -> Layout:
    try:
        return LAYOUTS[name]
    except KeyError:
        raise ValueError(
            f"unknown motor layout {name!r}; known layouts: {', '.join(sorted(LAYOUTS))}"
        ) from None


def allocation_matrix(layout: Layout, arm_length_m: float, torque_thrust_ratio_m: float):
    """B (4 x n): [collective thrust, tau_x, tau_y, tau_z] per newton of each rotor's thrust.

    A rotor at r = (x, y, 0) pushing T along body +z makes the torque r x (0, 0, T) =
    (y T, -x T, 0); its drag torque opposes its spin: -spin * kappa * T about +z.
    """
    pos = layout.rotor_positions(arm_length_m)
    b = np.empty((4, layout.n_rotors))
    b[0] = 1.0
    b[1] = pos[:, 1]
    b[2] = -pos[:, 0]
    b[3] = -layout.spins() * torque_thrust_ratio_m
    # Exact zeros where the geometry gives round-off (cos 90 deg), so mixing is symmetric.
    b[np.abs(b) < 1e-12 * max(1.0, arm_length_m)] = 0.0
    return b


def max_axis_torques(b: np.ndarray, thrust_min_n: float, thrust_max_n: float) -> np.ndarray:
    """Largest positive torque about x, y, z the rotor box [T_min, T_max]^n can produce.

    Every rotor whose coefficient is positive runs at T_max, every other one at T_min:
    for the cross and plus quads this is exactly eqs. 4/5 of the FLYINGTRUST paper with
    the opposing rotors at their minimum speed.
    """
    out = np.empty(3)
    for k in range(3):
        row = b[k + 1]
        out[k] = np.sum(np.where(row > 0, row * thrust_max_n, row * thrust_min_n))
    return out

