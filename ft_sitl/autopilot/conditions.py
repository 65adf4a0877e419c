"""ArduCopter's CONDITION_* mission items: a condition runs beside the next navigation item.

ArduPilot's mission (AP_Mission) keeps two commands in hand: the navigation command being
flown and one "do" command. The do and condition items between two navigation items run, in
order, while the vehicle flies the second of them; a condition holds back the items after
it until it is met (ModeAuto's verify_wait_delay, verify_within_distance, verify_yaw), and
whatever is still waiting when the navigation item ends is dropped. The facts are
ArduCopter's (mode_auto.cpp, autoyaw.cpp, AP_Mission.cpp); the code is ours.

* CONDITION_DELAY: met ``seconds`` after it started.
* CONDITION_DISTANCE: met when the vehicle is within ``metres`` (horizontally) of the
  navigation item's destination.
* CONDITION_YAW: the heading is held at ``angle`` (degrees from north, or an offset from the
  heading now, clockwise, or anticlockwise for a negative direction; an absolute angle
  turns the way ``direction`` says, the shorter way for 0), turned toward at ``rate`` deg/s
  (0 or more than the default: the default of 60 deg/s, ArduCopter's ATC_SLEW_YAW); met
  when the turn is done and the heading within 2 degrees. The heading stays there until the
  navigation item ends.

:class:`DoQueue` is the executor's queue of these items; :class:`Condition` is what an
item asks (the ArduCopter face makes them from the uploaded items).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ft_sitl.autopilot.status import VehicleState

if TYPE_CHECKING:  # the executor owns this object
    from ft_sitl.autopilot.mission import MissionExecutor, MissionItem

CONDITION_DELAY, CONDITION_DISTANCE, CONDITION_YAW = 112, 114, 115
#: the navigation commands (MAV_CMD_NAV_* ids are up to 95, AP_Mission::is_nav_cmd)
NAV_LAST = 95
_CMD_DO_JUMP = 177
#: CONDITION_YAW's turn rate when none (or a faster one) is asked: ATC_SLEW_YAW's default
YAW_SLEW_DEFAULT_RAD_S = math.radians(60.0)
#: how close the heading must come to a CONDITION_YAW's angle (autoyaw.cpp: 2 degrees)
YAW_REACHED_RAD = math.radians(2.0)


@dataclass(frozen=True)
class Condition:
    """What a CONDITION_* item asks: ``value`` is seconds (DELAY), metres (DISTANCE) or the
    angle in degrees (YAW, with ``rate_deg_s``, ``direction`` and ``relative``)."""

    kind: int
    value: float
    rate_deg_s: float = 0.0
    direction: int = 0
    relative: bool = False


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


class _Turn:
    """A CONDITION_YAW turn: the heading target (clockwise from north) slewing toward its
    end at the rate asked."""

    def __init__(self, cond: Condition, yaw_enu: float):
        self.heading = math.pi / 2.0 - yaw_enu  # (clockwise from north)
        angle = math.radians(cond.value)
        if cond.relative:
            self.left = angle * (1.0 if cond.direction >= 0 else -1.0)
        else:
            self.left = _wrap(angle - self.heading)
            if cond.direction < 0 < self.left:
                self.left -= 2.0 * math.pi
            elif cond.direction > 0 > self.left:
                self.left += 2.0 * math.pi
        rate = math.radians(cond.rate_deg_s)
        self.rate = min(rate, YAW_SLEW_DEFAULT_RAD_S) if rate > 0 else YAW_SLEW_DEFAULT_RAD_S

    def advance(self, dt: float) -> None:
        step = math.copysign(min(abs(self.left), self.rate * dt), self.left)
        self.heading += step
        self.left -= step

    @property
    def yaw_enu(self) -> float:
        return _wrap(math.pi / 2.0 - self.heading)

    def reached(self, yaw_enu: float) -> bool:
        return self.left == 0.0 and abs(_wrap(self.yaw_enu - yaw_enu)) <= YAW_REACHED_RAD


class DoQueue:
    """The condition and do items waiting beside one navigation item."""

    def __init__(self, executor: MissionExecutor):
        self.ex = executor
        #: (index, item) still to run, the head first; the index of the navigation item
        #: they run beside (None: the next one to fly; -1: no queue)
        self.items: list[tuple[int, MissionItem]] = []
        self.nav_index: int | None = -1
        self._head_started_us: int | None = None
        self._last_us: int | None = None
        #: a CONDITION_YAW's turn, held until the navigation item ends
        self.turn: _Turn | None = None

    def clear(self) -> None:
        self.items = []
        self.nav_index = -1
        self._head_started_us = None
        self._last_us = None
        self.turn = None

    def take(self, index: int) -> int:
        """The items from the condition at ``index`` up to the next navigation item (or a
        DO_JUMP, which the executor then takes) join the queue, to run beside the next
        navigation item flown; the index the executor goes on from."""
        mission = self.ex.cmdr.mission
        self.clear()
        k = index
        while k < len(mission) and mission[k].command > NAV_LAST and \
                mission[k].command != _CMD_DO_JUMP:
            self.items.append((k, mission[k]))
            k += 1
        self.nav_index = None
        return k

    def tick(self, s: VehicleState, destination: np.ndarray | None) -> None:
        """Run the queue for one tick of the navigation item ``nav_index`` (dropped once
        another item flies): the head condition, and what follows it once it is met."""
        c = self.ex.cmdr
        if self.nav_index == -1:
            return
        if self.nav_index is None:  # (the first navigation item flown after the take)
            if c.mission_seq >= len(c.mission) or c.mission[c.mission_seq].command > NAV_LAST:
                return
            self.nav_index = c.mission_seq
        elif c.mission_seq != self.nav_index:
            self.clear()
            return
        dt = 0.0 if self._last_us is None else (c.time_us - self._last_us) * 1e-6
        self._last_us = c.time_us
        if self.turn is not None:
            self.turn.advance(dt)
        while self.items:
            index, item = self.items[0]
            cond = item.condition
            if cond is None:
                self.ex.run_do(item)
            else:
                if self._head_started_us is None:
                    self._start(cond, s)
                if not self._met(cond, s, destination):
                    return
                self._head_started_us = None
            c.reached.append(index)
            self.items.pop(0)

    def _start(self, cond: Condition, s: VehicleState) -> None:
        self._head_started_us = self.ex.cmdr.time_us
        if cond.kind == CONDITION_YAW:
            held = self.turn.yaw_enu if self.turn is not None else s.yaw
            self.turn = _Turn(cond, held)

    def _met(self, cond: Condition, s: VehicleState, destination) -> bool:
        c = self.ex.cmdr
        if cond.kind == CONDITION_DELAY:
            return (c.time_us - self._head_started_us) * 1e-6 > max(cond.value, 0.0)
        if cond.kind == CONDITION_DISTANCE:
            if destination is None:
                return False
            d = float(np.hypot(*(destination[:2] - s.position[:2])))
            return d < max(cond.value, 0.0)
        if cond.kind == CONDITION_YAW:
            return self.turn.reached(s.yaw)
        return True

    def heading(self) -> float | None:
        """The heading a CONDITION_YAW holds (ENU rad), None when none does."""
        return self.turn.yaw_enu if self.turn is not None else None
