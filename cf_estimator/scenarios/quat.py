"""Vectorised quaternion helpers for the simulator (NumPy, ``(w, x, y, z)`` order).

Conventions (docs/ARCHITECTURE.md): quaternions are ``q_world_from_body`` (sensor = body here),
``v_world = q ⊗ v_body ⊗ q*``; integration over a sample is ``q_k = q_{k-1} ⊗ Exp(ω_k·dt_k)``
with ``ω_k`` the body rate [rad/s] sampled at ``t_k`` and ``dt_k = t_k − t_{k-1}`` [s].
All functions broadcast over leading axes.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


def quat_mul(p: ArrayLike, q: ArrayLike) -> FloatArray:
    """Hamilton product ``p ⊗ q`` of (..., 4) wxyz quaternions."""
    p = np.asarray(p, dtype=float)
    q = np.asarray(q, dtype=float)
    pw, px, py, pz = np.moveaxis(p, -1, 0)
    qw, qx, qy, qz = np.moveaxis(q, -1, 0)
    return np.stack(
        (
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        ),
        axis=-1,
    )


def quat_conj(q: ArrayLike) -> FloatArray:
    """Conjugate (inverse for unit quaternions) of (..., 4) wxyz quaternions."""
    q = np.asarray(q, dtype=float)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_normalize(q: ArrayLike) -> FloatArray:
    """Unit quaternion(s) of the same direction (..., 4)."""
    q = np.asarray(q, dtype=float)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def quat_exp(rotvec: ArrayLike) -> FloatArray:
    """``Exp(v)``: unit quaternion (..., 4) of the rotation vector ``v`` (..., 3) [rad].

    ``Exp(v) = (cos(|v|/2), sin(|v|/2)·v/|v|)``; a Taylor series is used for |v| < 1e-4 rad.
    """
    v = np.asarray(rotvec, dtype=float)
    angle = np.linalg.norm(v, axis=-1, keepdims=True)
    half = 0.5 * angle
    small = angle < 1e-4
    safe = np.where(small, 1.0, angle)
    k = np.where(small, 0.5 - angle**2 / 48.0, np.sin(half) / safe)
    return np.concatenate((np.cos(half), k * v), axis=-1)


def quat_to_matrix(q: ArrayLike) -> FloatArray:
    """Rotation matrices (..., 3, 3) ``R_world_from_body`` of unit quaternions (..., 4)."""
    q = np.asarray(q, dtype=float)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        (
            np.stack((1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)), -1),
            np.stack((2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)), -1),
            np.stack((2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)), -1),
        ),
        axis=-2,
    )


def rotate(q: ArrayLike, v: ArrayLike) -> FloatArray:
    """``q ⊗ v ⊗ q*``: body-frame vectors (..., 3) expressed in the world frame."""
    return np.einsum("...ij,...j->...i", quat_to_matrix(q), np.asarray(v, dtype=float))


def rotate_inverse(q: ArrayLike, v: ArrayLike) -> FloatArray:
    """``q* ⊗ v ⊗ q``: world-frame vectors (..., 3) expressed in the body frame (Rᵀ·v)."""
    return np.einsum("...ji,...j->...i", quat_to_matrix(q), np.asarray(v, dtype=float))


def quat_from_euler_zyx(
    roll_rad: ArrayLike, pitch_rad: ArrayLike, yaw_rad: ArrayLike
) -> FloatArray:
    """Quaternion(s) of aerospace ZYX Euler angles: ``R = Rz(yaw)·Ry(pitch)·Rx(roll)`` [rad]."""
    hr = 0.5 * np.asarray(roll_rad, dtype=float)
    hp = 0.5 * np.asarray(pitch_rad, dtype=float)
    hy = 0.5 * np.asarray(yaw_rad, dtype=float)
    cr, sr, cp, sp, cy, sy = np.cos(hr), np.sin(hr), np.cos(hp), np.sin(hp), np.cos(hy), np.sin(hy)
    return np.stack(
        (
            cy * cp * cr + sy * sp * sr,
            cy * cp * sr - sy * sp * cr,
            cy * sp * cr + sy * cp * sr,
            sy * cp * cr - cy * sp * sr,
        ),
        axis=-1,
    )


def euler_zyx_from_quat(q: ArrayLike) -> FloatArray:
    """Aerospace ZYX Euler angles (..., 3) = (roll, pitch, yaw) [rad] of unit quaternions.

    Roll and yaw in (−π, π], pitch in [−π/2, π/2] (wrapped angles; no unwrapping).
    """
    q = np.asarray(q, dtype=float)
    w, x, y, z = np.moveaxis(q, -1, 0)
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - x * z), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.stack((roll, pitch, yaw), axis=-1)


def _mul_cols(p: FloatArray, q: FloatArray) -> FloatArray:
    """Hamilton product of quaternions stored component-first, shape (4, ...)."""
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return np.stack(
        (
            pw * qw - px * qx - py * qy - pz * qz,
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
        )
    )


def _normalize_cols(q: FloatArray) -> FloatArray:
    return q / np.sqrt(np.einsum("i...,i...->...", q, q))


_SCAN_BLOCK = 256


def _scan_cols(q: FloatArray) -> FloatArray:
    """Inclusive ordered product scan of (4, m) quaternions: out[i] = q[0] ⊗ … ⊗ q[i].

    Hillis-Steele scan inside blocks, recursion on the block totals, then one product per element
    to apply each block's prefix; renormalised at every level.
    """
    m = q.shape[1]
    b = min(_SCAN_BLOCK, m)
    nb = -(-m // b)
    acc = np.zeros((4, nb * b))
    acc[0] = 1.0  # identity padding
    acc[:, :m] = q
    acc = acc.reshape(4, nb, b)
    shift = 1
    while shift < b:
        # acc[i] <- acc[i-shift] ⊗ acc[i] (the earlier factor stays on the left)
        acc[:, :, shift:] = _normalize_cols(_mul_cols(acc[:, :, :-shift], acc[:, :, shift:]))
        shift *= 2
    if nb > 1:
        before = _scan_cols(acc[:, :-1, -1])  # product of all complete blocks before block j+1
        acc[:, 1:, :] = _normalize_cols(_mul_cols(before[:, :, None], acc[:, 1:, :]))
    return acc.reshape(4, -1)[:, :m]


def integrate_body_rates(q0: ArrayLike, t_s: ArrayLike, gyro_rad_s: ArrayLike) -> FloatArray:
    """Orientation history (N, 4) from body rates by the project rule.

    ``q_0 = q0`` and ``q_k = q_{k-1} ⊗ Exp(ω_k·dt_k)`` with ``dt_k = t_k − t_{k-1}`` [s] and
    ``ω_k`` = ``gyro_rad_s[k]`` [rad/s, body frame] (``gyro_rad_s[0]`` is not used). The ordered
    product is evaluated as a blocked parallel prefix scan (vectorised Hamilton products,
    renormalised at every level), which equals the sequential loop to rounding (~1e-15).
    """
    t = np.asarray(t_s, dtype=float)
    w = np.asarray(gyro_rad_s, dtype=float)
    n = t.shape[0]
    if w.shape != (n, 3):
        raise ValueError(f"gyro_rad_s must have shape ({n}, 3), got {w.shape}")
    q0 = quat_normalize(np.asarray(q0, dtype=float).reshape(4))
    out = np.empty((n, 4))
    if n == 0:
        return out
    out[0] = q0
    if n == 1:
        return out
    inc = quat_exp(w[1:] * np.diff(t)[:, None]).T  # increment of sample k at column k-1
    out[1:] = _normalize_cols(_mul_cols(q0[:, None], _scan_cols(inc))).T
    return out
