"""One trial of the protocol (ft_sitl.missions.trial): outcomes, metrics, determinism, specs.

Trials fly the real fleet (commander, cascade, plant) in real scenarios with the collision
guard. The navigators here are small test classes handed to ``run_trial`` directly; the
registry path is covered in test_campaign.py. Most trials fly in the ``yard`` (conftest):
one wall across the start -> goal line, short flights.
"""

import dataclasses
import hashlib
import json
import math
import signal
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
import trimesh

from ft_sitl.autopilot import cascade
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.missions.results import COLUMNS, REASONS
from ft_sitl.missions.trial import (
    TrialSpec,
    TrialSpecError,
    load_scenario_for,
    platform_for,
    run_trial,
)
from ft_sitl.navigation.base import GiveUp, Limits, Navigator
from ft_sitl.scenarios.solvability import scenario_path
from tests.missions.conftest import PLATFORM, YARD_GOAL, YARD_START, write_yard

# columns that depend on the wall clock, not on the spec
WALL_CLOCK = ("wall_time_s", "planner_time_s", "finished_utc")
TICK_S = 0.02  # the protocol checks the outcome at least every 20 ms of simulated time


def yard_spec(yard, **kw) -> TrialSpec:
    return TrialSpec(algorithm="straight", platform=PLATFORM, family="yard",
                     scenario_file=str(yard), **kw)


def same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


# --- test navigators -------------------------------------------------------------------------
class Carrot(Navigator):
    """Flies a polyline: a position setpoint on the next waypoint, switched to the one
    after once the vehicle is within ``lookahead`` of it. Once it has been in the goal
    sphere it targets ``away`` instead (None: it stays)."""

    name = "carrot"

    def __init__(self, points, lookahead=1.0, away=None):
        super().__init__()
        self.points = np.asarray(points, dtype=float)
        self.lookahead = lookahead
        self.away = away
        self.k = 1
        self.arrived = False

    def step(self, obs):
        if np.linalg.norm(obs.position - self.task.goal) <= self.task.limits.goal_radius_m:
            self.arrived = True
        if self.arrived and self.away is not None:
            return Setpoint.position(self.away, yaw=self.task.start_yaw)
        while (self.k < len(self.points) - 1
               and np.linalg.norm(obs.position - self.points[self.k]) < self.lookahead):
            self.k += 1
        return Setpoint.position(self.points[self.k], yaw=self.task.start_yaw)


class Hover(Navigator):
    name = "hover"

    def step(self, obs):
        return Setpoint.position(self.task.start, yaw=self.task.start_yaw)


class Velocity(Navigator):
    name = "velocity"

    def __init__(self, v):
        super().__init__()
        self.v = v

    def step(self, obs):
        return Setpoint.velocity(self.v)


class Raising(Navigator):
    """Raises ``exc`` in reset or in the step at 0.5 s."""

    name = "raising"

    def __init__(self, where, exc):
        super().__init__()
        self.where, self.exc = where, exc

    def reset(self, task):
        super().reset(task)
        if self.where == "reset":
            raise self.exc

    def step(self, obs):
        if self.where == "step" and obs.time_s >= 0.5:
            raise self.exc
        return Setpoint.position(self.task.start)


class Returning(Navigator):
    """Returns ``value`` from its third step on (a valid setpoint before)."""

    name = "returning"

    def __init__(self, value):
        super().__init__()
        self.value = value
        self.calls = 0

    def step(self, obs):
        self.calls += 1
        return Setpoint.position(self.task.start) if self.calls < 3 else self.value


def _with_inf() -> Setpoint:
    row = Setpoint.position([1.0, 2.0, 3.0]).row.copy()
    row[np.flatnonzero(~np.isnan(row))[-1]] = np.inf
    return Setpoint(row)


# --- fixtures --------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def yard_path(yard):
    """A collision-free polyline start -> goal in the yard, 0.4 m more clearance than the
    platform's collision radius (for the tracking error)."""
    spec = yard_spec(yard)
    radius = platform_for(spec).collision_radius_m
    path = scenario_path(load_scenario_for(spec), radius + 0.4)
    assert path is not None, "the yard must be solvable with a margin"
    return path


@pytest.fixture(scope="module")
def flown(yard, yard_path):
    """The path follower's successful trial, with its trajectory."""
    return run_trial(yard_spec(yard), record=True, navigator=Carrot(yard_path))


# --- the baseline ----------------------------------------------------------------------------
def _first_contact(scenario, radius):
    """Distance along the straight start -> goal line at which a sphere of ``radius``
    first touches an obstacle, and that obstacle's name (independent of the guard)."""
    d = scenario.goal - scenario.start
    length = float(np.linalg.norm(d))
    s = np.arange(0.0, length, 0.01)
    pts = scenario.start + s[:, None] * (d / length)
    _, dist, tri = trimesh.proximity.closest_point(scenario.mesh, pts)
    hit = np.flatnonzero(dist <= radius)
    assert len(hit), "the scenario's straight line must be blocked"
    return float(s[hit[0]]), scenario.obstacle_name(int(tri[hit[0]]))


def test_the_baseline_hits_the_obstacle_on_the_line():
    # Narrow-Gap's first generator: a wall across the line (version 2's configuration 1
    # has its gap on the line)
    spec = TrialSpec("straight", PLATFORM, "narrow_gap", scenario_index=1, scenario_version=1)
    out = run_trial(spec)
    row = out.row
    assert set(row) == set(COLUMNS)
    radius = platform_for(spec).collision_radius_m
    s_hit, name = _first_contact(out.scenario, radius)
    assert name != "obstacle", "generated scenarios name their obstacles"
    assert (row["reason"], row["success"]) == ("collision", False)
    assert row["detail"].startswith(f"hit {name} at ")
    assert row["min_clearance_m"] == 0.0
    # it flew the line from the start waypoint until its sphere touched
    assert row["path_length_m"] == pytest.approx(s_hit, abs=0.3)
    assert math.isnan(row["time_to_goal_s"])
    assert s_hit / 4.0 <= row["nav_time_s"] <= s_hit / 4.0 + 1.5  # 4 m/s after a ramp
    assert 3.5 < row["max_speed_m_s"] < 4.2  # MPC_XY_VEL_MAX
    assert row["algorithm"] == "straight" and row["platform"] == PLATFORM
    assert (row["family"], row["scenario_index"], row["scenario"]) == (
        "narrow_gap", 1, "narrow_gap-01-s0")
    assert row["trial_id"] == spec.trial_id and json.loads(row["spec"]) == spec.to_dict()
    assert row["planner_calls"] >= row["nav_time_s"] * 20 - 1  # 20 Hz
    assert row["sim_time_s"] > row["nav_time_s"]  # plus the approach


def test_the_same_spec_gives_the_same_row(yard):
    spec = yard_spec(yard, trial=1, seed=5)
    a, b = run_trial(spec).row, run_trial(spec).row
    assert a["reason"] == "collision"
    differ = [k for k in COLUMNS if k not in WALL_CLOCK and not same(a[k], b[k])]
    assert differ == []
    assert a["wall_time_s"] > 0 and a["planner_time_s"] >= 0


# --- success and its metrics -----------------------------------------------------------------
def test_a_navigator_on_a_collision_free_path_succeeds(flown, yard):
    row, traj = flown.row, flown.trajectory
    assert (row["reason"], row["success"], row["detail"]) == ("success", True, "")
    limits = Limits()
    # reached the goal sphere, then held it for 3 s (checked every tick)
    assert row["time_to_goal_s"] < row["nav_time_s"]
    assert limits.hold_s <= row["nav_time_s"] - row["time_to_goal_s"] <= limits.hold_s + TICK_S
    # the trajectory: navigation time, ENU positions, one sample per check
    assert traj.shape[1] == 4 and np.all(np.diff(traj[:, 0]) > 0)
    assert traj[-1, 0] == pytest.approx(row["nav_time_s"])
    assert np.diff(traj[:, 0]).max() <= TICK_S + 1e-9
    dist = np.linalg.norm(traj[:, 1:] - np.array(YARD_GOAL), axis=1)
    inside = dist <= limits.goal_radius_m
    first = int(np.argmax(inside))
    assert traj[first, 0] == pytest.approx(row["time_to_goal_s"])
    assert inside[first:].all() and not inside[:first].any()
    # metrics agree with the flown trajectory
    steps = np.linalg.norm(np.diff(traj[:, 1:], axis=0), axis=1).sum()
    assert steps <= row["path_length_m"] <= steps + 0.1
    assert row["path_length_m"] > np.linalg.norm(np.subtract(YARD_GOAL, YARD_START)) - 2.0
    # the clearance is the body's (protocol 5): between what its bounding sphere and its
    # thinnest reach (half its height) leave from the centre's distance to the obstacle
    body = platform_for(yard_spec(yard)).body()
    centre = trimesh.proximity.closest_point(flown.scenario.mesh, traj[:, 1:])[1].min()
    assert centre - body.bounding_radius_m - 1e-3 <= row["min_clearance_m"]
    assert row["min_clearance_m"] <= centre - body.half_height_m + 1e-3
    assert 0.2 < row["min_clearance_m"] < 1.5
    assert 0.0 < row["mean_speed_m_s"] < row["max_speed_m_s"] <= 4.2
    assert 0.0 <= row["max_tilt_deg"] < 45.0
    assert 0.0 <= row["saturation_fraction"] <= 1.0
    assert row["energy_j"] > 0.0
    assert row["replans"] == 0 and row["planner_calls"] > 0
    assert row["sim_time_s"] > row["nav_time_s"]


def test_entering_the_goal_before_the_timeout_and_holding_past_it_succeeds(flown, yard,
                                                                        yard_path):
    ttg = flown.row["time_to_goal_s"]
    spec = yard_spec(yard, limits=Limits(timeout_s=ttg + 0.5))
    row = run_trial(spec, navigator=Carrot(yard_path)).row
    assert row["reason"] == "success" and row["nav_time_s"] > spec.limits.timeout_s


def test_a_goal_radius_too_small_to_reach_is_a_timeout(yard, yard_path):
    spec = yard_spec(yard, limits=Limits(goal_radius_m=0.01, timeout_s=12.0))
    row = run_trial(spec, navigator=Carrot(yard_path)).row
    assert row["reason"] == "timeout", row["detail"]


# --- failures --------------------------------------------------------------------------------
def test_leaving_the_goal_sphere_during_the_hold_is_unstable(yard, yard_path):
    away = np.array(YARD_GOAL) + [4.0, 0.0, 0.0]  # 4 m beside the goal, inside the area
    row = run_trial(yard_spec(yard), navigator=Carrot(yard_path, away=away)).row
    assert row["reason"] == "unstable", row["detail"]
    assert row["detail"].startswith("left the goal sphere ")
    assert row["detail"].endswith(" s after entering it (hold 3 s)")
    left_after = float(row["detail"].split()[4])
    assert 0.0 < left_after < 3.0
    assert row["nav_time_s"] == pytest.approx(row["time_to_goal_s"] + left_after, abs=0.01)


@pytest.mark.parametrize("v, detail", [
    ((0.0, 0.0, 2.0), "climbed above the ceiling"),
    ((0.0, 0.0, -1.0), "touched the floor"),
    ((-3.0, 0.0, 0.0), "left the flight volume past the west edge"),
])
def test_leaving_the_flight_volume_is_out_of_bounds(yard, v, detail):
    row = run_trial(yard_spec(yard), navigator=Velocity(v)).row
    assert (row["reason"], row["detail"]) == ("out_of_bounds", detail)
    assert not row["success"] and math.isnan(row["time_to_goal_s"])


def test_a_flip_is_a_loss_of_control(yard):
    class Flip(Navigator):
        def step(self, obs):
            return Setpoint.body_rates([30.0, 0.0, 0.0], 0.6)

    row = run_trial(yard_spec(yard), navigator=Flip()).row
    assert row["reason"] == "loss_of_control"
    assert row["detail"].startswith("tilt ") and row["max_tilt_deg"] > 90.0


def test_hovering_times_out(yard):
    spec = yard_spec(yard, limits=Limits(timeout_s=2.0))
    row = run_trial(spec, navigator=Hover()).row
    assert row["reason"] == "timeout"
    assert row["detail"] == "not in the goal sphere after 2 s (16.0 m away)"
    assert 2.0 <= row["nav_time_s"] <= 2.0 + TICK_S
    assert math.isnan(row["time_to_goal_s"]) and row["path_length_m"] < 0.5


class Offset(Navigator):
    """Holds a point ``dz`` above the start: a step the vehicle must fly to."""

    name = "offset"

    def __init__(self, dz):
        super().__init__()
        self.dz = dz

    def step(self, obs):
        return Setpoint.position(np.add(self.task.start, [0.0, 0.0, self.dz]),
                                 yaw=self.task.start_yaw)


def test_tracking_error_is_the_rms_distance_to_the_commanded_position(yard):
    spec = yard_spec(yard, limits=Limits(timeout_s=4.0))
    held = run_trial(spec, navigator=Hover()).row
    assert held["reason"] == "timeout"
    assert 0.0 <= held["tracking_rms_m"] < 0.05  # holding the start it hovers at
    # a 2 m step: the error starts at 2 m and falls as the vehicle climbs to it, so the
    # RMS over 4 s lies between those
    stepped = run_trial(spec, navigator=Offset(2.0)).row
    assert 0.3 < stepped["tracking_rms_m"] < 2.0
    # nothing commands a position: no tracking error
    moving = run_trial(spec, navigator=Velocity([1.0, 0.0, 0.0])).row
    assert math.isnan(moving["tracking_rms_m"])


def test_a_protocol_with_a_stall_timeout_ends_a_hover_early_and_no_flight(yard, yard_path,
                                                                          monkeypatch):
    from ft_sitl.missions import spec as spec_module

    rules = dataclasses.replace(spec_module.PROTOCOLS[4], version=99, stall_timeout_s=1.0)
    monkeypatch.setitem(spec_module.PROTOCOLS, 99, rules)
    spec = yard_spec(yard, limits=Limits(timeout_s=5.0), protocol=99)
    row = run_trial(spec, navigator=Hover()).row
    assert row["reason"] == "timeout"
    assert row["detail"] == ("stalled: no 0.5 m of progress toward the goal in 1 s "
                             "(16.0 m away)")
    assert 1.0 <= row["nav_time_s"] <= 1.0 + TICK_S
    # a flight that keeps getting closer is not touched
    monkeypatch.setitem(spec_module.PROTOCOLS, 98, dataclasses.replace(rules, version=98,
                                                                      stall_timeout_s=5.0))
    flying = run_trial(yard_spec(yard, protocol=98), navigator=Carrot(yard_path)).row
    before = run_trial(yard_spec(yard, protocol=4), navigator=Carrot(yard_path)).row
    assert flying["reason"] == "success"
    for k in ("time_to_goal_s", "nav_time_s", "path_length_m", "energy_j"):
        assert flying[k] == before[k], k


class Hung(Exception):
    """The trial did not end in time (wall clock)."""


@contextmanager
def watchdog(seconds):
    def expire(signum, frame):
        raise Hung(f"the trial did not end within {seconds} s of wall-clock time")

    old = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


class RateHover(Hover):
    def __init__(self, rate_hz):
        super().__init__()
        self.rate_hz = rate_hz


def test_the_navigator_is_stepped_at_its_rate(yard):
    spec = yard_spec(yard, limits=Limits(timeout_s=1.0))
    for rate_hz, calls in ((25.0, 25), (4.0, 4), (1000.0, 1000)):
        with watchdog(20):
            row = run_trial(spec, navigator=RateHover(rate_hz)).row
        assert (row["reason"], row["planner_calls"]) == ("timeout", calls), rate_hz


def test_a_rate_off_the_physics_step_grid_ends(yard):
    spec = yard_spec(yard, limits=Limits(timeout_s=1.0))
    with watchdog(3):
        row = run_trial(spec, navigator=RateHover(30.0)).row
    assert row["reason"] == "timeout" and 29 <= row["planner_calls"] <= 31


@pytest.mark.parametrize("where", ["reset", "step"])
def test_a_navigator_that_raises_is_a_navigator_error(yard, where):
    nav = Raising(where, RuntimeError("boom: no map"))
    row = run_trial(yard_spec(yard), navigator=nav).row
    assert (row["reason"], row["success"]) == ("navigator_error", False)
    assert row["detail"] == f"{where} raised RuntimeError: boom: no map"


class Stuck(Navigator):
    """Steps normally until ``at_s``, then spins (``spin``: for up to 60 s, so a broken
    watchdog cannot hang the test run) or takes ``sleep_s`` of wall-clock time per step.
    ``returned_stuck`` counts the stuck steps that returned."""

    name = "stuck"

    def __init__(self, at_s=0.3, spin=True, sleep_s=0.0):
        super().__init__()
        self.at_s, self.spin, self.sleep_s = at_s, spin, sleep_s
        self.returned_stuck = 0

    def step(self, obs):
        import time

        if obs.time_s >= self.at_s:
            if self.spin:
                end = time.monotonic() + 60.0
                while time.monotonic() < end:  # a hung planner, even `except Exception`
                    try:
                        pass
                    except Exception:  # noqa: BLE001, S110
                        pass
            else:
                time.sleep(self.sleep_s)
            self.returned_stuck += 1
        return Setpoint.position(self.task.start)


def test_a_hung_navigator_fails_its_trial_at_the_wall_clock_budget(yard):
    before = signal.getsignal(signal.SIGALRM)
    nav = Stuck()
    row = run_trial(yard_spec(yard), navigator=nav, wall_budget_s=3.0).row
    assert nav.returned_stuck == 0  # interrupted inside the step, not after it
    assert (row["reason"], row["success"]) == ("navigator_error", False)
    assert "wall-clock budget of 3 s" in row["detail"] and "at 0.3 s" in row["detail"]
    # the alarm is disarmed and the previous handler back
    assert signal.getitimer(signal.ITIMER_REAL)[0] == 0.0
    assert signal.getsignal(signal.SIGALRM) is before
    # a normal trial after it is not cut short by a leftover alarm
    spec = yard_spec(yard, limits=Limits(timeout_s=2.0))
    assert run_trial(spec, navigator=Hover(), wall_budget_s=3.0).row["reason"] == "timeout"


def test_a_far_too_slow_navigator_is_stopped_between_steps_off_the_main_thread(yard):
    import threading

    out = {}
    th = threading.Thread(target=lambda: out.update(run_trial(
        yard_spec(yard), navigator=Stuck(at_s=0.0, spin=False, sleep_s=0.02),
        wall_budget_s=3.0).row))
    th.start()
    th.join(30.0)
    assert not th.is_alive()
    assert out["reason"] == "navigator_error" and "wall-clock budget of 3 s" in out["detail"]
    assert out["nav_time_s"] < 10.0  # stopped long before the 90 s simulated timeout


@pytest.mark.parametrize("bad", [0, -1.0, "600", True, float("nan")])
def test_bad_wall_budgets_are_refused(yard, bad):
    with pytest.raises(ValueError, match="wall_budget_s"):
        run_trial(yard_spec(yard), navigator=Hover(), wall_budget_s=bad)


@pytest.mark.parametrize("value, detail", [
    (None, "step returned NoneType, not a Setpoint"),
    ("forward", "step returned str, not a Setpoint"),
    (np.array([5.0, 18.0, 1.5]), "step returned ndarray, not a Setpoint"),
    (_with_inf(), "step returned a setpoint with an infinite value"),
    (Setpoint.off(), "step returned a motors-off/idle setpoint"),
    (Setpoint.idle(), "step returned a motors-off/idle setpoint"),
])
def test_a_navigator_returning_garbage_is_a_navigator_error(yard, value, detail):
    row = run_trial(yard_spec(yard), navigator=Returning(value)).row
    assert (row["reason"], row["detail"]) == ("navigator_error", detail)
    assert row["planner_calls"] == 3


def _row_with(**entries) -> Setpoint:
    row = Setpoint.position([5.0, 2.0, 1.5]).row.copy()
    for index, value in entries.items():
        row[getattr(cascade, index)] = value
    return Setpoint(row)


class Misbehaving(Navigator):
    name = "misbehaving"

    def __init__(self, case):
        super().__init__()
        self.case = case
        if case == "rate 0":
            self.rate_hz = 0.0
        if case == "rate NaN":
            self.rate_hz = math.nan

    def step(self, obs):
        if self.case == "sys.exit":
            raise SystemExit(3)
        if self.case == "replans not a number":
            self.replans = "many"
        return {
            "NaN kind": lambda: _row_with(SP_KIND=math.nan),
            "unknown kind": lambda: _row_with(SP_KIND=99),
            "row not an array": lambda: Setpoint([1.0, 2.0]),
            "no axis controlled": lambda: _row_with(SP_POS=math.nan),
        }.get(self.case, lambda: Setpoint.position(self.task.start))()


@pytest.mark.parametrize("case", ["rate 0", "rate NaN", "NaN kind", "unknown kind",
                                  "row not an array", "no axis controlled",
                                  "replans not a number", "sys.exit"])
def test_navigator_mistakes_are_navigator_errors(yard, case):
    spec = yard_spec(yard, limits=Limits(timeout_s=1.0))
    try:
        with watchdog(20):
            row = run_trial(spec, navigator=Misbehaving(case)).row
    except BaseException as exc:  # noqa: BLE001 - SystemExit included: report, do not exit
        pytest.fail(f"run_trial raised {type(exc).__name__}: {exc}")
    if case == "replans not a number":
        # a broken counter does not change how the trial flew: it is recorded as -1
        assert row["replans"] == -1 and row["reason"] == "timeout", row["detail"]
        return
    assert row["reason"] == "navigator_error", row["detail"]


@pytest.mark.parametrize("where", ["reset", "step"])
def test_a_navigator_that_gives_up_times_out(yard, where):
    row = run_trial(yard_spec(yard), navigator=Raising(where, GiveUp("no path"))).row
    assert (row["reason"], row["detail"]) == ("timeout", "navigator gave up: no path")
    assert row["nav_time_s"] < 1.0  # at once, not after 90 s


def test_every_reason_is_a_known_category():
    assert set(REASONS) == {"success", "collision", "mover_collision", "out_of_bounds",
                            "geofence", "timeout", "unstable", "loss_of_control",
                            "navigator_error"}


# --- the spec --------------------------------------------------------------------------------
FULL = TrialSpec(algorithm="straight", platform=PLATFORM, family="maze", scenario_index=3,
                 scenario_seed=1, trial=2, seed=7, algorithm_params={"speed_m_s": 3.0},
                 limits=Limits(timeout_s=60.0), campaign="c", label="straight-3",
                 platform_def=None, scenario_file=None, physics_hz=500, protocol=2,
                 gains="px4", scenario_version=2, wind={"speed_m_s": 3.0},
                 params={"MPC_XY_P": 1.1}, actuators={"lag_s": 0.01},
                 perception={"latency_s": 0.05},
                 estimator={"position_bias_m": [0.1, 0.0, 0.0], "rate_latency_s": 0.004},
                 failures=[{"at_s": 5.0, "unit": "gps", "type": "off", "instance": 0}],
                 movers={"count": 3, "speed_m_s": 2.0},
                 fence={"action": "land", "max_ver_dist_m": 3.5,
                        "circles": [{"inclusion": True, "center": [0, 0], "radius_m": 50}]},
                 aggressiveness="mine")


def test_spec_round_trips_through_dict_and_json():
    d = FULL.to_dict()
    assert set(d) == {f.name for f in dataclasses.fields(TrialSpec)}
    back = TrialSpec.from_dict(json.loads(FULL.to_json()))
    assert back == FULL and back.trial_id == FULL.trial_id
    assert TrialSpec.from_dict({**d, "code_version": "9.9"}) == FULL  # ignored
    assert back.limits == Limits(timeout_s=60.0)


def test_trial_id_is_stable():
    spec = TrialSpec("straight", PLATFORM, "maze", scenario_index=3, scenario_seed=1, trial=2,
                     seed=7, protocol=1, scenario_version=1)
    # the key of every stored result: a change here orphans existing result directories
    assert spec.trial_id == "3f5892779a3fd6af"
    assert dataclasses.replace(spec, protocol=2).trial_id == "927138a9ce742cce"
    assert spec.trial_id == hashlib.sha256(spec.to_json().encode()).hexdigest()[:16]
    assert TrialSpec(**{f.name: getattr(spec, f.name)
                        for f in dataclasses.fields(TrialSpec)}).trial_id == spec.trial_id


CHANGES = {
    "algorithm": "other", "platform": "0.60kg-EMAX", "family": "forest", "scenario_index": 4,
    "scenario_seed": 2, "trial": 3, "seed": 8, "algorithm_params": {"speed_m_s": 2.0},
    "limits": Limits(timeout_s=61.0), "campaign": "d", "label": "x",
    "platform_def": {"name": PLATFORM}, "scenario_file": "/tmp/x.yaml", "physics_hz": 1000,
    "protocol": 1, "gains": "bandwidth", "scenario_version": 1, "wind": {"speed_m_s": 4.0},
    "params": {"MPC_XY_P": 1.2}, "actuators": {"lag_s": 0.02},
    "perception": {"latency_s": 0.1}, "estimator": {"position_noise_m": 0.1},
    "failures": [{"at_s": 1.0, "unit": "battery", "type": "off", "instance": 0}],
    "movers": {"count": 4},
    "fence": {"action": "hold", "max_ver_dist_m": 3.5,
              "circles": [{"inclusion": True, "center": [0, 0], "radius_m": 50}]},
    "aggressiveness": "gentle",
}
# (protocol 2 here: FULL with protocol 3 would carry 3's acceleration limit, which 1 refuses)


def test_trial_id_changes_with_every_field():
    assert set(CHANGES) == {f.name for f in dataclasses.fields(TrialSpec)}
    ids = {FULL.trial_id}
    for name, value in CHANGES.items():
        assert getattr(FULL, name) != value
        # (a scenario file has no generator version; another family has its own)
        extra = {"scenario_version": None} if name in ("scenario_file", "family") else {}
        ids.add(dataclasses.replace(FULL, **{name: value}, **extra).trial_id)
    assert len(ids) == 1 + len(CHANGES)
    for name in ("max_speed_m_s", "timeout_s", "goal_radius_m", "hold_s"):
        limits = dataclasses.replace(FULL.limits, **{name: 1.5})
        assert dataclasses.replace(FULL, limits=limits).trial_id not in ids


@pytest.mark.parametrize("field, value", [
    ("algorithm", ""), ("platform", None), ("family", 3), ("scenario_index", 0),
    ("scenario_index", 1.0), ("scenario_seed", -1), ("trial", True), ("seed", "1"),
    ("physics_hz", 0), ("algorithm_params", [1]), ("limits", {"timeout_s": 5.0}),
    ("gains", "PX4"), ("gains", 1), ("gains", None),
])
def test_bad_spec_fields_are_refused_by_name(field, value):
    with pytest.raises(TrialSpecError, match=f"^{field}: "):
        dataclasses.replace(FULL, **{field: value})


@pytest.mark.parametrize("doc, message", [
    ([], "a trial spec must be a table"),
    ({**FULL.to_dict(), "limits": {"timeout_s": -1}},
     r"limits: timeout_s: must be a number 0.1..3600 \(s\), got -1"),
    ({**FULL.to_dict(), "limits": {"timeout": 5}}, "limits: "),
    ({**FULL.to_dict(), "colour": "red"}, "trial spec: .*colour"),
    ({"algorithm": "straight"}, "trial spec: .*missing"),
])
def test_bad_spec_documents_are_refused(doc, message):
    with pytest.raises(TrialSpecError, match=message):
        TrialSpec.from_dict(doc)


def test_campaign_workers_share_one_build_of_a_scenario_distance_grid(tmp_path, yard,
                                                                      monkeypatch):
    from ft_sitl.missions import resources
    from ft_sitl.scenarios.distance_grid import DistanceGrid
    from ft_sitl.scenarios.io import load_scenario

    sc = load_scenario(str(yard))
    built = DistanceGrid.build(sc.mesh, sc.bounds_min, sc.bounds_max)

    def grid_of(scenario):  # a fresh process's resources, sharing through tmp_path
        return resources.TrialResources(grid_dir=str(tmp_path)).world_and_grid(scenario)[1]

    first = grid_of(sc)  # builds it and leaves it for the others
    saved = list(tmp_path.glob("*.npz"))
    assert len(saved) == 1

    def no_build(*args, **kwargs):
        raise AssertionError("a shared grid must be loaded, not built again")

    monkeypatch.setattr(DistanceGrid, "build", no_build)
    loaded = grid_of(sc)
    for grid in (first, loaded):
        assert np.array_equal(grid.data, built.data) and grid.data.dtype == np.float32
        assert np.array_equal(grid.origin, built.origin) and grid.pitch == built.pitch

    saved[0].write_bytes(b"not a grid")  # unreadable: built again and replaced
    monkeypatch.undo()
    again = grid_of(sc)
    assert np.array_equal(again.data, built.data)
    with np.load(saved[0]) as z:
        assert np.array_equal(z["data"], built.data)

    # only the newest GRID_CACHE_KEEP grids stay on disk
    monkeypatch.setattr(resources, "GRID_CACHE_KEEP", 1)
    other = load_scenario(str(write_yard(tmp_path / "other", "other",
                                         wall=((1.0, 5.0, 0.0), (9.0, 5.5, 2.0)))))
    grid_of(other)
    assert len(list(tmp_path.glob("*.npz"))) == 1 and not saved[0].exists()


# --- protocol versions -------------------------------------------------------------------------
def test_protocol_version_is_in_the_row_and_absent_means_1():
    from ft_sitl.missions.spec import PROTOCOL_VERSION, PROTOCOLS

    spec = TrialSpec("straight", PLATFORM, "forest")
    assert spec.protocol == PROTOCOL_VERSION and PROTOCOL_VERSION in PROTOCOLS
    old = {k: v for k, v in TrialSpec("straight", PLATFORM, "forest", protocol=2).to_dict()
           .items() if k != "protocol"}
    assert TrialSpec.from_dict(old).protocol == 1
    assert "protocol" not in TrialSpec.from_dict(old).to_dict()  # the old ids stay


# --- controller-gain mode ----------------------------------------------------------------------
def test_the_default_gain_mode_is_left_out_of_the_spec_so_old_ids_stay():
    spec = TrialSpec("straight", PLATFORM, "maze", scenario_index=3, scenario_seed=1, trial=2,
                     seed=7, protocol=1, scenario_version=1)
    assert spec.gains == "bandwidth" and "gains" not in spec.to_dict()
    assert spec.trial_id == "3f5892779a3fd6af"  # (test_trial_id_is_stable's)
    px4 = dataclasses.replace(spec, gains="px4")
    assert px4.to_dict()["gains"] == "px4" and px4.trial_id != spec.trial_id
    assert TrialSpec.from_dict(json.loads(px4.to_json())) == px4


def test_a_bad_gain_mode_is_refused_naming_the_key_and_the_modes():
    with pytest.raises(TrialSpecError, match=r"^gains: 'PX4' is not a controller-gain mode "
                                             r"\('bandwidth', 'px4'"):
        TrialSpec("straight", PLATFORM, "forest", gains="PX4")


def test_the_gain_mode_reaches_the_vehicle_and_the_row(yard):
    """The spec's gains set FT_GAIN_MODE on the trial's vehicle (trial_vehicle, both
    transports) and are written into the row."""
    from ft_sitl.autopilot.params import GAIN_MODES
    from ft_sitl.missions.plan import plan_trial
    from ft_sitl.missions.protocol import trial_vehicle

    for gains, mode in GAIN_MODES.items():
        spec = yard_spec(yard, gains=gains)
        _, fleet = trial_vehicle(plan_trial(spec))
        assert fleet.params[0]["FT_GAIN_MODE"] == mode
    row = run_trial(yard_spec(yard, gains="px4")).row
    assert row["gains"] == "px4" and json.loads(row["spec"])["gains"] == "px4"
    assert run_trial(yard_spec(yard)).row["gains"] == "bandwidth"


def test_a_committed_paper_row_keeps_its_trial_id_and_version():
    """Committed rows re-read as the protocol they were flown under and hash to the ids they
    were stored under: the one-tenth sample predates recorded versions (its specs name none
    and read as protocol 1), the full paper run names version 6 in its specs and its
    ``protocol_version`` column."""
    import pandas as pd

    results = Path(__file__).resolve().parents[2] / "docs" / "results"
    old = pd.read_parquet(results / "paper-sample" / "trials.parquet",
                          columns=["trial_id", "spec"]).head(50)
    for tid, doc in zip(old["trial_id"], old["spec"]):
        assert "protocol" not in json.loads(doc)
        spec = TrialSpec.from_dict(json.loads(doc))
        assert spec.protocol == 1 and spec.trial_id == tid
    paper = pd.read_parquet(results / "paper" / "trials.parquet",
                            columns=["trial_id", "spec", "protocol_version"])
    assert set(paper["protocol_version"]) == {6}
    for tid, doc in zip(paper["trial_id"].head(50), paper["spec"].head(50)):
        spec = TrialSpec.from_dict(json.loads(doc))
        assert spec.protocol == 6 and spec.trial_id == tid


@pytest.mark.parametrize("version", [0, 99, "1", True])
def test_a_spec_of_an_unknown_protocol_version_is_refused_by_name(version):
    with pytest.raises(TrialSpecError, match=rf"protocol: version {version!r} is not one "
                                             r"this ft-sitl flies \(1"):
        TrialSpec("straight", PLATFORM, "forest", protocol=version)
    doc = {**TrialSpec("straight", PLATFORM, "forest").to_dict(), "protocol": version}
    with pytest.raises(TrialSpecError, match="needs the ft-sitl that wrote it"):
        TrialSpec.from_dict(doc)


@pytest.mark.slow
def test_a_navigators_map_at_navigation_start_holds_what_it_saw_on_the_approach():
    """Protocol 3: the navigator is reset before arming and observes the approach, so its
    map at the first navigation step already holds the trees seen on the way (in protocol
    2 it held nothing yet). The camera runs at 30 Hz (15 Hz in protocols 1 and 2)."""
    from ft_sitl.missions.plan import navigator_params
    from ft_sitl.navigation.planners.ego import EgoPlanner
    from ft_sitl.navigation.registry import create

    class Spy(EgoPlanner):
        first = None

        def step(self, obs):
            if self.first is None:
                self.first = (obs.time_s, self.map.frames_fused, self.map.occupied_count)
            return super().step(obs)

    seen = {}
    for protocol in (2, 3):
        spec = TrialSpec("ego", "0.98kg-EGO Planner DIY", "forest", scenario_index=1,
                         protocol=protocol)
        spy = Spy(**navigator_params(spec))
        assert spy.camera.rate_hz == (15.0 if protocol == 2 else 30.0)
        assert create("ego", navigator_params(spec)).camera == spy.camera
        run_trial(spec, navigator=spy, wall_budget_s=None)
        seen[protocol] = spy.first
    t2, frames2, occupied2 = seen[2]
    t3, frames3, occupied3 = seen[3]
    assert t2 == t3 == 0.0
    assert frames2 == 0 and occupied2 == 0
    assert frames3 > 60 and occupied3 > 50  # > 2 s of frames at 30 Hz; trees ahead


def test_one_protocol_acceleration_limit_for_every_planner():
    """Protocol 3: limits.max_acc_m_s2 (default 3 m/s^2, written into the spec) is what
    every planner plans with, whatever its own max_acc_m_s2 default (EGO 3, Fast and PGO
    2); protocols 1 and 2 have none and refuse one."""
    from ft_sitl.navigation.registry import create

    spec = TrialSpec("fast", PLATFORM, "forest", protocol=3)
    assert spec.limits.max_acc_m_s2 == 3.0
    assert json.loads(spec.to_json())["limits"]["max_acc_m_s2"] == 3.0
    from ft_sitl.missions.plan import plan_trial

    for name, own in (("ego", 3.0), ("fast", 2.0), ("pgo", 2.0)):
        for protocol, acc, want in ((1, None, own), (3, None, 3.0), (3, 6.5, 6.5)):
            s = TrialSpec(name, PLATFORM, "forest", protocol=protocol,
                          limits=Limits(max_acc_m_s2=acc))
            nav = create(name, {})
            nav.reset(plan_trial(s).task())
            assert nav.max_acc == want, (name, protocol, acc)
    with pytest.raises(TrialSpecError, match="limits.max_acc_m_s2: protocol version 1 has "
                                             "no protocol acceleration limit"):
        TrialSpec("ego", PLATFORM, "forest", protocol=1, limits=Limits(max_acc_m_s2=3.0))
    with pytest.raises(ValueError,
                       match=r"limits: max_acc_m_s2: must be a number 0.1..100, or none"):
        Limits(max_acc_m_s2=-1.0)


@pytest.mark.slow
def test_navigators_keep_their_platforms_footprint_from_protocol_4():
    """Protocol 4: the task carries the platform's footprint; each planner's map is
    inflated by it (rounded up to whole voxels, as the originals' obstacles_inflation) and
    NavRL's shield uses it as the agent radius. Fast-Planner on a 4.5 kg platform (0.356 m)
    in Forest 1 passed trunks 0.11 m away under protocol 3 and keeps > 0.3 m under 4."""
    from ft_sitl.missions.plan import plan_trial
    from ft_sitl.navigation.maps.mapping import inflation_voxels, local_map_for
    from ft_sitl.navigation.planners.fast import FastPlanner

    big = "4.50kg-UAV 14"
    for protocol, want in ((3, None), (4, platform_for(TrialSpec("fast", big, "forest"))
                                        .collision_radius_m)):
        task = plan_trial(TrialSpec("fast", big, "forest", protocol=protocol)).task()
        assert task.footprint_m == want
        voxels = 1 if want is None else 4  # 0.356 m -> 4 voxels of 0.1 m
        assert inflation_voxels(task) == voxels
        assert local_map_for(task, None).config.inflation_voxels == voxels
    clearance = {}
    for protocol in (3, 4):
        nav = FastPlanner()
        row = run_trial(TrialSpec("fast", big, "forest", scenario_index=1, protocol=protocol),
                        navigator=nav, wall_budget_s=None).row
        assert row["reason"] == "success", row["detail"]
        clearance[protocol] = row["min_clearance_m"]
    assert clearance[3] < 0.2 and clearance[4] > 0.3


def test_navrl_shield_takes_the_footprint_as_its_agent_radius():
    """A velocity passing 0.6 m from a 0.3 m obstacle is safe for a point agent (protocols
    1-3) and inside the velocity obstacle for an agent of 0.4 m (a footprint, protocol 4)."""
    from ft_sitl.navigation.learned.navrl import orca_plane

    def in_vo(agent_radius):
        return orca_plane(np.zeros(3), np.array([1.0, 0.0, 0.0]), agent_radius,
                          np.array([1.5, 0.6, 0.0]), np.zeros(3), 0.3)[2]

    assert in_vo(0.0) is False and in_vo(0.4) is True


def test_the_vehicles_half_span_is_its_bodys_from_protocol_5_its_spheres_before():
    """The size a trial's collision check takes the vehicle to be, seen from above (what
    the campaign report regresses success on): the body's half span under 5, the collision
    radius under 1-4; a version this code does not fly is refused."""
    from ft_sitl.missions.spec import vehicle_half_span_m

    big = platform_for(TrialSpec("fast", "4.50kg-UAV 14", "forest"))
    small = platform_for(TrialSpec("fast", PLATFORM, "forest"))
    for p in (big, small):
        for protocol in (1, 2, 3, 4):
            assert vehicle_half_span_m(protocol, p) == p.collision_radius_m
        assert vehicle_half_span_m(5, p) == p.body().half_span_m
        assert p.body().half_span_m != p.collision_radius_m
    assert vehicle_half_span_m(5, big) > vehicle_half_span_m(5, small)
    with pytest.raises(TrialSpecError, match="version 99"):
        vehicle_half_span_m(99, big)


@pytest.mark.slow
def test_protocol_5_flies_the_vehicle_body_and_tells_its_half_span():
    """Protocol 5: the guard checks the body (central box and rotor disks) inside the
    bounding sphere, the row's clearance is the body's, and the footprint a navigator
    inflates by is the body's half span (the collision radius in 4)."""
    from ft_sitl.missions.plan import plan_trial
    from ft_sitl.missions.protocol import trial_vehicle

    spec4 = TrialSpec("straight", PLATFORM, "forest", scenario_index=2, protocol=4)
    spec5 = TrialSpec("straight", PLATFORM, "forest", scenario_index=2, protocol=5)
    platform = platform_for(spec5)
    body = platform.body()
    g4, _ = trial_vehicle(plan_trial(spec4))
    g5, _ = trial_vehicle(plan_trial(spec5))
    assert g4.probes == [None] and g4.radii == [platform.collision_radius_m]
    assert g5.probes[0].body == body and g5.radii == [body.bounding_radius_m]
    assert plan_trial(spec4).task().footprint_m == platform.collision_radius_m
    assert plan_trial(spec5).task().footprint_m == body.half_span_m
    row = run_trial(spec5, wall_budget_s=None).row
    assert row["protocol_version"] == 5
    assert row["reason"] == "collision" and row["detail"].startswith("hit tree ")
    assert row["min_clearance_m"] <= 0.0


def test_protocol_6_maps_take_the_latest_30_hz_frame_on_a_20_hz_timer():
    """Protocol 6: the navigator's map takes a frame every 0.05 s of its clock, on the
    approach and in flight, and the frame is the camera's latest (captured on the 30 Hz
    grid, at most one camera period before); the camera's skipped frames are not rendered.
    Protocol 5 hands over every 30 Hz frame as it is captured."""
    from ft_sitl.missions.plan import navigator_params
    from ft_sitl.navigation.planners.ego import EgoPlanner

    class Spy(EgoPlanner):
        def reset(self, task):
            super().reset(task)
            self.got = []  # (phase, observation time, frame time), microseconds

        def observe(self, obs):
            if obs.depth is not None:
                self.got.append(("approach", round(obs.time_s * 1e6), obs.depth.t_us))
            super().observe(obs)

        def step(self, obs):
            if obs.depth is not None:
                self.got.append(("flight", round(obs.time_s * 1e6), obs.depth.t_us))
            return super().step(obs)

    got = {}
    for protocol in (5, 6):
        spec = TrialSpec("ego", "0.98kg-EGO Planner DIY", "forest", scenario_index=1,
                         protocol=protocol, limits=Limits(timeout_s=3.0))
        spy = Spy(**navigator_params(spec))
        row = run_trial(spec, navigator=spy, wall_budget_s=None).row
        assert row["protocol_version"] == protocol
        got[protocol] = spy.got
    period_us = 33_333
    for phase, step_us, floor in (("approach", 1_000, True), ("flight", 10_000, False)):
        # events are served on the physics steps (the last at or before the camera's
        # tick) on the approach, on the navigator's steps (the first at or after) in flight
        def served(t, step_us=step_us, floor=floor):
            return (t // step_us if floor else -(-t // step_us)) * step_us

        five = [(t, f) for p, t, f in got[5] if p == phase]
        six = [(t, f) for p, t, f in got[6] if p == phase]
        assert len(five) > 30 and len(six) > 20, phase
        # protocol 5: every frame at its capture, one per camera period
        assert all(t == f for t, f in five)
        assert all(period_us - step_us <= b[1] - a[1] <= period_us + step_us
                   for a, b in zip(five, five[1:])), phase
        # protocol 6: one frame per map update, updates 50 ms apart from 0, each the
        # camera's latest frame (captured on the 30 Hz grid before the update)
        assert [t for t, _ in six] == [50_000 * k for k in range(len(six))], phase
        for t, f in six:
            assert any(served(k * period_us) == f for k in range(f // period_us,
                                                                  f // period_us + 2))
            assert 0 <= t - f < period_us + step_us, (phase, t, f)
        # two frames of every three are rendered
        assert 0.6 < len(six) / len(five) < 0.72, phase
