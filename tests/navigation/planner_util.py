"""The planners' unit tests share an open 35 x 20 m box task and bare observations."""

import numpy as np

from ft_sitl.navigation.base import Limits, Observation, Task


def open_task() -> Task:
    """From (0, 0, 1.5) to (20, 0, 1.5) with nothing in the way."""
    return Task(start=np.array([0.0, 0.0, 1.5]), start_yaw=0.0,
                goal=np.array([20.0, 0.0, 1.5]), limits=Limits(),
                bounds_min=np.array([-5.0, -10.0, 0.0]), bounds_max=np.array([30.0, 10.0, 3.0]),
                collision_radius_m=0.2, twr_max=3.0, alpha_xy_max=200.0, alpha_z_max=20.0)


def obs_at(t: float, p=(0.0, 0.0, 1.5)) -> Observation:
    """At rest at ``p`` facing east, no depth frame."""
    return Observation(time_s=t, position=np.array(p), velocity=np.zeros(3), yaw=0.0,
                       attitude=np.array([1.0, 0.0, 0.0, 0.0]), angular_velocity=np.zeros(3))
