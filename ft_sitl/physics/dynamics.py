"""The plant: rigid body + rotors, one vectorised kernel over a batch of vehicles.

State of one vehicle (world ENU, body FLU), a fixed-layout float64 row:

    [0:3]   p_world     position (m)
    [3:6]   v_world     velocity (m/s)
    [6:10]  q_world_body attitude quaternion (w, x, y, z)
    [10:13] w_body      angular velocity (rad/s)
    [13:]   w_rotor     rotor speeds (rad/s), one per rotor in layout order

A step is a sequence of named stages (ArduPilot SIM_Motor / PX4 SIH style):
motors (first-order lag, separate spin-up/spin-down constants, saturation to
[idle, max] while commanded, stopped for a zero command) -> forces and
torques (c_T w^2, c_M w^2 through the allocation matrix, rotor and body drag, gravity)
-> equations of motion (semi-implicit Euler, exact quaternion exponential, renormalised)
-> ground contact. A single vehicle is a batch of one: there is no second copy of
these equations anywhere.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from ft_sitl import G
from ft_sitl.physics.platform import Platform

# --- state layout ---------------------------------------------------------------------
X_POS, X_VEL, X_QUAT, X_OMEGA, X_ROTOR = 0, 3, 6, 10, 13


def state_size(n_rotors: int) -> int:
    return X_ROTOR + n_rotors


# --- plant parameter layout -----------------------------------------------------------
(
    P_MASS,
    P_JXX,
    P_JYY,
    P_JZZ,
    P_CT,
    P_KAPPA,
    P_WMIN,
    P_WMAX,
    P_TAU_UP,
    P_TAU_DN,
    P_KRD,
    P_BDX,
    P_BDY,
    P_BDZ,
) = range(14)
N_PLANT_PARAMS = 14

# --- environment per vehicle ------------------------------------------------------------
E_GROUND_Z, E_WIND_X, E_WIND_Y, E_WIND_Z = range(4)
N_ENV = 4

# --- status per vehicle (written by the kernel) ----------------------------------------
S_CONTACT, S_IMPACT_LAST, S_IMPACT_MAX, S_ENERGY, S_SPECIFIC_FORCE = 0, 1, 2, 3, 4
N_STATUS = 7  # specific force (accelerometer, body FLU) occupies 4:7

HARD_IMPACT_SPEED_M_S = 2.0
"""Vertical touchdown speed above which a ground contact counts as a hard impact (crash):
typical landing gear of 0.5-5 kg multirotors is rated for 1-2 m/s."""


def plant_params(p: Platform) -> np.ndarray:
    """Pack a platform into the kernel's parameter row."""
    prm = np.empty(N_PLANT_PARAMS)
    prm[P_MASS] = p.mass_kg
    prm[P_JXX], prm[P_JYY], prm[P_JZZ] = p.inertia_kg_m2
    prm[P_CT] = p.thrust_coefficient
    prm[P_KAPPA] = p.torque_thrust_ratio_m
    prm[P_WMIN] = p.rotor_speed_min_rad_s
    prm[P_WMAX] = p.rotor_speed_max_rad_s
    prm[P_TAU_UP] = p.motor_tau_up_s
    prm[P_TAU_DN] = p.motor_tau_down_s
    prm[P_KRD] = p.rotor_drag_coefficient
    prm[P_BDX], prm[P_BDY], prm[P_BDZ] = p.body_drag_coefficient
    return prm


@dataclass
class PlantBatch:
    """Arrays for N vehicles of the same rotor count. The kernel mutates them in place."""

    x: np.ndarray  # (N, 13 + n) state
    prm: np.ndarray  # (N, N_PLANT_PARAMS)
    alloc: np.ndarray  # (N, 4, n) allocation matrices
    env: np.ndarray  # (N, N_ENV)
    status: np.ndarray  # (N, N_STATUS)

    @classmethod
    def from_platforms(cls, platforms: list[Platform]) -> PlantBatch:
        if not platforms:
            raise ValueError("a plant batch needs at least one platform")
        n = {p.n_rotors for p in platforms}
        if len(n) != 1:
            raise ValueError(f"a batch needs one rotor count, got {sorted(n)}")
        (n_rot,) = n
        N = len(platforms)
        x = np.zeros((N, state_size(n_rot)))
        x[:, X_QUAT] = 1.0
        prm = np.stack([plant_params(p) for p in platforms])
        alloc = np.stack([p.allocation() for p in platforms])
        x[:, X_ROTOR:] = prm[:, P_WMIN : P_WMIN + 1]
        env = np.zeros((N, N_ENV))
        status = np.zeros((N, N_STATUS))
        return cls(x, prm, alloc, env, status)


@njit(cache=True, fastmath=False)
def plant_step_one(x, w_cmd, prm, alloc, env, status, dt):
    """Advance one vehicle by dt seconds. x and status are updated in place."""
    n = alloc.shape[1]
    m = prm[P_MASS]
    ct = prm[P_CT]
    kappa = prm[P_KAPPA]
    wmin = prm[P_WMIN]
    wmax = prm[P_WMAX]
    a_up = -math.expm1(-dt / prm[P_TAU_UP])
    a_dn = -math.expm1(-dt / prm[P_TAU_DN])

    # 1. motors: saturate the command, first-order lag towards it (exact discretisation)
    thrust = 0.0
    tx = 0.0
    ty = 0.0
    tz = 0.0
    wsum = 0.0
    power = 0.0
    for i in range(n):
        c = w_cmd[i]
        if not (c > 0.0):  # zero, negative or NaN: the ESC stops the motor (disarmed)
            c = 0.0
        elif c < wmin:  # armed: never below idle
            c = wmin
        elif c > wmax:
            c = wmax
        w = x[X_ROTOR + i]
        w += (c - w) * (a_up if c > w else a_dn)
        x[X_ROTOR + i] = w
        t_i = ct * w * w
        thrust += alloc[0, i] * t_i
        tx += alloc[1, i] * t_i
        ty += alloc[2, i] * t_i
        tz += alloc[3, i] * t_i
        wsum += w
        power += kappa * t_i * w

    qw = x[X_QUAT]
    qx = x[X_QUAT + 1]
    qy = x[X_QUAT + 2]
    qz = x[X_QUAT + 3]
    # rotation matrix R_world_body
    r00 = 1.0 - 2.0 * (qy * qy + qz * qz)
    r01 = 2.0 * (qx * qy - qw * qz)
    r02 = 2.0 * (qx * qz + qw * qy)
    r10 = 2.0 * (qx * qy + qw * qz)
    r11 = 1.0 - 2.0 * (qx * qx + qz * qz)
    r12 = 2.0 * (qy * qz - qw * qx)
    r20 = 2.0 * (qx * qz - qw * qy)
    r21 = 2.0 * (qy * qz + qw * qx)
    r22 = 1.0 - 2.0 * (qx * qx + qy * qy)

    # 2. forces in the body frame: thrust, rotor drag (in-plane), quadratic body drag
    ax_w = x[X_VEL] - env[E_WIND_X]
    ay_w = x[X_VEL + 1] - env[E_WIND_Y]
    az_w = x[X_VEL + 2] - env[E_WIND_Z]
    vbx = r00 * ax_w + r10 * ay_w + r20 * az_w
    vby = r01 * ax_w + r11 * ay_w + r21 * az_w
    vbz = r02 * ax_w + r12 * ay_w + r22 * az_w
    krd = prm[P_KRD] * wsum
    fbx = -krd * vbx - prm[P_BDX] * abs(vbx) * vbx
    fby = -krd * vby - prm[P_BDY] * abs(vby) * vby
    fbz = thrust - prm[P_BDZ] * abs(vbz) * vbz
    # accelerometer: specific force in the body frame
    status[S_SPECIFIC_FORCE] = fbx / m
    status[S_SPECIFIC_FORCE + 1] = fby / m
    status[S_SPECIFIC_FORCE + 2] = fbz / m

    # 3. equations of motion
    acc_x = (r00 * fbx + r01 * fby + r02 * fbz) / m
    acc_y = (r10 * fbx + r11 * fby + r12 * fbz) / m
    acc_z = (r20 * fbx + r21 * fby + r22 * fbz) / m - G
    jxx = prm[P_JXX]
    jyy = prm[P_JYY]
    jzz = prm[P_JZZ]
    p = x[X_OMEGA]
    q = x[X_OMEGA + 1]
    r = x[X_OMEGA + 2]
    # J w_dot = tau - w x (J w)
    pd = (tx - (q * jzz * r - r * jyy * q)) / jxx
    qd = (ty - (r * jxx * p - p * jzz * r)) / jyy
    rd = (tz - (p * jyy * q - q * jxx * p)) / jzz

    vx = x[X_VEL] + acc_x * dt
    vy = x[X_VEL + 1] + acc_y * dt
    vz = x[X_VEL + 2] + acc_z * dt
    x[X_VEL] = vx
    x[X_VEL + 1] = vy
    x[X_VEL + 2] = vz
    x[X_POS] += vx * dt
    x[X_POS + 1] += vy * dt
    x[X_POS + 2] += vz * dt
    p += pd * dt
    q += qd * dt
    r += rd * dt
    x[X_OMEGA] = p
    x[X_OMEGA + 1] = q
    x[X_OMEGA + 2] = r
    # q <- q * exp(w dt / 2)
    wn = math.sqrt(p * p + q * q + r * r)
    if wn > 1e-12:
        h = 0.5 * wn * dt
        s = math.sin(h) / wn
        dw = math.cos(h)
        dx = p * s
        dy = q * s
        dz = r * s
        nw = qw * dw - qx * dx - qy * dy - qz * dz
        nx = qw * dx + qx * dw + qy * dz - qz * dy
        ny = qw * dy - qx * dz + qy * dw + qz * dx
        nz = qw * dz + qx * dy - qy * dx + qz * dw
        inv = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
        x[X_QUAT] = nw * inv
        x[X_QUAT + 1] = nx * inv
        x[X_QUAT + 2] = ny * inv
        x[X_QUAT + 3] = nz * inv

    # 4. ground contact: the vehicle never sinks below the ground plane
    zg = env[E_GROUND_Z]
    if x[X_POS + 2] <= zg:
        x[X_POS + 2] = zg
        if vz < 0.0:
            status[S_IMPACT_LAST] = -vz
            if -vz > status[S_IMPACT_MAX]:
                status[S_IMPACT_MAX] = -vz
        status[S_CONTACT] = 1.0
        thrust_up = r22 * thrust
        if thrust_up < m * G:
            # resting on the landing gear: friction holds it, the gear levels it (yaw kept)
            x[X_VEL] = 0.0
            x[X_VEL + 1] = 0.0
            x[X_VEL + 2] = 0.0
            x[X_OMEGA] = 0.0
            x[X_OMEGA + 1] = 0.0
            x[X_OMEGA + 2] = 0.0
            qw = x[X_QUAT]
            qx = x[X_QUAT + 1]
            qy = x[X_QUAT + 2]
            qz = x[X_QUAT + 3]
            yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
            x[X_QUAT] = math.cos(0.5 * yaw)
            x[X_QUAT + 1] = 0.0
            x[X_QUAT + 2] = 0.0
            x[X_QUAT + 3] = math.sin(0.5 * yaw)
            # the accelerometer feels the ground's reaction: 1 g up, level
            status[S_SPECIFIC_FORCE] = 0.0
            status[S_SPECIFIC_FORCE + 1] = 0.0
            status[S_SPECIFIC_FORCE + 2] = G
        elif vz < 0.0:
            x[X_VEL + 2] = 0.0
    else:
        status[S_CONTACT] = 0.0
    status[S_ENERGY] += power * dt


@njit(cache=True)
def plant_step(x, w_cmd, prm, alloc, env, status, dt):
    """Advance a batch: x (N, nx), w_cmd (N, n) rotor speed commands (rad/s)."""
    for i in range(x.shape[0]):
        plant_step_one(x[i], w_cmd[i], prm[i], alloc[i], env[i], status[i], dt)
