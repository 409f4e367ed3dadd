"""Simulated magnetometer recordings with a known calibration (tests, docs, the report).

:func:`tumble` turns a sensor about a smooth random angular velocity (every orientation when
``max_tilt_rad`` is None; a vehicle's yaw turns with tilts bounded by it otherwise) and returns
what its IMU and a distorted magnetometer measure: ``m_raw = A · (Rᵀ b_world) + h + noise``
(sensor frame, Tesla), with the soft iron ``A`` and hard iron ``h`` given.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cf_estimator.core import quaternion as quat

#: The field of the test site [T], ENU: 20 uT north, 45 uT down (a dip of about 66 deg).
FIELD_ENU_T = np.array([0.0, 20e-6, -45e-6])
GRAVITY_M_S2 = 9.80665


@dataclass
class Tumble:
    """``t_s`` (N,), ``q_world_from_sensor`` (N, 4) w,x,y,z ENU, ``gyro_rad_s``, ``accel_m_s2``,
    ``mag_true_t`` (undistorted) and ``mag_raw_t`` (distorted, noisy) (N, 3), sensor frame."""

    t_s: np.ndarray
    q_world_from_sensor: np.ndarray
    gyro_rad_s: np.ndarray
    accel_m_s2: np.ndarray
    mag_true_t: np.ndarray
    mag_raw_t: np.ndarray


def tumble(duration_s: float = 60.0, rate_hz: float = 100.0, *, seed: int = 0,
           max_tilt_rad: float | None = None, hard_iron_t: np.ndarray | None = None,
           soft_iron: np.ndarray | None = None, noise_t: float = 0.2e-6,
           rate_rad_s: float = 1.0) -> Tumble:
    """A recording of ``duration_s`` at ``rate_hz`` (see the module docstring). ``rate_rad_s``:
    the typical angular rate; ``max_tilt_rad``: roll and pitch bounded (a flight), None: free."""
    rng = np.random.default_rng(seed)
    n = int(round(duration_s * rate_hz))
    dt = 1.0 / rate_hz
    t = np.arange(n) * dt
    # smooth random angular velocity: white noise through two first-order lags (~2 s)
    w = rng.normal(size=(n, 3))
    a = dt / 2.0
    for _ in range(2):
        for k in range(1, n):
            w[k] = w[k - 1] + a * (w[k] - w[k - 1])
    w *= rate_rad_s / np.sqrt(np.mean(np.sum(w * w, axis=1)))
    if max_tilt_rad is not None:  # a vehicle: yaw free, roll and pitch a bounded oscillation
        yaw = np.cumsum(w[:, 2]) * dt + rng.uniform(0, 2 * np.pi)
        ph = rng.uniform(0, 2 * np.pi, 2)
        roll = max_tilt_rad * np.sin(2 * np.pi * t / 7.0 + ph[0])
        pitch = max_tilt_rad * np.sin(2 * np.pi * t / 11.0 + ph[1])
        q = quat.from_euler(roll, pitch, yaw)
        dq = quat.multiply(quat.conjugate(q[:-1]), q[1:])
        gyro = np.vstack([2.0 * dq[:, 1:] / dt, 2.0 * dq[-1:, 1:] / dt])
    else:
        q = np.empty((n, 4))
        q[0] = quat.exp(rng.normal(size=3))
        step = quat.exp(w * dt)
        for k in range(1, n):
            q[k] = quat.multiply(q[k - 1], step[k - 1])
            q[k] /= np.linalg.norm(q[k])
        gyro = w
    inv = quat.conjugate(q)
    accel = quat.rotate(inv, np.array([0.0, 0.0, GRAVITY_M_S2]))
    m_true = quat.rotate(inv, FIELD_ENU_T)
    a_soft = np.eye(3) if soft_iron is None else np.asarray(soft_iron, dtype=float)
    h = np.zeros(3) if hard_iron_t is None else np.asarray(hard_iron_t, dtype=float)
    m_raw = m_true @ a_soft.T + h + rng.normal(scale=noise_t, size=(n, 3))
    return Tumble(t, q, np.asarray(gyro), accel, m_true, m_raw)
