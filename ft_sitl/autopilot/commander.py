"""The commander of the virtual PX4, transport-free: the public face of the autopilot.

One :class:`Commander` per vehicle decides what PX4's commander decides: arming, the
flight mode and which switches are allowed, the offboard rules, and when a failsafe takes
over. How each mode flies is delegated, along PX4's own seams, to one object per concern
that the commander owns and calls every tick:

================  ==================================================================
``auto``          take-off, hold, reposition, land, return (:mod:`.auto`)
``mission_exec``  AUTO.MISSION item by item (:mod:`.mission`)
``follow``        AUTO.FOLLOW_TARGET (:mod:`.follow`)
``orbit_task``    POSCTL.ORBIT (:mod:`.orbit`)
``manual``        the sticks and the failsafe on their loss (:mod:`.manual`)
``stick_flight``  what the stick modes fly (:mod:`.stick_flight`)
``failsafes``     battery, geofence and position-loss failsafes (:mod:`.failsafe`)
``land_detector`` the landed state and auto-disarm (:mod:`.land_detector`)
================  ==================================================================

and the pre-arm checks are :func:`.arming.arming_denial`. Every tick the commander turns
all that into one :class:`~ft_sitl.autopilot.setpoints.Setpoint` for the cascade. The
MAVLink layer and the in-process mission runner call the same methods, so a script
flying over MAVSDK and a trial flying in-process see identical behaviour. Positions are
local ENU metres from the home point; times are integer microseconds of simulated time.

The names callers import from here (the modes, :class:`Result`, :class:`MissionItem`,
the mission command ids...) are re-exported from the modules that define them.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ft_sitl.autopilot import cascade as c
from ft_sitl.autopilot.arming import FENCE_ARM_DENIAL, arming_denial
from ft_sitl.autopilot.auto import AutoFlight
from ft_sitl.autopilot.battery import Battery
from ft_sitl.autopilot.failsafe import Failsafes
from ft_sitl.autopilot.follow import FollowMode, TargetEstimator
from ft_sitl.autopilot.geofence import GF_ACTIONS, Fence, nearest_safe_point
from ft_sitl.autopilot.land_detector import LandDetector
from ft_sitl.autopilot.manual import NAV_RCL_ACTIONS, ManualControl
from ft_sitl.autopilot.mission import (
    CMD_DO_CHANGE_SPEED,
    CMD_NAV_DELAY,
    CMD_NAV_LAND,
    CMD_NAV_RETURN_TO_LAUNCH,
    CMD_NAV_TAKEOFF,
    CMD_NAV_WAYPOINT,
    MissionExecutor,
    MissionItem,
    MissionState,
)
from ft_sitl.autopilot.modes import (
    MAIN_ACRO,
    MAIN_ALTCTL,
    MAIN_AUTO,
    MAIN_MANUAL,
    MAIN_OFFBOARD,
    MAIN_POSCTL,
    MAIN_STABILIZED,
    MANUAL_MODES,
    MODE_BY_NAME,
    MODE_NAMES,
    STICK_MODES,
    SUB_FOLLOW_TARGET,
    SUB_LAND,
    SUB_LOITER,
    SUB_MISSION,
    SUB_POSCTL_ORBIT,
    SUB_READY,
    SUB_RTL,
    SUB_TAKEOFF,
)
from ft_sitl.autopilot.orbit import (
    ORBIT_DEFAULT_SPEED_M_S,
    ORBIT_MAX_RADIUS_M,
    ORBIT_MIN_RADIUS_M,
    OrbitTask,
)
from ft_sitl.autopilot.params import ParamSet
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.autopilot.status import LandedState, Result, Severity, VehicleState
from ft_sitl.autopilot.stick_flight import StickFlight, hover_thrust
from ft_sitl.physics.platform import Platform

__all__ = [
    "CMD_DO_CHANGE_SPEED", "CMD_NAV_DELAY", "CMD_NAV_LAND", "CMD_NAV_RETURN_TO_LAUNCH",
    "CMD_NAV_TAKEOFF", "CMD_NAV_WAYPOINT", "FENCE_ARM_DENIAL", "GF_ACTIONS", "MAIN_ACRO",
    "MAIN_ALTCTL", "MAIN_AUTO", "MAIN_MANUAL", "MAIN_OFFBOARD", "MAIN_POSCTL",
    "MAIN_STABILIZED", "MANUAL_MODES", "MODE_BY_NAME", "MODE_NAMES", "NAV_RCL_ACTIONS",
    "ORBIT_DEFAULT_SPEED_M_S", "ORBIT_MAX_RADIUS_M", "ORBIT_MIN_RADIUS_M", "STICK_MODES",
    "SUB_FOLLOW_TARGET", "SUB_LAND", "SUB_LOITER", "SUB_MISSION", "SUB_POSCTL_ORBIT",
    "SUB_READY", "SUB_RTL", "SUB_TAKEOFF", "Battery", "Commander", "Fence", "LandedState",
    "MissionItem", "MissionState", "Result", "Severity", "VehicleState", "hover_thrust",
]

#: the modes whose entry holds where the vehicle is (the stick modes and ACRO)
_HOLDING_MODES = (MAIN_POSCTL, MAIN_ALTCTL, MAIN_MANUAL, MAIN_STABILIZED, MAIN_ACRO)


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
    #: where a return goes, from (position, home, rally points): PX4's nearest of home and
    #: the rally points; a face with another rule (ArduCopter's RALLY_*) sets its own
    rally_rule: Callable = nearest_safe_point
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
        self._offboard_sp: Setpoint | None = None
        self._offboard_t_us = -(10**12)
        self._armed_t_us = 0
        self._state: VehicleState | None = None
        self._last_sp = Setpoint.off()
        if self.battery is None:
            self.battery = Battery.for_platform(self.platform, self.params["FT_BAT_ENDURANCE"])
        self.mission_state = MissionState.NO_MISSION
        self.auto = AutoFlight(self)
        self.mission_exec = MissionExecutor(self)
        self.follow = FollowMode(self)
        self.orbit_task = OrbitTask(self)
        self.manual = ManualControl(self)
        self.stick_flight = StickFlight(self)
        self.failsafes = Failsafes(self)
        self.land_detector = LandDetector(self)

    # --- what the flight tasks read and do ---------------------------------------------
    @property
    def mode_name(self) -> str:
        return MODE_NAMES.get((self.main_mode, self.sub_mode), "UNKNOWN")

    def text(self, severity: Severity, msg: str) -> None:
        self.statustexts.append((int(severity), msg))

    def deny(self, msg: str, result: Result = Result.DENIED) -> Result:
        """Refuse a command: say why (critical) and return ``result``."""
        self.text(Severity.CRITICAL, msg)
        return result

    def position_now(self) -> np.ndarray:
        """The latest estimated position (a copy; home before the first tick)."""
        return self._state.position.copy() if self._state is not None else self.home.copy()

    def yaw_now(self) -> float:
        return self._state.yaw if self._state is not None else self.home_yaw

    def switch_mode(self, main: int, sub: int = 0) -> None:
        """Set the mode without set_mode's checks: the autopilot's own transitions."""
        self.main_mode, self.sub_mode = main, sub

    @property
    def took_off(self) -> bool:
        """The vehicle left the ground since it was armed."""
        return self.land_detector.took_off

    @property
    def last_setpoint(self) -> Setpoint:
        return self._last_sp

    # --- arming --------------------------------------------------------------------
    def offboard_fresh(self) -> bool:
        return (self._offboard_sp is not None and
                self.time_us - self._offboard_t_us <= self.params["COM_OF_LOSS_T"] * 1e6)

    def arm(self, force: bool = False) -> Result:
        if self.armed:
            return Result.ACCEPTED
        if not force:
            why = arming_denial(self)
            if why:
                return self.deny(why)
        self.manual.on_arm()
        self.armed = True
        self._armed_t_us = self.time_us
        self.land_detector.on_arm()
        if self.main_mode in _HOLDING_MODES or (self.main_mode == MAIN_AUTO
                                                and self.sub_mode == SUB_LOITER):
            self.auto.hold_here()
        self.text(Severity.INFO, "Armed by external command")
        return Result.ACCEPTED

    def disarm(self, force: bool = False) -> Result:
        if not self.armed:
            return Result.ACCEPTED
        if not force and self.landed_state not in (LandedState.ON_GROUND,):
            return self.deny("Disarming denied: not landed")
        self.disarm_now("Disarmed by external command")
        return Result.ACCEPTED

    def disarm_now(self, why: str) -> None:
        """Disarm without checks (auto-disarm, a failsafe); an AUTO mode that would fly on
        its own becomes a hold, so the next arming does not take off by surprise."""
        self.armed = False
        self.text(Severity.INFO, why)
        if self.main_mode == MAIN_AUTO and self.sub_mode in (SUB_LAND, SUB_RTL, SUB_TAKEOFF,
                                                             SUB_FOLLOW_TARGET):
            self.switch_mode(MAIN_AUTO, SUB_LOITER)

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

    # --- modes and the commands that set them -----------------------------------------
    def set_mode(self, main: int, sub: int = 0) -> Result:
        key = (main, sub if main == MAIN_AUTO else 0)
        if key not in MODE_NAMES:
            return self.deny(f"Mode {main}/{sub} is not supported", Result.UNSUPPORTED)
        main, sub = key
        if main == MAIN_OFFBOARD and not self.offboard_fresh():
            return self.deny("Switching to Offboard is currently not available",
                             Result.TEMPORARILY_REJECTED)
        if main == MAIN_AUTO and sub == SUB_MISSION and not self.mission:
            return self.deny("Switching to Mission is currently not available: no mission",
                             Result.TEMPORARILY_REJECTED)
        if main == MAIN_AUTO and sub == SUB_READY:
            sub = SUB_LOITER
        if (main, sub) == (self.main_mode, self.sub_mode):
            return Result.ACCEPTED
        self.switch_mode(main, sub)
        if main in _HOLDING_MODES:
            self.auto.hold_here()
        elif main == MAIN_AUTO:
            self.auto.enter(sub)
        return Result.ACCEPTED

    def takeoff(self, altitude_m: float | None = None) -> Result:
        """Climb to the altitude (local z, m; never down) or, if None or not finite,
        MIS_TAKEOFF_ALT above the current altitude, at the current horizontal position."""
        return self.auto.takeoff(altitude_m)

    def nav_takeoff(self, altitude_m: float | None = None) -> Result:
        """MAV_CMD_NAV_TAKEOFF: as :meth:`takeoff`, at least MIS_TAKEOFF_ALT up
        (:meth:`AutoFlight.nav_takeoff <ft_sitl.autopilot.auto.AutoFlight.nav_takeoff>`)."""
        return self.auto.nav_takeoff(altitude_m)

    def land(self) -> Result:
        return self.auto.land()

    def return_to_launch(self) -> Result:
        return self.auto.return_to_launch()

    def hold(self) -> Result:
        return self.set_mode(MAIN_AUTO, SUB_LOITER)

    def reposition(self, position: np.ndarray, yaw: float = math.nan) -> Result:
        """DO_REPOSITION: fly to a local position and hold there (mode AUTO.LOITER)."""
        return self.auto.reposition(position, yaw)

    def orbit(self, center: np.ndarray, radius_m: float, speed_m_s: float,
              yaw_behaviour: int) -> Result:
        """MAV_CMD_DO_ORBIT: circle ``center`` (local ENU; NaN x/y: the current position,
        NaN z: the current altitude) at ``radius_m`` (positive: clockwise seen from above,
        PX4's sign) and ``speed_m_s`` (NaN: ORBIT_DEFAULT_SPEED); ``yaw_behaviour`` is
        MAVLink's ORBIT_YAW_BEHAVIOUR. Mode POSCTL.ORBIT, as PX4."""
        return self.orbit_task.start(center, radius_m, speed_m_s, yaw_behaviour)

    @property
    def orbit_state(self) -> tuple | None:
        """The orbit in force: (centre, signed radius, speed, yaw behaviour, initial yaw)."""
        return self.orbit_task.state

    def follow_target_measurement(self, t_us: int, position: np.ndarray,
                                  velocity: np.ndarray | None) -> None:
        """A FOLLOW_TARGET fix: local ENU position (z NaN: altitude unknown) and ENU
        velocity (None: unknown), already checked by the caller."""
        self.follow.measurement(t_us, position, velocity)

    @property
    def follow_target(self) -> TargetEstimator:
        """The follow-target estimate (from FOLLOW_TARGET messages)."""
        return self.follow.target

    def change_speed(self, speed_m_s: float) -> Result:
        if not math.isfinite(speed_m_s) or speed_m_s <= 0:
            self.cruise_speed = math.nan  # -1 / NaN: back to the default
        else:
            self.cruise_speed = speed_m_s
        return Result.ACCEPTED

    def set_home(self, position: np.ndarray) -> Result:
        self.home = np.asarray(position, dtype=float).copy()
        return Result.ACCEPTED

    # --- offboard, mission, manual control: the inputs ----------------------------------
    def offboard_setpoint(self, sp: Setpoint) -> None:
        """A validated offboard setpoint arrived (it keeps the stream fresh)."""
        self._offboard_sp = sp.offboard()
        self._offboard_t_us = self.time_us

    def set_mission(self, items: list[MissionItem]) -> None:
        self.mission_exec.load(items)

    def set_mission_current(self, seq: int) -> Result:
        return self.mission_exec.set_current(seq)

    def manual_control(self, x: float, y: float, z: float, r: float) -> bool:
        """New stick positions, as PX4 reads MANUAL_CONTROL: x pitch (forward +), y roll
        (right +), r yaw (clockwise +) in -1..1, z throttle in 0..1. Values outside are
        clamped; a non-finite one refuses the whole input (False). Ignored (False) when
        COM_RC_IN_MODE allows no joystick (0 RC only, 4 disabled)."""
        return self.manual.input(x, y, z, r)

    def manual_fresh(self) -> bool:
        """Sticks arrived within COM_RC_LOSS_T."""
        return self.manual.fresh()

    @property
    def sticks(self) -> tuple[float, float, float, float]:
        """The latest sticks: x pitch, y roll, z throttle 0..1, r yaw."""
        return self.manual.sticks

    # --- injected failures and the geofence -------------------------------------------
    def record_failure(self, unit: str, ftype: str, instance: int) -> None:
        """An injected failure (ft_sitl.sim.fleet.Fleet.inject_failure applies its
        physics); ``ok`` clears the unit."""
        self.failsafes.record_failure(unit, ftype, instance)

    def sensor_ok(self, unit: str) -> bool:
        return unit not in self.failures

    def set_fence(self, fence: Fence) -> None:
        self.fence = fence
        self.failsafes.fence_breached = False

    def set_rally(self, points) -> None:
        self.rally = [np.asarray(p, dtype=float).copy() for p in points]

    @property
    def geofence_active(self) -> bool:
        """A fence is uploaded, or a maximum distance or height from home is set."""
        return (not self.fence.empty or self.params["GF_MAX_HOR_DIST"] > 0
                or self.params["GF_MAX_VER_DIST"] > 0)

    @property
    def fence_breached(self) -> bool:
        return self.failsafes.fence_breached

    def fence_breach_here(self) -> str | None:
        """Why the vehicle where it is now breaches the geofence, when a breach would act
        (GF_ACTION not 0, as PX4's navigator only checks then); None otherwise."""
        if int(self.params["GF_ACTION"]) == 0:
            return None
        return self.fence.breach(self.position_now(), self.home,
                                 self.params["GF_MAX_HOR_DIST"], self.params["GF_MAX_VER_DIST"])

    # --- the tick ----------------------------------------------------------------------
    def update(self, time_us: int, state: VehicleState, mech_energy_j: float) -> Setpoint:
        """Advance the commander to time_us and return the cascade's setpoint."""
        self.time_us = time_us
        self._state = state
        self.battery.draw(mech_energy_j)
        self.land_detector.update(state)
        self.failsafes.battery()
        self.failsafes.geofence(state)
        self.failsafes.position_loss(state)
        self.manual.check(state)
        if not self.armed:
            return self._emit(Setpoint.off())
        if self.land_detector.auto_disarm():
            return self._emit(Setpoint.off())
        sp = self._mode_setpoint(state)
        return self._emit(sp)

    def _emit(self, sp: Setpoint) -> Setpoint:
        self._last_sp = sp
        return sp

    def _mode_setpoint(self, s: VehicleState) -> Setpoint:
        if self.main_mode == MAIN_OFFBOARD:
            if not self.offboard_fresh():
                self.text(Severity.CRITICAL, "Offboard signal lost: holding position")
                self.switch_mode(MAIN_AUTO, SUB_LOITER)
                self.auto.hold_here()
            else:
                sp = self._offboard_sp
                if s.on_ground and sp.kind == 2 and not self._wants_up(sp, s):
                    return Setpoint.idle()
                return sp
        if self.main_mode == MAIN_AUTO:
            return self.auto.setpoint(s)
        if (self.main_mode, self.sub_mode) == (MAIN_POSCTL, SUB_POSCTL_ORBIT):
            if s.on_ground or self.orbit_task.state is None:
                self.switch_mode(MAIN_POSCTL)
            else:
                return self.orbit_task.setpoint(s)
        if self.manual.fresh() and self.main_mode in STICK_MODES:
            return self.stick_flight.setpoint(s)
        # POSCTL / ALTCTL / MANUAL / STABILIZED / ACRO without sticks: hold
        if s.on_ground:
            self.auto.hold_here()
            return Setpoint.idle()
        nav = self.auto.nav
        if nav.target is None:
            self.auto.hold_here()
            nav = self.auto.nav
        return Setpoint.position(nav.target, yaw=nav.yaw)

    @staticmethod
    def _wants_up(sp: Setpoint, s: VehicleState) -> bool:
        """An offboard setpoint on the ground asks to climb (else the rotors idle)."""
        row = sp.row
        pz, vz, az = row[c.SP_POS + 2], row[c.SP_VEL + 2], row[c.SP_ACC + 2]
        return ((math.isfinite(pz) and pz > s.position[2] + 0.1) or
                (math.isfinite(vz) and vz > 0.05) or (math.isfinite(az) and az > 0.05))
