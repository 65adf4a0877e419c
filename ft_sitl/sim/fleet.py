"""Vehicles with their flight controllers: a lockstep Simulation plus one Commander each.

The commander runs at COMMANDER_HZ of simulated time; the cascade and the plant at the
physics rate in between. An offboard setpoint that arrives while a vehicle is in
OFFBOARD reaches the cascade at once, not at the next commander tick, so the latency
from a setpoint to the first physics step that uses it is one physics step.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ft_sitl.autopilot import failures
from ft_sitl.autopilot.commander import (
    MAIN_OFFBOARD,
    Commander,
    Result,
    Severity,
    VehicleState,
)
from ft_sitl.autopilot.params import ParamSet
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.physics import dynamics as d
from ft_sitl.physics.platform import Platform
from ft_sitl.sim.guard import CollisionGuard, GuardEventKind
from ft_sitl.sim.lockstep import Simulation

COMMANDER_HZ = 50


class Fleet:
    def __init__(
        self,
        platforms: Platform | Sequence[Platform],
        *,
        params: Sequence[ParamSet] | None = None,
        spawn: Sequence[Sequence[float]] | None = None,
        spawn_yaw: Sequence[float] | None = None,
        physics_hz: int = 1000,
        scenario=None,
        guard=None,
    ):
        if isinstance(platforms, Platform):
            platforms = [platforms]
        platforms = list(platforms)
        n = len(platforms)
        self.params = list(params) if params is not None else [ParamSet() for _ in range(n)]
        self.sim = Simulation(platforms, params=self.params, physics_hz=physics_hz)
        self.commanders = [Commander(p, ps) for p, ps in zip(platforms, self.params)]
        spawn = spawn if spawn is not None else [[0.0, 0.0, 0.0]] * n
        if len(spawn) != n:
            raise ValueError(f"spawn: {len(spawn)} positions for {n} vehicles")
        self.spawn = [np.array(p, dtype=float) for p in spawn]
        self.spawn_yaw = [float(y) for y in spawn_yaw] if spawn_yaw is not None else [0.0] * n
        self.scenario = scenario
        if guard is None and scenario is not None:
            guard = CollisionGuard.for_platforms(scenario, platforms)
        self.guard = guard
        if guard is not None:
            self.sim.attach_guard(guard, self._on_guard_event)
        for i in range(n):
            self._place(i)
        self.steps_per_tick = max(1, round(1.0 / (COMMANDER_HZ * self.sim.dt)))
        self._scheduled: list = []  # failures to inject: (time_us, vehicle, unit, type, n)
        self._tick_all()

    def _place(self, i: int) -> None:
        self.sim.place(i, self.spawn[i], self.spawn_yaw[i], on_ground=True)
        self.commanders[i].set_home(self.spawn[i].copy())
        self.commanders[i].home_yaw = self.spawn_yaw[i]

    def respawn(self, i: int) -> None:
        """Put vehicle i back on its spawn point at rest, disarmed, crash cleared (what a
        reboot of a crashed vehicle does in this SITL; a real one would need carrying)."""
        cmd = self.commanders[i]
        cmd.armed = False
        cmd.crashed = cmd.terminated = False
        self._place(i)
        self.sim.sp[i] = Setpoint.off().row

    def _on_guard_event(self, ev) -> None:
        cmd = self.commanders[ev.vehicle]
        cmd.time_us = ev.time_us
        if ev.kind in (GuardEventKind.COLLISION, GuardEventKind.MOVER_COLLISION):
            cmd.crash(ev.what, ev.speed_m_s)
            self.sim.sp[ev.vehicle] = Setpoint.off().row  # motors off from the next step
        elif ev.kind == GuardEventKind.LEFT_VOLUME:
            where = "above the ceiling" if ev.what == "ceiling" else f"past the {ev.what}"
            cmd.text(Severity.WARNING, f"Left the flight volume: {where}")
        elif ev.kind == GuardEventKind.ENTERED_VOLUME:
            cmd.text(Severity.INFO, "Back inside the flight volume")

    @property
    def events(self) -> list:
        """The collision guard's events so far (empty without a scenario)."""
        return self.guard.events if self.guard is not None else []

    @property
    def n(self) -> int:
        return self.sim.n

    @property
    def time_us(self) -> int:
        return self.sim.time_us

    def state(self, i: int) -> VehicleState:
        """Vehicle i as its flight controller sees it: its estimate (the truth without an
        estimator, :meth:`~ft_sitl.sim.lockstep.Simulation.set_estimator`), what the
        commander and the MAVLink telemetry act on and report, as PX4's do with EKF2's."""
        return self._state(self.sim.estimated(i), i)

    def true_state(self, i: int) -> VehicleState:
        """Vehicle i as it is (the plant's state): what judges and referees use."""
        return self._state(self.sim.x[i], i)

    # Named read-outs for the layers above (the MAVLink side, the wire): they never index
    # the plant's arrays themselves, so its layout can change here without them. As with
    # state(), the attitude and rates are the estimate (what PX4 reports); the rotor
    # speeds and the specific force are the plant's, which no estimator models.
    def attitude(self, i: int) -> np.ndarray:
        """Vehicle i's estimated attitude, q_world_body (ENU to FLU, w x y z), a copy."""
        return self.sim.estimated(i)[d.X_QUAT : d.X_QUAT + 4].copy()

    def body_rates(self, i: int) -> np.ndarray:
        """Vehicle i's estimated angular velocity, w_body (FLU, rad/s), a copy."""
        return self.sim.estimated(i)[d.X_OMEGA : d.X_OMEGA + 3].copy()

    def rotor_speeds(self, i: int) -> np.ndarray:
        """Vehicle i's rotor speeds (rad/s, the layout's rotor order), a copy."""
        return self.sim.rotor_speeds(i)

    def rotor_speed_commands(self, i: int) -> np.ndarray:
        """The rotor speeds the controller last commanded for vehicle i (rad/s), a copy."""
        return self.sim.w_cmd[i].copy()

    def specific_force(self, i: int) -> np.ndarray:
        """What a perfect accelerometer on vehicle i read over the last physics step
        (body FLU, m/s^2), a copy."""
        return self.sim.plant.status[i, d.S_SPECIFIC_FORCE : d.S_SPECIFIC_FORCE + 3].copy()

    def _state(self, x, i: int) -> VehicleState:
        # yaw and tilt as qto_euler()[2] and tilt_angle() compute them (the same operations,
        # bit for bit), in plain floats: two compiled calls cost more than the arithmetic
        w, qx, qy, qz = x[d.X_QUAT : d.X_QUAT + 4].tolist()
        c = 1.0 - 2.0 * (qx * qx + qy * qy)
        return VehicleState(
            position=x[d.X_POS : d.X_POS + 3].copy(),
            velocity=x[d.X_VEL : d.X_VEL + 3].copy(),
            yaw=math.atan2(2.0 * (w * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz)),
            on_ground=self.sim.on_ground(i),
            tilt=math.acos(min(1.0, max(-1.0, c))),
        )

    def schedule_failure(self, i: int, at_us: int, unit: int, ftype: int,
                         instance: int = 0) -> None:
        """Inject a failure into vehicle i at simulated time ``at_us`` (served at the
        first commander tick at or after it: 20 ms resolution)."""
        self._scheduled.append((int(at_us), i, unit, ftype, instance))
        self._scheduled.sort()

    def _inject_due(self) -> None:
        now = self.sim.time_us
        while self._scheduled and self._scheduled[0][0] <= now:
            _, i, unit, ftype, instance = self._scheduled.pop(0)
            self.inject_failure(i, unit, ftype, instance)

    def inject_failure(self, i: int, unit: int, ftype: int, instance: int = 0) -> Result:
        """PX4's MAV_CMD_INJECT_FAILURE for vehicle i (MAVLink's FAILURE_UNIT and
        FAILURE_TYPE values; ft_sitl.autopilot.failures says what each does): DENIED unless
        SYS_FAILURE_EN is 1, UNSUPPORTED for what is not simulated (a STATUSTEXT says
        why), else applied now and ACCEPTED."""
        cmd = self.commanders[i]
        cmd.time_us = self.sim.time_us
        if int(self.params[i]["SYS_FAILURE_EN"]) != 1:
            cmd.text(Severity.CRITICAL, "Failure injection disabled (SYS_FAILURE_EN)")
            return Result.DENIED
        try:
            u, t, inst = failures.check(unit, ftype, instance, self.sim.platforms[i].n_rotors)
        except failures.FailureError as exc:
            cmd.text(Severity.WARNING, f"Failure injection: {exc}"[:50])
            return Result.UNSUPPORTED
        if u == "motor":
            act = dict(self.sim.actuator_settings[i] or {})
            for key in ("fail_motor", "stuck_motor", "degraded_motor"):
                if t == "ok" and (inst == 0 or act.get(key) == inst):
                    act[key] = 0
            if t == "off":
                act.update(fail_motor=inst, fail_at_s=0.0)
            elif t == "stuck":
                act.update(stuck_motor=inst, stuck_at_s=0.0)
            elif t in ("wrong", "slow"):
                act.update(degraded_motor=inst,
                           degraded_efficiency=failures.DEGRADED_EFFICIENCY)
            self.sim.set_actuators(i, act, seed=i)
        cmd.record_failure(u, t, inst)
        return Result.ACCEPTED

    def refresh_params(self) -> None:
        """Apply parameter changes to the cascade."""
        self.sim.refresh_gains()

    def offboard_setpoint(self, i: int, sp: Setpoint) -> None:
        cmd = self.commanders[i]
        cmd.time_us = self.sim.time_us
        cmd.offboard_setpoint(sp)
        if cmd.armed and cmd.main_mode == MAIN_OFFBOARD:
            self.sim.set_setpoint(i, cmd.update(self.sim.time_us, self.state(i),
                                                self.sim.energy_j(i)))

    def manual_control(self, i: int, x: float, y: float, z: float, r: float) -> bool:
        """Stick positions for vehicle i (Commander.manual_control), stamped now."""
        cmd = self.commanders[i]
        cmd.time_us = self.sim.time_us
        return cmd.manual_control(x, y, z, r)

    def _tick_all(self) -> None:
        if self._scheduled:
            self._inject_due()
        for i, cmd in enumerate(self.commanders):
            self.sim.set_setpoint(i, cmd.update(self.sim.time_us, self.state(i),
                                                self.sim.energy_j(i)))
            if cmd.terminated:
                self.sim.sp[i] = Setpoint.off().row

    def run_us(self, duration_us: int) -> None:
        """Advance every vehicle by duration_us (whole physics steps), commanders included."""
        steps = duration_us // self.sim.dt_us
        while steps > 0:
            to_tick = self.steps_per_tick - (self.sim.steps % self.steps_per_tick)
            k = min(steps, to_tick)
            self.sim.step(k)
            steps -= k
            if self.sim.steps % self.steps_per_tick == 0:
                self._tick_all()

    def run(self, seconds: float) -> None:
        self.run_us(round(seconds * 1e6))

    def run_until(self, predicate, timeout_s: float, poll_s: float = 0.1) -> bool:
        """Run until predicate() is true (checked every poll_s) or timeout_s passes."""
        t_end = self.sim.time_us + round(timeout_s * 1e6)
        while self.sim.time_us < t_end:
            if predicate():
                return True
            self.run(poll_s)
        return bool(predicate())
