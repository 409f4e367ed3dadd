"""Quaternion utilities (NumPy, vectorised over leading axes).

Quaternions are ``(w, x, y, z)``; a quaternion ``q_a_from_b`` maps vectors from frame b to
frame a: ``v_a = q ⊗ v_b ⊗ q*``. Euler angles are aerospace ZYX: ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]

#: q_ned_from_enu: x_ned = y_enu, y_ned = x_enu, z_ned = -z_enu (180° about (1, 1, 0)/√2).
Q_NED_FROM_ENU: Array = np.array([0.0, np.sqrt(0.5), np.sqrt(0.5), 0.0])


def multiply(a: ArrayLike, b: ArrayLike) -> Array:
    """Hamilton product a ⊗ b (broadcasting over leading axes)."""
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def conjugate(q: ArrayLike) -> Array:
    """Conjugate (the inverse of a unit quaternion)."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def normalize(q: ArrayLike) -> Array:
    """Unit quaternion with non-negative w (one representative of ±q)."""
    q = np.asarray(q, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def rotate(q: ArrayLike, v: ArrayLike) -> Array:
    """Rotate vectors v by q (v_a = q ⊗ v_b ⊗ q*)."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * _cross(u, v)
    return v + w * t + _cross(u, t)


def _cross(a: Array, b: Array) -> Array:
    """a × b over the last axis (3): np.cross's arithmetic (a1·b2 − a2·b1, ...), without its
    axis handling (small arrays in the alignment's fit call it thousands of times)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a1 * b2 - a2 * b1
    out[..., 1] = a2 * b0 - a0 * b2
    out[..., 2] = a0 * b1 - a1 * b0
    return out


def to_matrix(q: ArrayLike) -> Array:
    """Rotation matrix R (…, 3, 3) with v_a = R·v_b."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    r = np.empty(q.shape[:-1] + (3, 3))
    r[..., 0, 0] = 1 - 2 * (y * y + z * z)
    r[..., 0, 1] = 2 * (x * y - w * z)
    r[..., 0, 2] = 2 * (x * z + w * y)
    r[..., 1, 0] = 2 * (x * y + w * z)
    r[..., 1, 1] = 1 - 2 * (x * x + z * z)
    r[..., 1, 2] = 2 * (y * z - w * x)
    r[..., 2, 0] = 2 * (x * z - w * y)
    r[..., 2, 1] = 2 * (y * z + w * x)
    r[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return r


def from_matrix(r: ArrayLike) -> Array:
    """Unit quaternion (w ≥ 0) of a rotation matrix (single 3×3; robust Shepperd method)."""
    m = np.asarray(r, dtype=float)
    tr = np.trace(m)
    if tr > 0.0:
        s = 2.0 * np.sqrt(tr + 1.0)
        q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
    elif m[0, 0] > m[1, 1] and m[0, 0] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
    elif m[1, 1] > m[2, 2]:
        s = 2.0 * np.sqrt(1.0 + m[1, 1] - m[0, 0] - m[2, 2])
        q = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
    else:
        s = 2.0 * np.sqrt(1.0 + m[2, 2] - m[0, 0] - m[1, 1])
        q = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    return normalize(np.array(q))


def exp(rotvec: ArrayLike) -> Array:
    """Unit quaternion of a rotation vector [rad] (exact exponential map)."""
    v = np.asarray(rotvec, dtype=float)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    small = angle < 1e-8
    safe = np.where(small, 1.0, angle)
    k = np.where(small, 0.5 - angle**2 / 48.0, np.sin(0.5 * safe) / safe)
    return np.concatenate([np.cos(0.5 * angle), k * v], axis=-1)


def log(q: ArrayLike) -> Array:
    """Rotation vector [rad] of a unit quaternion (angle in [0, π])."""
    q = normalize(q)
    w = np.clip(q[..., :1], -1.0, 1.0)
    u = q[..., 1:]
    s = np.linalg.norm(u, axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(s, w)
    k = np.where(s < 1e-12, 2.0, angle / np.where(s < 1e-12, 1.0, s))
    return k * u


def angle_between(a: ArrayLike, b: ArrayLike) -> Array:
    """Rotation angle [rad] of a ⊗ b* (the attitude difference), in [0, π]."""
    d = multiply(a, conjugate(b))
    return 2.0 * np.arccos(np.clip(np.abs(d[..., 0]), 0.0, 1.0))


def from_euler(roll: ArrayLike, pitch: ArrayLike, yaw: ArrayLike) -> Array:
    """q_world_from_body of aerospace ZYX Euler angles [rad]."""
    cr, sr = np.cos(np.asarray(roll) / 2), np.sin(np.asarray(roll) / 2)
    cp, sp = np.cos(np.asarray(pitch) / 2), np.sin(np.asarray(pitch) / 2)
    cy, sy = np.cos(np.asarray(yaw) / 2), np.sin(np.asarray(yaw) / 2)
    return np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=-1,
    )


def to_euler(q: ArrayLike) -> Array:
    """Aerospace ZYX Euler angles (roll, pitch, yaw) [rad] of q_world_from_body.

    roll, yaw in (−π, π], pitch in [−π/2, π/2]; at pitch = ±π/2 (gimbal lock) roll absorbs
    the remaining rotation and yaw is kept continuous with the formula's branch.
    """
    q = np.asarray(q, dtype=float)
    w, x, y, z = np.moveaxis(q, -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack([roll, pitch, yaw], axis=-1)


def enu_to_ned(q_enu_from_body: ArrayLike) -> Array:
    """q_ned_from_body of q_enu_from_body (the body frame is unchanged)."""
    return multiply(Q_NED_FROM_ENU, q_enu_from_body)


def ned_to_enu(q_ned_from_body: ArrayLike) -> Array:
    """q_enu_from_body of q_ned_from_body (the body frame is unchanged)."""
    return multiply(conjugate(Q_NED_FROM_ENU), q_ned_from_body)
