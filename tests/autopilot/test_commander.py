"""Commander behaviour in-process: what a PX4 user expects of arming, modes and failsafes."""

import math

import numpy as np
import pytest

from ft_sitl.autopilot import commander as cm
from ft_sitl.autopilot.commander import LandedState, MissionItem, MissionState, Result
from ft_sitl.autopilot.params import ParamSet
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.physics.catalog import catalog
from ft_sitl.sim.fleet import Fleet

P = catalog()["0.98kg-EGO Planner DIY"]


def texts(cmd):
    return [t for _, t in cmd.statustexts]


def test_arm_takeoff_hold_land_and_auto_disarm():
    f = Fleet(P)
    c = f.commanders[0]
    assert c.landed_state == LandedState.ON_GROUND and not c.armed
    assert c.arm() == Result.ACCEPTED
    assert c.takeoff() == Result.ACCEPTED
    assert f.run_until(lambda: c.mode_name == "AUTO.LOITER", 15)
    assert f.state(0).position[2] == pytest.approx(2.5, abs=0.15)  # MIS_TAKEOFF_ALT
    assert c.landed_state == LandedState.IN_AIR
    f.run(3.0)
    assert f.state(0).position == pytest.approx([0, 0, 2.5], abs=0.05)
    assert c.land() == Result.ACCEPTED
    f.run(0.5)
    assert c.landed_state == LandedState.LANDING
    assert f.run_until(lambda: c.landed_state == LandedState.ON_GROUND, 10)
    assert c.armed
    assert f.run_until(lambda: not c.armed, 3.0)  # COM_DISARM_LAND 2 s
    assert "Disarmed by landing" in texts(c)
    assert f.sim.max_impact_speed(0) < 1.0


def test_arming_is_refused_in_the_air_and_in_offboard_without_setpoints():
    f = Fleet(P)
    c = f.commanders[0]
    assert c.set_mode(cm.MAIN_OFFBOARD) == Result.TEMPORARILY_REJECTED
    assert "Offboard" in texts(c)[-1]
    assert c.set_mode(cm.MAIN_AUTO, cm.SUB_MISSION) == Result.TEMPORARILY_REJECTED
    c.arm()
    c.takeoff()
    f.run(4.0)
    c.disarm()
    assert c.armed and "not landed" in texts(c)[-1]
    assert c.disarm(force=True) == Result.ACCEPTED and not c.armed


def test_unarmed_vehicle_disarms_after_the_preflight_timeout():
    f = Fleet(P)
    c = f.commanders[0]
    c.arm()
    f.run(9.0)
    assert c.armed
    f.run(1.5)
    assert not c.armed and "no takeoff" in texts(c)[-1]


def test_offboard_entry_flight_and_loss_failsafe():
    f = Fleet(P)
    c = f.commanders[0]
    sp = Setpoint.position([0.0, 0.0, 2.0], yaw=0.0)
    f.offboard_setpoint(0, sp)
    assert c.set_mode(cm.MAIN_OFFBOARD) == Result.ACCEPTED
    assert c.arm() == Result.ACCEPTED
    for _ in range(150):  # stream at 20 Hz for 7.5 s
        f.offboard_setpoint(0, Setpoint.position([3.0, 1.0, 2.0], yaw=0.5))
        f.run(0.05)
    assert f.state(0).position == pytest.approx([3.0, 1.0, 2.0], abs=0.1)
    assert c.mode_name == "OFFBOARD"
    f.run(1.5)  # stream stops: COM_OF_LOSS_T 1 s
    assert c.mode_name == "AUTO.LOITER"
    assert "Offboard signal lost" in texts(c)[-1]
    hold = f.state(0).position
    f.run(2.0)
    assert f.state(0).position == pytest.approx(hold, abs=0.15)


def test_rtl_climbs_returns_and_lands_at_home():
    ps = ParamSet({"RTL_RETURN_ALT": 6.0})
    f = Fleet(P, params=[ps])
    c = f.commanders[0]
    c.arm()
    c.takeoff()
    f.run_until(lambda: c.mode_name == "AUTO.LOITER", 15)
    assert c.reposition(np.array([12.0, -5.0, 3.0])) == Result.ACCEPTED
    assert f.run_until(lambda: np.linalg.norm(f.state(0).position - [12, -5, 3]) < 0.2, 20)
    c.return_to_launch()
    peak = 0.0
    for _ in range(400):
        f.run(0.1)
        peak = max(peak, f.state(0).position[2])
        if not c.armed:
            break
    assert peak == pytest.approx(6.0, abs=0.3)
    assert not c.armed
    assert f.state(0).position[:2] == pytest.approx([0.0, 0.0], abs=0.3)


def test_mission_runs_its_items_and_finishes():
    f = Fleet(P)
    c = f.commanders[0]
    nan = math.nan
    c.set_mission([
        MissionItem(cm.CMD_NAV_TAKEOFF, (nan, nan, 3.0)),
        MissionItem(cm.CMD_DO_CHANGE_SPEED, speed_m_s=2.0),
        MissionItem(cm.CMD_NAV_WAYPOINT, (10.0, 0.0, 3.0), hold_s=1.0, acceptance_radius_m=0.5),
        MissionItem(2000),  # a camera item: accepted and skipped
        MissionItem(cm.CMD_NAV_WAYPOINT, (10.0, 8.0, 4.0)),
        MissionItem(cm.CMD_NAV_LAND, (10.0, 8.0, nan)),
    ])
    assert c.arm() == Result.ACCEPTED
    assert c.set_mode(cm.MAIN_AUTO, cm.SUB_MISSION) == Result.ACCEPTED
    vmax = 0.0
    for _ in range(600):
        f.run(0.1)
        vmax = max(vmax, float(np.linalg.norm(f.state(0).velocity[:2])))
        if c.mission_state == MissionState.COMPLETE and not c.armed:
            break
    assert list(c.reached) == [0, 1, 2, 3, 4, 5]
    assert c.mission_state == MissionState.COMPLETE
    assert vmax <= 2.0 * 1.1  # DO_CHANGE_SPEED honoured
    assert f.state(0).position[:2] == pytest.approx([10.0, 8.0], abs=0.3)
    assert not c.armed


def test_a_mission_circles_loiter_turns_and_faces_its_region_of_interest():
    """NAV_LOITER_TURNS: to the circle's edge, then round it (clockwise for a positive
    radius) the turns asked, then on; DO_SET_ROI_LOCATION: the front toward the point on
    the next legs, a ROI without a position ends it."""
    from ft_sitl.autopilot.mission import (
        CMD_DO_SET_ROI_LOCATION,
        CMD_NAV_LOITER_TURNS,
    )

    f = Fleet(P)
    c = f.commanders[0]
    nan = math.nan
    roi = (0.0, 40.0, 0.0)
    c.set_mission([
        MissionItem(cm.CMD_NAV_TAKEOFF, (nan, nan, 4.0)),
        MissionItem(CMD_DO_SET_ROI_LOCATION, roi),
        MissionItem(cm.CMD_NAV_WAYPOINT, (15.0, 0.0, 4.0)),
        MissionItem(CMD_NAV_LOITER_TURNS, (15.0, 0.0, 4.0), turns=1.5, radius_m=5.0,
                    speed_m_s=2.0),
        MissionItem(CMD_DO_SET_ROI_LOCATION),
        MissionItem(cm.CMD_NAV_WAYPOINT, (15.0, -12.0, 4.0)),
        MissionItem(cm.CMD_NAV_LAND, (15.0, -12.0, nan)),
    ])
    assert c.arm() == Result.ACCEPTED
    assert c.set_mode(cm.MAIN_AUTO, cm.SUB_MISSION) == Result.ACCEPTED
    facing_roi, on_circle, angles, last_leg_yaw = [], [], [], []
    for _ in range(3000):
        f.run(0.05)
        s = f.state(0)
        seq = c.mission_seq
        if seq == 2 and np.linalg.norm(s.position[:2] - [15.0, 0.0]) > 3.0 and \
                s.position[0] > 3.0:
            want = math.atan2(roi[1] - s.position[1], roi[0] - s.position[0])
            facing_roi.append(abs((s.yaw - want + math.pi) % (2 * math.pi) - math.pi))
        if seq == 3 and c.mission_exec.circling is not None:
            d = s.position[:2] - np.array([15.0, 0.0])
            on_circle.append(float(np.hypot(*d)))
            angles.append(math.atan2(d[1], d[0]))
        if seq == 5 and np.linalg.norm(s.velocity[:2]) > 1.0:
            d = np.array([15.0, -12.0]) - s.position[:2]
            course = math.atan2(d[1], d[0])
            last_leg_yaw.append(abs((s.yaw - course + math.pi) % (2 * math.pi) - math.pi))
        if c.mission_state == MissionState.COMPLETE and not c.armed:
            break
    assert list(c.reached) == [0, 1, 2, 3, 4, 5, 6]
    assert facing_roi and max(facing_roi[len(facing_roi) // 2:]) < math.radians(10)
    assert on_circle and np.median(on_circle) == pytest.approx(5.0, abs=0.5)
    swept = -np.sum((np.diff(angles) + math.pi) % (2 * math.pi) - math.pi)
    assert swept == pytest.approx(1.5 * 2 * math.pi, abs=0.3)  # clockwise: bearing falls
    # the ROI ended: the last leg heads along its course again, not toward the ROI
    assert last_leg_yaw and np.median(last_leg_yaw[len(last_leg_yaw) // 2:]) < math.radians(15)
    assert f.state(0).position[:2] == pytest.approx([15.0, -12.0], abs=0.5)


def test_battery_drains_with_flight():
    f = Fleet(P, params=[ParamSet({"FT_BAT_ENDURANCE": 60.0})])
    c = f.commanders[0]
    v0 = c.battery.voltage()
    c.arm()
    c.takeoff()
    f.run(20.0)
    assert 0.5 < c.battery.remaining < 0.8
    assert c.battery.voltage() < v0


# --- geofence, rally points, a mission started on the ground ---------------------------------
def _flying(params=None):
    f = Fleet(P, params=[ParamSet(params or {})])
    c = f.commanders[0]
    c.arm()
    c.takeoff()
    assert f.run_until(lambda: c.mode_name == "AUTO.LOITER", 15)
    return f, c


@pytest.mark.parametrize("action,mode", [(1, "AUTO.LOITER"), (2, "AUTO.LOITER"),
                                         (3, "AUTO.RTL"), (4, None), (5, "AUTO.LAND")])
def test_a_geofence_breach_takes_gf_action(action, mode):
    from ft_sitl.autopilot.geofence import Fence, circle

    f, c = _flying({"GF_ACTION": action})
    c.set_fence(Fence([circle([0.0, 0.0], 8.0, True, "test")]))
    c.reposition(np.array([20.0, 0.0, 2.5]))  # out through the circle's edge
    f.run_until(lambda: c.fence_events, 20)
    assert [(r, a) for _, r, a in c.fence_events] == [("outside the fence",
                                                       cm.GF_ACTIONS[action])]
    x_breach = f.true_state(0).position[0]
    assert 7.9 < x_breach < 8.5
    f.run(3.0)
    if action == 1:  # a warning: the reposition goes on
        assert "Geofence breached: outside the fence" in texts(c)
        assert f.state(0).position[0] > 12.0
    elif action == 4:
        assert c.terminated
    else:
        assert c.mode_name == mode and f.state(0).position[0] < 11.0
    assert len(c.fence_events) == 1  # one breach, one action


@pytest.mark.parametrize("action", [1, 2, 5])
def test_arming_where_the_fence_is_breached_is_refused_unless_gf_action_is_none(action):
    from ft_sitl.autopilot.geofence import Fence, circle

    # PX4 (geofenceCheck.cpp): any action but "none", warning included, fails the check
    f = Fleet(P, params=[ParamSet({"GF_ACTION": action})])
    c = f.commanders[0]
    f.run(0.5)
    c.set_fence(Fence([circle([0.0, 0.0], 2.0, False, "test")]))  # keep out: we stand in it
    assert c.fence_breach_here() == "outside the fence"
    assert c.arm() == Result.DENIED and not c.armed
    assert texts(c)[-1] == cm.FENCE_ARM_DENIAL == "Preflight Fail: Geofence violation"
    assert c.arm(force=True) == Result.ACCEPTED and c.armed  # force skips the checks
    c.disarm(force=True)
    c.arm_fence_check = False  # the rule of trial protocols before 8
    assert c.arm() == Result.ACCEPTED
    c.disarm(force=True)
    c.arm_fence_check = True
    c.set_fence(Fence([circle([0.0, 0.0], 8.0, True, "test")]))  # now inside: arms
    assert c.fence_breach_here() is None and c.arm() == Result.ACCEPTED
    c.disarm(force=True)
    c.set_fence(Fence([circle([0.0, 0.0], 2.0, False, "test")]))
    c.params.set("GF_ACTION", 0)  # none: PX4's navigator does not check at all
    assert c.fence_breach_here() is None and c.arm() == Result.ACCEPTED


def test_max_distance_and_height_fences_and_rtl_to_the_nearest_rally_point():
    f, c = _flying({"GF_MAX_VER_DIST": 4.0, "GF_ACTION": 3, "RTL_RETURN_ALT": 3.5})
    c.set_rally([np.array([6.0, 6.0, 0.0]), np.array([-30.0, 0.0, 0.0])])
    c.reposition(np.array([8.0, 8.0, 2.5]))
    assert f.run_until(lambda: np.linalg.norm(f.state(0).position - [8, 8, 2.5]) < 0.2, 20)
    c.reposition(np.array([8.0, 8.0, 5.0]))  # up through 4 m: RTL
    assert f.run_until(lambda: c.fence_events, 20)
    assert c.fence_events[0][1:] == ("more than 4 m above home", "return")
    assert c.mode_name == "AUTO.RTL"
    assert f.run_until(lambda: not c.armed, 60)
    assert "RTL: land at rally point" in texts(c)
    assert f.true_state(0).position[:2] == pytest.approx([6.0, 6.0], abs=0.3)


def test_a_mission_started_on_the_ground_takes_off_first():
    f = Fleet(P)
    c = f.commanders[0]
    c.set_mission([MissionItem(cm.CMD_NAV_WAYPOINT, (10.0, 0.0, 4.0)),
                   MissionItem(cm.CMD_NAV_LAND, (10.0, 0.0, math.nan))])
    c.arm()
    assert c.set_mode(cm.MAIN_AUTO, cm.SUB_MISSION) == Result.ACCEPTED
    path = []
    for _ in range(400):
        f.run(0.1)
        path.append(f.true_state(0).position.copy())
        if c.mission_state == MissionState.COMPLETE and not c.armed:
            break
    path = np.array(path)
    assert "Mission: takeoff to 4.0 m first" in texts(c)
    # straight up before it heads out: no eastward motion below 3.5 m
    up = int(np.argmax(path[:, 2] >= 3.5))
    assert up > 0 and np.abs(path[:up, 0]).max() < 0.3
    assert c.mission_state == MissionState.COMPLETE and not c.armed
    assert path[-1][:2] == pytest.approx([10.0, 0.0], abs=0.3)


# --- failure injection (Fleet.inject_failure, as MAV_CMD_INJECT_FAILURE) -----------------------
GPS, BATTERY, MOTOR, GYRO, RC = 4, 100, 101, 0, 104
OK, OFF, STUCK, WRONG, GARBAGE = 0, 1, 2, 4, 3


def test_failure_injection_needs_sys_failure_en_and_refuses_what_is_not_simulated():
    f, c = _flying()
    assert f.inject_failure(0, MOTOR, OFF, 1) == Result.DENIED
    assert "Failure injection disabled (SYS_FAILURE_EN)" in texts(c)
    f.params[0].set("SYS_FAILURE_EN", 1)
    assert f.inject_failure(0, RC, OFF, 0) == Result.UNSUPPORTED
    assert f.inject_failure(0, GPS, GARBAGE, 0) == Result.UNSUPPORTED
    assert f.inject_failure(0, MOTOR, OFF, 7) == Result.UNSUPPORTED  # a quad has 4
    assert f.inject_failure(0, 77, OFF, 0) == Result.UNSUPPORTED
    assert c.failures == {}


def test_gps_loss_lands_after_the_delay_and_battery_loss_lands_at_once():
    f, c = _flying({"SYS_FAILURE_EN": 1, "COM_POS_FS_DELAY": 2})
    assert f.inject_failure(0, GPS, OFF, 0) == Result.ACCEPTED
    assert not c.sensor_ok("gps")
    f.run(1.5)
    assert c.mode_name == "AUTO.LOITER"  # not yet
    f.run(1.0)
    assert c.mode_name == "AUTO.LAND" and "Failsafe: no position estimate, landing" in texts(c)
    f2, c2 = _flying({"SYS_FAILURE_EN": 1})
    assert f2.inject_failure(0, BATTERY, OFF, 0) == Result.ACCEPTED
    f2.run(0.1)
    assert c2.mode_name == "AUTO.LAND" and c2.battery.remaining == 0.0
    assert f2.inject_failure(0, BATTERY, OK, 0) == Result.ACCEPTED
    assert c2.battery.remaining > 0.9 and "battery" not in c2.failures


def test_a_motor_off_stuck_or_weak_is_flown_by_the_physics():
    f, c = _flying({"SYS_FAILURE_EN": 1})
    assert f.inject_failure(0, MOTOR, STUCK, 2) == Result.ACCEPTED
    w_stuck = f.sim.w_cmd[0, 1]
    c.reposition(np.array([3.0, 0.0, 2.5]))
    f.run(0.3)
    assert f.sim.w_cmd[0, 1] == w_stuck  # frozen while the others work
    assert f.inject_failure(0, MOTOR, OK, 2) == Result.ACCEPTED
    f.run(0.3)
    assert f.sim.w_cmd[0, 1] != w_stuck
    assert f.inject_failure(0, MOTOR, WRONG, 3) == Result.ACCEPTED
    assert f.sim.actuator_settings[0]["degraded_efficiency"] == 0.5
    assert f.inject_failure(0, MOTOR, OFF, 1) == Result.ACCEPTED
    f.run(1.0)
    assert f.sim.rotor_speeds(0)[0] < 1.0
    assert f.true_state(0).position[2] < 1.5 or c.crashed  # a quad without a motor falls
    assert set(c.failures) == {"motor"}


def test_arducopter_mission_items_give_loiter_turns_their_circle_and_end_a_roi_at_zero():
    from types import SimpleNamespace

    from pymavlink.dialects.v20 import ardupilotmega as apm

    from ft_sitl.autopilot.mission import CMD_NAV_LOITER_TURNS
    from ft_sitl.mavlink.ardupilot.mission import ArduCopterMissionItems

    items = ArduCopterMissionItems(SimpleNamespace(origin=np.zeros(3),
                                                   alt_to_local=lambda z, frame: z))

    def item(command, p1=0.0, p3=0.0, x=0, y=0, frame=apm.MAV_FRAME_LOCAL_NED):
        return apm.MAVLink_mission_item_int_message(1, 1, 1, frame, command, 0, 1, p1, 0.0,
                                                    p3, 0.0, x, y, -5.0)

    turns = items.to_mission_item(item(apm.MAV_CMD_NAV_LOITER_TURNS, 2, -4.0, 100000))
    assert (turns.command, turns.turns, turns.radius_m) == (CMD_NAV_LOITER_TURNS, 2.0, -4.0)
    assert turns.position == pytest.approx((0.0, 10.0, 5.0))  # NED 10 m north, ENU y
    assert turns.speed_m_s == pytest.approx(math.radians(20) * 4.0)  # CIRCLE_RATE
    default = items.to_mission_item(item(apm.MAV_CMD_NAV_LOITER_TURNS, 1))
    assert default.radius_m == 10.0  # CIRCLE_RADIUS's default
    roi_off = items.to_mission_item(item(apm.MAV_CMD_DO_SET_ROI_LOCATION,
                                         frame=apm.MAV_FRAME_GLOBAL_RELATIVE_ALT))
    assert all(math.isnan(v) for v in roi_off.position[:2])
