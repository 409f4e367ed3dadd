"""Compass disturbances with known truth: a magnet fixed to a turning sensor (issue 22).

The motion is handheld-like turning (yaw rates up to ~1 rad/s, roll/pitch ±0.3 rad) after 5 s
at rest; the field is the Earth's (ENU, north, pointing down) plus, during ``on_s``, a hard-iron
offset of ``fraction`` × |B| in a random sensor-frame direction: a magnet on the sensor, whose
field turns with the body instead of staying in the world. The magnetometer is a calibrated one,
not a perfect one: what a calibration leaves (:data:`MAG_RESIDUE`) and white noise. Seeded and
reproducible.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cf_estimator.core import quaternion as quat

GRAVITY_M_S2 = 9.80665
FIELD_ENU_T = np.array([0.0, 25e-6, -43e-6])  #: Earth field [T], ENU (north, pointing down)
#: What a magnetometer's calibration leaves [1, a fraction of the field]: a symmetric soft-iron
#: and scale error matrix with entries of this σ and a hard-iron offset of this × |B|. An
#: ellipsoid fit leaves 1–2 % of the field; this is the middle of that (headings 0.2–2° off on
#: a turning sensor, seeds 0–3; BROAD's undisturbed trials 1.5° RMS). A sensor without it is
#: perfect in a way no real one is: the yaw floor the covariance reports stands for this residue.
MAG_RESIDUE = 0.015


@dataclass(frozen=True, eq=False)
class CompassCase:
    """One simulated run: sensor-frame samples, the truth and where the magnet is."""

    t_s: np.ndarray  #: (N,) [s]
    gyro_rad_s: np.ndarray  #: (N, 3) [rad/s], sensor frame
    accel_m_s2: np.ndarray  #: (N, 3) [m/s²], sensor frame
    mag_T: np.ndarray  #: (N, 3) [T], sensor frame (magnet included)
    q_true: np.ndarray  #: (N, 4) q_world(ENU)_from_sensor (w, x, y, z)
    magnet_on: np.ndarray  #: (N,) bool: the magnet is on the sensor
    rate_hz: float


def magnet_on_turning_sensor(seed: int, fraction: float, on_s: tuple[float, float] = (20.0, 80.0),
                             duration_s: float = 100.0, rate_hz: float = 100.0,
                             residue: float = MAG_RESIDUE) -> CompassCase:
    """A magnet of ``fraction`` × the Earth field fixed to the sensor during ``on_s`` [s]; the
    magnetometer's calibration residue ``residue`` (:data:`MAG_RESIDUE`; 0: a perfect sensor)
    acts on everything it measures, the magnet included."""
    rng = np.random.default_rng(seed)
    n = int(duration_s * rate_hz)
    t = np.arange(n) / rate_hz
    yaw, roll, pitch = np.zeros(n), np.zeros(n), np.zeros(n)
    moving = np.clip((t - 5.0) / 2.0, 0.0, 1.0)
    for _ in range(3):
        f, ph, amp = rng.uniform(0.05, 0.3), rng.uniform(0, 2 * np.pi), rng.uniform(0.3, 0.8)
        yaw += amp / (2 * np.pi * f) * (np.sin(2 * np.pi * f * t + ph) - np.sin(ph))
        roll += 0.1 * np.sin(2 * np.pi * rng.uniform(0.1, 0.5) * t + rng.uniform(0, 6.3))
        pitch += 0.1 * np.sin(2 * np.pi * rng.uniform(0.1, 0.5) * t + rng.uniform(0, 6.3))
    q = quat.from_euler(roll * moving, pitch * moving, yaw * moving)
    dq = quat.multiply(quat.conjugate(q[:-1]), q[1:])  # body-frame increments
    dq *= np.sign(dq[:, :1])
    w = np.vstack([2.0 * dq[:, 1:] * rate_hz, np.zeros((1, 3))])
    gyro = w + rng.normal(0.0, 0.003, (n, 3))
    inv = quat.conjugate(q)
    accel = quat.rotate(inv, np.array([0.0, 0.0, GRAVITY_M_S2])) + rng.normal(0, 0.03, (n, 3))
    mag = quat.rotate(inv, FIELD_ENU_T) + rng.normal(0.0, 2e-7, (n, 3))
    h = rng.normal(size=3)
    h *= fraction * np.linalg.norm(FIELD_ENU_T) / np.linalg.norm(h)
    on = (t >= on_s[0]) & (t < on_s[1])
    mag[on] += h
    soft = rng.normal(0.0, residue, (3, 3))
    hard = rng.normal(size=3)
    hard *= residue * np.linalg.norm(FIELD_ENU_T) / np.linalg.norm(hard)
    mag = mag @ (np.eye(3) + 0.5 * (soft + soft.T)).T + hard
    return CompassCase(t, gyro, accel, mag, q, on, rate_hz)


def heading_error_deg(q_est: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    """|yaw(q_est) − yaw(q_true)| [deg] per sample, wrapped to [0, 180]."""
    ye, yt = quat.to_euler(q_est)[:, 2], quat.to_euler(q_true)[:, 2]
    return np.degrees(np.abs((ye - yt + np.pi) % (2 * np.pi) - np.pi))
