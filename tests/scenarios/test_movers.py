"""Moving obstacles (ft_sitl.scenarios.movers): placement, paths, contact and rendering."""

import math

import numpy as np
import pytest
import trimesh

from ft_sitl.missions.spec import TrialSpec, TrialSpecError
from ft_sitl.missions.trial import run_trial
from ft_sitl.physics.catalog import get_platform
from ft_sitl.scenarios import movers as mv
from ft_sitl.scenarios.camera import CameraConfig, DepthCamera
from ft_sitl.scenarios.collision import CollisionWorld
from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.solvability import segment_mesh_distance
from ft_sitl.sim.guard import CollisionGuard, GuardEventKind
from ft_sitl.sim.lockstep import Simulation

PLATFORM = "0.98kg-EGO Planner DIY"


def person(points, speed, radius=0.4, height=2.0, **kw):
    return {"shape": "person", "radius_m": radius, "height_m": height, "points": points,
            "speed_m_s": speed, **kw}


def hovering(body: bool, movers):
    p = get_platform(PLATFORM)
    world = CollisionWorld(trimesh.Trimesh(), [-20.0, -20.0, 0.0], [20.0, 20.0, 6.0])
    sim = Simulation([p])
    sim.start_hovering(0, [0.0, 0.0, 1.0])
    b = p.body() if body else None
    guard = CollisionGuard(world, [b.bounding_radius_m if body else p.collision_radius_m],
                           bodies=[b])
    guard.set_movers(movers)
    sim.attach_guard(guard)
    return sim, guard, p


# --- paths -----------------------------------------------------------------------------------
def test_paths_walk_back_and_forth_or_round_at_their_speed():
    m = mv.movers_from_list([
        person([[0, 0], [10, 0]], 2.0),
        person([[0, 0], [4, 0], [4, 3]], 1.0, loop=True, start_m=1.0),
    ])
    p = m.poses(0)
    assert p[0, :3].tolist() == [0.0, 0.0, 1.0] and p[1, :2].tolist() == [1.0, 0.0]
    p = m.poses(3_000_000)  # 6 m along the line; 1 + 3 m round the loop
    assert p[0, :2] == pytest.approx([6.0, 0.0]) and p[0, 3] == pytest.approx(0.0)
    assert p[1, :2] == pytest.approx([4.0, 0.0]) and p[1, 3] == pytest.approx(math.pi / 2)
    p = m.poses(7_000_000)  # 14 m: back along the line, heading west
    assert p[0, :2] == pytest.approx([6.0, 0.0]) and abs(p[0, 3]) == pytest.approx(math.pi)
    p = m.poses(12_000_000)  # 1 + 12 m round a 12 m loop: where it started
    assert p[1, :2] == pytest.approx([1.0, 0.0])
    v = m.velocities(7_000_000)
    assert v[0] == pytest.approx([-2.0, 0.0, 0.0])
    assert m.velocities(3_000_000)[1] == pytest.approx([0.0, 1.0, 0.0])  # up the loop's side
    still = mv.movers_from_list([person([[0, 0]], 2.0),
                                 {"shape": "sphere", "radius_m": 0.3,
                                  "points": [[0, 0, 1], [0, 0, 4]], "speed_m_s": 0.5}])
    v = still.velocities(1_000_000)  # one point: still; a vertical path: climbing
    assert v[0].tolist() == [0.0, 0.0, 0.0] and v[1] == pytest.approx([0.0, 0.0, 0.5])


def test_the_clock_holds_the_movers_until_started():
    m = mv.movers_from_list([person([[0, 0], [10, 0]], 2.0)])
    m.start(mv.NOT_STARTED)
    assert m.poses(50_000_000)[0, 0] == 0.0
    m.start(2_000_000)
    assert m.poses(1_000_000)[0, 0] == 0.0 and m.poses(3_000_000)[0, 0] == pytest.approx(2.0)


# --- contact ---------------------------------------------------------------------------------
@pytest.mark.parametrize("body", [False, True])
def test_a_mover_driven_into_a_hovering_vehicle_hits_it_at_the_predicted_time(body):
    """A person (r 0.4 m) walks at 2 m/s from x = -10 m into a vehicle hovering at the
    origin. Contact comes when the cylinder reaches the vehicle's sphere (radius R) or its
    body's rearmost point (rotor disks included)."""
    m = mv.movers_from_list([person([[-10, 0], [10, 0]], 2.0)])
    sim, guard, p = hovering(body, m)
    if body:
        b = p.body()  # how far west the box or a rotor disk reaches (level hover)
        reach = max([-(b.box.center[0] - b.box.size[0] / 2)]
                    + [-(d.center[0] - d.radius) for d in b.rotors])
    else:
        reach = p.collision_radius_m
    predicted = (10.0 - 0.4 - reach) / 2.0
    sim.run(6.0)
    ev = [e for e in guard.events if e.kind == GuardEventKind.MOVER_COLLISION]
    assert len(ev) == 1 and ev[0].what == "person 1"
    assert ev[0].time_us * 1e-6 == pytest.approx(predicted, abs=0.01)
    assert ev[0].speed_m_s == pytest.approx(2.0, abs=0.05)


def test_a_mover_passing_by_touches_nothing_and_is_cheap_far_away():
    m = mv.movers_from_list([person([[-10, 1.5], [10, 1.5]], 2.0)])  # 1.1 m beside
    sim, guard, _ = hovering(True, m)
    sim.run(8.0)
    assert guard.events == [] and guard.mover_queries == 0


# --- the camera ------------------------------------------------------------------------------
def test_the_camera_sees_a_mover_move_between_frames():
    """A person crossing 5 m in front of the camera at 3 m/s: its silhouette moves by
    the projection of 0.1 m between frames 1/30 s apart, and its depth is the cylinder's
    near face."""
    sc = build_scenario("forest", 1)
    cam = DepthCamera(CameraConfig(width=160, height=120, fx=96.8, fy=96.8), sc.mesh)
    z0 = float(sc.ceiling) / 2.0
    p_cam = np.array([sc.bounds_min[0] + 0.5, sc.bounds_min[1] + 0.5, z0])  # a corner
    m = mv.movers_from_list([person([[p_cam[0] + 5.0, p_cam[1] - 3.0],
                                     [p_cam[0] + 5.0, p_cam[1] + 3.0]], 3.0,
                                    radius=0.3, height=2 * z0 + 1.0)])
    q_east = np.array([1.0, 0.0, 0.0, 0.0])  # looking east (+x)
    cols = []
    for k in range(3):
        t_us = 1_000_000 + k * 33_333
        f = cam.capture(t_us, p_cam, q_east, movers=m, movers_time_us=t_us)
        row = f.depth[60]
        hit = np.flatnonzero(np.abs(row - 4.7) < 0.1)
        assert len(hit) > 0
        cols.append(hit.mean())
        y = m.poses(t_us)[0, 1] - p_cam[1]
        u = (cam.config.width - 1) / 2 - 96.8 * y / 5.0  # the axis column, left positive
        assert hit.mean() == pytest.approx(u, abs=2.0)
    steps = np.diff(cols)
    assert np.all(steps < 0) and steps == pytest.approx(-96.8 * 0.1 / 5.0, abs=1.0)
    plain = cam.capture(1_000_000, p_cam, q_east)
    assert not np.any(np.abs(plain.depth[60] - 4.7) < 0.1)


def test_cast_hits_movers_too():
    sc = build_scenario("forest", 1)
    cam = DepthCamera(CameraConfig(width=32, height=24, fx=20.0, fy=20.0), sc.mesh)
    o = np.array([sc.bounds_min[0] + 0.5, sc.bounds_min[1] + 0.5, 1.0])
    m = mv.movers_from_list([{"shape": "sphere", "radius_m": 0.5, "z_m": 1.0,
                              "points": [[o[0] + 3.0, o[1]]], "speed_m_s": 0.0}])
    d = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    got = cam.cast(o, d, movers=m, movers_time_us=0)
    assert got[0] == pytest.approx(2.5) and got[1] > 2.5


# --- placement -------------------------------------------------------------------------------
def test_placement_is_deterministic_clear_of_obstacles_and_the_start():
    sc = build_scenario("forest", 3)
    a = mv.place_movers(sc, {"count": 12, "shape": "mixed"}, seed=4)
    b = mv.place_movers(sc, {"count": 12, "shape": "mixed"}, seed=4)
    c = mv.place_movers(sc, {"count": 12, "shape": "mixed"}, seed=5)
    assert a.count == 12 and a.describe() == b.describe() and a.describe() != c.describe()
    for t in (0, 3_000_000, 40_000_000):
        assert np.array_equal(a.poses(t), b.poses(t))
    start = np.asarray(sc.start)
    p0 = a.poses(0)
    for j in range(a.count):
        foot = a.dims[j, 0] if a.kind[j] != mv.BOX else math.hypot(*a.dims[j, :2])
        assert np.linalg.norm(p0[j, :2] - start[:2]) - foot >= 4.0
        for k in range(a.n_points[j] - 1):  # every leg clear of the trees at mid-height
            pa, pb = a.points[j, k], a.points[j, k + 1]
            assert segment_mesh_distance(sc.mesh, pa, pb, cutoff=1.0) > foot
    assert set(a.paths) <= set(mv.PATHS)
    # a crossing mover reaches the start-goal line when the settings say
    x = mv.place_movers(sc, {"count": 3, "path": "crossing", "crossing_s": [6.0, 6.0]}, seed=2)
    d = np.asarray(sc.goal[:2] - sc.start[:2])
    n = np.array([-d[1], d[0]]) / np.linalg.norm(d)
    side = (x.poses(6_000_000)[:, :2] - sc.start[:2]) @ n
    assert np.abs(side) == pytest.approx(0.0, abs=1e-9)


def test_density_gives_a_count_from_the_area():
    sc = build_scenario("forest", 3)
    area = float(np.prod(sc.bounds_max[:2] - sc.bounds_min[:2]))
    m = mv.place_movers(sc, {"density_per_1000m2": 2.0}, seed=1)
    assert m.count == round(2.0 * area / 1000.0)


@pytest.mark.parametrize("values, says", [
    ({"count": 3, "density_per_1000m2": 1.0}, "not both"),
    ({"count": -1}, "count"),
    ({"speed_m_s": float("nan")}, "speed_m_s"),
    ({"shape": "dog"}, "shape"),
    ({"radius_m": [0.5, 0.2]}, "radius_m"),
    ({"colour": "red"}, "colour"),
])
def test_bad_settings_are_refused_by_name(values, says):
    with pytest.raises(mv.MoverError, match=says):
        mv.settings(values)
    with pytest.raises(TrialSpecError, match=says):
        TrialSpec(algorithm="straight", platform=PLATFORM, family="forest", movers=values)


@pytest.mark.parametrize("text, says", [
    ("forest:3+static(count=2)", "dynamic"),
    ("forest:3+dynamic(count)", "KEY=VALUE"),
    ("forest:3+dynamic(pace=2)", "unknown setting 'pace'"),
    ("forest:3+dynamic(count=2, count=3)", "twice"),
    ("forest:3+dynamic(radius=a:b)", "interval"),
])
def test_the_scenario_string_form_names_what_is_wrong(text, says):
    with pytest.raises(mv.MoverError, match=says):
        mv.split_dynamic(text)


def test_the_scenario_string_form():
    assert mv.split_dynamic("maze:2:1+dynamic(count=8, speed=1.5, radius=0.2:0.4)") == (
        "maze:2:1", {"count": 8, "speed_m_s": 1.5, "radius_m": [0.2, 0.4]})
    assert mv.split_dynamic("maze:2") == ("maze:2", None)


@pytest.mark.parametrize("item, says", [
    ({"shape": "cat"}, "shape"),
    (person([[0, 0]], -1.0), "speed_m_s"),
    (person([[0, float("nan")]], 1.0), "points"),
    (person("east", 1.0), "points"),
])
def test_bad_listed_movers_are_refused_by_item(item, says):
    with pytest.raises(mv.MoverError, match=rf"movers\[0\]\.{says}"):
        mv.movers_from_list([item])


# --- trials ----------------------------------------------------------------------------------
@pytest.mark.slow
def test_a_trial_with_movers_reruns_identically_and_a_static_one_is_unchanged():
    base = dict(algorithm="straight", platform=PLATFORM, family="forest", scenario_index=3,
                trial=1, seed=3)
    static = run_trial(TrialSpec(**base)).row
    spec = TrialSpec(**base, movers={"count": 20, "path": "crossing", "speed_m_s": 2.0,
                                     "crossing_s": [1.0, 4.0]})
    a, b = run_trial(spec).row, run_trial(spec).row
    skip = {"wall_time_s", "planner_time_s", "finished_utc", "trial_id", "spec", "movers",
            "mover_count", "mover_speed_m_s", "reason", "detail", "success",
            "time_to_goal_s", "nav_time_s", "path_length_m", "mean_speed_m_s",
            "max_speed_m_s", "min_clearance_m", "max_tilt_deg", "saturation_fraction",
            "energy_j", "sim_time_s", "planner_calls", "replans"}
    assert {k: v for k, v in a.items() if k not in ("wall_time_s", "planner_time_s",
                                                     "finished_utc")} == \
        {k: v for k, v in b.items() if k not in ("wall_time_s", "planner_time_s",
                                                  "finished_utc")}
    assert (a["mover_count"], a["mover_speed_m_s"]) == (20, 2.0)
    assert (static["mover_count"], static["movers"]) == (0, "")
    assert {k: v for k, v in a.items() if k not in skip} == \
        {k: v for k, v in static.items() if k not in skip}


def test_the_docs_table_is_the_schema():
    from pathlib import Path
    doc = (Path(__file__).resolve().parents[2] / "docs" / "scenarios.md").read_text()
    assert (f"<!-- BEGIN generated: movers.SCHEMA.markdown() -->\n{mv.SCHEMA.markdown()}\n"
            "<!-- END generated -->") in doc


@pytest.mark.parametrize("suffix", [".toml", ".yaml"])
def test_an_exported_spec_carries_the_movers_on_the_same_paths(tmp_path, suffix):
    from ft_sitl.scenarios.io import load_scenario, write_scenario_spec
    sc = mv.with_movers(build_scenario("forest", 2), {"count": 9, "shape": "mixed"}, seed=3)
    back = load_scenario(write_scenario_spec(sc, tmp_path / f"s{suffix}")[0]).movers
    assert back.count == 9 and back.names == sc.movers.names
    for t in (0, 1_234_567, 20_000_000, 95_000_000):
        assert np.array_equal(back.poses(t), sc.movers.poses(t))
        assert np.array_equal(back.velocities(t), sc.movers.velocities(t))
    assert np.array_equal(back.dims, sc.movers.dims)
    assert np.array_equal(back.bounding, sc.movers.bounding)
