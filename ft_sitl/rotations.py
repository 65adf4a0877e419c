"""Quaternion and rotation-matrix helpers for plain-Python (not numba) code.

Quaternions are (w, x, y, z) arrays; a quaternion q_a_b rotates b-frame vectors into
frame a. The numba kernels' own helpers are :mod:`ft_sitl.physics.quaternion`; these are
the one copy of each conversion for the rest (frames, the bus codec, the camera, the
bridge's sensors). Some feed flights (the camera's pose, hence the planners' depth
frames): their floating-point operations are kept exactly as they were.
"""

from __future__ import annotations

import math

import numpy as np


def qmul(a, b) -> np.ndarray:
    """The Hamilton product a * b."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ]
    )


def matrix_from_quat(q, *, normalise: bool = True, name: str = "quaternion") -> np.ndarray:
    """The rotation matrix of q. ``normalise``: divide q by its norm first (ValueError,
    naming it ``name``, for a wrong shape or a zero or non-finite q); without it q must
    already be a unit quaternion."""
    q = np.asarray(q, dtype=np.float64)
    if q.shape != (4,):
        raise ValueError(f"{name} must have shape (4,), got {q.shape}")
    if normalise:
        n = float(np.sqrt(q @ q))
        if not (n > 0.0 and math.isfinite(n)):
            raise ValueError(f"{name} must be a finite non-zero quaternion, got {q}")
        q = q / n
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ])


def quat_from_matrix(r) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix, w >= 0 (Shepperd's method)."""
    m = np.asarray(r, dtype=np.float64)
    tr = m[0, 0] + m[1, 1] + m[2, 2]
    if tr > 0.0:
        s = 2.0 * math.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * math.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.array(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0.0 else q
