"""The vehicle an external autopilot flies: our physics driven by raw motor commands.

Autopilot in the loop: a real PX4 or ArduPilot runs the flight control and sends motor
outputs; ft-sitl provides the plant (the platform's rotor dynamics and motor limits), the
world (scenario mesh, collision guard) and the sensor truth. :class:`BridgeVehicle` is that
plant for one vehicle, without our own commander or controller:

- ``set_motors(u)``: commands in [0, 1] per rotor in **our** rotor order (the layout's
  order, which for ``quad_x`` is PX4's and ArduPilot's quad-X order); rotor speed command
  ``u * w_max`` (linear in speed, as Gazebo's motor model), then the platform's motor
  time constant and limits;
- ``step_us(dt)``: advance in whole physics steps (lockstep: only when the autopilot asks);
- truth for the sensor models: position/velocity (ENU and NED), attitude, body rates,
  and the specific force over the last step (what an accelerometer measures: at rest on
  the ground it reads 1 g up, i.e. -g on body z in FRD);
- a collision with the scenario, or with one of its moving obstacles (``scenario.movers``,
  moving from simulation time 0), crashes the vehicle: its motors are forced off from then
  on and ``crash`` says what was hit at what speed (the autopilot sees the fall in its
  sensors).

The vehicle spawns on the scenario's takeoff point facing its start direction, or at the
origin facing north (ENU yaw pi/2, PX4 and ArduPilot heading 0); ``spawn_yaw`` (ENU, rad)
or :func:`spawn_yaw_from_heading` turns it. (Gazebo puts a model at its pose's yaw in an
ENU world: PX4's Gazebo worlds, with a zero pose, face east, heading 90.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ft_sitl import G, frames
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.physics.layouts import get_layout
from ft_sitl.physics.quaternion import qrotate_inv
from ft_sitl.sim.guard import CollisionGuard, GuardEventKind
from ft_sitl.sim.lockstep import Simulation

NORTH_YAW_ENU = math.pi / 2.0  #: the spawn yaw without a scenario: facing north


def spawn_yaw_from_heading(heading_deg: float | None, scenario=None) -> float:
    """The ENU spawn yaw (rad) of a heading (deg clockwise from north, PX4's and
    ArduPilot's convention); None: the scenario's start yaw, or north without one."""
    if heading_deg is None:
        return float(scenario.start_yaw) if scenario is not None else NORTH_YAW_ENU
    if not math.isfinite(heading_deg):
        raise ValueError(f"spawn heading: {heading_deg!r} is not a finite number of degrees")
    return frames.yaw_ned_to_enu(math.radians(heading_deg))


@dataclass(frozen=True)
class Crash:
    time_us: int
    what: str
    speed_m_s: float


class BridgeVehicle:
    def __init__(self, platform, *, scenario=None, spawn=None, spawn_yaw: float | None = None,
                 physics_hz: int = 1000):
        self.platform = platform
        self.sim = Simulation(platform, physics_hz=physics_hz)
        self.layout = get_layout(platform.layout)
        self.n_motors = self.layout.n_rotors
        if spawn is None:
            spawn = scenario.takeoff if scenario is not None else (0.0, 0.0, 0.0)
        if spawn_yaw is None:
            spawn_yaw = spawn_yaw_from_heading(None, scenario)
        self.spawn = np.array(spawn, dtype=float)
        self.spawn_yaw = float(spawn_yaw)
        self.scenario = scenario
        self.guard = None
        self.crash: Crash | None = None
        self.events: list = []
        if scenario is not None:
            self.guard = CollisionGuard.for_scenario(scenario, [platform.collision_radius_m])
            self.sim.attach_guard(self.guard, self._on_guard_event)
        self.reset()

    def reset(self) -> None:
        """Back on the spawn point at rest, motors off, crash cleared (an autopilot restart)."""
        self.sim.place(0, self.spawn, self.spawn_yaw, on_ground=True)
        self.crash = None
        self._u = np.zeros(self.n_motors)
        self.sim.set_setpoint(0, Setpoint.motors(self._u))
        self._v_prev = self.velocity_enu()
        self._specific_force_enu = np.array([0.0, 0.0, G])

    def _on_guard_event(self, ev) -> None:
        self.events.append(ev)
        if ev.kind in (GuardEventKind.COLLISION, GuardEventKind.MOVER_COLLISION) and \
                self.crash is None:
            self.crash = Crash(int(ev.time_us), str(ev.what), float(ev.speed_m_s))
            self.sim.set_setpoint(0, Setpoint.motors(np.zeros(self.n_motors)))

    # --- inputs ------------------------------------------------------------------------
    def set_motors(self, u) -> None:
        """Motor commands in [0, 1], our rotor order (clipped; NaN counts as 0)."""
        u = np.nan_to_num(np.asarray(u, dtype=float).reshape(-1), nan=0.0)
        if len(u) != self.n_motors:
            raise ValueError(f"{len(u)} motor commands for a {self.n_motors}-rotor vehicle")
        self._u = np.clip(u, 0.0, 1.0)
        if self.crash is None:
            self.sim.set_setpoint(0, Setpoint.motors(self._u))

    @property
    def motor_commands(self) -> np.ndarray:
        return self._u.copy()

    def step_us(self, dt_us: int) -> None:
        """Advance by dt_us (whole physics steps; at least one)."""
        n = max(1, int(dt_us) // self.sim.dt_us)
        v0 = self.velocity_enu()
        self.sim.step(n)
        v1 = self.velocity_enu()
        # specific force = kinematic acceleration - gravity (ENU: gravity is -G on z)
        self._specific_force_enu = (v1 - v0) / (n * self.sim.dt) + np.array([0.0, 0.0, G])

    # --- truth -------------------------------------------------------------------------
    @property
    def time_us(self) -> int:
        return int(self.sim.time_us)

    def position_enu(self) -> np.ndarray:
        return self.sim.position(0)

    def velocity_enu(self) -> np.ndarray:
        return self.sim.velocity(0)

    def q_enu_flu(self) -> np.ndarray:
        return self.sim.attitude(0)

    def omega_flu(self) -> np.ndarray:
        return self.sim.body_rates(0)

    def specific_force_flu(self) -> np.ndarray:
        """What a perfect accelerometer reads (body FLU, m/s^2)."""
        return qrotate_inv(self.q_enu_flu(), self._specific_force_enu)

    # NED / FRD views (PX4, ArduPilot)
    def position_ned(self) -> np.ndarray:
        """Relative to the spawn point (the autopilot's home / EKF origin)."""
        return frames.enu_to_ned(self.position_enu() - self.spawn)

    def velocity_ned(self) -> np.ndarray:
        return frames.enu_to_ned(self.velocity_enu())

    def q_ned_frd(self) -> np.ndarray:
        return frames.q_enu_flu_to_ned_frd(self.q_enu_flu())

    def gyro_frd(self) -> np.ndarray:
        return frames.flu_to_frd(self.omega_flu())

    def accel_frd(self) -> np.ndarray:
        return frames.flu_to_frd(self.specific_force_flu())

    def on_ground(self) -> bool:
        return self.sim.on_ground(0)

    def motor_positions_flu(self) -> np.ndarray:
        """(n, 3) rotor hub positions, our order (for mapping an autopilot's motor order)."""
        return self.layout.rotor_positions(self.platform.arm_length_m)

    def motor_spins(self) -> np.ndarray:
        """+1 counter-clockwise seen from above, -1 clockwise, our order."""
        return self.layout.spins()
