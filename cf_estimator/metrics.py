"""Attitude error metrics of the BROAD benchmark (Laidig et al., Data 6(7), 2021).

Error quaternion in the earth frame q_err = q_est ⊗ q_ref⁻¹; total error 2·acos|w|, heading
error 2·atan|z/w|, inclination error 2·acos√(w² + z²) [rad]; RMSE in degrees. Used by the
benchmarks, the bag replay's reference statistics and the demo.

The inclination error is the angle between the estimated and the true "up" seen in the sensor
frame: for q_err = (w, x, y, z), R_err·e_z has z component 1 − 2(x² + y²) = 2(w² + z²) − 1
= cos(2·acos√(w² + z²)). It is therefore blind to any heading (yaw) offset between the two
world frames: the metric for 6-D estimates and for references whose heading is arbitrary.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from cf_estimator.core import quaternion as quat


def error_quaternion(q_est: ArrayLike, q_ref: ArrayLike) -> np.ndarray:
    """q_err = q_est ⊗ q_ref⁻¹ (earth frame), normalised; inputs normalised first (N, 4)."""
    qe = np.asarray(q_est, dtype=float)
    qr = np.asarray(q_ref, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        qe = qe / np.linalg.norm(qe, axis=-1, keepdims=True)
        qr = qr / np.linalg.norm(qr, axis=-1, keepdims=True)
        out = quat.multiply(qe, quat.conjugate(qr))
        return out / np.linalg.norm(out, axis=-1, keepdims=True)


def error_angles(q_err: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(total, heading, inclination) error angles [rad] of earth-frame error quaternions."""
    q = np.asarray(q_err, dtype=float)
    w, z = q[..., 0], q[..., 3]
    with np.errstate(invalid="ignore", divide="ignore"):
        total = 2.0 * np.arccos(np.clip(np.abs(w), 0.0, 1.0))
        heading = 2.0 * np.arctan(np.abs(z / w))
        incl = 2.0 * np.arccos(np.clip(np.sqrt(w * w + z * z), 0.0, 1.0))
    return total, heading, incl


def _rmse_deg(x: np.ndarray) -> float:
    if x.size == 0 or np.all(np.isnan(x)):
        return float("nan")
    return float(np.degrees(np.sqrt(np.nanmean(x * x))))


def rmse_deg(
    q_est: ArrayLike, q_ref: ArrayLike, movement: ArrayLike | None = None
) -> dict[str, float]:
    """Total/heading/inclination RMSE [deg] over the ``movement`` samples (NaN rows ignored)."""
    total, heading, incl = error_angles(error_quaternion(q_est, q_ref))
    if movement is not None:
        mv = np.asarray(movement, dtype=bool)
        total, heading, incl = total[mv], heading[mv], incl[mv]
    return {
        "total_rmse_deg": _rmse_deg(total),
        "heading_rmse_deg": _rmse_deg(heading),
        "inclination_rmse_deg": _rmse_deg(incl),
    }


def tilt_error_rad(q_est: ArrayLike, q_ref: ArrayLike) -> np.ndarray:
    """Inclination (tilt) error [rad] per sample (the BROAD inclination metric, unsquared)."""
    return error_angles(error_quaternion(q_est, q_ref))[2]


def inclination_error_deg(q_est: ArrayLike, q_ref: ArrayLike) -> np.ndarray:
    """Inclination error [deg] per sample: angle between estimated and true up in the sensor
    frame (NaN where either quaternion is NaN); both q_world_from_sensor, world z up."""
    return np.degrees(tilt_error_rad(q_est, q_ref))


def rms_max(errors: ArrayLike, mask: ArrayLike | None = None) -> tuple[float, float, int]:
    """(RMS, max, count) of ``errors`` over ``mask`` (all samples if None); NaN errors inside
    the mask propagate (a missing estimate is not silently skipped); (nan, nan, 0) if empty."""
    e = np.asarray(errors, dtype=float).reshape(-1)
    if mask is not None:
        e = e[np.asarray(mask, dtype=bool).reshape(-1)]
    if e.size == 0:
        return float("nan"), float("nan"), 0
    return float(np.sqrt(np.mean(e * e))), float(np.max(e)), int(e.size)


# -- is the reported covariance honest? (bench/consistency.py pools it per family) ---------
#: Samples are scored from this long after the first one [s] (as the benchmarks' RMS).
SETTLE_S = 10.0
#: e > this many σ counts as beyond.
SIGMAS = 2.0
#: A consistent Gaussian's share beyond 2σ, as printed: tilt (2-D, σ² = cov[0] + cov[4]) e⁻⁴,
#: heading (1-D) 4.6 %, and the tilt's share beyond twice its per-axis σ e⁻².
CONSISTENT_BEYOND = {"tilt": "1.8 %", "heading": "4.6 %", "tilt per axis": "13.5 %"}


def consistency(err_rad: np.ndarray, var_rad2: np.ndarray) -> dict[str, float]:
    """``{samples, rms_deg, median_sigma_deg, beyond_2sigma_pct, beyond_2sigma_axis_pct,
    mean_ratio}`` of errors [rad]
    against reported variances [rad²] (non-finite pairs left out; NaN figures when empty)."""
    e = np.asarray(err_rad, dtype=float).reshape(-1)
    v = np.asarray(var_rad2, dtype=float).reshape(-1)
    ok = np.isfinite(e) & np.isfinite(v) & (v > 0.0)
    e, v = e[ok], v[ok]
    if e.size == 0:
        nan = math.nan
        return {"samples": 0, "rms_deg": nan, "median_sigma_deg": nan, "beyond_2sigma_pct": nan,
                "beyond_2sigma_axis_pct": nan, "mean_ratio": nan}
    z = e * e / v
    return {"samples": int(e.size), "rms_deg": math.degrees(math.sqrt(float(np.mean(e * e)))),
            "median_sigma_deg": math.degrees(math.sqrt(float(np.median(v)))),
            "beyond_2sigma_pct": 100.0 * float(np.mean(z > SIGMAS * SIGMAS)),
            "beyond_2sigma_axis_pct": 100.0 * float(np.mean(z > SIGMAS * SIGMAS / 2.0)),
            "mean_ratio": float(np.mean(z))}
