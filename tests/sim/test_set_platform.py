"""A batch's vehicle given another platform (Simulation.set_platform, CollisionGuard.
set_vehicle) flies exactly as a fresh simulation of that platform, and refuses what the
constructors refuse."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import trimesh

from ft_sitl.autopilot.params import ParamError
from ft_sitl.autopilot.setpoints import Setpoint
from ft_sitl.physics.catalog import catalog
from ft_sitl.scenarios.collision import CollisionWorld
from ft_sitl.sim.guard import CollisionGuard
from ft_sitl.sim.lockstep import Simulation

PLATFORMS = list(catalog().values())
A, B = PLATFORMS[0], PLATFORMS[-1]


def fly(sim: Simulation, i: int) -> np.ndarray:
    sim.start_hovering(i, [1.0, 2.0, 3.0], 0.3)
    sim.set_wind(i, {"speed_m_s": 3.0, "turbulence": "light"}, seed=5)
    sim.set_setpoint(i, Setpoint.velocity([2.0, -1.0, 0.5], yaw_rate=0.4).offboard())
    rec = sim.step(500, record_every=50)
    return rec[:, i]


def test_a_switched_vehicle_flies_as_a_fresh_one():
    sim = Simulation([A, A, A])
    sim.set_platform(1, B)
    fresh = Simulation([B])
    assert np.array_equal(fly(sim, 1), fly(fresh, 0))
    assert sim.platforms[1] is B and sim.platforms[0] is A


def test_what_set_platform_refuses():
    sim = Simulation([A])
    with pytest.raises(TypeError, match="platform: a Platform"):
        sim.set_platform(0, "0.98kg-EGO Planner DIY")
    twr = A.indicators().twr_max  # a TWR of 9 hovers below MPC_THR_MIN
    agile = replace(A, rotor_speed_max_rad_s=A.rotor_speed_max_rad_s * (9.0 / twr) ** 0.5)
    gains = sim.gains[0].copy()
    with pytest.raises(ParamError, match="hovers at"):
        sim.set_platform(0, agile)
    assert np.array_equal(sim.gains[0], gains) and sim.platforms[0] is A


def test_guard_set_vehicle_checks_the_body():
    world = CollisionWorld(trimesh.creation.box(extents=[1.0, 1.0, 1.0]), [-5, -5, 0],
                           [5, 5, 4])
    body = A.body()
    guard = CollisionGuard(world, [body.bounding_radius_m], bodies=[body])
    with pytest.raises(ValueError, match="smaller than its body's bounding radius"):
        guard.set_vehicle(0, 0.01, B.body())
    with pytest.raises(ValueError, match="non-negative number of metres"):
        guard.set_vehicle(0, float("nan"))
    guard.set_vehicle(0, B.body().bounding_radius_m, B.body())
    assert guard.radii[0] == B.body().bounding_radius_m and guard.probes[0] is not None
