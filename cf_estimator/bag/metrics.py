"""Scoring a replay against a reference: reference messages as quaternions, the estimate
interpolated to the reference stamps, error angles (roll, pitch, yaw, inclination, heading
[rad]) and their statistics [deg], the covariance's consistency with the errors."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from cf_estimator import metrics
from cf_estimator.bag import types as bagtypes
from cf_estimator.core import quaternion as quat

#: Largest gap [s] between two estimates across which the estimate is interpolated to a
#: reference stamp; reference samples inside longer gaps are not scored.
MAX_INTERPOLATION_GAP_S = 0.5


def reference_quaternion(msgtype: str, msg: Any) -> tuple[float, float, float, float]:
    """(w, x, y, z) of a reference message as recorded (all zero: no orientation)."""
    if msgtype == bagtypes.IMU_TYPE:  # an Imu's orientation; REP-145: covariance[0] = -1 = unknown
        if float(msg.orientation_covariance[0]) < 0.0:
            return 0.0, 0.0, 0.0, 0.0
        q = msg.orientation
    elif msgtype == bagtypes.QUATERNION_STAMPED_TYPE:
        q = msg.quaternion
    elif msgtype == bagtypes.POSE_STAMPED_TYPE:
        q = msg.pose.orientation
    else:  # nav_msgs/Odometry
        q = msg.pose.pose.orientation
    return float(q.w), float(q.x), float(q.y), float(q.z)


def interpolate_quaternions(
    t: np.ndarray, q: np.ndarray, t_query: np.ndarray, max_gap_s: float = MAX_INTERPOLATION_GAP_S
) -> tuple[np.ndarray, np.ndarray]:
    """q(t_query) by normalised linear interpolation between the bracketing samples.

    Exact where ``t_query`` coincides with a sample. Returns ``(q_query, valid)``; a query is
    invalid outside ``[t[0], t[-1]]`` or inside a gap longer than ``max_gap_s``.
    """
    n = t.shape[0]
    out = np.full((t_query.shape[0], 4), np.nan)
    if n == 0:
        return out, np.zeros(t_query.shape[0], dtype=bool)
    i = np.searchsorted(t, t_query, side="right") - 1
    exact = (i >= 0) & (t[np.clip(i, 0, n - 1)] == t_query)
    inside = (i >= 0) & (i < n - 1)
    i0 = np.clip(i, 0, n - 1)
    i1 = np.clip(i + 1, 0, n - 1)
    span = t[i1] - t[i0]
    valid = exact | (inside & (span <= max_gap_s) & (span > 0))
    frac = np.where(span > 0, (t_query - t[i0]) / np.where(span > 0, span, 1.0), 0.0)
    frac = np.where(exact, 0.0, frac)
    q0, q1 = q[i0], q[i1]
    sign = np.where(np.sum(q0 * q1, axis=1) < 0, -1.0, 1.0)[:, None]
    qi = (1 - frac)[:, None] * q0 + frac[:, None] * sign * q1
    qi /= np.linalg.norm(qi, axis=1, keepdims=True)
    out[valid] = qi[valid]
    return out, valid


def _yaw_quaternion(angle: np.ndarray | float) -> np.ndarray:
    a = np.asarray(angle, dtype=float) / 2.0
    return np.stack([np.cos(a), np.zeros_like(a), np.zeros_like(a), np.sin(a)], axis=-1)


def error_angles(q_est: np.ndarray, q_ref: np.ndarray) -> dict[str, np.ndarray]:
    """Errors [rad] from the earth-frame error quaternion q_err = q_est ⊗ q_ref⁻¹ (BROAD).

    total 2·acos|w|, heading 2·atan|z/w|, inclination 2·acos(√(w²+z²)).
    """
    total, heading, inclination = metrics.error_angles(metrics.error_quaternion(q_est, q_ref))
    return {"total": total, "heading": heading, "inclination": inclination}


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def error_statistics(
    t_est: np.ndarray, q_est: np.ndarray, t_ref: np.ndarray, q_ref: np.ndarray,
    heading_alignment: str,
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Score the estimate against a reference, at the reference's stamps.

    The estimate is interpolated to each reference stamp (exact when stamps coincide); samples
    before initialisation, outside the estimate's span or in gaps are not scored.
    ``heading_alignment`` handles an unknown constant heading offset between the estimate's
    world frame and the reference's: ``none`` (same world frame, e.g. ENU with magnetic north),
    ``first`` (rotate the estimate about the world vertical so its heading matches the first
    scored reference sample; for 6-D, where the filter starts at yaw 0), ``mean`` (the circular
    mean of the heading offset over all scored samples, a least-squares fit).
    """
    ok = np.all(np.isfinite(q_est), axis=1)
    t_e, q_e = t_est[ok], q_est[ok]
    q_i, valid = interpolate_quaternions(t_e, q_e, t_ref)
    t_s, qe, qr = t_ref[valid], q_i[valid], q_ref[valid]
    n = int(t_s.shape[0])
    stats: dict[str, Any] = {"samples_scored": n, "heading_alignment": heading_alignment}
    if n == 0:
        stats["rmse_deg"] = None
        return stats, {}
    e = quat.multiply(qe, quat.conjugate(qr))
    offset = 2.0 * np.arctan2(e[:, 3], e[:, 0])  # heading of the error, per sample
    if heading_alignment == "first":
        delta = float(offset[0])
    elif heading_alignment == "mean":
        delta = float(np.arctan2(np.mean(np.sin(offset)), np.mean(np.cos(offset))))
    else:
        delta = 0.0
    delta = float(_wrap(np.array(delta)))
    if delta != 0.0:
        qe = quat.multiply(_yaw_quaternion(-delta), qe)
    stats["heading_offset_deg"] = math.degrees(delta)
    errs = error_angles(qe, qr)
    rpy_e, rpy_r = quat.to_euler(qe), quat.to_euler(qr)
    d_rpy = _wrap(rpy_e - rpy_r)
    for i, name in enumerate(("roll", "pitch", "yaw")):
        errs[name] = d_rpy[:, i]
    stats["rmse_deg"] = {k: _deg_rms(errs[k]) for k in ("total", "inclination", "heading")}
    stats["max_deg"] = {k: _deg_max(errs[k]) for k in ("total", "inclination", "heading")}
    stats["rpy_rmse_deg"] = {k: _deg_rms(errs[k]) for k in ("roll", "pitch", "yaw")}
    stats["rpy_max_deg"] = {k: _deg_max(errs[k]) for k in ("roll", "pitch", "yaw")}
    scored = {"t_s": t_s, "q_ref": qr, "q_est_aligned": qe, **errs}
    return stats, scored


def covariance_consistency(series: Any, scored: dict[str, np.ndarray],
                           heading: bool) -> dict[str, Any]:
    """Is the reported orientation covariance honest against the reference? (issue 27)
    ``series``: a :class:`~cf_estimator.bag.replay.ReplaySeries` (t_s, tilt_var_rad2,
    yaw_var_rad2).

    At each scored reference sample from :data:`cf_estimator.metrics.SETTLE_S` after
    the first estimate on: the inclination error against the reported tilt variance
    ``cov[0] + cov[4]`` (and, with ``heading``: the magnetometer references it, the heading
    error against ``cov[8]``), the variance interpolated to the reference stamp. ``{"tilt":
    figures, "heading": figures | None}`` with the figures of
    :func:`cf_estimator.metrics.consistency` (share beyond 2σ [%], mean(e²/σ²)).
    """
    from cf_estimator.metrics import SETTLE_S, consistency

    t = series.t_s
    out: dict[str, Any] = {"settle_s": SETTLE_S, "tilt": None, "heading": None}
    ok = np.isfinite(series.tilt_var_rad2) if series.tilt_var_rad2.size == t.size else None
    if ok is None or not ok.any():
        return out
    t_ok = t[ok]
    ts = scored["t_s"]
    keep = ts >= t_ok[0] + SETTLE_S
    pairs = [("tilt", "inclination", series.tilt_var_rad2)]
    if heading:
        pairs.append(("heading", "heading", series.yaw_var_rad2))
    for name, err, var in pairs:
        v = np.interp(ts, t_ok, var[ok])
        c = consistency(scored[err][keep], v[keep])
        out[name] = c if c["samples"] else None
    return out


def _deg_rms(x: np.ndarray) -> float:
    return float(np.degrees(np.sqrt(np.mean(np.square(x)))))


def _deg_max(x: np.ndarray) -> float:
    return float(np.degrees(np.max(np.abs(x))))
