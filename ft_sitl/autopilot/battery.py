"""The vehicle's battery, as far as the failsafes and telemetry need one.

No cell chemistry: the charge used follows the mechanical energy the motors delivered
(the plant integrates it), so a vehicle that flies harder empties sooner, and the
battery failsafes (``BAT_LOW_THR``, ``BAT_CRIT_THR``, ``BAT_EMERGEN_THR``) fire at a
flight time that depends on how it was flown, as on a real vehicle.
"""

from __future__ import annotations

from dataclasses import dataclass

from ft_sitl.physics.platform import Platform


@dataclass
class Battery:
    """A simple battery: energy drawn through the motors at a fixed efficiency.

    Capacity is sized so the platform hovers for FT_BAT_ENDURANCE seconds; voltage
    falls linearly from 4.2 V to 3.5 V per cell with charge used, minus a sag with load.
    """

    capacity_j: float
    cells: int
    efficiency: float = 0.7
    used_j: float = 0.0
    #: an injected battery failure: it reads empty
    failed: bool = False

    @classmethod
    def for_platform(cls, platform: Platform, endurance_s: float) -> Battery:
        w = platform.hover_rotor_speed_rad_s
        hover_power = (platform.n_rotors * platform.torque_thrust_ratio_m
                       * platform.thrust_coefficient * w**3)
        cells = max(2, min(12, round(2 + 2 * platform.mass_kg)))
        return cls(capacity_j=hover_power / 0.7 * endurance_s, cells=cells)

    def draw(self, mech_energy_j: float) -> None:
        self.used_j = mech_energy_j / self.efficiency

    @property
    def remaining(self) -> float:
        if self.failed:
            return 0.0
        return max(0.0, 1.0 - self.used_j / self.capacity_j)

    def voltage(self, current_a: float = 0.0) -> float:
        cell = 3.5 + 0.7 * self.remaining
        return self.cells * cell - 0.002 * current_a * self.cells

    def current_a(self, power_w: float) -> float:
        return power_w / self.efficiency / max(self.voltage(), 1.0)
