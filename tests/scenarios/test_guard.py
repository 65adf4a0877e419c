"""Collision checking inside the physics loop (ft_sitl.sim.guard + lockstep kernel)."""

import math

import numpy as np
import pytest
import trimesh

from ft_sitl.autopilot.commander import MAIN_OFFBOARD, Severity
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.physics import dynamics as d
from ft_sitl.physics.catalog import get_platform
from ft_sitl.scenarios.collision import CollisionMonitor, CollisionWorld
from ft_sitl.scenarios.distance_grid import DistanceGrid
from ft_sitl.scenarios.families import build_scenario
from ft_sitl.scenarios.scenario import Scenario
from ft_sitl.sim.fleet import Fleet
from ft_sitl.sim.guard import CollisionGuard
from ft_sitl.sim.lockstep import Simulation

PLATFORM = "0.98kg-EGO Planner DIY"
R = 0.25


def wall_world(x0=5.0, thickness=0.2):
    wall = trimesh.creation.box(extents=[thickness, 20.0, 6.0])
    wall.apply_translation([x0 + thickness / 2, 0.0, 3.0])
    return CollisionWorld(wall, [-10.0, -10.0, 0.0], [20.0, 10.0, 5.0])


def guarded_sim(world, n=1, physics_hz=1000, radius=R, grid=True):
    p = get_platform(PLATFORM)
    sim = Simulation([p] * n, physics_hz=physics_hz)
    g = None
    if grid:
        g = DistanceGrid.build(world_mesh(world), world.bounds_min, world.bounds_max)
    guard = CollisionGuard(world, [radius] * n, grid=g)
    return sim, guard


def world_mesh(world):
    return trimesh.Trimesh(world._tri.reshape(-1, 3),
                           np.arange(3 * len(world._tri)).reshape(-1, 3), process=False)


# --- the distance grid ---------------------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("family", ["forest", "perlin", "maze", "random_angle_cylinder"])
def test_grid_is_a_lower_bound_of_the_true_distance(family):
    sc = build_scenario(family, 4)
    grid = DistanceGrid.build(sc.mesh, sc.bounds_min, sc.bounds_max)
    world = CollisionWorld(sc.mesh, sc.bounds_min, sc.bounds_max)
    rng = np.random.default_rng(7)
    lo, hi = sc.bounds_min - 0.5, sc.bounds_max + 0.5
    pts = rng.uniform(lo, hi, size=(1500, 3))
    # and points hugging the surface, where the bound is tightest
    surf, _ = trimesh.sample.sample_surface(sc.mesh, 500, seed=3)
    pts = np.vstack([pts, surf + rng.normal(0.0, 0.15, surf.shape)])
    slack = []
    for p in pts:
        lb = grid.lower_bound(p)
        true = abs(world.obstacle_distance(p))
        assert lb <= true + 1e-9, (p, lb, true)
        if math.isfinite(lb) and lb > 0:
            slack.append(true - lb)
    # useful, not just safe: mostly within the worst case of the construction (voxel centre
    # to surface twice, the sampling spacing, query point to voxel centre twice); surfaces
    # beyond the grid, projected onto its faces, loosen it near them
    worst = 2.0 * grid.pitch * math.sqrt(3.0) + grid.pitch / 2
    assert np.quantile(slack, 0.95) <= worst + 1e-6
    assert np.median(slack) < 0.6 * worst


def test_grid_outside_is_unknown_and_far_obstacles_still_count():
    box = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    box.apply_translation([30.0, 0.0, 0.5])  # far outside the grid's bounds
    grid = DistanceGrid.build(box, [0.0, -5.0, 0.0], [10.0, 5.0, 3.0])
    assert grid.lower_bound([100.0, 0.0, 1.0]) == -math.inf
    lb = grid.lower_bound([10.5, 0.0, 0.5])  # near the grid's edge facing the box
    assert 0.0 <= lb <= 29.5 - 10.5


# --- the kernel and the exact slow path ---------------------------------------------------
@pytest.mark.parametrize("speed,physics_hz", [(4.0, 1000), (4.0, 250), (8.0, 100)])
def test_thin_wall_crossed_at_speed_is_never_missed(speed, physics_hz):
    world = wall_world()
    sim, guard = guarded_sim(world, physics_hz=physics_hz)
    sim.start_hovering(0, [0.0, 0.0, 2.0])
    sim.attach_guard(guard)
    sim.set_setpoint(0, Setpoint.velocity([speed, 0.0, 0.0]))
    rec = sim.run(4.0, record_hz=physics_hz)
    hits = [e for e in guard.events if e.kind == "collision"]
    assert len(hits) == 1
    ev = hits[0]
    # on the near face, where the sphere first touches it
    assert ev.contact.point[0] == pytest.approx(5.0, abs=1e-6)
    assert ev.position[0] == pytest.approx(5.0 - R, abs=1e-5)
    assert ev.contact.normal == pytest.approx([-1.0, 0.0, 0.0], abs=1e-9)
    # it never got through: no recorded centre beyond the touching position
    assert rec.positions(0)[:, 0].max() <= 5.0 - R + 2e-3


def test_flying_past_close_by_is_not_a_collision():
    world = wall_world()
    sim, guard = guarded_sim(world)
    # along the wall at 0.1 m of clearance of the sphere
    sim.start_hovering(0, [5.0 - R - 0.1, -8.0, 2.0])
    sim.attach_guard(guard)
    sim.set_setpoint(0, Setpoint.trajectory(velocity=[0.0, 4.0, 0.0],
                                            position=[5.0 - R - 0.1, math.nan, 2.0]))
    rec = sim.run(5.0, record_hz=100)
    assert rec.positions(0)[-1, 1] > 6.0
    assert not [e for e in guard.events if e.kind == "collision"]
    assert guard.trips > 0  # it was close enough to need the exact check


@pytest.mark.slow
def test_guard_matches_the_monitor_on_recorded_flights():
    """The kernel's first contact is the step the exact monitor finds on the same flight."""
    sc = build_scenario("perlin", 6)
    p = get_platform(PLATFORM)
    rng = np.random.default_rng(11)
    world = CollisionWorld(sc.mesh, sc.bounds_min, sc.bounds_max)
    grid = DistanceGrid.build(sc.mesh, sc.bounds_min, sc.bounds_max)
    found = 0
    flights = 0
    while flights < 4:
        start = sc.start + np.array([rng.uniform(-4, 4), 0.0, rng.uniform(-0.5, 0.5)])
        if world.clearance(start, R, kinds=("obstacle",)) < 0.5:
            continue
        flights += 1
        heading = np.array([rng.uniform(-0.5, 0.5), 1.0, 0.0])
        sp = Setpoint.velocity(4.0 * heading / np.linalg.norm(heading))
        # unguarded reference flight, every step recorded
        ref = Simulation([p])
        ref.start_hovering(0, start)
        ref.set_setpoint(0, sp)
        pts = np.vstack([start, ref.run(8.0, record_hz=1000).positions(0)])
        hit = CollisionMonitor(world, kinds=("obstacle",)).update_path(pts, R)
        sim = Simulation([p])
        sim.start_hovering(0, start)
        guard = CollisionGuard(world, [R], grid=grid, names=sc.obstacle_name,
                               check_volume=False)
        sim.attach_guard(guard)
        sim.set_setpoint(0, sp)
        sim.run(8.0)
        hits = [e for e in guard.events if e.kind == "collision"]
        if hit is None:
            assert not hits
            continue
        found += 1
        k, contact = hit
        assert len(hits) == 1
        assert hits[0].time_us == (k + 1) * sim.dt_us
        assert hits[0].contact.center == pytest.approx(contact.center, abs=1e-6)
        assert hits[0].what.startswith("noise blob")
    assert found >= 1


def test_volume_events_on_the_centre():
    world = wall_world()
    sim, guard = guarded_sim(world)
    sim.start_hovering(0, [0.0, 0.0, 4.0])
    sim.attach_guard(guard)
    sim.set_setpoint(0, Setpoint.position([0.0, 0.0, 6.0]))
    sim.run(4.0)
    sim.set_setpoint(0, Setpoint.position([0.0, 0.0, 3.0]))
    sim.run(5.0)
    kinds = [(e.kind, e.what) for e in guard.events]
    assert kinds == [("left_volume", "ceiling"), ("entered_volume", "flight volume")]
    sim.set_setpoint(0, Setpoint.position([-12.0, 0.0, 3.0]))
    sim.run(8.0)
    assert (guard.events[-1].kind, guard.events[-1].what) == ("left_volume", "west edge")
    assert guard.events[-1].position[0] < -10.0


def test_no_grid_and_no_obstacles():
    world = wall_world()
    sim, guard = guarded_sim(world, grid=False)  # every check exact: slower, same answer
    sim.start_hovering(0, [0.0, 0.0, 2.0])
    sim.attach_guard(guard)
    sim.set_setpoint(0, Setpoint.velocity([4.0, 0.0, 0.0]))
    sim.run(3.0)
    assert [e.kind for e in guard.events] == ["collision"]
    empty = CollisionWorld(trimesh.Trimesh(), [-10.0, -10.0, 0.0], [10.0, 10.0, 5.0])
    sim2 = Simulation([get_platform(PLATFORM)])
    sim2.start_hovering(0, [0.0, 0.0, 2.0])
    g2 = CollisionGuard(empty, [R])
    sim2.attach_guard(g2)
    sim2.set_setpoint(0, Setpoint.velocity([4.0, 0.0, 0.0]))
    sim2.run(5.0)
    assert sim2.position(0)[0] > 10.0
    assert [e.what for e in g2.events] == ["east edge"]
    assert g2.queries == 0


# --- the fleet: a crash ---------------------------------------------------------------------
def fly_into_first_tree():
    sc = build_scenario("forest", 2)
    p = get_platform(PLATFORM)
    fleet = Fleet([p], spawn=[sc.takeoff], spawn_yaw=[sc.start_yaw], scenario=sc)
    cmd = fleet.commanders[0]
    fleet.offboard_setpoint(0, Setpoint.position(sc.start, yaw=sc.start_yaw))
    cmd.set_mode(MAIN_OFFBOARD)
    assert cmd.arm().name == "ACCEPTED"
    for _ in range(200):
        fleet.offboard_setpoint(0, Setpoint.position(sc.start, yaw=sc.start_yaw))
        fleet.run(0.02)
    u = (sc.goal - sc.start) / np.linalg.norm(sc.goal - sc.start)
    path = []
    for _ in range(1000):
        fleet.offboard_setpoint(0, Setpoint.velocity(4.0 * u, yaw=sc.start_yaw))
        fleet.run(0.02)
        path.append(fleet.state(0).position)
        if cmd.crashed:
            break
    return sc, fleet, path


@pytest.mark.slow
def test_fleet_crash_stops_motors_names_the_obstacle_and_the_vehicle_falls():
    sc, fleet, _ = fly_into_first_tree()
    cmd = fleet.commanders[0]
    assert cmd.crashed and cmd.terminated and not cmd.armed
    ev = [e for e in fleet.events if e.kind == "collision"][0]
    assert ev.what.startswith("tree ")
    assert ev.speed_m_s > 2.0
    texts = [t for sev, t in cmd.statustexts if sev == Severity.EMERGENCY]
    assert texts and texts[-1].startswith(f"Collision: hit {ev.what} at ")
    # the obstacle the triangle belongs to really is that tree: the contact lies on it
    k = int(ev.what.split()[1]) - 1
    lo = sc.piece_first_face[k]
    hi = sc.piece_first_face[k + 1] if k + 1 < len(sc.piece_first_face) else len(sc.mesh.faces)
    assert lo <= ev.contact.triangle < hi
    fleet.run(3.0)
    st = fleet.state(0)
    assert st.on_ground
    assert np.all(fleet.sim.rotor_speeds(0) < 1.0)  # motors stopped
    # it stayed on its side of the trunk: clearance never below -contact tolerance
    assert fleet.guard.clearance(0) >= -1e-6
    assert arming_denied(cmd)


def arming_denied(cmd):
    return cmd.arm().name != "ACCEPTED"


@pytest.mark.slow
def test_respawn_after_a_crash():
    sc, fleet, _ = fly_into_first_tree()
    fleet.run(2.0)
    fleet.respawn(0)
    cmd = fleet.commanders[0]
    assert not cmd.crashed and not cmd.terminated
    assert fleet.state(0).position == pytest.approx(sc.takeoff)
    assert fleet.sim.x[0, d.X_VEL:d.X_VEL + 3] == pytest.approx(np.zeros(3))
    fleet.run(1.0)
    assert not [e for e in fleet.events[1:] if e.kind == "collision"]


def test_fleet_without_scenario_has_no_guard():
    fleet = Fleet([get_platform(PLATFORM)])
    assert fleet.guard is None and fleet.events == []


def test_scenario_piece_names_validated():
    sc = build_scenario("maze", 1)
    with pytest.raises(ValueError, match="piece_first_face"):
        Scenario(family=sc.family, index=1, seed=0, category=sc.category, mesh=sc.mesh,
                 bounds_min=sc.bounds_min, bounds_max=sc.bounds_max, takeoff=sc.takeoff,
                 start=sc.start, start_yaw=sc.start_yaw, goal=sc.goal,
                 piece_first_face=[0, 5], piece_names=("wall 1",))
    assert sc.obstacle_name(0) == "wall 1"
    assert sc.obstacle_name(10**9) == "obstacle"
