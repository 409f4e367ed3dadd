"""Unit sanity checks of whole input arrays for :func:`cf_estimator.core.batch.estimate`.

The same checks the message pipeline makes (``cf_estimator/pipeline/checks.py``, same
thresholds, on the norm of the mean vector): an accelerometer whose mean is ≈ 1 is in g, not
m/s²; one far below g has gravity removed; a gyro beyond 35 rad/s (~2000 °/s) is probably in
deg/s. Nothing is rejected (the filter uses directions, the data stay usable), but the user is
told once per call site
through :mod:`warnings` (category :class:`InputUnitsWarning`, shown once per line of the
caller by Python's default filter).
"""

from __future__ import annotations

import warnings

import numpy as np

#: Finite samples averaged before judging the accelerometer's units (as the pipeline).
ACCEL_CHECK_SAMPLES = 200
#: |gyro| above this [rad/s] suggests deg/s (as the pipeline's GYRO_IMPLAUSIBLE_RAD_S).
GYRO_IMPLAUSIBLE_RAD_S = 35.0


class InputUnitsWarning(UserWarning):
    """The input arrays look like the wrong units (g instead of m/s², deg/s instead of rad/s)."""


def unit_problems(gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray, gravity_m_s2: float
                  ) -> list[str]:
    """Messages for suspicious units of (N, 3) gyro [rad/s] and accelerometer [m/s²] arrays."""
    out: list[str] = []
    acc = np.asarray(accel_m_s2, dtype=float)
    first = acc[np.all(np.isfinite(acc), axis=1)][:ACCEL_CHECK_SAMPLES]
    if first.shape[0]:
        # |mean a|, not mean |a|: vibration adds to every |a| (13 m/s^2 on a quadrotor) but
        # averages out of the vector (as the pipeline's check)
        mean = float(np.linalg.norm(np.mean(first, axis=0)))
        if abs(mean - 1.0) < 0.3:
            out.append(f"accel_m_s2 norm averages {mean:.3g}: looks like units of g; pass m/s^2 "
                       f"(multiply by {gravity_m_s2:g})")
        elif mean < 0.25 * gravity_m_s2:
            out.append(f"accel_m_s2 norm averages {mean:.3g} m/s^2, far below g: gravity seems "
                       "removed; a tilt estimate needs the raw specific force")
        elif abs(mean / gravity_m_s2 - 1.0) > 0.3:
            out.append(f"accel_m_s2 norm averages {mean:.3g} m/s^2, far from g = "
                       f"{gravity_m_s2:g}: check the accelerometer scale")
    gyro = np.asarray(gyro_rad_s, dtype=float)
    finite = gyro[np.all(np.isfinite(gyro), axis=1)]
    if finite.size:
        peak = float(np.max(np.linalg.norm(finite, axis=1)))
        if peak > GYRO_IMPLAUSIBLE_RAD_S:
            out.append(f"gyro_rad_s norm reaches {peak:.3g} rad/s (> "
                       f"{GYRO_IMPLAUSIBLE_RAD_S:g}): deg/s? pass rad/s (np.radians)")
    return out


def warn_units(gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray, gravity_m_s2: float,
               stacklevel: int = 3) -> None:
    """Issue one :class:`InputUnitsWarning` per problem :func:`unit_problems` finds."""
    for text in unit_problems(gyro_rad_s, accel_m_s2, gravity_m_s2):
        warnings.warn(text, InputUnitsWarning, stacklevel=stacklevel)
