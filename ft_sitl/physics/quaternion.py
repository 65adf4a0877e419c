"""Quaternion helpers (Hamilton convention, scalar first: w, x, y, z).

``q_world_body`` rotates body-frame vectors into the world frame. Every function is
compiled with numba so the physics and controller kernels call them directly; they are
also plain callables from Python.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def qmul(a, b):
    """Hamilton product a * b."""
    out = np.empty(4)
    out[0] = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3]
    out[1] = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2]
    out[2] = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1]
    out[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0]
    return out


@njit(cache=True, inline="always")
def qconj(q):
    out = np.empty(4)
    out[0] = q[0]
    out[1] = -q[1]
    out[2] = -q[2]
    out[3] = -q[3]
    return out


@njit(cache=True, inline="always")
def qnormalize(q):
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    out = np.empty(4)
    for i in range(4):
        out[i] = q[i] / n
    return out


@njit(cache=True, inline="always")
def qrotate(q, v):
    """Rotate vector v by q (body -> world for q_world_body)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    # v + 2 w (r x v) + 2 r x (r x v), r = (x, y, z)
    cx = y * v[2] - z * v[1]
    cy = z * v[0] - x * v[2]
    cz = x * v[1] - y * v[0]
    out = np.empty(3)
    out[0] = v[0] + 2.0 * (w * cx + y * cz - z * cy)
    out[1] = v[1] + 2.0 * (w * cy + z * cx - x * cz)
    out[2] = v[2] + 2.0 * (w * cz + x * cy - y * cx)
    return out


@njit(cache=True, inline="always")
def qrotate_inv(q, v):
    """Rotate vector v by the inverse of q (world -> body for q_world_body)."""
    return qrotate(qconj(q), v)


@njit(cache=True)
def qfrom_rotmat(r):
    """Quaternion from a proper rotation matrix (columns = body axes in world)."""
    tr = r[0, 0] + r[1, 1] + r[2, 2]
    q = np.empty(4)
    if tr > 0.0:
        s = math.sqrt(tr + 1.0) * 2.0
        q[0] = 0.25 * s
        q[1] = (r[2, 1] - r[1, 2]) / s
        q[2] = (r[0, 2] - r[2, 0]) / s
        q[3] = (r[1, 0] - r[0, 1]) / s
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        s = math.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2.0
        q[0] = (r[2, 1] - r[1, 2]) / s
        q[1] = 0.25 * s
        q[2] = (r[0, 1] + r[1, 0]) / s
        q[3] = (r[0, 2] + r[2, 0]) / s
    elif r[1, 1] > r[2, 2]:
        s = math.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2.0
        q[0] = (r[0, 2] - r[2, 0]) / s
        q[1] = (r[0, 1] + r[1, 0]) / s
        q[2] = 0.25 * s
        q[3] = (r[1, 2] + r[2, 1]) / s
    else:
        s = math.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2.0
        q[0] = (r[1, 0] - r[0, 1]) / s
        q[1] = (r[0, 2] + r[2, 0]) / s
        q[2] = (r[1, 2] + r[2, 1]) / s
        q[3] = 0.25 * s
    if q[0] < 0.0:
        for i in range(4):
            q[i] = -q[i]
    return qnormalize(q)


@njit(cache=True)
def qfrom_axis_angle(axis, angle):
    n = math.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
    q = np.empty(4)
    h = 0.5 * angle
    s = math.sin(h) / n
    q[0] = math.cos(h)
    q[1] = axis[0] * s
    q[2] = axis[1] * s
    q[3] = axis[2] * s
    return q


@njit(cache=True)
def qfrom_euler(roll, pitch, yaw):
    """Quaternion from intrinsic Z-Y-X (yaw, pitch, roll) Euler angles, radians."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    q = np.empty(4)
    q[0] = cr * cp * cy + sr * sp * sy
    q[1] = sr * cp * cy - cr * sp * sy
    q[2] = cr * sp * cy + sr * cp * sy
    q[3] = cr * cp * sy - sr * sp * cy
    return q


@njit(cache=True)
def qto_euler(q):
    """(roll, pitch, yaw) in radians from a unit quaternion (Z-Y-X convention)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    roll = math.atan2(2.0 * (w * x + y * z), 1.0 - 2.0 * (x * x + y * y))
    s = 2.0 * (w * y - z * x)
    s = min(1.0, max(-1.0, s))
    pitch = math.asin(s)
    yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
    out = np.empty(3)
    out[0] = roll
    out[1] = pitch
    out[2] = yaw
    return out


@njit(cache=True)
def tilt_angle(q):
    """Angle (rad) between the body z axis and the world z axis."""
    c = 1.0 - 2.0 * (q[1] * q[1] + q[2] * q[2])
    return math.acos(min(1.0, max(-1.0, c)))
