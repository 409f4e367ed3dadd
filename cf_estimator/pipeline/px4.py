"""PX4's conventions for PX4 input (ulog flight logs, px4_msgs topics): no ROS, no pyulog here.

PX4 measures in the body's FRD axes (x forward, y right, z down) and states its attitude
(``vehicle_attitude.q``) as FRD body → NED world, Hamilton (w, x, y, z); every topic is stamped
in µs since the autopilot booted (``timestamp``). On PX4 input the estimator therefore defaults
to ``body_frame`` ``frd`` and ``world_frame`` ``ned`` (and ``velocity_frame`` ``ned``, the axes
of ``vehicle_local_position``), so its output reads like ``vehicle_attitude``; a parameter the
user set explicitly (a parameter file, a ROS override) is never changed: ``world_frame: enu``
gives the REP-103 FLU → ENU orientation from the same FRD data.

PX4's world frame is true north (EKF2 turns the magnetometer's heading by the declination it
looks up, or by ``EKF2_MAG_DECL``): a ulog's replay takes ``magnetic_declination_rad`` from the
log's ``EKF2_MAG_DECL`` [deg] (:func:`log_defaults`; the value the autopilot saved, from the
World Magnetic Model at its last GNSS position) unless the user set it.

PX4 up to v1.11 learned a magnetometer bias in flight (EKF2's body-field states), saved it on
disarm as ``EKF2_MAGBIAS_X/Y/Z`` [Gauss] with the magnetometer's device id
(``EKF2_MAGBIAS_ID``), and at the next boot subtracted it from ``vehicle_magnetometer`` before
fusing, for that device only; later versions fold it into the ``CAL_MAGn_*`` calibration that
``vehicle_magnetometer`` already carries. :func:`saved_mag_bias` says whether a log's
magnetometer needs it subtracted to read as EKF2's did.

Stamps stay the log's time since boot (``timestamp`` µs → header stamp ns), so the output lines
up with every other topic of the log.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection, Mapping
from typing import Any

import numpy as np

from cf_estimator.core.params import FilterParams
from cf_estimator.pipeline.params import PipelineParams
from cf_estimator.schema import specs_of

#: The defaults PX4 input gets for parameters the user did not set: FilterParams' ...
PX4_FILTER_DEFAULTS: dict[str, Any] = {"world_frame": "ned"}
#: ... and PipelineParams'.
PX4_PIPELINE_DEFAULTS: dict[str, Any] = {"body_frame": "frd", "velocity_frame": "ned"}
#: frame_id of the IMU messages built from PX4 data (FRD body axes; the output keeps it).
PX4_BODY_FRAME_ID = "base_link_frd"
#: PX4's relative timestamp meaning "no valid sample" (RELATIVE_TIMESTAMP_INVALID, INT32_MAX).
RELATIVE_TIMESTAMP_INVALID = 2147483647
#: 1 Gauss in tesla (PX4 logs magnetometer_ga; sensor_msgs/MagneticField is in T).
GAUSS_TO_TESLA = 1e-4


#: PX4 parameter holding the magnetic declination [deg, east positive] (EKF2's; saved on
#: disarm when EKF2_DECL_TYPE says so).
PX4_DECLINATION_PARAM = "EKF2_MAG_DECL"


def log_defaults(log_parameters: Mapping[str, Any]) -> dict[str, Any]:
    """The estimator parameters a PX4 log's own parameters imply: ``magnetic_declination_rad``
    [rad] from :data:`PX4_DECLINATION_PARAM` [deg] when it is there, finite and within ±180°
    (none otherwise)."""
    try:
        decl = float(log_parameters[PX4_DECLINATION_PARAM])
    except (KeyError, TypeError, ValueError):
        return {}
    if not (math.isfinite(decl) and abs(decl) <= 180.0):
        return {}
    return {"magnetic_declination_rad": math.radians(decl)}


#: PX4 parameters of EKF2's saved magnetometer bias [Gauss, FRD body axes] (PX4 ≤ v1.11) ...
PX4_MAG_BIAS_PARAMS = ("EKF2_MAGBIAS_X", "EKF2_MAGBIAS_Y", "EKF2_MAGBIAS_Z")
#: ... and of the device id of the magnetometer it belongs to.
PX4_MAG_BIAS_ID_PARAM = "EKF2_MAGBIAS_ID"
#: A saved bias beyond this [Gauss] is not a bias (the Earth's field is at most 0.65 G).
PX4_MAG_BIAS_MAX_GA = 1.0


def saved_mag_bias(log_parameters: Mapping[str, Any], device_ids: Collection[int]
                   ) -> tuple[np.ndarray | None, str]:
    """``(bias, text)``: EKF2's saved magnetometer bias [Gauss, FRD] (:data:`PX4_MAG_BIAS_PARAMS`)
    when EKF2 subtracted it from this log's magnetometer, i.e. the log's ``device_ids`` (the
    magnetometer read; from the log's topics) are all :data:`PX4_MAG_BIAS_ID_PARAM`; else
    ``None``. ``text`` says what was done: empty when no bias is saved (the parameters absent,
    all zero, not finite or beyond :data:`PX4_MAG_BIAS_MAX_GA`: nothing to subtract), else one
    line for the replay's summary."""
    try:
        bias = np.array([float(log_parameters[k]) for k in PX4_MAG_BIAS_PARAMS])
        saved_id = int(log_parameters[PX4_MAG_BIAS_ID_PARAM])
    except (KeyError, TypeError, ValueError, OverflowError):
        return None, ""
    if not (np.all(np.isfinite(bias)) and 0.0 < np.linalg.norm(bias) <= PX4_MAG_BIAS_MAX_GA):
        return None, ""
    saved = (f"EKF2_MAGBIAS_X/Y/Z ({bias[0]:+.4f}, {bias[1]:+.4f}, {bias[2]:+.4f}) G of "
             f"device {saved_id}")
    ids = sorted(set(device_ids))
    if ids == [saved_id]:
        return bias, f"{saved} subtracted from the magnetometer (as EKF2 did)"
    if not ids:
        return None, (f"{saved} not subtracted: the log does not say which magnetometer it "
                      "read (no device id), so whether EKF2 subtracted it is unknown")
    return None, (f"{saved} not subtracted: the magnetometer is device "
                  f"{', '.join(map(str, ids))} (neither did EKF2)")


def _defaults(cls: type) -> dict[str, Any]:
    return {s.name: s.default for s in specs_of(cls)}


def explicit_from_values(fp: FilterParams, pp: PipelineParams) -> set[str]:
    """The parameters whose values differ from the schema defaults (what a caller who does not
    know which ones were set explicitly can go by)."""
    out = {k for k, v in _defaults(FilterParams).items() if getattr(fp, k) != v}
    out |= {k for k, v in _defaults(PipelineParams).items() if getattr(pp, k) != v}
    return out


def apply_px4_conventions(
    fp: FilterParams, pp: PipelineParams, explicit: Collection[str] | None = None,
    log_parameters: Mapping[str, Any] | None = None, *,
    from_log: Mapping[str, Any] | None = None,
    declination_name: str = PX4_DECLINATION_PARAM,
) -> tuple[FilterParams, PipelineParams, list[str]]:
    """``(fp, pp, changed)``: the PX4 defaults (:data:`PX4_FILTER_DEFAULTS`,
    :data:`PX4_PIPELINE_DEFAULTS`, and :func:`log_defaults` of the log's own parameters)
    applied to every parameter not in ``explicit`` (None: the parameters that differ from the
    schema default count as explicit); ``changed`` names the parameters set, ``name=value``.
    ``from_log``: the log's own defaults when they are not PX4's (an ArduPilot log: its
    ``COMPASS_DEC``, named ``declination_name`` in ``changed``). The same frames hold for
    ArduPilot, whose IMU is FRD and whose attitude is FRD → NED too."""
    given = explicit_from_values(fp, pp) if explicit is None else set(explicit)
    if from_log is None:
        from_log = log_defaults(log_parameters or {})
    f_names = set(_defaults(FilterParams))
    f_changes = {k: v for k, v in {**PX4_FILTER_DEFAULTS, **from_log}.items()
                 if k in f_names and k not in given and getattr(fp, k) != v}
    p_changes = {k: v for k, v in {**PX4_PIPELINE_DEFAULTS, **from_log}.items()
                 if k not in f_names and k not in given and getattr(pp, k) != v}
    if f_changes:
        fp = dataclasses.replace(fp, **f_changes)
    if p_changes:
        pp = dataclasses.replace(pp, **p_changes)
    changed = [f"{k}={v:.6g} ({declination_name} {math.degrees(v):.2f} deg)"
               if k == "magnetic_declination_rad" else f"{k}={v}"
               for k, v in {**f_changes, **p_changes}.items()]
    return fp, pp, changed


def output_body(body_frame: str, world_frame: str) -> str:
    """The body convention of the output orientation for FRD input data: ``frd`` or ``flu``
    (``sensor``: the message axes, FRD; ``flu``/``frd``: the one paired with world_frame)."""
    if body_frame == "sensor":
        return "frd"
    return "frd" if world_frame == "ned" else "flu"


#: Rotation quaternions (w, x, y, z): ENU ← NED (x↔y, z flipped) and FRD ← FLU (half turn
#: about x, its own inverse).
_Q_ENU_FROM_NED = np.array([0.0, np.sqrt(0.5), np.sqrt(0.5), 0.0])
_Q_FRD_FROM_FLU = np.array([0.0, 1.0, 0.0, 0.0])


def _mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=float), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=float), -1, 0)
    return np.stack([aw * bw - ax * bx - ay * by - az * bz,
                     aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw], axis=-1)


def attitude_in_output_frames(q_ned_frd: np.ndarray, world_frame: str,
                              body: str) -> np.ndarray | None:
    """PX4's ``vehicle_attitude.q`` (FRD → NED, (N, 4) w x y z) in the estimator's output
    conventions: world ``ned``/``enu``/``nwu``, body ``frd``/``flu`` (:func:`output_body`).
    None for a world frame this module does not know (the comparison is then left out)."""
    q = np.asarray(q_ned_frd, dtype=float).reshape(-1, 4)
    if world_frame == "enu":
        q = _mul(_Q_ENU_FROM_NED, q)
    elif world_frame == "nwu":  # north, west, up: NED turned half a turn about north
        q = _mul(_Q_FRD_FROM_FLU, q)
    elif world_frame != "ned":
        return None
    if body == "flu":
        q = _mul(q, _Q_FRD_FROM_FLU)
    return q
