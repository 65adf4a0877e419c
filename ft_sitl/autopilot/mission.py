"""Mission execution: AUTO.MISSION, one item after the other, as PX4's navigator runs it.

The mission itself (the items, the current sequence number, its state and the items
reached) is the commander's, because the MAVLink layer reports it whatever the mode;
:class:`MissionExecutor` is the logic that advances it while AUTO.MISSION flies, and the
few facts about the item in progress (started, holding until, climbing first). Items are
MAVLink's MAV_CMD ids with positions already converted to local ENU metres, so the same
executor runs a mission uploaded over MAVLink and one a trial builds in-process. Two
ArduCopter behaviours are there for the items that ask for them (only the ArduCopter face
makes such items): a waypoint with ``spline`` flies a curve (:mod:`.spline`), and an item
with a ``condition`` runs, with the DO items after it, beside the next navigation item
(:mod:`.conditions`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum
from typing import TYPE_CHECKING

import numpy as np

from ft_sitl.autopilot.auto import NavTarget
from ft_sitl.autopilot.conditions import Condition, DoQueue
from ft_sitl.autopilot.modes import MAIN_AUTO, SUB_LOITER, SUB_MISSION
from ft_sitl.autopilot.orbit import ORBIT_DEFAULT_SPEED_M_S, circle_setpoint, circle_speed
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.autopilot.spline import SplineLegs
from ft_sitl.autopilot.status import LandedState, Result, Severity, VehicleState

if TYPE_CHECKING:  # the commander owns this object; only its type is needed here
    from ft_sitl.autopilot.commander import Commander

# MAV_CMD ids of the mission items the navigator executes
CMD_NAV_WAYPOINT = 16
CMD_NAV_LOITER_TURNS = 18
CMD_NAV_RETURN_TO_LAUNCH = 20
CMD_NAV_LAND = 21
CMD_NAV_TAKEOFF = 22
CMD_NAV_DELAY = 93
CMD_DO_JUMP = 177
CMD_DO_CHANGE_SPEED = 178
CMD_DO_SET_ROI_LOCATION = 195
CMD_DO_SET_ROI = 201
#: the items that point the vehicle's front at a location (NaN position: no longer)
ROI_COMMANDS = (CMD_DO_SET_ROI, CMD_DO_SET_ROI_LOCATION)


class MissionState(IntEnum):
    """MISSION_STATE values (MISSION_CURRENT.mission_state)."""

    UNKNOWN = 0
    NO_MISSION = 1
    NOT_STARTED = 2
    ACTIVE = 3
    PAUSED = 4
    COMPLETE = 5


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
    #: DO_JUMP: the index (in this list) to jump to, and how often (-1: for ever)
    jump_to: int = -1
    repeat: int = 0
    #: NAV_LOITER_TURNS: the turns to fly round ``position`` and the signed radius (m;
    #: positive clockwise seen from above); ``speed_m_s`` the speed on the circle
    turns: float = 0.0
    radius_m: float = 0.0
    #: a waypoint flown as a curve through it (ArduCopter's NAV_SPLINE_WAYPOINT, :mod:`.spline`)
    spline: bool = False
    #: an ArduCopter CONDITION_* item: it and the DO items after it run beside the next
    #: navigation item (:mod:`.conditions`)
    condition: Condition | None = None


class MissionExecutor:
    """Runs the commander's mission item by item in AUTO.MISSION."""

    def __init__(self, cmdr: Commander):
        self.cmdr = cmdr
        self.item_started = False
        #: when a waypoint's hold or a delay item ends (None: not holding yet)
        self.item_hold_until: int | None = None
        #: a mission started on the ground climbs here first (None: no climb pending)
        self.takeoff: np.ndarray | None = None
        #: the jumps each DO_JUMP item (by index) has made since the mission was loaded
        self.jumps: dict[int, int] = {}
        #: the location a DO_SET_ROI item points the front at (None: the course's heading)
        self.roi: np.ndarray | None = None
        #: a NAV_LOITER_TURNS item on its circle: [bearing last step, angle swept] (rad)
        self.circling: list[float] | None = None
        #: the curves of spline waypoints (only items with ``spline`` fly them)
        self.spline = SplineLegs(cmdr)
        #: the condition and DO items running beside the navigation item (ArduCopter's)
        self.queue = DoQueue(self)

    def load(self, items: list[MissionItem]) -> None:
        """A new mission replaces the old one; an empty one in AUTO.MISSION holds."""
        c = self.cmdr
        c.mission = list(items)
        self.takeoff = None
        self.jumps = {}
        self.roi = None
        self._item_afresh()
        c.mission_seq = 0
        c.mission_state = MissionState.NOT_STARTED if items else MissionState.NO_MISSION
        if not items and c.main_mode == MAIN_AUTO and c.sub_mode == SUB_MISSION:
            c.switch_mode(MAIN_AUTO, SUB_LOITER)
            c.auto.hold_here()

    def set_current(self, seq: int) -> Result:
        """Jump to item ``seq`` (DENIED: no such item)."""
        c = self.cmdr
        if not 0 <= seq < max(1, len(c.mission)):
            return Result.DENIED
        c.mission_seq = seq
        self._item_afresh()
        if c.mission_state == MissionState.COMPLETE:
            c.mission_state = MissionState.NOT_STARTED
        return Result.ACCEPTED

    def enter(self) -> None:
        """AUTO.MISSION starts: a finished mission restarts from the first item."""
        c = self.cmdr
        if (c.mission_state in (MissionState.NOT_STARTED, MissionState.COMPLETE)
                or c.mission_seq >= len(c.mission)):
            if c.mission_seq >= len(c.mission):
                c.mission_seq = 0
                self.jumps = {}  # (a restarted mission jumps again, as ArduPilot's)
        c.mission_state = MissionState.ACTIVE
        self._item_afresh()

    def _item_afresh(self) -> None:
        """The current item starts from its beginning: not begun, no hold running, no
        spline curve and no DO/condition item queued from before (a new mission, a jump
        to an item, AUTO.MISSION entered)."""
        self.item_started = False
        self.item_hold_until = None
        self.spline.reset()
        self.queue.clear()

    def setpoint(self, s: VehicleState) -> Setpoint:
        c = self.cmdr
        auto = c.auto
        if c.mission_state == MissionState.COMPLETE or c.mission_seq >= len(c.mission):
            if c.mission_state != MissionState.COMPLETE:
                c.mission_state = MissionState.COMPLETE
                c.text(Severity.INFO, "Mission finished, loitering")
            if s.on_ground:
                return Setpoint.idle()
            if auto.nav.target is None or auto.nav.phase != "hold":
                auto.hold_here()
            return Setpoint.position(auto.nav.target, yaw=auto.nav.yaw)
        c.mission_state = MissionState.ACTIVE
        item = c.mission[c.mission_seq]
        if item.condition is not None:  # (it waits beside the next navigation item)
            c.mission_seq = self.queue.take(c.mission_seq)
            self.item_started = False
            return self.setpoint(s)
        if not self.item_started:
            self._start_item(item, s)
        self.queue.tick(s, auto.nav.target)
        if self.takeoff is not None:  # started on the ground: climb first (PX4)
            tko = self.takeoff
            if s.position[2] >= tko[2] - 0.2 and not s.on_ground:
                self.takeoff = None
            else:
                return Setpoint.trajectory(position=[tko[0], tko[1], math.nan],
                                           velocity=[math.nan, math.nan,
                                                     c.params["MPC_TKO_SPEED"]],
                                           yaw=auto.nav.yaw)
        nav = auto.nav
        done = False
        sp: Setpoint
        if item.command == CMD_DO_CHANGE_SPEED:
            self.run_do(item)
            done = True
            sp = c.last_setpoint
        elif item.command == CMD_DO_JUMP and 0 <= item.jump_to < len(c.mission) and \
                (item.repeat < 0 or self.jumps.get(c.mission_seq, 0) < item.repeat):
            # (a jump out of range, or one whose repeats are used up, is skipped below)
            self.jumps[c.mission_seq] = self.jumps.get(c.mission_seq, 0) + 1
            c.mission_seq = item.jump_to
            self.item_started = False
            self.item_hold_until = None
            last = c.last_setpoint
            return last if last.kind != 0 else Setpoint.position(s.position, yaw=s.yaw)
        elif item.command == CMD_NAV_TAKEOFF:
            if s.position[2] >= nav.target[2] - 0.2 and not s.on_ground:
                done = True
            sp = Setpoint.trajectory(position=[nav.target[0], nav.target[1], math.nan],
                                     velocity=[math.nan, math.nan, c.params["MPC_TKO_SPEED"]],
                                     yaw=nav.yaw)
        elif item.command == CMD_NAV_WAYPOINT:
            if item.spline:
                sp, arrived = self.spline.step(s, self._heading(s, math.nan))
            else:
                radius = item.acceptance_radius_m if item.acceptance_radius_m > 0 \
                    else c.params["NAV_ACC_RAD"]
                arrived = float(np.linalg.norm(nav.target - s.position)) <= radius
                sp = auto.fly_to(s, nav.target, self._heading(s, nav.yaw))
            if arrived or self.item_hold_until is not None:
                if self.item_hold_until is None:
                    self.item_hold_until = c.time_us + int(item.hold_s * 1e6)
                    c.reached.append(c.mission_seq)
                done = c.time_us >= self.item_hold_until
                if done:
                    self.item_hold_until = None
                    c.mission_seq += 1
                    self.item_started = False
                    return sp
        elif item.command == CMD_NAV_LOITER_TURNS:
            sp, done = self._loiter_turns(item, s)
        elif item.command in ROI_COMMANDS:
            self.run_do(item)
            done = True
            last = c.last_setpoint
            sp = last if last.kind != 0 else Setpoint.position(s.position, yaw=s.yaw)
        elif item.command == CMD_NAV_DELAY:
            if self.item_hold_until is None:
                self.item_hold_until = c.time_us + int(max(item.hold_s, 0.0) * 1e6)
            done = c.time_us >= self.item_hold_until
            sp = Setpoint.position(nav.target, yaw=nav.yaw) if not s.on_ground \
                else Setpoint.idle()
        elif item.command == CMD_NAV_LAND:
            sp = auto.land_setpoint(s, nav.target)
            done = s.on_ground
        elif item.command == CMD_NAV_RETURN_TO_LAUNCH:
            sp = auto.rtl_setpoint(s)
            done = s.on_ground and nav.phase == "rtl_land"
        else:  # DO_* items we do not model: accepted and skipped
            done = True
            last = c.last_setpoint
            sp = last if last.kind != 0 else Setpoint.position(s.position, yaw=s.yaw)
        if done:
            if item.command != CMD_NAV_WAYPOINT:
                c.reached.append(c.mission_seq)
            self.item_hold_until = None
            c.mission_seq += 1
            self.item_started = False
        return sp

    def run_do(self, item: MissionItem) -> None:
        """A DO item's effect: DO_CHANGE_SPEED's speed, DO_SET_ROI's point (none: no
        longer); the others have none here."""
        if item.command == CMD_DO_CHANGE_SPEED:
            self.cmdr.change_speed(item.speed_m_s)
        elif item.command in ROI_COMMANDS:
            p = np.array(item.position, dtype=float)
            self.roi = p if np.all(np.isfinite(p[:2])) else None

    def _heading(self, s: VehicleState, yaw: float) -> float:
        """The heading a CONDITION_YAW holds, else the front toward the region of interest
        when one is set, else ``yaw``."""
        held = self.queue.heading()
        if held is not None:
            return held
        if self.roi is None:
            return yaw
        d = self.roi[:2] - s.position[:2]
        return math.atan2(d[1], d[0]) if float(np.hypot(*d)) > 0.5 else yaw

    def _loiter_turns(self, item: MissionItem, s: VehicleState) -> tuple[Setpoint, bool]:
        """NAV_LOITER_TURNS: fly to the circle's nearest point, then round it, the front to
        the centre, until ``item.turns`` turns are swept (ArduCopter's AUTO circle)."""
        c = self.cmdr
        centre = c.auto.nav.target
        r = item.radius_m
        d = s.position[:2] - centre[:2]
        dist = float(np.hypot(*d))
        if self.circling is None:
            u = d / dist if dist > 1e-3 else np.array([1.0, 0.0])
            edge = np.array([centre[0] + abs(r) * u[0], centre[1] + abs(r) * u[1], centre[2]])
            if float(np.linalg.norm(edge - s.position)) > c.params["NAV_ACC_RAD"]:
                return c.auto.fly_to(s, edge, self._heading(s, c.auto.nav.yaw)), False
            self.circling = [math.atan2(d[1], d[0]), 0.0]
        bearing = math.atan2(d[1], d[0])
        step = (bearing - self.circling[0] + math.pi) % (2.0 * math.pi) - math.pi
        self.circling[0] = bearing
        self.circling[1] += -step if r > 0 else step  # clockwise: the bearing falls
        speed = circle_speed(c, r, item.speed_m_s if math.isfinite(item.speed_m_s)
                             else ORBIT_DEFAULT_SPEED_M_S)
        sp = circle_setpoint(c, s, centre, r, speed, 0, s.yaw)
        return sp, self.circling[1] >= item.turns * 2.0 * math.pi

    def _start_item(self, item: MissionItem, s: VehicleState) -> None:
        c = self.cmdr
        self.item_started = True
        self.item_hold_until = None
        self.takeoff = None
        self.circling = None
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
        self.spline.leg_started(item, c.mission_seq, target)
        if item.command == CMD_NAV_RETURN_TO_LAUNCH:
            c.auto.start_rtl()
            return
        c.auto.nav = NavTarget(target=target, yaw=yaw, phase="mission", t_phase_us=c.time_us)
        if item.command == CMD_NAV_WAYPOINT and c.landed_state == LandedState.ON_GROUND:
            # PX4 takes off before a mission's first position item when it starts landed:
            # straight up to the item's altitude, at least MIS_TAKEOFF_ALT above home
            alt = max(target[2], c.home[2] + c.params["MIS_TAKEOFF_ALT"])
            self.takeoff = np.array([p[0], p[1], alt])
            c.text(Severity.INFO, f"Mission: takeoff to {alt - c.home[2]:.1f} m first")
