"""A navigator's Observation as a lockstep tick on the bus (:mod:`ft_sitl.bus.tick`) and
back, bit for bit: the simulator's side makes the tick of the observation its driver would
hand an in-process navigator, the client rebuilds exactly that observation (its depth
frame and the moving obstacles' truth included)."""

from __future__ import annotations

import numpy as np

from ft_sitl.bus.tick import Tick
from ft_sitl.navigation.base import Observation, ObstacleStates
from ft_sitl.scenarios.camera import DepthFrame

_STATE = ("position", "velocity", "attitude", "angular_velocity")
_FRAME = ("depth", "points_body", "points_world", "pixels", "p_world_body", "q_world_body",
          "p_world_camera", "r_world_optical")
_MOVERS = ("position", "velocity", "size")


def observation_tick(seq: int, phase: str, time_usec: int, obs: Observation) -> Tick:
    """The tick ``seq`` of ``phase`` ("observe", "step") at the vehicle's simulated time
    ``time_usec``, carrying ``obs``."""
    scalars = {"time_s": float(obs.time_s), "yaw": float(obs.yaw)}
    arrays = {k: np.asarray(getattr(obs, k)) for k in _STATE}
    if obs.depth is not None:
        scalars["depth.t_us"] = int(obs.depth.t_us)
        arrays.update({f"depth.{k}": np.asarray(getattr(obs.depth, k)) for k in _FRAME})
    if obs.movers is not None:
        arrays.update({f"movers.{k}": np.asarray(getattr(obs.movers, k)) for k in _MOVERS})
    return Tick(seq, phase, int(time_usec), scalars, arrays)


def tick_observation(tick: Tick) -> Observation:
    """The Observation a tick carries."""
    a, sc = tick.arrays, tick.scalars
    depth = None
    if "depth.t_us" in sc:
        depth = DepthFrame(t_us=int(sc["depth.t_us"]), **{k: a[f"depth.{k}"] for k in _FRAME})
    movers = None
    if "movers.position" in a:
        movers = ObstacleStates(*(a[f"movers.{k}"] for k in _MOVERS))
    return Observation(time_s=sc["time_s"], position=a["position"], velocity=a["velocity"],
                       yaw=sc["yaw"], attitude=a["attitude"],
                       angular_velocity=a["angular_velocity"], depth=depth, movers=movers)
