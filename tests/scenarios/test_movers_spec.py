"""Moving obstacles wherever a scenario is named (issue #24): the ``+dynamic(...)`` form of
a scenario on a command line, the ``movers`` table of a scenario spec file, and the guard
every scenario-built vehicle gets (the Fleet's, a bridge's)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from ft_sitl.bridge.vehicle import BridgeVehicle
from ft_sitl.physics.catalog import get_platform
from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.io import load_scenario, scenario_from_spec
from ft_sitl.scenarios.movers import with_movers
from ft_sitl.sim.fleet import Fleet

PLATFORM = "0.98kg-EGO Planner DIY"
EXE = shutil.which("ft-sitl", path=str(Path(sys.executable).parent))


def test_dynamic_suffix_places_movers_for_the_scenario_seed():
    sc = scenario_from_spec("forest:3+dynamic(count=8, speed=1.5)")
    same = with_movers(build_scenario("forest", 3, 0), {"count": 8, "speed_m_s": 1.5}, 0)
    m = sc.movers
    assert sc.name == "forest-03-s0" and m.count == 8
    assert np.all(m.speed == 1.5) and m.start_us == 0  # the field moves from t = 0
    np.testing.assert_array_equal(m.poses(3_000_000), same.movers.poses(3_000_000))
    assert not np.array_equal(m.poses(0), m.poses(3_000_000))  # they move
    other = scenario_from_spec("forest:3:2+dynamic(count=8,speed=1.5)")
    assert other.seed == 2 and not np.array_equal(other.movers.poses(0)[:, :2],
                                                  m.poses(0)[:, :2])
    boxes = scenario_from_spec("forest:3+dynamic(count=3, shape=box, path=line)")
    assert boxes.movers.names == ("box 1", "box 2", "box 3")
    assert boxes.movers.paths == ("line",) * 3
    assert scenario_from_spec("forest:3").movers is None


@pytest.mark.parametrize("spec, message", [
    ("forest:3+dynamic(count=8,sped=1)", "dynamic(count=8,sped=1): unknown setting 'sped'"),
    ("forest:3+dynamic(count=100)", "scenario 'forest:3+dynamic(count=100)': dynamic: count: "
                                    "must be an integer 0..64, got 100"),
    ("forest:3+dyn(count=1)", "scenario 'forest:3+dyn(count=1)': after '+' expected "
                              "dynamic(KEY=VALUE, ...)"),
    ("forest:3+", "scenario 'forest:3+': after '+' expected dynamic(KEY=VALUE, ...)"),
    ("forest:3+dynamic(count)", "dynamic(count): 'count' is not KEY=VALUE"),
    ("forest:3+dynamic(shape=car)", "dynamic: shape: must be 'person' or 'box' or 'sphere' "
                                    "or 'mixed', got 'car'"),
    ("forest:3+dynamic(count=2,density=3)", "dynamic: give count or density_per_1000m2, "
                                            "not both"),
    ("forest+dynamic(count=2)", "expected FAMILY:INDEX[:SEED]"),
])
def test_bad_dynamic_suffix_says_what_is_wrong(spec, message):
    with pytest.raises(ValueError) as err:
        scenario_from_spec(spec)
    assert message in str(err.value)


# --- spec files -------------------------------------------------------------------------------

def _yard(directory: Path, movers_text: str, suffix: str = ".toml") -> Path:
    """A 30 x 30 m yard with one box at its far corner; start (5, 5, 1.5), goal (25, 25,
    1.5); ``movers_text`` appended to the spec."""
    directory.mkdir(parents=True, exist_ok=True)
    trimesh.creation.box(bounds=[[26, 2, 0], [28, 4, 3]]).export(directory / "yard.ply")
    if suffix == ".toml":
        head = ('name = "yard"\nmesh = "yard.ply"\nstart = [5.0, 5.0, 1.5]\n'
                'goal = [25.0, 25.0, 1.5]\nbounds_min = [0.0, 0.0, 0.0]\n'
                'bounds_max = [30.0, 30.0, 5.0]\n')
    else:
        head = ("name: yard\nmesh: yard.ply\nstart: [5.0, 5.0, 1.5]\ngoal: [25.0, 25.0, 1.5]\n"
                "bounds_min: [0, 0, 0]\nbounds_max: [30, 30, 5]\n")
    path = directory / f"yard{suffix}"
    path.write_text(head + movers_text)
    return path


def test_spec_file_movers_as_settings_or_as_a_list(tmp_path):
    placed = load_scenario(_yard(tmp_path / "a", "[movers]\ncount = 3\nspeed_m_s = 1.2\n"
                                                 'shape = "sphere"\n'))
    assert placed.movers.count == 3 and np.all(placed.movers.speed == 1.2)
    assert placed.movers.names == ("ball 1", "ball 2", "ball 3")
    again = load_scenario(tmp_path / "a" / "yard.toml")  # placed for the scenario's seed 0
    np.testing.assert_array_equal(again.movers.poses(0), placed.movers.poses(0))

    listed = load_scenario(_yard(tmp_path / "b", (
        "movers:\n"
        "  - {shape: person, radius_m: 0.3, height_m: 1.8, points: [[10, 4], [10, 20]],"
        " speed_m_s: 2.0}\n"
        "  - {shape: box, length_m: 3, width_m: 1.5, height_m: 1.6,"
        " points: [[20, 10], [24, 10], [24, 14]], speed_m_s: 1.0, loop: true}\n"), ".yaml"))
    m = listed.movers
    assert m.names == ("person 1", "box 1") and list(m.speed) == [2.0, 1.0]
    # the person walks north from (10, 4) at 2 m/s, its centre at half its height
    np.testing.assert_allclose(m.poses(0)[0], [10.0, 4.0, 0.9, np.pi / 2])
    np.testing.assert_allclose(m.poses(3_000_000)[0], [10.0, 10.0, 0.9, np.pi / 2])
    np.testing.assert_allclose(m.velocities(3_000_000)[0], [0.0, 2.0, 0.0], atol=1e-12)
    # and turns back at (10, 20): at 10 s it is 4 m back south, heading south
    np.testing.assert_allclose(m.poses(10_000_000)[0], [10.0, 16.0, 0.9, -np.pi / 2])
    assert load_scenario(_yard(tmp_path / "c", "")).movers is None


@pytest.mark.parametrize("text, message", [
    ("movers = 3\n", "movers: must be a table of mover settings or a list of movers"),
    ("[movers]\ncount = 3\nsped = 1\n", "movers has no parameter 'sped'; did you mean"),
    ("[movers]\ncount = 99\n", "movers: count: must be an integer 0..64, got 99"),
    ('[[movers]]\nshape = "car"\n', "movers[0].shape: 'car' is not one of person, box, "
                                    "sphere"),
    ('[[movers]]\nshape = "person"\nradius_m = 0.3\nheight_m = 1.8\npoints = [1, 2]\n'
     "speed_m_s = 1\n", "movers[0].points: needs at least one finite [x, y] or [x, y, z] "
                        "point"),
])
def test_bad_spec_file_movers_name_the_file_and_the_key(tmp_path, text, message):
    path = _yard(tmp_path, text)
    with pytest.raises(ValueError) as err:
        load_scenario(path)
    assert str(err.value).startswith(f"{path}: ") and message in str(err.value), err.value


def test_spec_file_movers_and_a_dynamic_suffix_are_not_both_taken(tmp_path):
    path = _yard(tmp_path, "[movers]\ncount = 2\n")
    with pytest.raises(ValueError, match="has movers of its own; give them in the spec file "
                                         r"or in \+dynamic\(...\), not both"):
        scenario_from_spec(f"{path}+dynamic(count=3)")
    plain = _yard(tmp_path / "plain", "")
    assert scenario_from_spec(f"{plain}+dynamic(count=3)").movers.count == 3


# --- the vehicles of a scenario meet its movers ---------------------------------------------

@pytest.mark.slow
def test_a_fleet_built_in_a_scenario_checks_its_movers():
    sc = scenario_from_spec("forest:3+dynamic(count=4)")
    fleet = Fleet([get_platform(PLATFORM)], spawn=[sc.takeoff], scenario=sc)
    assert fleet.guard.movers is sc.movers
    assert Fleet([get_platform(PLATFORM)], spawn=[sc.takeoff],
                 scenario=build_scenario("forest", 3, 0)).guard.movers is None


def test_a_bridge_vehicle_is_knocked_down_by_a_mover(tmp_path):
    """A person walks through the spot where the bridge's vehicle stands (motors off, as
    before its autopilot arms): the vehicle crashes into 'person 1', as into an obstacle."""
    spec = _yard(tmp_path, "[[movers]]\nshape = \"person\"\nradius_m = 0.3\nheight_m = 1.8\n"
                           "points = [[5.0, 1.0], [5.0, 12.0]]\nspeed_m_s = 2.0\n")
    sc = load_scenario(spec)
    v = BridgeVehicle(get_platform(PLATFORM), scenario=sc)
    assert np.allclose(v.position_enu()[:2], (5.0, 5.0))
    for _ in range(100):  # 1 s: the person is still 2 m short of it
        v.step_us(10_000)
    assert v.crash is None
    for _ in range(200):
        v.step_us(10_000)
        if v.crash is not None:
            break
    assert v.crash is not None and v.crash.what == "person 1", v.events
    # it reached the vehicle's spot within about a body radius of (5, 5): t ~ 2 s
    assert 1.5e6 < v.crash.time_us < 2.1e6, v.crash
    assert v.events[-1].kind == "mover_collision"


@pytest.mark.e2e
def test_cli_bad_dynamic_suffix_is_one_line(tmp_path):
    assert EXE, "the ft-sitl console script is not installed next to this Python"
    bad = subprocess.run([EXE, "sitl", "--scenario", "forest:3+dynamic(count=8,sped=1)"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2, bad.stderr
    assert bad.stderr.strip().splitlines() == [
        "ft-sitl: error: --scenario: dynamic(count=8,sped=1): unknown setting 'sped' "
        "(settings: count, density_per_1000m2, speed_m_s, shape, path, radius_m, height_m, "
        "box_length_m, box_width_m, path_length_m, crossing_s, keep_out_m; short forms: "
        "speed, density, radius, height, keep_out, length)"]
    bad = subprocess.run([EXE, "bridge", "px4", "--scenario", "forest:3+dynamic(count=99)",
                          "--duration", "1"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2, bad.stderr
    assert bad.stderr.strip() == ("ft-sitl: error: scenario 'forest:3+dynamic(count=99)': "
                                  "dynamic: count: must be an integer 0..64, got 99")


def test_a_trial_takes_movers_from_its_spec_or_its_scenario_file_not_both(tmp_path):
    from ft_sitl.missions.resources import TrialResources
    from ft_sitl.missions.spec import TrialSpec, TrialSpecError

    res = TrialResources()
    own = _yard(tmp_path / "own", "[movers]\ncount = 2\n")
    spec = TrialSpec("straight", PLATFORM, "yard", scenario_file=str(own))
    assert res.scenario(spec).movers.count == 2  # the file's own
    with pytest.raises(TrialSpecError, match="has movers of its own; give them in the file "
                                             "or in the trial's movers, not both"):
        res.scenario(TrialSpec("straight", PLATFORM, "yard", scenario_file=str(own),
                               movers={"count": 3}))
    plain = _yard(tmp_path / "plain", "")
    assert res.scenario(TrialSpec("straight", PLATFORM, "yard", scenario_file=str(plain),
                                  movers={"count": 3})).movers.count == 3
