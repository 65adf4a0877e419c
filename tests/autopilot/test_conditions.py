"""ArduCopter's CONDITION_* items (ft_sitl.autopilot.conditions), flown in-process through
the flight controller: a condition and the DO items after it run beside the next navigation
item, the DO items held back until the condition is met and dropped when the navigation
item ends first; CONDITION_YAW turns the heading at the rate asked and holds it."""

import math

import numpy as np
import pytest

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import MissionItem, MissionState, Result
from ft_sitl.autopilot.conditions import (
    CONDITION_DELAY,
    CONDITION_DISTANCE,
    CONDITION_YAW,
    Condition,
)
from ft_sitl.autopilot.mission import CMD_DO_SET_ROI_LOCATION
from ft_sitl.physics.catalog import catalog
from ft_sitl.sim.fleet import Fleet

P = catalog()["0.98kg-EGO Planner DIY"]
nan = math.nan
DT = 0.05


def _fly(items, limit_s=200.0):
    """Fly ``items`` in AUTO from the ground; per tick: time, current item, position,
    horizontal speed, yaw and the items reached so far."""
    f = Fleet(P)
    c = f.commanders[0]
    c.set_mission(items)
    assert c.arm() == Result.ACCEPTED
    assert c.set_mode(cm.MAIN_AUTO, cm.SUB_MISSION) == Result.ACCEPTED
    rows = []
    for k in range(int(limit_s / DT)):
        f.run(DT)
        s = f.state(0)
        rows.append(((k + 1) * DT, c.mission_seq, s.position.copy(),
                     float(np.linalg.norm(s.velocity[:2])), s.yaw, list(c.reached)))
        if c.mission_state == MissionState.COMPLETE and not c.armed:
            break
    return rows, c


def _cond(kind, value, **kw):
    return MissionItem(kind, condition=Condition(kind, value, **kw))


def _when_reached(rows, index):
    """The first row whose reached items include ``index``."""
    return next(r for r in rows if index in r[5])


def test_a_delay_holds_back_the_speed_change_after_it_until_it_has_run():
    items = [MissionItem(cm.CMD_NAV_TAKEOFF, (nan, nan, 5.0)),
             MissionItem(cm.CMD_NAV_WAYPOINT, (0.0, 5.0, 5.0), hold_s=1.0),
             _cond(CONDITION_DELAY, 4.0),
             MissionItem(cm.CMD_DO_CHANGE_SPEED, speed_m_s=1.0),
             MissionItem(cm.CMD_NAV_WAYPOINT, (40.0, 5.0, 5.0)),
             MissionItem(cm.CMD_NAV_LAND, (nan, nan, nan))]
    rows, c = _fly(items)
    assert list(c.reached) == [0, 1, 2, 3, 4, 5] and not c.armed
    leg = [r for r in rows if r[1] == 4]
    start = leg[0][0]
    early = [r[3] for r in leg if r[0] - start < 4.0]
    late = [r[3] for r in leg if r[0] - start > 7.0 and np.linalg.norm(r[2][:2] - [40, 5]) > 3]
    assert max(early) > 2.5  # the cruise speed: the change waits for the delay
    assert late and max(late) < 1.0 * 1.15  # then DO_CHANGE_SPEED's 1 m/s
    met = _when_reached(rows, 2)
    assert met[0] - start == pytest.approx(4.0, abs=2 * DT)
    assert _when_reached(rows, 3)[0] == met[0]  # the DO item runs as the condition is met


def test_a_distance_condition_starts_the_region_of_interest_near_the_waypoint():
    roi = (60.0, 60.0, 0.0)
    items = [MissionItem(cm.CMD_NAV_TAKEOFF, (nan, nan, 5.0)),
             _cond(CONDITION_DISTANCE, 20.0),
             MissionItem(CMD_DO_SET_ROI_LOCATION, roi),
             MissionItem(cm.CMD_NAV_WAYPOINT, (40.0, 0.0, 5.0)),
             MissionItem(cm.CMD_NAV_LAND, (nan, nan, nan))]
    rows, c = _fly(items)
    assert list(c.reached) == [0, 1, 2, 3, 4]
    met = _when_reached(rows, 2)
    assert met[1] == 3  # while flying item 3
    d = float(np.linalg.norm(met[2][:2] - [40.0, 0.0]))
    assert 19.0 < d < 20.0  # (it moves about 0.2 m a tick)
    before = [r for r in rows if r[1] == 3 and r[0] < met[0] - 1.0 and r[3] > 1.0]
    assert before and max(abs(r[4]) for r in before) < math.radians(10)  # along the leg
    near = [r for r in rows if r[1] == 3 and r[0] > met[0] + 2.0 and
            np.linalg.norm(r[2][:2] - [40.0, 0.0]) > 1.0]
    want = [math.atan2(roi[1] - r[2][1], roi[0] - r[2][0]) for r in near]
    assert near and max(abs((r[4] - w + math.pi) % (2 * math.pi) - math.pi)
                        for r, w in zip(near, want)) < math.radians(10)


def test_condition_yaw_turns_at_its_rate_holds_and_a_pending_item_is_dropped():
    """CONDITION_YAW 270 (west, absolute) anticlockwise at 20 deg/s beside a leg north: the
    heading turns from east through north to west at about that rate and stays west on the
    leg; a CONDITION_DELAY too long for its leg drops the speed change after it."""
    items = [MissionItem(cm.CMD_NAV_TAKEOFF, (nan, nan, 5.0)),
             _cond(CONDITION_YAW, 270.0, rate_deg_s=20.0, direction=-1),
             MissionItem(cm.CMD_NAV_WAYPOINT, (0.0, 60.0, 5.0)),
             _cond(CONDITION_DELAY, 300.0),
             MissionItem(cm.CMD_DO_CHANGE_SPEED, speed_m_s=1.0),
             MissionItem(cm.CMD_NAV_WAYPOINT, (20.0, 60.0, 5.0)),
             MissionItem(cm.CMD_NAV_LAND, (nan, nan, nan))]
    rows, c = _fly(items)
    assert list(c.reached) == [0, 1, 2, 5, 6]  # the yaw met while flying 2; 3, 4 dropped
    leg = [r for r in rows if r[1] == 2]
    yaws = np.unwrap([r[4] for r in leg])
    assert abs(yaws[0]) < math.radians(5)  # (it took off facing east, ENU yaw 0)
    turned = _when_reached(rows, 1)
    assert turned[1] == 2
    assert abs((turned[4] - math.pi + math.pi) % (2 * math.pi) - math.pi) <= math.radians(2.5)
    assert np.all(np.diff(yaws[yaws < math.pi - 0.1]) > -1e-3)  # anticlockwise (ENU +)
    took = turned[0] - leg[0][0]
    assert 8.5 < took < 11.0  # the 180 degrees at 20 deg/s
    assert np.max(np.abs(np.diff(yaws))) / DT < math.radians(20) * 1.5
    after = [r[4] for r in leg if r[0] > turned[0] + 0.5]
    assert after and max(abs((y - math.pi + math.pi) % (2 * math.pi) - math.pi)
                         for y in after) < math.radians(3)  # held to the leg's end
    last = [r[3] for r in rows if r[1] == 5]
    assert max(last) > 2.5  # the speed change was dropped with its leg


def test_the_arducopter_face_reads_condition_items_as_ap_mission_stores_them():
    from types import SimpleNamespace

    from pymavlink.dialects.v20 import ardupilotmega as apm

    from ft_sitl.mavlink.ardupilot.mission import ArduCopterMissionItems

    items = ArduCopterMissionItems(SimpleNamespace(origin=np.zeros(3),
                                                   alt_to_local=lambda z, frame: z))

    def item(command, *params):
        return apm.MAVLink_mission_item_int_message(1, 1, 1, apm.MAV_FRAME_GLOBAL, command,
                                                    0, 1, *params, 0, 0, 0.0)

    yaw = items.to_mission_item(item(apm.MAV_CMD_CONDITION_YAW, 270.0, 15.0, -1.0, 1.0))
    assert yaw.condition == Condition(CONDITION_YAW, 270.0, 15.0, -1, True)
    delay = items.to_mission_item(item(apm.MAV_CMD_CONDITION_DELAY, 3.0, 0, 0, 0))
    assert delay.condition == Condition(CONDITION_DELAY, 3.0)
    dist = items.to_mission_item(item(apm.MAV_CMD_CONDITION_DISTANCE, 12.5, 0, 0, 0))
    assert (dist.command, dist.condition) == (114, Condition(CONDITION_DISTANCE, 12.5))
    # the PX4 face knows no conditions: its items carry none (it skips them, as before)
    from ft_sitl.mavlink.mission_items import MissionItems

    px4 = MissionItems(SimpleNamespace(origin=np.zeros(3), alt_to_local=lambda z, frame: z))
    assert px4.to_mission_item(item(apm.MAV_CMD_CONDITION_DELAY, 3.0, 0, 0, 0)).condition \
        is None
