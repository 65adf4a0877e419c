"""A short demonstration flight: arm, take off, fly a leg, turn, land, in lockstep.

It exercises the whole foundation (catalog platform, plant, cascade) and reports each
phase: what was commanded, where the vehicle went, how long it took.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.physics.platform import Platform
from ft_sitl.physics.quaternion import tilt_angle
from ft_sitl.sim.lockstep import Recording, Simulation


@dataclass
class Phase:
    name: str
    command: str
    t_start_s: float
    t_end_s: float
    end_position_enu_m: list[float]
    end_yaw_deg: float
    max_speed_m_s: float
    max_tilt_deg: float


@dataclass
class DemoResult:
    platform: str
    phases: list[Phase]
    sim_time_s: float
    wall_time_s: float
    energy_j: float
    max_impact_speed_m_s: float
    landed: bool
    recording: Recording

    @property
    def speed_up(self) -> float:
        return self.sim_time_s / self.wall_time_s if self.wall_time_s > 0 else math.inf

    def summary(self) -> dict:
        d = {k: v for k, v in asdict(self).items() if k != "recording"}
        d["speed_up"] = self.speed_up
        return d


def run_demo(platform: Platform, *, altitude_m: float = 2.0, leg_m: float = 8.0) -> DemoResult:
    # compile (or load) the kernels before the clock starts
    Simulation(platform).step(1)
    tilt_angle(np.array([1.0, 0.0, 0.0, 0.0]))
    Recording(np.zeros(1), np.zeros((1, 1, 17))).eulers(0)
    sim = Simulation(platform)
    sim.place(0, [0.0, 0.0, 0.0])
    plan = [
        ("arm", "idle on the ground", Setpoint.idle(), 1.0),
        ("takeoff", f"position (0, 0, {altitude_m:g}) m", Setpoint.position(
            [0.0, 0.0, altitude_m], yaw=0.0), 8.0),
        ("leg", f"position ({leg_m:g}, 0, {altitude_m:g}) m at MPC_XY_VEL_MAX", Setpoint.position(
            [leg_m, 0.0, altitude_m], yaw=0.0), 8.0),
        ("turn", "yaw 90 deg", Setpoint.position([leg_m, 0.0, altitude_m], yaw=math.pi / 2), 4.0),
        ("descend", "velocity (0, 0, -0.7) m/s", Setpoint.velocity(
            [0.0, 0.0, -0.7], yaw=math.pi / 2), 5.0),
        ("disarm", "motors off", Setpoint.off(), 1.0),
    ]
    phases: list[Phase] = []
    recs: list[Recording] = []
    wall0 = time.perf_counter()
    for name, what, sp, duration in plan:
        t0 = sim.time_us * 1e-6
        sim.set_setpoint(0, sp)
        rec = sim.run(duration, record_hz=50)
        recs.append(rec)
        vel = rec.x[:, 0, 3:6]
        tilts = [tilt_angle(q) for q in rec.x[:, 0, 6:10]]
        phases.append(
            Phase(
                name=name,
                command=what,
                t_start_s=t0,
                t_end_s=sim.time_us * 1e-6,
                end_position_enu_m=[round(float(v), 3) for v in sim.position(0)],
                end_yaw_deg=round(math.degrees(float(sim.euler(0)[2])), 2),
                max_speed_m_s=round(float(np.linalg.norm(vel, axis=1).max()), 3),
                max_tilt_deg=round(math.degrees(max(tilts)), 2),
            )
        )
    wall = time.perf_counter() - wall0
    recording = Recording(
        np.concatenate([r.t_s for r in recs]), np.concatenate([r.x for r in recs], axis=0)
    )
    return DemoResult(
        platform=platform.name,
        phases=phases,
        sim_time_s=sim.time_us * 1e-6,
        wall_time_s=wall,
        energy_j=round(sim.energy_j(0), 2),
        max_impact_speed_m_s=round(sim.max_impact_speed(0), 3),
        landed=sim.on_ground(0),
        recording=recording,
    )


def plot_demo(result: DemoResult, path: str) -> None:
    """Save position, speed and tilt over time as a PNG (or any matplotlib format)."""
    # matplotlib: heavy, loaded only when plotting
    import matplotlib

    matplotlib.use("Agg")
    # matplotlib: heavy, loaded only when plotting
    import matplotlib.pyplot as plt

    rec = result.recording
    pos = rec.positions(0)
    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for k, label in enumerate("xyz"):
        axes[0].plot(rec.t_s, pos[:, k], label=f"{label} (ENU)")
    axes[0].set_ylabel("position (m)")
    axes[0].legend(loc="upper left")
    axes[1].plot(rec.t_s, np.linalg.norm(rec.x[:, 0, 3:6], axis=1))
    axes[1].set_ylabel("speed (m/s)")
    axes[2].plot(rec.t_s, np.degrees([tilt_angle(q) for q in rec.x[:, 0, 6:10]]), label="tilt")
    axes[2].plot(rec.t_s, np.degrees(rec.eulers(0)[:, 2]), label="yaw")
    axes[2].set_ylabel("angle (deg)")
    axes[2].set_xlabel("simulated time (s)")
    axes[2].legend(loc="upper left")
    for ph in result.phases:
        for ax in axes:
            ax.axvline(ph.t_start_s, color="0.8", lw=0.8)
        axes[0].annotate(ph.name, (ph.t_start_s, axes[0].get_ylim()[1]), fontsize=8,
                         va="top", rotation=90)
    fig.suptitle(f"ft-sitl demo flight: {result.platform}")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
