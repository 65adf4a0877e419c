"""The flight-control cascade of the virtual PX4, compiled, over a batch of vehicles.

position P -> velocity PID -> acceleration (tilt, thrust and acceleration limits) ->
attitude (quaternion error, roll/pitch before yaw) -> body-rate PID -> torque and
collective thrust -> control allocation with sequential desaturation -> rotor speed
commands. The structure and the parameter names follow PX4's mc_pos_control,
mc_att_control and mc_rate_control and its ControlAllocationSequentialDesaturation;
the code is ours and works in ENU/FLU and SI units.

Setpoints use PX4's trajectory_setpoint convention: a NaN component is "not controlled"
(position NaN -> velocity control on that axis; both NaN -> acceleration only; yaw NaN ->
hold the current heading, yaw rate as feed-forward). NaN never reaches the motors: the
Python API (:mod:`ft_sitl.autopilot.setpoints`) rejects non-finite values where a value
is required before they get here.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from ft_sitl import G
from ft_sitl.physics.dynamics import X_OMEGA, X_POS, X_QUAT, X_VEL

# --- setpoint row -----------------------------------------------------------------------
SP_KIND, SP_POS, SP_VEL, SP_ACC, SP_YAW, SP_YAWRATE, SP_Q, SP_RATES, SP_THRUST = (
    0, 1, 4, 7, 10, 11, 12, 16, 19,
)
#: 1.0 when the setpoint came from outside (offboard), NaN for the flight controller's own
SP_OFFBOARD = 20
N_SP = 21
KIND_OFF, KIND_IDLE, KIND_TRAJECTORY, KIND_ATTITUDE, KIND_RATES = 0, 1, 2, 3, 4
#: direct motor commands (an external autopilot's outputs, autopilot-in-the-loop): u in
#: [0, 1] per rotor in SP_MOTORS.., rotor speed command u * w_max (as Gazebo's motor model)
KIND_MOTORS = 5
SP_MOTORS = 1
MAX_SP_MOTORS = 12

# --- gain / limit row ---------------------------------------------------------------------
(
    G_KP_XY, G_KP_Z, G_KV_XY_P, G_KV_XY_I, G_KV_XY_D, G_KV_Z_P, G_KV_Z_I, G_KV_Z_D,
    G_KATT_R, G_KATT_P, G_KATT_Y, G_YAW_W,
) = range(12)
G_RATE_P, G_RATE_I, G_RATE_D, G_RATE_ILIM, G_TSCALE = 12, 15, 18, 21, 24
(
    G_VMAX_XY, G_VMAX_UP, G_VMAX_DN, G_AMAX_XY, G_AMAX_UP, G_AMAX_DN, G_TILT_MAX,
    G_FMIN, G_FMAX,
) = range(27, 36)
G_RATE_MAX = 36
G_TROT_MIN, G_TROT_MAX, G_CT, G_MASS, G_POS_DIV, G_AIRMODE = 39, 40, 41, 42, 43, 44
G_OFFB_ACC_LIM = 45  # FT_OFFB_ACC_LIM
N_GAINS = 46

# --- controller state row ---------------------------------------------------------------
C_VEL_INT, C_RATE_INT, C_RATE_PREV, C_VEL_PREV, C_ACC_EST = 0, 3, 6, 9, 12
C_QSP, C_FSP, C_RATE_SP, C_ACC_SP = 15, 19, 20, 23
C_POS_COUNT, C_SAT_RP, C_SAT_Y, C_SAT_MOTOR, C_SAT_STEPS, C_TORQUE = 26, 27, 28, 29, 30, 31
N_CTRL = 34

I_FACTOR_RATE = math.radians(400.0)  # rate error at which integration stops (PX4)
YAW_MARGIN = 0.15  # yaw may push rotors 15 % past T_max, then collective gives way (PX4)


@njit(cache=True, inline="always")
def _qmul(a0, a1, a2, a3, b0, b1, b2, b3):
    return (
        a0 * b0 - a1 * b1 - a2 * b2 - a3 * b3,
        a0 * b1 + a1 * b0 + a2 * b3 - a3 * b2,
        a0 * b2 - a1 * b3 + a2 * b0 + a3 * b1,
        a0 * b3 + a1 * b2 - a2 * b1 + a3 * b0,
    )


@njit(cache=True, inline="always")
def _body_z(w, x, y, z):
    """Third column of R(q): the body z axis in the world frame."""
    return 2.0 * (x * z + w * y), 2.0 * (y * z - w * x), 1.0 - 2.0 * (x * x + y * y)


@njit(cache=True, inline="always")
def _clamp(v, lo, hi):
    return lo if v < lo else (hi if v > hi else v)


@njit(cache=True)
def _quat_from_bodyz_yaw(bx, by, bz, yaw):
    """Attitude with body z = (bx, by, bz) (unit) and heading yaw (PX4 bodyzToAttitude)."""
    cx = math.cos(yaw)
    cy = math.sin(yaw)
    # y_B = z_B x x_C
    yx = by * 0.0 - bz * cy
    yy = bz * cx - bx * 0.0
    yz = bx * cy - by * cx
    n = math.sqrt(yx * yx + yy * yy + yz * yz)
    if n < 1e-6:
        # thrust horizontal and along the heading: pick y_B along the horizontal normal
        yx, yy, yz = -cy, cx, 0.0
        n = 1.0
    yx /= n
    yy /= n
    yz /= n
    # x_B = y_B x z_B
    xx = yy * bz - yz * by
    xy = yz * bx - yx * bz
    xz = yx * by - yy * bx
    # rotation matrix columns x_B, y_B, z_B -> quaternion
    r00, r10, r20 = xx, xy, xz
    r01, r11, r21 = yx, yy, yz
    r02, r12, r22 = bx, by, bz
    tr = r00 + r11 + r22
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        w, x, y, z = 0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s
    elif r00 > r11 and r00 > r22:
        s = math.sqrt(1.0 + r00 - r11 - r22) * 2.0
        w, x, y, z = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 > r22:
        s = math.sqrt(1.0 + r11 - r00 - r22) * 2.0
        w, x, y, z = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = math.sqrt(1.0 + r22 - r00 - r11) * 2.0
        w, x, y, z = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s
    n = math.sqrt(w * w + x * x + y * y + z * z)
    if w < 0.0:
        n = -n
    return w / n, x / n, y / n, z / n


@njit(cache=True)
def position_control(x, sp, gn, cs, dt):
    """Position P + velocity PID + thrust-vector limits -> attitude and thrust setpoints."""
    mass = gn[G_MASS]
    vel_cmd = np.empty(3)
    vel_ctrl = np.zeros(3, dtype=np.bool_)
    for i in range(3):
        kp = gn[G_KP_XY] if i < 2 else gn[G_KP_Z]
        p_sp = sp[SP_POS + i]
        v_sp = sp[SP_VEL + i]
        if math.isfinite(p_sp):
            vel_cmd[i] = kp * (p_sp - x[X_POS + i]) + (v_sp if math.isfinite(v_sp) else 0.0)
            vel_ctrl[i] = True
        elif math.isfinite(v_sp):
            vel_cmd[i] = v_sp
            vel_ctrl[i] = True
        else:
            vel_cmd[i] = 0.0
    # velocity limits: horizontal norm, vertical up/down
    hx = vel_cmd[0] if vel_ctrl[0] else 0.0
    hy = vel_cmd[1] if vel_ctrl[1] else 0.0
    hn = math.sqrt(hx * hx + hy * hy)
    if hn > gn[G_VMAX_XY] and hn > 0.0:
        s = gn[G_VMAX_XY] / hn
        vel_cmd[0] *= s
        vel_cmd[1] *= s
    vel_cmd[2] = _clamp(vel_cmd[2], -gn[G_VMAX_DN], gn[G_VMAX_UP])

    acc = np.empty(3)
    err = np.zeros(3)
    for i in range(3):
        v = x[X_VEL + i]
        a_est = (v - cs[C_VEL_PREV + i]) / dt
        cs[C_ACC_EST + i] = a_est
        cs[C_VEL_PREV + i] = v
        a_ff = sp[SP_ACC + i]
        a_ff = a_ff if math.isfinite(a_ff) else 0.0
        if vel_ctrl[i]:
            kvp = gn[G_KV_XY_P] if i < 2 else gn[G_KV_Z_P]
            kvd = gn[G_KV_XY_D] if i < 2 else gn[G_KV_Z_D]
            err[i] = vel_cmd[i] - v
            acc[i] = kvp * err[i] + cs[C_VEL_INT + i] - kvd * a_est + a_ff
        else:
            cs[C_VEL_INT + i] = 0.0
            acc[i] = a_ff
    # acceleration limits: MPC_ACC_* bound the flight controller's own trajectories; an
    # offboard setpoint is bound only by the tilt and thrust limits below, as in PX4
    # (unless FT_OFFB_ACC_LIM = 1, the rule of protocol 1)
    sat_xy = False
    sat_z = False
    if not sp[SP_OFFBOARD] == 1.0 or gn[G_OFFB_ACC_LIM] > 0.5:
        an = math.sqrt(acc[0] * acc[0] + acc[1] * acc[1])
        if an > gn[G_AMAX_XY]:
            s = gn[G_AMAX_XY] / an
            acc[0] *= s
            acc[1] *= s
            sat_xy = True
        if acc[2] > gn[G_AMAX_UP]:
            acc[2] = gn[G_AMAX_UP]
            sat_z = True
        elif acc[2] < -gn[G_AMAX_DN]:
            acc[2] = -gn[G_AMAX_DN]
            sat_z = True
    # thrust vector: vertical first, then what is left for horizontal within the tilt limit
    fz = mass * (acc[2] + G)
    if fz < gn[G_FMIN]:
        fz = gn[G_FMIN]
        sat_z = True
    elif fz > gn[G_FMAX]:
        fz = gn[G_FMAX]
        sat_z = True
    fx = mass * acc[0]
    fy = mass * acc[1]
    fxy_max = min(fz * math.tan(gn[G_TILT_MAX]), math.sqrt(max(gn[G_FMAX] ** 2 - fz * fz, 0.0)))
    fxy = math.sqrt(fx * fx + fy * fy)
    if fxy > fxy_max:
        s = fxy_max / fxy
        fx *= s
        fy *= s
        sat_xy = True
    # integrators with anti-windup: frozen while the output saturates
    for i in range(3):
        if not vel_ctrl[i]:
            continue
        if (i < 2 and not sat_xy) or (i == 2 and not sat_z):
            kvi = gn[G_KV_XY_I] if i < 2 else gn[G_KV_Z_I]
            cs[C_VEL_INT + i] += kvi * err[i] * dt
    f = math.sqrt(fx * fx + fy * fy + fz * fz)
    cs[C_ACC_SP] = fx / mass
    cs[C_ACC_SP + 1] = fy / mass
    cs[C_ACC_SP + 2] = fz / mass - G
    yaw = sp[SP_YAW]
    if not math.isfinite(yaw):
        qw, qx, qy, qz = x[X_QUAT], x[X_QUAT + 1], x[X_QUAT + 2], x[X_QUAT + 3]
        yaw = math.atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
    q = _quat_from_bodyz_yaw(fx / f, fy / f, fz / f, yaw)
    for i in range(4):
        cs[C_QSP + i] = q[i]
    cs[C_FSP] = f


@njit(cache=True)
def attitude_control(x, qd0, qd1, qd2, qd3, yawrate_ff, gn, cs):
    """Quaternion attitude control with yaw de-prioritised (PX4 AttitudeControl)."""
    q0, q1, q2, q3 = x[X_QUAT], x[X_QUAT + 1], x[X_QUAT + 2], x[X_QUAT + 3]
    ez = _body_z(q0, q1, q2, q3)
    ezd = _body_z(qd0, qd1, qd2, qd3)
    # shortest rotation taking the current thrust axis to the desired one
    dot = ez[0] * ezd[0] + ez[1] * ezd[1] + ez[2] * ezd[2]
    cx = ez[1] * ezd[2] - ez[2] * ezd[1]
    cy = ez[2] * ezd[0] - ez[0] * ezd[2]
    cz = ez[0] * ezd[1] - ez[1] * ezd[0]
    if dot > -0.9999:
        rw = 1.0 + dot
        n = math.sqrt(rw * rw + cx * cx + cy * cy + cz * cz)
        red = _qmul(rw / n, cx / n, cy / n, cz / n, q0, q1, q2, q3)
    else:  # thrust axis reversed: no unique reduced attitude, use the full one
        red = (qd0, qd1, qd2, qd3)
    # yaw part of the full setpoint relative to the reduced one, scaled by the yaw weight
    mix = _qmul(red[0], -red[1], -red[2], -red[3], qd0, qd1, qd2, qd3)
    mw, mz = mix[0], mix[3]
    if mw < 0.0:
        mw, mz = -mw, -mz
    yaw_w = gn[G_YAW_W]
    mw = math.cos(yaw_w * math.acos(_clamp(mw, -1.0, 1.0)))
    mz = math.sin(yaw_w * math.asin(_clamp(mz, -1.0, 1.0)))
    qd = _qmul(red[0], red[1], red[2], red[3], mw, 0.0, 0.0, mz)
    qe = _qmul(q0, -q1, -q2, -q3, qd[0], qd[1], qd[2], qd[3])
    sgn = 2.0 if qe[0] >= 0.0 else -2.0
    rx = gn[G_KATT_R] * sgn * qe[1]
    ry = gn[G_KATT_P] * sgn * qe[2]
    rz = gn[G_KATT_Y] * sgn * qe[3]
    # yaw-rate feed-forward: world z expressed in the body frame
    if yawrate_ff != 0.0:
        rx += yawrate_ff * 2.0 * (q1 * q3 - q0 * q2)
        ry += yawrate_ff * 2.0 * (q2 * q3 + q0 * q1)
        rz += yawrate_ff * (1.0 - 2.0 * (q1 * q1 + q2 * q2))
    cs[C_RATE_SP] = _clamp(rx, -gn[G_RATE_MAX], gn[G_RATE_MAX])
    cs[C_RATE_SP + 1] = _clamp(ry, -gn[G_RATE_MAX + 1], gn[G_RATE_MAX + 1])
    cs[C_RATE_SP + 2] = _clamp(rz, -gn[G_RATE_MAX + 2], gn[G_RATE_MAX + 2])


@njit(cache=True)
def rate_control(x, gn, cs, dt):
    """Body-rate PID (derivative on measurement) -> torque in N m."""
    for i in range(3):
        w = x[X_OMEGA + i]
        err = cs[C_RATE_SP + i] - w
        w_dot = (w - cs[C_RATE_PREV + i]) / dt
        cs[C_RATE_PREV + i] = w
        u = gn[G_RATE_P + i] * err + cs[C_RATE_INT + i] - gn[G_RATE_D + i] * w_dot
        cs[C_TORQUE + i] = gn[G_TSCALE + i] * u
        saturated = cs[C_SAT_Y] > 0.0 if i == 2 else cs[C_SAT_RP] > 0.0
        if not saturated:
            # as PX4: integrate less while the error is large (no wind-up in big manoeuvres)
            i_factor = err / I_FACTOR_RATE
            i_factor = max(0.0, 1.0 - i_factor * i_factor)
            lim = gn[G_RATE_ILIM + i]
            cs[C_RATE_INT + i] = _clamp(
                cs[C_RATE_INT + i] + i_factor * gn[G_RATE_I + i] * err * dt, -lim, lim
            )


@njit(cache=True)
def allocate(f, tx, ty, tz, a, gn, cs, w_out):
    """Rotor thrusts from collective and torques with sequential desaturation.

    1. Collective + roll/pitch. If some rotor goes above T_max, lower the collective
       (roll/pitch exact, thrust gives way: the headroom rule); what still does not fit
       (a rotor below T_min) is taken from roll/pitch. With MC_AIRMODE 1 the collective
       may also rise, and roll/pitch are scaled only when their spread alone exceeds
       the rotor range.
    2. Yaw on top, scaled down as far as needed to stay within [T_min, T_max + 15 %],
       then the collective is lowered to bring every rotor back under T_max
       (PX4's MINIMUM_YAW_MARGIN: some yaw authority even at full thrust).
    """
    n = a.shape[0]
    tmin = gn[G_TROT_MIN]
    tmax = gn[G_TROT_MAX]
    t = w_out  # rotor thrusts are worked out in place, then turned into speeds
    lo = -1e300
    hi = 1e300
    rp_max = -1e300
    rp_min = 1e300
    for i in range(n):
        rp = a[i, 1] * tx + a[i, 2] * ty
        t[i] = a[i, 0] * f + rp
        rp_max = max(rp_max, rp / a[i, 0])
        rp_min = min(rp_min, rp / a[i, 0])
        lo = max(lo, (tmin - t[i]) / a[i, 0])
        hi = min(hi, (tmax - t[i]) / a[i, 0])
    sat_rp = 0.0
    if gn[G_AIRMODE] > 0.0:
        # airmode (MC_AIRMODE 1): the collective may rise as well as fall for roll/pitch
        if lo <= hi:
            k = _clamp(0.0, lo, hi)
            for i in range(n):
                t[i] += k * a[i, 0]
        else:
            # a[i,0] is the same for every rotor of a symmetric frame: scale the spread
            a0 = a[0, 0]
            s = (tmax - tmin) / (a0 * (rp_max - rp_min))
            centre = 0.5 * (tmax + tmin) - 0.5 * s * a0 * (rp_max + rp_min)
            for i in range(n):
                t[i] = centre + s * (a[i, 1] * tx + a[i, 2] * ty)
            sat_rp = 1.0
    else:
        # PX4 default (MC_AIRMODE 0): the collective may only be lowered; what still does
        # not fit is taken from roll/pitch, scaled about the (lowered) collective
        k = min(0.0, hi)
        s = 1.0
        for i in range(n):
            base = a[i, 0] * (f + k)
            rp = t[i] - a[i, 0] * f
            v = base + rp
            if v > tmax and rp > 0.0:
                s = min(s, (tmax - base) / rp)
            elif v < tmin and rp < 0.0:
                s = min(s, (tmin - base) / rp)
        s = max(0.0, s)
        for i in range(n):
            base = a[i, 0] * (f + k)
            t[i] = base + s * (t[i] - a[i, 0] * f)
        if s < 1.0:
            sat_rp = 1.0
    # yaw: allowed 15 % above T_max, then the collective is lowered (never raised) to fit
    tmax_y = tmax + YAW_MARGIN * (tmax - tmin)
    s_y = 1.0
    for i in range(n):
        y = a[i, 3] * tz
        if y > 1e-15:
            s_y = min(s_y, (tmax_y - t[i]) / y)
        elif y < -1e-15:
            s_y = min(s_y, (tmin - t[i]) / y)
    s_y = max(0.0, s_y)
    over = 0.0
    for i in range(n):
        t[i] += s_y * a[i, 3] * tz
        over = max(over, (t[i] - tmax) / a[i, 0])
    sat_motor = 0.0
    ct = gn[G_CT]
    for i in range(n):
        ti = _clamp(t[i] - over * a[i, 0], tmin, tmax)
        if ti >= tmax * (1.0 - 1e-9) or ti <= tmin * (1.0 + 1e-9):
            sat_motor = 1.0
        w_out[i] = math.sqrt(ti / ct)
    cs[C_SAT_RP] = sat_rp
    cs[C_SAT_Y] = 1.0 if s_y < 1.0 else 0.0
    cs[C_SAT_MOTOR] = sat_motor
    cs[C_SAT_STEPS] += sat_motor


@njit(cache=True)
def reset_controller(cs):
    for k in (C_VEL_INT, C_RATE_INT):
        for i in range(3):
            cs[k + i] = 0.0
    cs[C_POS_COUNT] = 0.0


@njit(cache=True)
def controller_step_one(x, sp, gn, a, cs, dt, w_out):
    """One control tick for one vehicle: fills w_out with rotor speed commands (rad/s)."""
    kind = int(sp[SP_KIND])
    if kind == KIND_MOTORS:
        w_max = math.sqrt(gn[G_TROT_MAX] / gn[G_CT])
        for i in range(w_out.shape[0]):
            u = sp[SP_MOTORS + i] if i < MAX_SP_MOTORS else 0.0
            if not math.isfinite(u):
                u = 0.0
            w_out[i] = _clamp(u, 0.0, 1.0) * w_max
        reset_controller(cs)
        for i in range(3):
            cs[C_RATE_PREV + i] = x[X_OMEGA + i]
            cs[C_VEL_PREV + i] = x[X_VEL + i]
        return
    if kind == KIND_OFF or kind == KIND_IDLE:
        w_idle = math.sqrt(gn[G_TROT_MIN] / gn[G_CT]) if kind == KIND_IDLE else 0.0
        for i in range(w_out.shape[0]):
            w_out[i] = w_idle
        reset_controller(cs)
        for i in range(3):
            cs[C_RATE_PREV + i] = x[X_OMEGA + i]
            cs[C_VEL_PREV + i] = x[X_VEL + i]
        return
    if kind == KIND_TRAJECTORY:
        if cs[C_POS_COUNT] <= 0.0:
            position_control(x, sp, gn, cs, dt * gn[G_POS_DIV])
            cs[C_POS_COUNT] = gn[G_POS_DIV]
        cs[C_POS_COUNT] -= 1.0
        yr = sp[SP_YAWRATE]
        attitude_control(
            x, cs[C_QSP], cs[C_QSP + 1], cs[C_QSP + 2], cs[C_QSP + 3],
            yr if math.isfinite(yr) else 0.0, gn, cs,
        )
        f = cs[C_FSP]
    else:
        # not under position control: keep the velocity memory fresh for the D term
        cs[C_POS_COUNT] = 0.0
        for i in range(3):
            cs[C_VEL_PREV + i] = x[X_VEL + i]
    if kind == KIND_ATTITUDE:
        attitude_control(
            x, sp[SP_Q], sp[SP_Q + 1], sp[SP_Q + 2], sp[SP_Q + 3], 0.0, gn, cs
        )
        f = sp[SP_THRUST] * gn[G_TROT_MAX] * a.shape[0]
    elif kind == KIND_RATES:
        for i in range(3):
            cs[C_RATE_SP + i] = _clamp(
                sp[SP_RATES + i], -gn[G_RATE_MAX + i], gn[G_RATE_MAX + i]
            )
        f = sp[SP_THRUST] * gn[G_TROT_MAX] * a.shape[0]
    rate_control(x, gn, cs, dt)
    allocate(f, cs[C_TORQUE], cs[C_TORQUE + 1], cs[C_TORQUE + 2], a, gn, cs, w_out)
