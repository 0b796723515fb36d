"""Rotation helpers (numpy only), the one home for every quaternion and frame computation.

Quaternions are (w, x, y, z) as in MuJoCo; matrices are 3x3 with the frame's axes as columns.
"""

from __future__ import annotations

import math

import numpy as np


def quat_to_mat(q) -> np.ndarray:
    """Rotation matrix of a (not necessarily unit) quaternion."""
    w, x, y, z = np.asarray(q, dtype=float) / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def mat_to_quat(m) -> np.ndarray:
    """Unit quaternion of a rotation matrix, with w >= 0."""
    m = np.asarray(m, dtype=float)
    t = np.trace(m)
    if t > 0:
        s = np.sqrt(t + 1.0) * 2
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2]) * 2
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2]) * 2
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1]) * 2
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q = np.asarray(q)
    q /= np.linalg.norm(q)
    return -q if q[0] < 0 else q


def mat9_to_quat(m9, out: np.ndarray | None = None) -> np.ndarray:
    """`mat_to_quat` of a row-major 9-vector (MuJoCo's ``xmat`` rows), in plain float arithmetic.

    The same operations in the same order as `mat_to_quat` (``np.trace`` sums the diagonal left to
    right; ``np.linalg.norm`` of a vector is ``sqrt(q.dot(q))``), so the same numbers to the bit,
    several times faster: for per-step observations. ``out``: a 4-array to write the quaternion
    into (returned), instead of a new one.
    """
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m9.tolist()
    t = m00 + m11 + m22
    if t > 0:
        s = math.sqrt(t + 1.0) * 2
        q = [0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s]
    elif m00 > m11 and m00 > m22:
        s = math.sqrt(1.0 + m00 - m11 - m22) * 2
        q = [(m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s]
    elif m11 > m22:
        s = math.sqrt(1.0 + m11 - m00 - m22) * 2
        q = [(m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s]
    else:
        s = math.sqrt(1.0 + m22 - m00 - m11) * 2
        q = [(m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s]
    if out is None:
        q = np.array(q)
        q /= math.sqrt(q.dot(q))
        return -q if q[0] < 0 else q
    out[:] = q
    out /= math.sqrt(out.dot(out))
    if out[0] < 0:
        np.negative(out, out=out)
    return out


def quat_mul(a, b) -> np.ndarray:
    """Hamilton product a * b (rotate by b, then by a)."""
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def axis_angle_quat(axis, angle: float) -> np.ndarray:
    """Quaternion of a rotation by ``angle`` (rad) about ``axis``."""
    axis = np.asarray(axis, float)
    axis = axis / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


def yaw_quat(angle: float) -> np.ndarray:
    """Quaternion of a rotation by ``angle`` (rad) about the world z axis."""
    return np.array([math.cos(angle / 2), 0.0, 0.0, math.sin(angle / 2)])


def turn_about_z(quat, angle: float) -> np.ndarray:
    """``quat`` turned by ``angle`` about the world z axis (unit)."""
    q = quat_mul(yaw_quat(angle), quat)
    return q / np.linalg.norm(q)


def quat_axis_z(q) -> np.ndarray:
    """The rotated frame's z axis in world coordinates."""
    return quat_to_mat(q)[:, 2]


def look_rotation(forward) -> np.ndarray:
    """Camera frame looking along ``forward`` with z up: columns image-right, image-up, backward
    (MuJoCo cameras look along their -z). Straight up or down: image-right is -y."""
    f = np.asarray(forward, float)
    f = f / np.linalg.norm(f)
    right = np.cross(f, [0.0, 0.0, 1.0])
    if np.linalg.norm(right) < 1e-9:
        right = np.array([0.0, -1.0, 0.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, f)
    return np.stack([right, up, -f], axis=1)
