"""Truth orientation from body rates: the project's integration rule, vectorised.

``q_k = q_{k-1} ⊗ Exp(ω_k·dt_k)`` with ``ω_k`` the body rate [rad/s] sampled at ``t_k`` and
``dt_k = t_k − t_{k-1}`` [s] (docs/ARCHITECTURE.md), evaluated as a parallel prefix scan.
Quaternion algebra comes from :mod:`cf_estimator.core.quaternion`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from cf_estimator.core import quaternion as quat

FloatArray = NDArray[np.float64]


def _mul_cols(p: FloatArray, q: FloatArray) -> FloatArray:
    """Hamilton product of quaternions stored component-first, shape (4, ...)."""
    return np.moveaxis(quat.multiply(np.moveaxis(p, 0, -1), np.moveaxis(q, 0, -1)), -1, 0)


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
    q0 = quat.normalize(np.asarray(q0, dtype=float).reshape(4))
    out = np.empty((n, 4))
    if n == 0:
        return out
    out[0] = q0
    if n == 1:
        return out
    inc = quat.exp(w[1:] * np.diff(t)[:, None]).T  # increment of sample k at column k-1
    out[1:] = _normalize_cols(_mul_cols(q0[:, None], _scan_cols(inc))).T
    return out
