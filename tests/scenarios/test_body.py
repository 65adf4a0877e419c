"""The vehicle body (ft_sitl.physics.body) in the collision world and the guard."""

import math

import numpy as np
import pytest
import trimesh

from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.physics.body import build_body
from ft_sitl.physics.catalog import catalog, get_platform, load_platform_file
from ft_sitl.physics.layouts import get_layout
from ft_sitl.physics.platform import PlatformError
from ft_sitl.physics.quaternion import qfrom_euler
from ft_sitl.rotations import matrix_from_quat
from ft_sitl.scenarios.collision import BodyProbe, CollisionWorld
from ft_sitl.scenarios.distance_grid import DistanceGrid
from ft_sitl.scenarios.families import build_scenario
from ft_sitl.sim.guard import CollisionGuard
from ft_sitl.sim.lockstep import Simulation

PLATFORM = "0.98kg-EGO Planner DIY"


def wall(x0=5.0):
    """A wall whose face is the plane x = x0, and its world and distance grid."""
    box = trimesh.creation.box(extents=[0.2, 20.0, 6.0])
    box.apply_translation([x0 + 0.1, 0.0, 3.0])
    world = CollisionWorld(box, [-10.0, -10.0, 0.0], [20.0, 10.0, 5.0])
    return world, DistanceGrid.build(box, world.bounds_min, world.bounds_max)


def test_every_platform_body_is_its_arm_length_and_its_propellers():
    for p in catalog().values():
        b = p.body()
        hubs = get_layout(p.layout).rotor_positions(p.arm_length_m)
        assert len(b.rotors) == p.n_rotors == len(hubs)
        for disk, hub in zip(b.rotors, hubs):
            assert math.hypot(disk.center[0], disk.center[1]) == pytest.approx(p.arm_length_m)
            assert disk.center[:2] == pytest.approx(hub[:2])
            assert disk.radius == pytest.approx(p.prop_diameter_m / 2)
        # the rotor tip is the farthest point sideways; the bounding sphere holds it all
        assert b.half_span_m == pytest.approx(p.arm_length_m + p.prop_diameter_m / 2)
        assert b.bounding_radius_m >= b.half_span_m
        assert b.bounding_radius_m == pytest.approx(math.hypot(
            b.half_span_m, b.rotors[0].center[2] + b.rotors[0].thickness / 2))


def test_user_platform_sets_its_body_and_bad_values_are_named(tmp_path):
    src = get_platform(PLATFORM).physical_dict()
    f = tmp_path / "mine.toml"

    def write(**extra):
        entry = {**src, "name": "mine", "category": "user", **extra}
        lines = ["[[platform]]"]
        for k, v in entry.items():
            lines.append(f"{k} = {v!r}".replace("'", '"'))
        f.write_text("\n".join(lines) + "\n")

    write(body_size_m=[0.3, 0.2, 0.1], rotor_disk_thickness_m=0.03, rotor_height_m=0.05)
    (p,) = load_platform_file(f)
    b = p.body()
    assert b.box.size == (0.3, 0.2, 0.1)
    assert b.rotors[0].thickness == 0.03 and b.rotors[0].center[2] == 0.05
    assert p.physical_dict()["body_size_m"] == [0.3, 0.2, 0.1]
    # left out, the rule from the arm length; and the platform's dict (its trial spec)
    # does not grow keys it never set
    assert "body_size_m" not in get_platform(PLATFORM).physical_dict()
    write(body_size_m=[0.3, 0.2])
    with pytest.raises(PlatformError, match="body_size_m"):
        load_platform_file(f)
    write(rotor_disk_thickness_m=-0.01)
    with pytest.raises(PlatformError, match=r"rotor_disk_thickness_m.*outside the allowed"):
        load_platform_file(f)


def test_yawed_45_degrees_beside_a_wall_touches_it_where_unyawed_does_not():
    """An X-frame reaches d + r_prop along its arms (45 deg off the nose) and only
    d cos 45 + r_prop along its body axes: beside a wall, the yaw decides."""
    p = get_platform(PLATFORM)
    b = p.body()
    across = p.arm_length_m * math.cos(math.pi / 4) + p.prop_diameter_m / 2
    gap = 0.5 * (across + b.half_span_m)  # between the two reaches
    world, grid = wall()
    probe = BodyProbe(b)
    centre = np.array([5.0 - gap, 0.0, 2.0])
    for yaw_deg, touches in ((0.0, False), (45.0, True), (90.0, False)):
        rot = matrix_from_quat(qfrom_euler(0.0, 0.0, math.radians(yaw_deg)))
        free = world.body_distance(probe, centre, rot) > world.contact_tol
        assert free != touches, yaw_deg
    # the same in flight: hovering there is fine, yawing by 45 deg hits the wall
    for yaw_deg, hits in ((0.0, 0), (45.0, 1)):
        sim = Simulation([p])
        sim.start_hovering(0, centre)
        guard = CollisionGuard(world, [b.bounding_radius_m], grid=grid, bodies=[b])
        sim.attach_guard(guard)
        sim.set_setpoint(0, Setpoint.position(centre, yaw=math.radians(yaw_deg)))
        sim.run(3.0)
        found = [e for e in guard.events if e.kind == "collision"]
        assert len(found) == hits, yaw_deg
        if hits:
            # the rotor tip touched, the centre never came closer than the axis reach
            assert found[0].position[0] < 5.0 - across
            assert found[0].contact.point[0] == pytest.approx(5.0, abs=0.01)
    # and the sphere of the same bounding radius would have hit it either way
    assert gap < b.bounding_radius_m


def test_passing_closer_than_the_bounding_sphere_but_clear_of_the_body():
    """Along the wall inside the bounding sphere's reach: the body (narrower across the
    nose) passes, the guard works in body mode and measures the body's clearance."""
    p = get_platform(PLATFORM)
    b = p.body()
    across = p.arm_length_m * math.cos(math.pi / 4) + p.prop_diameter_m / 2
    x = 5.0 - across - 0.03
    world, grid = wall()
    sim = Simulation([p])
    sim.start_hovering(0, [x, -8.0, 2.0], yaw=math.pi / 2)  # (yawing there would hit)
    guard = CollisionGuard(world, [b.bounding_radius_m], grid=grid, bodies=[b])
    sim.attach_guard(guard)
    sim.set_setpoint(0, Setpoint.trajectory(velocity=[0.0, 3.0, 0.0],
                                            position=[x, math.nan, 2.0], yaw=math.pi / 2))
    sim.run(6.0)
    assert sim.position(0)[1] > 6.0
    assert not [e for e in guard.events if e.kind == "collision"]
    assert guard.trips > 0
    c = guard.clearance(0)
    assert 0.0 < c < 0.06
    assert guard.clearance_bound(0) <= c + 1e-9


@pytest.mark.slow
def test_guard_first_body_contact_is_the_first_touching_step():
    """The kernel's body anchor (translation plus rotation bound) never skips a touching
    pose: its first contact is the first recorded step whose body touches, found by
    checking every step exactly."""
    sc = build_scenario("forest", 2)
    p = get_platform(PLATFORM)
    b = p.body()
    world = CollisionWorld(sc.mesh, sc.bounds_min, sc.bounds_max)
    grid = DistanceGrid.build(sc.mesh, sc.bounds_min, sc.bounds_max)
    probe = BodyProbe(b)
    u = (sc.goal - sc.start) / np.linalg.norm(sc.goal - sc.start)
    # weaving with yaw turns, so the rotation term matters
    sp = [Setpoint.velocity(3.5 * u, yaw=sc.start_yaw + 0.6 * math.sin(k)) for k in range(20)]
    ref = Simulation([p])
    ref.start_hovering(0, sc.start)
    states = []
    for s in sp:
        ref.set_setpoint(0, s)
        states.append(ref.run(0.5, record_hz=1000).x[:, 0, :].copy())
    xs = np.vstack(states)
    first = None
    for k, xk in enumerate(xs):
        rot = matrix_from_quat(xk[6:10], name="attitude")
        if world.body_distance(probe, xk[:3].copy(), rot) <= world.contact_tol:
            first = k
            break
    assert first is not None, "the weave should end in a trunk"
    sim = Simulation([p])
    sim.start_hovering(0, sc.start)
    guard = CollisionGuard(world, [b.bounding_radius_m], grid=grid, bodies=[b],
                           names=sc.obstacle_name, check_volume=False)
    sim.attach_guard(guard)
    for s in sp:
        sim.set_setpoint(0, s)
        sim.run(0.5)
        if guard.events:
            break
    hits = [e for e in guard.events if e.kind == "collision"]
    assert len(hits) == 1
    assert hits[0].time_us == (first + 1) * sim.dt_us
    assert hits[0].what.startswith("tree ")


def test_body_rules_scale_with_the_arm():
    small = build_body("quad_x", 0.1, 0.115)
    big = build_body("quad_x", 0.3, 0.345)
    assert big.bounding_radius_m == pytest.approx(3 * small.bounding_radius_m)
    assert big.box.size == pytest.approx([3 * s for s in small.box.size])
    with pytest.raises(ValueError, match="smaller than its body's bounding radius"):
        CollisionGuard(wall()[0], [0.1], bodies=[small])


def test_the_clearance_bound_holds_the_last_measurement_less_any_body_points_motion():
    """After an exact clearance the bound is that clearance less how far any point of the
    body can have moved since (translation plus the bounding radius's chord of the
    rotation): at the measured pose it is the measurement, and it never exceeds the exact
    clearance along a flight that yaws past a wall."""
    p = get_platform(PLATFORM)
    b = p.body()
    world, grid = wall()
    sim = Simulation([p])
    sim.start_hovering(0, [3.6, -4.0, 2.0], yaw=math.pi / 2)
    guard = CollisionGuard(world, [b.bounding_radius_m], grid=grid, bodies=[b])
    sim.attach_guard(guard)
    c = guard.clearance(0)
    assert guard.clearance_bound(0) == pytest.approx(c, abs=1e-8)
    sim.set_setpoint(0, Setpoint.trajectory(velocity=[0.0, 1.0, 0.0],
                                            position=[3.6, math.nan, 2.0], yaw=math.pi))
    gains = []
    for _ in range(40):
        sim.run(0.05)
        bound = guard.clearance_bound(0)
        exact = guard.clearance(0)  # (and measures anew)
        assert bound <= exact + 1e-9
        gains.append(bound)
    # the bound tracks the vehicle (it is not the sphere anchor's -inf or a constant)
    assert max(gains) > 0.0 and len(set(gains)) > 10
