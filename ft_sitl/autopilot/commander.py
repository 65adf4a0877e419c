"""The commander and navigator of the virtual PX4, transport-free.

One :class:`Commander` per vehicle owns what PX4's commander, navigator and flight tasks
own: arming with pre-arm checks, the flight mode, landed-state detection, auto-disarm,
take-off / hold / land / return / reposition, offboard rules and failsafes, mission
execution and the battery. Every control tick it turns all that into one
:class:`~ft_sitl.autopilot.setpoints.Setpoint` for the cascade.

The MAVLink layer and the in-process mission runner call the same methods, so a script
flying over MAVSDK and a trial flying in-process see identical behaviour. Positions are
local ENU metres from the home point; times are integer microseconds of simulated time.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

from ft_sitl import G
from ft_sitl.autopilot import cascade as c
from ft_sitl.autopilot.follow import FollowTask, TargetEstimator
from ft_sitl.autopilot.geofence import GF_ACTIONS, Fence, nearest_safe_point
from ft_sitl.autopilot.params import ParamSet
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.physics.platform import Platform
from ft_sitl.physics.quaternion import qfrom_axis_angle, qmul

# PX4 custom modes: main mode, and the sub mode for AUTO
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO, MAIN_ACRO, MAIN_OFFBOARD, MAIN_STABILIZED = (
    1, 2, 3, 4, 5, 6, 7,
)
SUB_READY, SUB_TAKEOFF, SUB_LOITER, SUB_MISSION, SUB_RTL, SUB_LAND = 1, 2, 3, 4, 5, 6
#: PX4's position-mode sub mode of an orbit (MAV_CMD_DO_ORBIT)
SUB_POSCTL_ORBIT = 1
#: PX4's AUTO sub mode of follow-target (follow me)
SUB_FOLLOW_TARGET = 8

MODE_NAMES = {
    (MAIN_MANUAL, 0): "MANUAL",
    (MAIN_ALTCTL, 0): "ALTCTL",
    (MAIN_POSCTL, 0): "POSCTL",
    (MAIN_POSCTL, SUB_POSCTL_ORBIT): "POSCTL.ORBIT",
    (MAIN_AUTO, SUB_READY): "AUTO.READY",
    (MAIN_AUTO, SUB_TAKEOFF): "AUTO.TAKEOFF",
    (MAIN_AUTO, SUB_LOITER): "AUTO.LOITER",
    (MAIN_AUTO, SUB_MISSION): "AUTO.MISSION",
    (MAIN_AUTO, SUB_RTL): "AUTO.RTL",
    (MAIN_AUTO, SUB_LAND): "AUTO.LAND",
    (MAIN_AUTO, SUB_FOLLOW_TARGET): "AUTO.FOLLOW_TARGET",
    (MAIN_ACRO, 0): "ACRO",
    (MAIN_OFFBOARD, 0): "OFFBOARD",
    (MAIN_STABILIZED, 0): "STABILIZED",
}
MODE_BY_NAME = {v: k for k, v in MODE_NAMES.items()}


#: the status text of an arming the geofence refused (Commander.arm_fence_check), PX4's
FENCE_ARM_DENIAL = "Preflight Fail: Geofence violation"


class Result(IntEnum):
    """MAV_RESULT values, so the MAVLink layer can send them as they are."""

    ACCEPTED = 0
    TEMPORARILY_REJECTED = 1
    DENIED = 2
    UNSUPPORTED = 3
    FAILED = 4
    IN_PROGRESS = 5


class LandedState(IntEnum):
    """MAV_LANDED_STATE values."""

    UNDEFINED = 0
    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4


class MissionState(IntEnum):
    """MISSION_STATE values (MISSION_CURRENT.mission_state)."""

    UNKNOWN = 0
    NO_MISSION = 1
    NOT_STARTED = 2
    ACTIVE = 3
    PAUSED = 4
    COMPLETE = 5


class Severity(IntEnum):
    """MAV_SEVERITY values for status texts."""

    EMERGENCY = 0
    ALERT = 1
    CRITICAL = 2
    ERROR = 3
    WARNING = 4
    NOTICE = 5
    INFO = 6


# MAV_CMD ids of the mission items the navigator executes
#: NAV_RCL_ACT's values (PX4's manual control loss actions), by name
NAV_RCL_ACTIONS = {1: "hold", 2: "return", 3: "land", 5: "terminate", 6: "disarm"}
#: the modes flown with the sticks (PX4 multicopters fly MANUAL as STABILIZED)
STICK_MODES = (MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_STABILIZED)
#: the modes PX4 calls manual (its arming checks look at the throttle stick in them)
MANUAL_MODES = STICK_MODES + (MAIN_ACRO,)

#: DO_ORBIT's limits and default speed (PX4: MC_ORBIT_RAD_MAX's default, its 1 m minimum)
ORBIT_MIN_RADIUS_M, ORBIT_MAX_RADIUS_M, ORBIT_DEFAULT_SPEED_M_S = 1.0, 1000.0, 1.0

CMD_NAV_WAYPOINT = 16
CMD_NAV_RETURN_TO_LAUNCH = 20
CMD_NAV_LAND = 21
CMD_NAV_TAKEOFF = 22
CMD_NAV_DELAY = 93
CMD_DO_CHANGE_SPEED = 178


@dataclass(frozen=True)
class MissionItem:
    """One mission item, positions already in local ENU metres (NaN: keep current)."""

    command: int
    position: tuple[float, float, float] = (math.nan, math.nan, math.nan)
    hold_s: float = 0.0
    acceptance_radius_m: float = 0.0
    yaw_rad: float = math.nan
    speed_m_s: float = math.nan
    autocontinue: bool = True


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


@dataclass
class VehicleState:
    """What the commander knows of the vehicle each tick (from the estimator stage)."""

    position: np.ndarray
    velocity: np.ndarray
    yaw: float
    on_ground: bool
    tilt: float = 0.0


@dataclass
class _Nav:
    """The current automatic target."""

    target: np.ndarray | None = None
    yaw: float = math.nan
    phase: str = ""
    t_phase_us: int = 0


@dataclass
class Commander:
    platform: Platform
    params: ParamSet
    time_us: int = 0
    armed: bool = False
    main_mode: int = MAIN_POSCTL
    sub_mode: int = 0
    landed_state: LandedState = LandedState.ON_GROUND
    home: np.ndarray = field(default_factory=lambda: np.zeros(3))
    home_yaw: float = 0.0
    cruise_speed: float = math.nan
    mission: list[MissionItem] = field(default_factory=list)
    mission_seq: int = 0
    mission_state: MissionState = MissionState.NOT_STARTED
    statustexts: deque = field(default_factory=lambda: deque(maxlen=64))
    reached: deque = field(default_factory=lambda: deque(maxlen=64))
    battery: Battery | None = None
    terminated: bool = False
    crashed: bool = False
    #: the geofence (MAV_MISSION_TYPE_FENCE) and rally points (local ENU), see geofence.py
    fence: Fence = field(default_factory=Fence)
    rally: list = field(default_factory=list)
    #: every breach: (time_us, reason, action taken)
    fence_events: list = field(default_factory=list)
    #: injected failures in force: unit name -> (type name, instance) (autopilot.failures)
    failures: dict = field(default_factory=dict)
    #: PX4's arming check on the geofence (HealthAndArmingChecks/checks/geofenceCheck.cpp):
    #: with GF_ACTION not 0 ("none"), a vehicle breaching the fence where it stands is
    #: refused arming, "Preflight Fail: Geofence violation". False: arm anyway (the rule of
    #: trial protocols before 8, missions.spec.PROTOCOLS)
    arm_fence_check: bool = True

    def __post_init__(self):
        self._nav = _Nav()
        self._offboard_sp: Setpoint | None = None
        self._offboard_t_us = -(10**12)
        self._armed_t_us = 0
        self._landed_since_us: int | None = 0
        self._took_off = False
        self._state: VehicleState | None = None
        self._last_sp = Setpoint.off()
        self._hold_sp: np.ndarray | None = None
        self._item_started = False
        self._item_hold_until: int | None = None
        if self.battery is None:
            self.battery = Battery.for_platform(self.platform, self.params["FT_BAT_ENDURANCE"])
        self.mission_state = MissionState.NO_MISSION
        self._bat_warned = 0
        self._fence_breached = False
        self._rtl_dest = self.home.copy()
        self._mission_takeoff: np.ndarray | None = None
        self._gps_lost_us: int | None = None
        #: an orbit: (centre, signed radius, speed, yaw behaviour, initial yaw)
        self.orbit_state: tuple | None = None
        self._init_follow()
        self._init_manual()

    # --- helpers -------------------------------------------------------------------
    @property
    def mode_name(self) -> str:
        return MODE_NAMES.get((self.main_mode, self.sub_mode), "UNKNOWN")

    def text(self, severity: Severity, msg: str) -> None:
        self.statustexts.append((int(severity), msg))

    def _deny(self, msg: str, result: Result = Result.DENIED) -> Result:
        self.text(Severity.CRITICAL, msg)
        return result

    def _pos(self) -> np.ndarray:
        return self._state.position.copy() if self._state is not None else self.home.copy()

    def _yaw(self) -> float:
        return self._state.yaw if self._state is not None else self.home_yaw

    def _set_mode(self, main: int, sub: int = 0) -> None:
        self.main_mode, self.sub_mode = main, sub

    def _hold_here(self) -> None:
        self._nav = _Nav(target=self._pos(), yaw=self._yaw(), phase="hold",
                         t_phase_us=self.time_us)

    # --- arming --------------------------------------------------------------------
    def offboard_fresh(self) -> bool:
        return (self._offboard_sp is not None and
                self.time_us - self._offboard_t_us <= self.params["COM_OF_LOSS_T"] * 1e6)

    def arm(self, force: bool = False) -> Result:
        if self.armed:
            return Result.ACCEPTED
        if not force:
            if self.terminated:
                return self._deny("Arming denied: flight terminated, reboot required")
            if self.landed_state != LandedState.ON_GROUND:
                return self._deny("Arming denied: vehicle not landed")
            if self.battery.remaining < self.params["BAT_CRIT_THR"]:
                return self._deny("Arming denied: battery critically low")
            if self.main_mode == MAIN_OFFBOARD and not self.offboard_fresh():
                return self._deny("Arming denied: no offboard setpoints")
            if self.main_mode == MAIN_AUTO and self.sub_mode == SUB_MISSION and not self.mission:
                return self._deny("Arming denied: no valid mission")
            if self._follow_active():
                return self._deny("Arming denied: mode not suitable for arming")
            if self.arm_fence_check and self.fence_breach_here() is not None:
                return self._deny(FENCE_ARM_DENIAL)
            why = self._manual_arm_check()
            if why:
                return self._deny(why)
        self._manual_on_arm()
        self.armed = True
        self._armed_t_us = self.time_us
        self._took_off = False
        self._landed_since_us = self.time_us if self.landed_state == LandedState.ON_GROUND \
            else None
        if self.main_mode in (MAIN_POSCTL, MAIN_ALTCTL, MAIN_MANUAL, MAIN_STABILIZED,
                              MAIN_ACRO) or (self.main_mode == MAIN_AUTO
                                             and self.sub_mode == SUB_LOITER):
            self._hold_here()
        self.text(Severity.INFO, "Armed by external command")
        return Result.ACCEPTED

    def disarm(self, force: bool = False) -> Result:
        if not self.armed:
            return Result.ACCEPTED
        if not force and self.landed_state not in (LandedState.ON_GROUND,):
            return self._deny("Disarming denied: not landed")
        self._disarm("Disarmed by external command")
        return Result.ACCEPTED

    def _disarm(self, why: str) -> None:
        self.armed = False
        self.text(Severity.INFO, why)
        if self.main_mode == MAIN_AUTO and self.sub_mode in (SUB_LAND, SUB_RTL, SUB_TAKEOFF,
                                                             SUB_FOLLOW_TARGET):
            self._set_mode(MAIN_AUTO, SUB_LOITER)

    def terminate(self) -> Result:
        """MAV_CMD_DO_FLIGHTTERMINATION: motors off now, wherever the vehicle is."""
        self.terminated = True
        self.armed = False
        self.text(Severity.EMERGENCY, "Flight termination active")
        return Result.ACCEPTED

    def crash(self, what: str, speed_m_s: float) -> None:
        """The vehicle hit something: motors off now, as after a flight termination."""
        self.crashed = True
        self.terminated = True
        self.armed = False
        self.text(Severity.EMERGENCY,
                  f"Collision: hit {what} at {speed_m_s:.1f} m/s, motors stopped")

    # --- modes ----------------------------------------------------------------------
    def set_mode(self, main: int, sub: int = 0) -> Result:
        key = (main, sub if main == MAIN_AUTO else 0)
        if key not in MODE_NAMES:
            return self._deny(f"Mode {main}/{sub} is not supported", Result.UNSUPPORTED)
        main, sub = key
        if main == MAIN_OFFBOARD and not self.offboard_fresh():
            return self._deny("Switching to Offboard is currently not available",
                              Result.TEMPORARILY_REJECTED)
        if main == MAIN_AUTO and sub == SUB_MISSION and not self.mission:
            return self._deny("Switching to Mission is currently not available: no mission",
                              Result.TEMPORARILY_REJECTED)
        if main == MAIN_AUTO and sub == SUB_READY:
            sub = SUB_LOITER
        if (main, sub) == (self.main_mode, self.sub_mode):
            return Result.ACCEPTED
        self._set_mode(main, sub)
        if main in (MAIN_POSCTL, MAIN_ALTCTL, MAIN_MANUAL, MAIN_STABILIZED, MAIN_ACRO):
            self._hold_here()
        elif main == MAIN_AUTO:
            self._enter_auto(sub)
        return Result.ACCEPTED

    def _enter_auto(self, sub: int) -> None:
        if sub == SUB_LOITER:
            self._hold_here()
        elif sub == SUB_TAKEOFF:
            self._start_takeoff(self._default_takeoff_alt())
        elif sub == SUB_LAND:
            self._nav = _Nav(target=self._pos(), yaw=self._yaw(), phase="land",
                             t_phase_us=self.time_us)
            self.text(Severity.INFO, "Landing at current position")
        elif sub == SUB_RTL:
            self._start_rtl()
        elif sub == SUB_FOLLOW_TARGET:
            self._start_follow()
        elif sub == SUB_MISSION:
            if (self.mission_state in (MissionState.NOT_STARTED, MissionState.COMPLETE)
                    or self.mission_seq >= len(self.mission)):
                if self.mission_seq >= len(self.mission):
                    self.mission_seq = 0
            self.mission_state = MissionState.ACTIVE
            self._item_started = False
            self._item_hold_until = None

    def takeoff(self, altitude_m: float | None = None) -> Result:
        """Climb to the altitude (local z, m; never down) or, if None or not finite,
        MIS_TAKEOFF_ALT above the current altitude, at the current horizontal position."""
        if altitude_m is not None and not math.isfinite(altitude_m):
            altitude_m = None
        alt = self._default_takeoff_alt() if altitude_m is None else altitude_m
        self._set_mode(MAIN_AUTO, SUB_TAKEOFF)
        self._start_takeoff(alt)
        return Result.ACCEPTED

    def nav_takeoff(self, altitude_m: float | None = None) -> Result:
        """MAV_CMD_NAV_TAKEOFF as PX4's navigator takes it (takeoff.cpp, up to v1.14): the
        target (local z, m) is at least MIS_TAKEOFF_ALT above the current altitude. A lower
        one (e.g. a height above home sent as param7, which is AMSL) is raised to that
        minimum with a critical message; None or NaN means the minimum."""
        minimum = self._default_takeoff_alt()
        if altitude_m is not None and math.isfinite(altitude_m) and altitude_m < minimum:
            if altitude_m < minimum - 0.1:  # PX4: no complaint within 10 cm
                self.text(Severity.CRITICAL, "Using minimum takeoff altitude: "
                          f"{self.params['MIS_TAKEOFF_ALT']:.2f} m")
            altitude_m = minimum
        return self.takeoff(altitude_m)

    def _default_takeoff_alt(self) -> float:
        """MIS_TAKEOFF_ALT above the current altitude (PX4: global altitude + MIS_TAKEOFF_ALT;
        on the ground at home, above home)."""
        return float(self._pos()[2]) + self.params["MIS_TAKEOFF_ALT"]

    def _start_takeoff(self, alt: float) -> None:
        p = self._pos()
        p[2] = max(alt, p[2])
        self._nav = _Nav(target=p, yaw=self._yaw(), phase="takeoff", t_phase_us=self.time_us)
        self.text(Severity.INFO, f"Takeoff to {alt - self.home[2]:.1f} m above home")

    def land(self) -> Result:
        self._set_mode(MAIN_AUTO, SUB_LAND)
        self._enter_auto(SUB_LAND)
        return Result.ACCEPTED

    def return_to_launch(self) -> Result:
        self._set_mode(MAIN_AUTO, SUB_RTL)
        self._start_rtl()
        return Result.ACCEPTED

    def _start_rtl(self) -> None:
        p = self._pos()
        # PX4: the nearest safe point, home or a rally point
        self._rtl_dest = nearest_safe_point(p, self.home, self.rally)
        climb = max(p[2], self.home[2] + self.params["RTL_RETURN_ALT"])
        self._nav = _Nav(target=np.array([p[0], p[1], climb]), yaw=self._yaw(),
                         phase="rtl_climb", t_phase_us=self.time_us)
        where = "home" if self._rtl_to_home() else "rally point"
        self.text(Severity.INFO, f"RTL: start return to {where} at "
                  f"{climb - self.home[2]:.0f} m above home")

    def _rtl_to_home(self) -> bool:
        return bool(np.allclose(self._rtl_dest[:2], self.home[:2]))

    def hold(self) -> Result:
        return self.set_mode(MAIN_AUTO, SUB_LOITER)

    def reposition(self, position: np.ndarray, yaw: float = math.nan) -> Result:
        """DO_REPOSITION: fly to a local position and hold there (mode AUTO.LOITER)."""
        if not self.armed or self.landed_state == LandedState.ON_GROUND:
            return self._deny("Reposition denied: not flying", Result.TEMPORARILY_REJECTED)
        target = self._pos()
        for i in range(3):
            if math.isfinite(position[i]):
                target[i] = position[i]
        self._set_mode(MAIN_AUTO, SUB_LOITER)
        self._nav = _Nav(target=target, yaw=yaw if math.isfinite(yaw) else self._yaw(),
                         phase="goto", t_phase_us=self.time_us)
        return Result.ACCEPTED

    # --- orbit ---------------------------------------------------------------------------
    def orbit(self, center: np.ndarray, radius_m: float, speed_m_s: float,
              yaw_behaviour: int) -> Result:
        """MAV_CMD_DO_ORBIT: circle ``center`` (local ENU; NaN x/y: the current position,
        NaN z: the current altitude) at ``radius_m`` (positive: clockwise seen from above,
        PX4's sign) and ``speed_m_s`` (NaN: ORBIT_DEFAULT_SPEED); ``yaw_behaviour`` is
        MAVLink's ORBIT_YAW_BEHAVIOUR. Mode POSCTL.ORBIT, as PX4."""
        if not self.armed or self.landed_state == LandedState.ON_GROUND:
            return self._deny("Orbit denied: not flying", Result.TEMPORARILY_REJECTED)
        if not math.isfinite(radius_m) or not ORBIT_MIN_RADIUS_M <= abs(radius_m) \
                <= ORBIT_MAX_RADIUS_M:
            return self._deny(f"Orbit denied: radius must be {ORBIT_MIN_RADIUS_M:g} to "
                              f"{ORBIT_MAX_RADIUS_M:g} m", Result.DENIED)
        p = self._pos()
        c = np.array([center[i] if math.isfinite(center[i]) else p[i] for i in range(3)])
        speed = abs(speed_m_s) if math.isfinite(speed_m_s) and speed_m_s != 0 \
            else ORBIT_DEFAULT_SPEED_M_S
        # the centripetal acceleration within MPC_ACC_HOR_MAX, the speed within the cap
        speed = min(speed, self.params["MPC_XY_VEL_MAX"],
                    math.sqrt(self.params["MPC_ACC_HOR_MAX"] * abs(radius_m)))
        self.orbit_state = (c, float(radius_m), speed, int(yaw_behaviour), self._yaw())
        self._set_mode(MAIN_POSCTL, SUB_POSCTL_ORBIT)
        self.text(Severity.INFO, f"Orbit: radius {abs(radius_m):.1f} m at {speed:.1f} m/s")
        return Result.ACCEPTED

    def _orbit_setpoint(self, s: VehicleState) -> Setpoint:
        c, r, v, yaw_mode, yaw0 = self.orbit_state
        d = s.position[:2] - c[:2]
        dist = float(np.hypot(*d))
        er = d / dist if dist > 1e-3 else np.array([1.0, 0.0])
        # positive radius: clockwise seen from above (east-north plane: -90 deg from e_r)
        et = np.array([er[1], -er[0]]) if r > 0 else np.array([-er[1], er[0]])
        radial = _clamp_abs(self.params["MPC_XY_P"] * (abs(r) - dist), self._cruise())
        vel = v * et + radial * er
        acc = -(v * v / abs(r)) * er if abs(abs(r) - dist) < 0.2 * abs(r) else np.zeros(2)
        if yaw_mode == 0:  # front to the centre
            yaw = math.atan2(-er[1], -er[0])
        elif yaw_mode == 3:  # front along the tangent
            yaw = math.atan2(et[1], et[0])
        elif yaw_mode == 2:  # uncontrolled: wherever it points
            yaw = math.nan
        else:  # the initial heading (1; RC-controlled, 4, without RC)
            yaw = yaw0
        return Setpoint.trajectory(position=[math.nan, math.nan, c[2]],
                                   velocity=[vel[0], vel[1], math.nan],
                                   acceleration=[acc[0], acc[1], math.nan], yaw=yaw)

    # --- follow target ----------------------------------------------------------------
    def _init_follow(self) -> None:
        #: the follow-target estimate (FOLLOW_TARGET messages) and flight task (follow.py)
        self.follow_target = TargetEstimator()
        self._follow_task = FollowTask()
        self._follow_t_us = 0
        self._follow_lost_said = False

    def _follow_active(self) -> bool:
        return self.main_mode == MAIN_AUTO and self.sub_mode == SUB_FOLLOW_TARGET

    def follow_target_measurement(self, t_us: int, position: np.ndarray,
                                  velocity: np.ndarray | None) -> None:
        """A FOLLOW_TARGET fix: local ENU position (z NaN: altitude unknown) and ENU
        velocity (None: unknown), already checked by the caller."""
        self.follow_target.measure(t_us, position, velocity, self.params["FLW_TGT_RS"])

    def _start_follow(self) -> None:
        """AUTO.FOLLOW_TARGET: a fresh flight task; a target lost (or never heard) starts
        a fresh estimate too, as PX4 starts its estimator with the task."""
        if self.follow_target.lost(self.time_us):
            self.follow_target = TargetEstimator()
        self._follow_task = FollowTask(yaw=self._yaw())
        self._follow_t_us = self.time_us
        self._follow_lost_said = False
        self._hold_here()
        self.text(Severity.INFO, "Follow target: following")

    def _follow_setpoint(self, s: VehicleState) -> Setpoint:
        if s.on_ground:  # PX4 refuses arming in it; on the ground it stays idle here
            return self._on_ground_idle()
        dt = max(self.time_us - self._follow_t_us, 0) * 1e-6
        self._follow_t_us = self.time_us
        est = self.follow_target
        if not est.valid:  # no target yet: hold where the mode was entered
            if self._nav.target is None:
                self._hold_here()
            return Setpoint.position(self._nav.target, yaw=self._nav.yaw)
        lost = est.lost(self.time_us)
        if lost and not self._follow_lost_said:
            self.text(Severity.WARNING, "Follow target lost: holding")
        elif not lost and self._follow_lost_said:
            self.text(Severity.INFO, "Follow target found again")
        self._follow_lost_said = lost
        target, target_vel = est.estimate(self.time_us)
        pos, vel, acc, yaw = self._follow_task.setpoint(dt, s.position, target, target_vel,
                                                        self.params, self.home[2])
        return Setpoint.trajectory(pos, vel, acc, yaw=yaw)

    def change_speed(self, speed_m_s: float) -> Result:
        if not math.isfinite(speed_m_s) or speed_m_s <= 0:
            self.cruise_speed = math.nan  # -1 / NaN: back to the default
        else:
            self.cruise_speed = speed_m_s
        return Result.ACCEPTED

    def set_home(self, position: np.ndarray) -> Result:
        self.home = np.asarray(position, dtype=float).copy()
        return Result.ACCEPTED

    # --- offboard ------------------------------------------------------------------
    def offboard_setpoint(self, sp: Setpoint) -> None:
        """A validated offboard setpoint arrived (it keeps the stream fresh)."""
        self._offboard_sp = sp.offboard()
        self._offboard_t_us = self.time_us

    # --- mission -------------------------------------------------------------------
    def set_mission(self, items: list[MissionItem]) -> None:
        self.mission = list(items)
        self._mission_takeoff = None
        self.mission_seq = 0
        self.mission_state = MissionState.NOT_STARTED if items else MissionState.NO_MISSION
        self._item_started = False
        if not items and self.main_mode == MAIN_AUTO and self.sub_mode == SUB_MISSION:
            self._set_mode(MAIN_AUTO, SUB_LOITER)
            self._hold_here()

    def set_mission_current(self, seq: int) -> Result:
        if not 0 <= seq < max(1, len(self.mission)):
            return Result.DENIED
        self.mission_seq = seq
        self._item_started = False
        self._item_hold_until = None
        if self.mission_state == MissionState.COMPLETE:
            self.mission_state = MissionState.NOT_STARTED
        return Result.ACCEPTED

    # --- the tick ----------------------------------------------------------------------
    def update(self, time_us: int, state: VehicleState, mech_energy_j: float) -> Setpoint:
        """Advance the commander to time_us and return the cascade's setpoint."""
        self.time_us = time_us
        self._state = state
        self.battery.draw(mech_energy_j)
        self._update_landed(state)
        self._battery_failsafe()
        self._geofence_check(state)
        self._position_loss_failsafe(state)
        self._manual_control_failsafe(state)
        if not self.armed:
            return self._emit(Setpoint.off())
        if self._auto_disarm():
            return self._emit(Setpoint.off())
        sp = self._mode_setpoint(state)
        return self._emit(sp)

    def _emit(self, sp: Setpoint) -> Setpoint:
        self._last_sp = sp
        return sp

    def _update_landed(self, s: VehicleState) -> None:
        if s.on_ground:
            if self.landed_state != LandedState.ON_GROUND:
                self.landed_state = LandedState.ON_GROUND
                self._landed_since_us = self.time_us
                if self._took_off:
                    self.text(Severity.INFO, "Landing detected")
        elif self.armed:
            if self.landed_state == LandedState.ON_GROUND:
                self._took_off = True
                self._landed_since_us = None
            if self.main_mode == MAIN_AUTO and self.sub_mode == SUB_TAKEOFF:
                self.landed_state = LandedState.TAKEOFF
            elif self.main_mode == MAIN_AUTO and (
                self.sub_mode == SUB_LAND or (self.sub_mode == SUB_RTL
                                              and self._nav.phase == "rtl_land")):
                self.landed_state = LandedState.LANDING
            else:
                self.landed_state = LandedState.IN_AIR
        else:
            self.landed_state = LandedState.IN_AIR

    def _auto_disarm(self) -> bool:
        if self.landed_state != LandedState.ON_GROUND or self._landed_since_us is None:
            return False
        waited = (self.time_us - self._landed_since_us) * 1e-6
        if self._took_off:
            limit = self.params["COM_DISARM_LAND"]
            why = "Disarmed by landing"
        else:
            limit = self.params["COM_DISARM_PRFLT"]
            why = "Disarmed: no takeoff"
            if self.main_mode == MAIN_AUTO and self.sub_mode in (SUB_TAKEOFF, SUB_MISSION):
                return False
            if self.main_mode == MAIN_OFFBOARD:
                return False
        if limit >= 0 and waited > limit:
            self._disarm(why)
            return True
        return False

    def _battery_failsafe(self) -> None:
        rem = self.battery.remaining
        if rem < self.params["BAT_EMERGEN_THR"] and self._bat_warned < 3:
            self._bat_warned = 3
            self.text(Severity.EMERGENCY, "Battery emergency: landing")
            if self.armed and self.landed_state != LandedState.ON_GROUND:
                self.land()
        elif rem < self.params["BAT_CRIT_THR"] and self._bat_warned < 2:
            self._bat_warned = 2
            self.text(Severity.CRITICAL, "Battery critical: returning")
            if self.armed and self.landed_state != LandedState.ON_GROUND:
                self.return_to_launch()
        elif rem < self.params["BAT_LOW_THR"] and self._bat_warned < 1:
            self._bat_warned = 1
            self.text(Severity.WARNING, "Battery low")

    # --- injected failures --------------------------------------------------------------
    def record_failure(self, unit: str, ftype: str, instance: int) -> None:
        """An injected failure (ft_sitl.sim.fleet.Fleet.inject_failure applies its
        physics); ``ok`` clears the unit."""
        if ftype == "ok":
            if self.failures.pop(unit, None) is not None:
                self.text(Severity.INFO, f"Failure injection: {unit} ok")
            if unit == "gps":
                self._gps_lost_us = None
            if unit == "battery":
                self.battery.failed = False
            return
        self.failures[unit] = (ftype, instance)
        which = f" {instance}" if instance else ""
        self.text(Severity.WARNING, f"Failure injection: {unit}{which} {ftype}")
        if unit == "gps":
            self._gps_lost_us = self.time_us
        if unit == "battery":
            self.battery.failed = True

    def sensor_ok(self, unit: str) -> bool:
        return unit not in self.failures

    def _position_loss_failsafe(self, s: VehicleState) -> None:
        """PX4: no position (GPS lost) for COM_POS_FS_DELAY in the air: land."""
        lost = self._gps_lost_us
        if lost is None or not self.armed or s.on_ground or self.terminated:
            return
        if self.time_us - lost < self.params["COM_POS_FS_DELAY"] * 1e6:
            return
        self._gps_lost_us = None  # (once)
        if self.main_mode == MAIN_AUTO and self.sub_mode == SUB_LAND:
            return
        self.text(Severity.CRITICAL, "Failsafe: no position estimate, landing")
        self.land()

    # --- manual control (MANUAL_CONTROL sticks, RC loss) ---------------------------------
    def _init_manual(self) -> None:
        #: the latest sticks (x pitch, y roll, z throttle 0..1, r yaw) and when they came
        self.sticks: tuple[float, float, float, float] = (0.0, 0.0, 0.5, 0.0)
        self._man_t_us: int | None = None
        self._man_lost = False
        self._man_lost_at_arming = True
        #: the failsafe in force: (action, mode it set, due time of a delayed action or None)
        self._man_fs: tuple | None = None
        self._man_user_mode: tuple[int, int] = (MAIN_POSCTL, 0)
        #: position/altitude/yaw locks of the stick modes, and the mode and time they are for
        self._man_lock_xy: np.ndarray | None = None
        self._man_lock_z: float | None = None
        self._man_yaw: float | None = None
        self._man_key: tuple = ()
        self._man_tick_us = 0

    def manual_control(self, x: float, y: float, z: float, r: float) -> bool:
        """New stick positions, as PX4 reads MANUAL_CONTROL: x pitch (forward +), y roll
        (right +), r yaw (clockwise +) in -1..1, z throttle in 0..1. Values outside are
        clamped; a non-finite one refuses the whole input (False). Ignored (False) when
        COM_RC_IN_MODE allows no joystick (0 RC only, 4 disabled)."""
        if int(self.params["COM_RC_IN_MODE"]) not in (1, 2, 3):
            return False
        vals = (x, y, z, r)
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in vals):
            return False
        self.sticks = (min(1.0, max(-1.0, float(x))), min(1.0, max(-1.0, float(y))),
                       min(1.0, max(0.0, float(z))), min(1.0, max(-1.0, float(r))))
        self._man_t_us = self.time_us
        return True

    def manual_fresh(self) -> bool:
        """Sticks arrived within COM_RC_LOSS_T."""
        return (self._man_t_us is not None and
                self.time_us - self._man_t_us <= self.params["COM_RC_LOSS_T"] * 1e6)

    def _manual_arm_check(self) -> str:
        """PX4's stick checks at arming in a manual mode (Commander.cpp): with a climb-rate
        mode (ALTCTL, POSCTL) the throttle must not be above centre (> 0.6 of 0..1), in the
        others it must be low (< 0.1)."""
        if self.main_mode not in MANUAL_MODES or not self.manual_fresh():
            return ""
        throttle = 2.0 * self.sticks[2] - 1.0
        if self.main_mode in (MAIN_POSCTL, MAIN_ALTCTL):
            return "Arming denied: throttle above center" if throttle > 0.2 else ""
        return "Arming denied: high throttle" if throttle >= -0.8 else ""

    def _manual_on_arm(self) -> None:
        # PX4: without manual control at arming, its loss is no failsafe until it comes
        self._man_lost_at_arming = not self.manual_fresh()
        self._man_key = ()

    @staticmethod
    def _deadzone(v: float, dz: float) -> float:
        if dz >= 1.0 or abs(v) <= dz:
            return 0.0
        return (v - math.copysign(dz, v)) / (1.0 - dz)

    def _man_climb_rate(self, dz: float) -> float:
        """Climb rate (m/s, up +) from the throttle around its centre."""
        t = self._deadzone(2.0 * self.sticks[2] - 1.0, dz)
        return t * (self.params["MPC_Z_VEL_MAX_UP"] if t > 0 else
                    self.params["MPC_Z_VEL_MAX_DN"])

    def _manual_setpoint(self, s: VehicleState) -> Setpoint:
        """The stick modes, as PX4's flight tasks fly them (see docs/mavlink.md, Manual
        control): POSCTL velocity, ALTCTL tilt, both with climb rate and position,
        altitude and heading locks at centred sticks; MANUAL / STABILIZED attitude and
        direct throttle."""
        key = (self.main_mode, self.sub_mode)
        if key != self._man_key or self.time_us - self._man_tick_us > 200_000:
            self._man_key = key
            self._man_lock_xy, self._man_lock_z, self._man_yaw = None, None, None
        dt = min(max(self.time_us - self._man_tick_us, 0), 200_000) * 1e-6
        self._man_tick_us = self.time_us
        x, y, _, r = self.sticks
        dz = self.params["MPC_HOLD_DZ"]
        xs, ys, rs = self._deadzone(x, dz), self._deadzone(y, dz), self._deadzone(r, dz)
        norm = math.hypot(xs, ys)
        if norm > 1.0:
            xs, ys, norm = xs / norm, ys / norm, 1.0
        yaw_rate = -rs * math.radians(self.params["MPC_MAN_Y_MAX"])  # ENU: counter-clockwise
        cy, sy = math.cos(s.yaw), math.sin(s.yaw)

        def body_to_enu(fwd: float, right: float) -> tuple[float, float]:
            return fwd * cy + right * sy, fwd * sy - right * cy

        if self.main_mode in (MAIN_POSCTL, MAIN_ALTCTL):
            vz = self._man_climb_rate(dz)
            if s.on_ground:
                self._man_lock_xy, self._man_lock_z, self._man_yaw = None, None, None
                if 2.0 * self.sticks[2] - 1.0 <= 0.3:  # PX4 takes off above 65 % throttle
                    return self._on_ground_idle()
                return Setpoint.trajectory(position=[s.position[0], s.position[1], math.nan],
                                           velocity=[math.nan, math.nan, max(vz, 0.0)],
                                           yaw=s.yaw)
            pos, vel, acc = [math.nan] * 3, [math.nan] * 3, [math.nan] * 3
            if self.main_mode == MAIN_POSCTL:
                vmax = min(self.params["MPC_VEL_MANUAL"], self.params["MPC_XY_VEL_MAX"])
                if xs or ys:
                    self._man_lock_xy = None
                    vel[0], vel[1] = body_to_enu(xs * vmax, ys * vmax)
                else:
                    hold = self.params["MPC_HOLD_MAX_XY"]
                    if self._man_lock_xy is None and (
                            hold <= 0 or math.hypot(*s.velocity[:2]) < hold):
                        self._man_lock_xy = s.position[:2].copy()
                    if self._man_lock_xy is None:
                        vel[0], vel[1] = 0.0, 0.0
                    else:
                        pos[0], pos[1] = self._man_lock_xy
            else:  # ALTCTL: the sticks tilt the vehicle, as an acceleration
                scale = G * math.tan(norm * math.radians(self.params["MPC_MAN_TILT_MAX"])) \
                    / norm if norm else 0.0
                acc[0], acc[1] = body_to_enu(xs * scale, ys * scale)
            if vz:
                self._man_lock_z = None
                vel[2] = vz
            else:
                hold_z = self.params["MPC_HOLD_MAX_Z"]
                if self._man_lock_z is None and (hold_z <= 0 or abs(s.velocity[2]) < hold_z):
                    self._man_lock_z = float(s.position[2])
                if self._man_lock_z is None:
                    vel[2] = 0.0
                else:
                    pos[2] = self._man_lock_z
            if rs:
                self._man_yaw = None
                yaw, yr = None, yaw_rate
            else:
                if self._man_yaw is None:
                    self._man_yaw = s.yaw
                yaw, yr = self._man_yaw, None
            sp = Setpoint.trajectory(position=pos, velocity=vel, acceleration=acc, yaw=yaw,
                                     yaw_rate=yr)
            # the tilt of ALTCTL is bound by the tilt limit only, not by MPC_ACC_HOR_MAX
            return sp.offboard() if self.main_mode == MAIN_ALTCTL else sp
        # MANUAL / STABILIZED: attitude from the sticks, throttle direct
        t = 2.0 * self.sticks[2] - 1.0
        hover = min(max(hover_thrust(self.platform), 0.05), 0.95)
        lo, hi = self.params["MPC_MANTHR_MIN"], self.params["MPC_THR_MAX"]
        thrust = lo + (hover - lo) * (t + 1.0) if t < 0 else hover + (hi - hover) * t
        thrust = min(max(thrust, 0.0), 1.0)
        if self._man_yaw is None or s.on_ground:
            self._man_yaw = s.yaw
        if s.on_ground and thrust <= hover:
            return self._on_ground_idle()
        self._man_yaw = _wrap_pi(self._man_yaw + yaw_rate * dt)
        tmax = math.radians(self.params["MPC_MAN_TILT_MAX"])
        # FLU: forward stick pitches the nose down (+y rotation), right stick rolls right
        rv = np.array([ys * tmax, xs * tmax, 0.0])
        angle = float(np.linalg.norm(rv))
        q_yaw = np.array([math.cos(self._man_yaw / 2), 0.0, 0.0, math.sin(self._man_yaw / 2)])
        q_tilt = qfrom_axis_angle(rv, angle) if angle > 0 else np.array([1.0, 0, 0, 0])
        return Setpoint.attitude(qmul(q_yaw, q_tilt), thrust)

    def _manual_control_failsafe(self, s: VehicleState) -> None:
        """PX4's manual control loss: sticks that came and stopped for COM_RC_LOSS_T take
        NAV_RCL_ACT (after COM_FAIL_ACT_T in Hold, for hold/return/land), unless the mode
        is exempt by COM_RCL_EXCEPT, or the sticks were already absent at arming."""
        if self._man_t_us is None:
            return
        if self.manual_fresh():
            if self._man_lost:
                self._man_lost = False
                gap = (self.time_us - self._man_t_us) * 1e-6
                self.text(Severity.INFO, f"Manual control regained after {gap:.1f} s")
                self._manual_regained()
            self._man_lost_at_arming = False
            return
        if not self._man_lost:
            self._man_lost = True
            self.text(Severity.INFO, "Manual control lost")
            self._manual_lost(s)
        if self._man_fs is not None:
            action, mode, due = self._man_fs
            if (self.main_mode, self.sub_mode) != mode:  # the user changed mode: over
                self._man_fs = None
            elif due is not None and self.time_us >= due:
                self._manual_fs_act(action)

    def _manual_lost(self, s: VehicleState) -> None:
        if not self.armed or self.terminated or self._man_lost_at_arming:
            return
        mode = (self.main_mode, self.sub_mode)
        exc = int(self.params["COM_RCL_EXCEPT"])
        if ((mode == (MAIN_AUTO, SUB_MISSION) and exc & 1)
                or (mode in ((MAIN_AUTO, SUB_LOITER), (MAIN_AUTO, SUB_TAKEOFF)) and exc & 2)
                or (mode == (MAIN_OFFBOARD, 0) and exc & 4)
                or mode in ((MAIN_AUTO, SUB_RTL), (MAIN_AUTO, SUB_LAND))):
            return
        action = int(self.params["NAV_RCL_ACT"])
        if action in (5, 6):  # terminate, disarm: at once, wherever it is
            self._man_user_mode = mode
            self._manual_fs_act(action)
            return
        if action not in (1, 2, 3) or s.on_ground:
            return
        self._man_user_mode = mode
        delay = self.params["COM_FAIL_ACT_T"]
        self._set_mode(MAIN_AUTO, SUB_LOITER)
        self._hold_here()
        if delay > 0.1 and action != 1:
            self.text(Severity.CRITICAL,
                      f"Failsafe activated: entering Hold for {round(delay)} seconds")
            self._man_fs = (action, (MAIN_AUTO, SUB_LOITER),
                            self.time_us + int(delay * 1e6))
        else:
            self._manual_fs_act(action)

    def _manual_fs_act(self, action: int) -> None:
        name = NAV_RCL_ACTIONS.get(action, "none")
        self.text(Severity.CRITICAL, f"Manual control lost: failsafe {name}")
        if action == 1:
            self._set_mode(MAIN_AUTO, SUB_LOITER)
            self._hold_here()
        elif action == 2:
            self.return_to_launch()
        elif action == 3:
            self.land()
        elif action == 5:
            self.terminate()
        elif action == 6:
            if self.armed:
                self._disarm("Disarmed by failsafe")
        self._man_fs = (action, (self.main_mode, self.sub_mode), None) \
            if action in (1, 2, 3) else None

    def _manual_regained(self) -> None:
        """PX4 clears a hold or land failsafe (and the hold before a delayed action) when
        the sticks come back: the vehicle returns to the mode it was in. A return goes on
        until the user changes mode."""
        if self._man_fs is None:
            return
        action, mode, due = self._man_fs
        self._man_fs = None
        if (self.main_mode, self.sub_mode) != mode or (action == 2 and due is None):
            return
        if not self.armed:
            return
        main, sub = self._man_user_mode
        self._set_mode(main, sub)
        self._man_key = ()
        if main == MAIN_AUTO:
            self._enter_auto(sub)
        else:
            self._hold_here()

    # --- geofence ------------------------------------------------------------------------
    def set_fence(self, fence: Fence) -> None:
        self.fence = fence
        self._fence_breached = False

    def set_rally(self, points) -> None:
        self.rally = [np.asarray(p, dtype=float).copy() for p in points]

    @property
    def geofence_active(self) -> bool:
        """A fence is uploaded, or a maximum distance or height from home is set."""
        return (not self.fence.empty or self.params["GF_MAX_HOR_DIST"] > 0
                or self.params["GF_MAX_VER_DIST"] > 0)

    @property
    def fence_breached(self) -> bool:
        return self._fence_breached

    def fence_breach_here(self) -> str | None:
        """Why the vehicle where it is now breaches the geofence, when a breach would act
        (GF_ACTION not 0, as PX4's navigator only checks then); None otherwise."""
        if int(self.params["GF_ACTION"]) == 0:
            return None
        return self.fence.breach(self._pos(), self.home, self.params["GF_MAX_HOR_DIST"],
                                 self.params["GF_MAX_VER_DIST"])

    def _geofence_check(self, s: VehicleState) -> None:
        """PX4's geofence: in the air, a breach (entering it, not staying in it) takes
        GF_ACTION once; back inside, the next breach acts again."""
        if not self.armed or s.on_ground or self.terminated:
            return
        reason = self.fence.breach(s.position, self.home, self.params["GF_MAX_HOR_DIST"],
                                   self.params["GF_MAX_VER_DIST"])
        if reason is None:
            self._fence_breached = False
            return
        if self._fence_breached:
            return
        self._fence_breached = True
        action = int(self.params["GF_ACTION"])
        name = GF_ACTIONS.get(action, "none")
        self.fence_events.append((self.time_us, reason, name))
        if action == 0:
            return
        self.text(Severity.CRITICAL, f"Geofence breached: {reason}")
        if action == 2:
            self._set_mode(MAIN_AUTO, SUB_LOITER)
            self._hold_here()
        elif action == 3:
            self.return_to_launch()
        elif action == 4:
            self.terminate()
        elif action == 5:
            self.land()

    def _on_ground_idle(self) -> Setpoint:
        return Setpoint.idle()

    def _mode_setpoint(self, s: VehicleState) -> Setpoint:
        if self.main_mode == MAIN_OFFBOARD:
            if not self.offboard_fresh():
                self.text(Severity.CRITICAL, "Offboard signal lost: holding position")
                self._set_mode(MAIN_AUTO, SUB_LOITER)
                self._hold_here()
            else:
                sp = self._offboard_sp
                if s.on_ground and sp.kind == 2 and not self._wants_up(sp, s):
                    return self._on_ground_idle()
                return sp
        if self.main_mode == MAIN_AUTO:
            return self._auto_setpoint(s)
        if (self.main_mode, self.sub_mode) == (MAIN_POSCTL, SUB_POSCTL_ORBIT):
            if s.on_ground or self.orbit_state is None:
                self._set_mode(MAIN_POSCTL)
            else:
                return self._orbit_setpoint(s)
        if self.manual_fresh() and self.main_mode in STICK_MODES:
            return self._manual_setpoint(s)
        # POSCTL / ALTCTL / MANUAL / STABILIZED / ACRO without sticks: hold
        if s.on_ground:
            self._hold_here()
            return self._on_ground_idle()
        if self._nav.target is None:
            self._hold_here()
        return Setpoint.position(self._nav.target, yaw=self._nav.yaw)

    @staticmethod
    def _wants_up(sp: Setpoint, s: VehicleState) -> bool:
        row = sp.row
        pz, vz, az = row[c.SP_POS + 2], row[c.SP_VEL + 2], row[c.SP_ACC + 2]
        return ((math.isfinite(pz) and pz > s.position[2] + 0.1) or
                (math.isfinite(vz) and vz > 0.05) or (math.isfinite(az) and az > 0.05))

    # --- automatic flight -------------------------------------------------------------
    def _cruise(self) -> float:
        v = self.params["MPC_XY_CRUISE"] if not math.isfinite(self.cruise_speed) \
            else self.cruise_speed
        return min(v, self.params["MPC_XY_VEL_MAX"])

    def _fly_to(self, s: VehicleState, target: np.ndarray, yaw: float) -> Setpoint:
        """Approach a point along the straight line at cruise speed, then hold it."""
        err = target - s.position
        dist = float(np.linalg.norm(err[:2]))
        acc = self.params["MPC_ACC_HOR_MAX"]
        speed = min(self._cruise(), math.sqrt(2.0 * 0.5 * acc * dist),
                    self.params["MPC_XY_P"] * dist)
        if dist > 0.3:
            vel = np.array([err[0] / dist * speed, err[1] / dist * speed, math.nan])
            return Setpoint.trajectory(position=[math.nan, math.nan, target[2]],
                                       velocity=vel, yaw=yaw)
        return Setpoint.position(target, yaw=yaw)

    def _auto_setpoint(self, s: VehicleState) -> Setpoint:
        nav = self._nav
        sub = self.sub_mode
        if sub == SUB_TAKEOFF:
            if nav.target is None:
                self._start_takeoff(self._default_takeoff_alt())
                nav = self._nav
            if s.position[2] >= nav.target[2] - 0.1 and not s.on_ground:
                self.text(Severity.INFO, "Takeoff complete: holding")
                self._set_mode(MAIN_AUTO, SUB_LOITER)
                self._nav = _Nav(target=nav.target.copy(), yaw=nav.yaw, phase="hold")
                return Setpoint.position(nav.target, yaw=nav.yaw)
            climb = self.params["MPC_TKO_SPEED"]
            return Setpoint.trajectory(position=[nav.target[0], nav.target[1], math.nan],
                                       velocity=[math.nan, math.nan, climb], yaw=nav.yaw)
        if sub == SUB_LAND:
            return self._land_setpoint(s, nav.target)
        if sub == SUB_RTL:
            return self._rtl_setpoint(s)
        if sub == SUB_MISSION:
            return self._mission_setpoint(s)
        if sub == SUB_FOLLOW_TARGET:
            return self._follow_setpoint(s)
        # LOITER (hold, reposition)
        if s.on_ground and not self._took_off:
            return self._on_ground_idle()
        if nav.target is None:
            self._hold_here()
            nav = self._nav
        if nav.phase == "goto":
            return self._fly_to(s, nav.target, nav.yaw)
        return Setpoint.position(nav.target, yaw=nav.yaw)

    def _land_setpoint(self, s: VehicleState, xy: np.ndarray | None) -> Setpoint:
        if s.on_ground:
            return self._on_ground_idle()
        xy = s.position if xy is None else xy
        return Setpoint.trajectory(position=[xy[0], xy[1], math.nan],
                                   velocity=[math.nan, math.nan, -self.params["MPC_LAND_SPEED"]],
                                   yaw=self._nav.yaw if math.isfinite(self._nav.yaw) else s.yaw)

    def _rtl_setpoint(self, s: VehicleState) -> Setpoint:
        nav = self._nav
        if nav.target is None:
            self._start_rtl()
            nav = self._nav
        if nav.phase == "rtl_climb":
            if s.position[2] >= nav.target[2] - 0.3:
                nav.phase = "rtl_return"
                nav.target = np.array([self._rtl_dest[0], self._rtl_dest[1], nav.target[2]])
            else:
                return Setpoint.position(nav.target, yaw=nav.yaw)
        if nav.phase == "rtl_return":
            if np.linalg.norm(nav.target[:2] - s.position[:2]) < 0.5:
                nav.phase = "rtl_land"
                self.text(Severity.INFO, "RTL: land at " + (
                    "home" if self._rtl_to_home() else "rally point"))
            else:
                return self._fly_to(s, nav.target, nav.yaw)
        return self._land_setpoint(s, self._rtl_dest)

    def _mission_setpoint(self, s: VehicleState) -> Setpoint:
        if self.mission_state == MissionState.COMPLETE or self.mission_seq >= len(self.mission):
            if self.mission_state != MissionState.COMPLETE:
                self.mission_state = MissionState.COMPLETE
                self.text(Severity.INFO, "Mission finished, loitering")
            if s.on_ground:
                return self._on_ground_idle()
            if self._nav.target is None or self._nav.phase != "hold":
                self._hold_here()
            return Setpoint.position(self._nav.target, yaw=self._nav.yaw)
        self.mission_state = MissionState.ACTIVE
        item = self.mission[self.mission_seq]
        if not self._item_started:
            self._start_item(item, s)
        if self._mission_takeoff is not None:  # started on the ground: climb first (PX4)
            tko = self._mission_takeoff
            if s.position[2] >= tko[2] - 0.2 and not s.on_ground:
                self._mission_takeoff = None
            else:
                return Setpoint.trajectory(position=[tko[0], tko[1], math.nan],
                                           velocity=[math.nan, math.nan,
                                                     self.params["MPC_TKO_SPEED"]],
                                           yaw=self._nav.yaw)
        nav = self._nav
        done = False
        sp: Setpoint
        if item.command == CMD_DO_CHANGE_SPEED:
            self.change_speed(item.speed_m_s)
            done = True
            sp = self._last_sp
        elif item.command == CMD_NAV_TAKEOFF:
            if s.position[2] >= nav.target[2] - 0.2 and not s.on_ground:
                done = True
            sp = Setpoint.trajectory(position=[nav.target[0], nav.target[1], math.nan],
                                     velocity=[math.nan, math.nan, self.params["MPC_TKO_SPEED"]],
                                     yaw=nav.yaw)
        elif item.command == CMD_NAV_WAYPOINT:
            radius = item.acceptance_radius_m if item.acceptance_radius_m > 0 \
                else self.params["NAV_ACC_RAD"]
            dist = float(np.linalg.norm(nav.target - s.position))
            sp = self._fly_to(s, nav.target, nav.yaw)
            if dist <= radius or self._item_hold_until is not None:
                if self._item_hold_until is None:
                    self._item_hold_until = self.time_us + int(item.hold_s * 1e6)
                    self.reached.append(self.mission_seq)
                done = self.time_us >= self._item_hold_until
                if done:
                    self._item_hold_until = None
                    self.mission_seq += 1
                    self._item_started = False
                    return sp
        elif item.command == CMD_NAV_DELAY:
            if self._item_hold_until is None:
                self._item_hold_until = self.time_us + int(max(item.hold_s, 0.0) * 1e6)
            done = self.time_us >= self._item_hold_until
            sp = Setpoint.position(nav.target, yaw=nav.yaw) if not s.on_ground \
                else self._on_ground_idle()
        elif item.command == CMD_NAV_LAND:
            sp = self._land_setpoint(s, nav.target)
            done = s.on_ground
        elif item.command == CMD_NAV_RETURN_TO_LAUNCH:
            sp = self._rtl_setpoint(s)
            done = s.on_ground and nav.phase == "rtl_land"
        else:  # DO_* items we do not model: accepted and skipped
            done = True
            sp = self._last_sp if self._last_sp.kind != 0 else Setpoint.position(
                s.position, yaw=s.yaw)
        if done:
            if item.command != CMD_NAV_WAYPOINT:
                self.reached.append(self.mission_seq)
            self._item_hold_until = None
            self.mission_seq += 1
            self._item_started = False
        return sp

    def _start_item(self, item: MissionItem, s: VehicleState) -> None:
        self._item_started = True
        self._item_hold_until = None
        self._mission_takeoff = None
        p = s.position.copy()
        target = np.array([item.position[i] if math.isfinite(item.position[i]) else p[i]
                           for i in range(3)])
        yaw = item.yaw_rad if math.isfinite(item.yaw_rad) else s.yaw
        if item.command == CMD_NAV_TAKEOFF:
            target = np.array([p[0], p[1], max(target[2], p[2])])
        if item.command == CMD_NAV_WAYPOINT and not math.isfinite(item.yaw_rad):
            d = target[:2] - p[:2]
            if np.linalg.norm(d) > 1.0:
                yaw = math.atan2(d[1], d[0])  # PX4 default: head toward the waypoint
        if item.command == CMD_NAV_RETURN_TO_LAUNCH:
            self._start_rtl()
            return
        self._nav = _Nav(target=target, yaw=yaw, phase="mission", t_phase_us=self.time_us)
        if item.command == CMD_NAV_WAYPOINT and self.landed_state == LandedState.ON_GROUND:
            # PX4 takes off before a mission's first position item when it starts landed:
            # straight up to the item's altitude, at least MIS_TAKEOFF_ALT above home
            alt = max(target[2], self.home[2] + self.params["MIS_TAKEOFF_ALT"])
            self._mission_takeoff = np.array([p[0], p[1], alt])
            self.text(Severity.INFO, f"Mission: takeoff to {alt - self.home[2]:.1f} m first")


def _clamp_abs(v: float, limit: float) -> float:
    return max(-limit, min(limit, v))


def hover_thrust(platform: Platform) -> float:
    """Normalised collective thrust that holds a hover."""
    return platform.mass_kg * G / platform.thrust_max_n


def _wrap_pi(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi
