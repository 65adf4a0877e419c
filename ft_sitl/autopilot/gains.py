"""Turn PX4-named parameters and a platform into the cascade's gain row.

Two gain modes (FT_GAIN_MODE):

* 0, bandwidth (default): the rate loop is specified as closed-loop bandwidths
  (FT_RATE_BW_RP, FT_RATE_BW_Y, rad/s) and converted to torque through each platform's
  inertia: tau = J (bw e + bw * wi * int e). Every platform gets the same closed-loop
  response while it stays inside its limits; TWR and alpha decide when it cannot.
* 1, normalised: PX4's MC_*RATE_P/I/D act on normalised torque, scaled by each
  platform's full torque authority: tau = tau_max (P e + I int e - D w_dot). The same
  numbers then mean different bandwidths on different platforms, as when one PX4
  tuning is flown on many airframes (paper Sec. V: controller sensitivity).

The outer loops (position, velocity, attitude) are already physical (1/s, m/s^2) in
PX4 and use its parameters directly in both modes; velocity outputs are accelerations,
turned into force through the platform's mass.
"""

from __future__ import annotations

import math

import numpy as np

from ft_sitl import G
from ft_sitl.autopilot import cascade as c
from ft_sitl.autopilot.params import ParamError, ParamSet
from ft_sitl.physics.platform import Platform

# gain-row entries that are a PX4 parameter as it is (units already SI)
_DIRECT = {
    c.G_KP_XY: "MPC_XY_P",
    c.G_KP_Z: "MPC_Z_P",
    c.G_KV_XY_P: "MPC_XY_VEL_P_ACC",
    c.G_KV_XY_I: "MPC_XY_VEL_I_ACC",
    c.G_KV_XY_D: "MPC_XY_VEL_D_ACC",
    c.G_KV_Z_P: "MPC_Z_VEL_P_ACC",
    c.G_KV_Z_I: "MPC_Z_VEL_I_ACC",
    c.G_KV_Z_D: "MPC_Z_VEL_D_ACC",
    c.G_KATT_R: "MC_ROLL_P",
    c.G_KATT_P: "MC_PITCH_P",
    c.G_VMAX_XY: "MPC_XY_VEL_MAX",
    c.G_VMAX_UP: "MPC_Z_VEL_MAX_UP",
    c.G_VMAX_DN: "MPC_Z_VEL_MAX_DN",
    c.G_AMAX_XY: "MPC_ACC_HOR_MAX",
    c.G_AMAX_UP: "MPC_ACC_UP_MAX",
    c.G_AMAX_DN: "MPC_ACC_DOWN_MAX",
    c.G_OFFB_ACC_LIM: "FT_OFFB_ACC_LIM",
}


def build_gains(platform: Platform, params: ParamSet, dt: float) -> np.ndarray:
    hover = platform.mass_kg * G / platform.thrust_max_n
    if hover <= params["MPC_THR_MIN"]:
        raise ParamError(
            f"platform {platform.name!r} hovers at {hover:.1%} of its maximum thrust, at or "
            f"below MPC_THR_MIN ({params['MPC_THR_MIN']:.0%}): in position control it could "
            "not descend; lower MPC_THR_MIN"
        )
    gn = np.zeros(c.N_GAINS)
    for index, name in _DIRECT.items():
        gn[index] = params[name]
    yaw_w = params["MC_YAW_WEIGHT"]
    # PX4 divides the yaw gain by the yaw weight, which the reduced attitude scales down
    gn[c.G_KATT_Y] = params["MC_YAW_P"] / yaw_w if yaw_w > 1e-3 else 0.0
    gn[c.G_YAW_W] = yaw_w
    if int(params["FT_GAIN_MODE"]) == 0:
        bw = np.array([params["FT_RATE_BW_RP"], params["FT_RATE_BW_RP"], params["FT_RATE_BW_Y"]])
        wi = params["FT_RATE_I_RATIO"] * bw
        gn[c.G_RATE_P : c.G_RATE_P + 3] = bw
        gn[c.G_RATE_I : c.G_RATE_I + 3] = bw * wi
        gn[c.G_RATE_D : c.G_RATE_D + 3] = 0.0
        gn[c.G_RATE_ILIM : c.G_RATE_ILIM + 3] = params["FT_RATE_INT_LIM"]
        gn[c.G_TSCALE : c.G_TSCALE + 3] = platform.inertia_kg_m2
    else:
        for k, axis in enumerate(("ROLL", "PITCH", "YAW")):
            gn[c.G_RATE_P + k] = params[f"MC_{axis}RATE_P"]
            gn[c.G_RATE_I + k] = params[f"MC_{axis}RATE_I"]
            gn[c.G_RATE_D + k] = params[f"MC_{axis}RATE_D"]
        gn[c.G_RATE_ILIM : c.G_RATE_ILIM + 3] = [
            params["MC_RR_INT_LIM"], params["MC_PR_INT_LIM"], params["MC_YR_INT_LIM"],
        ]
        gn[c.G_TSCALE : c.G_TSCALE + 3] = platform.max_torques()
    gn[c.G_TILT_MAX] = math.radians(params["MPC_TILTMAX_AIR"])
    gn[c.G_FMIN] = params["MPC_THR_MIN"] * platform.thrust_max_n
    gn[c.G_FMAX] = params["MPC_THR_MAX"] * platform.thrust_max_n
    gn[c.G_RATE_MAX : c.G_RATE_MAX + 3] = np.radians(
        [params["MC_ROLLRATE_MAX"], params["MC_PITCHRATE_MAX"], params["MC_YAWRATE_MAX"]]
    )
    gn[c.G_TROT_MIN] = platform.rotor_thrust_min_n
    gn[c.G_TROT_MAX] = platform.rotor_thrust_max_n
    gn[c.G_CT] = platform.thrust_coefficient
    gn[c.G_MASS] = platform.mass_kg
    gn[c.G_AIRMODE] = params["MC_AIRMODE"]
    gn[c.G_POS_DIV] = max(1, round(1.0 / (params["FT_POS_LOOP_HZ"] * dt)))
    return gn


def mixer(platform: Platform) -> np.ndarray:
    """A = B^+ (n x 4): rotor thrusts for a wanted [collective, tau_x, tau_y, tau_z]."""
    return np.linalg.pinv(platform.allocation())
