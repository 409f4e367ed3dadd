"""Input validation vocabulary and warn-once sanity checks (units, frames).

Rejection reasons are short snake_case codes: they are the keys of the pipeline's ``rejected``
counter and of ``rejected.<reason>`` in /diagnostics. The sanity checks never reject anything:
each raises one warning, once, the first time its condition is seen, because the data are still
usable (the filter uses directions only) but something upstream is probably misconfigured.
"""

from __future__ import annotations

import math

# -- rejection reasons of IMU messages (see docs/ros_interface.md, failure-mode table) -------
MALFORMED = "malformed"  #: a field is missing or has the wrong type
ZERO_STAMP = "zero_stamp"  #: header.stamp is 0 (driver did not stamp): dt is unknowable
NONFINITE_GYRO = "nonfinite_gyro"  #: NaN/Inf in angular_velocity
NONFINITE_ACCEL = "nonfinite_accel"  #: NaN/Inf in linear_acceleration
ZERO_ACCEL = "zero_accel"  #: |linear_acceleration| == 0 (no direction; driver not filling it)
IMPLAUSIBLE_GYRO = "implausible_gyro"  #: finite |angular_velocity| > GYRO_MAX_RAD_S (garbage)
IMPLAUSIBLE_ACCEL = "implausible_accel"  #: finite |linear_acceleration| > ACCEL_MAX_M_S2
DUPLICATE_STAMP = "duplicate_stamp"  #: same stamp as the last processed message (dt = 0)
OUT_OF_ORDER = "out_of_order"  #: stamp slightly before the last processed one
TIME_BACKWARDS = "time_backwards"  #: time jumped back and reset_on_time_jump_back is false
INTERNAL_ERROR = "internal_error"  #: the filter raised (a bug): message dropped, node lives on

REJECT_REASONS = (
    MALFORMED, ZERO_STAMP, NONFINITE_GYRO, NONFINITE_ACCEL, ZERO_ACCEL, IMPLAUSIBLE_GYRO,
    IMPLAUSIBLE_ACCEL, DUPLICATE_STAMP, OUT_OF_ORDER, TIME_BACKWARDS, INTERNAL_ERROR,
)

# -- reset reasons -----------------------------------------------------------------------------
RESET_TIME_JUMP_BACK = "time_jump_back"  #: header stamps went back (bag loop)
RESET_LONG_GAP = "long_gap"  #: stamp gap longer than reset_after_gap_s
RESET_CLOCK_JUMP = "clock_jump_back"  #: the node clock jumped back (use_sim_time rewind)

# -- sanity thresholds (constants, documented; not parameters) ---------------------------------
#: Processed samples averaged before judging the accelerometer's units.
ACCEL_CHECK_SAMPLES = 200
#: |gyro| above this [rad/s] (~2000 deg/s, beyond most MEMS ranges) suggests deg/s.
GYRO_IMPLAUSIBLE_RAD_S = 35.0
#: |gyro| above this [rad/s] is not a measurement (~57 000 deg/s, 14x the widest MEMS range):
#: rejected. A single such sample would otherwise poison the filter's rest detector for many
#: seconds (its low-pass decays from the spike), or overflow the arithmetic (|w| > ~1e154).
GYRO_MAX_RAD_S = 1000.0
#: |accel| above this [m/s^2] (~1000 g) is not a measurement: rejected (same reason).
ACCEL_MAX_M_S2 = 10000.0
#: Magnetometer samples averaged before judging its units.
MAG_CHECK_SAMPLES = 20
#: Plausible Earth-field norm [T]: Earth's 25-65 uT with a margin for local fields.
MAG_PLAUSIBLE_T = (10e-6, 100e-6)


def frame_id_warning(frame_id: str, what: str) -> tuple[str, str] | None:
    """``(tag, message)`` when a frame id is empty or starts with '/', else None."""
    if not frame_id:
        return (
            f"{what}_frame_id_empty",
            f"{what} messages have an empty header.frame_id: consumers (tf2, "
            "robot_localization) cannot place them; outputs keep the input frame_id",
        )
    if frame_id.startswith("/"):
        return (
            f"{what}_frame_id_slash",
            f"{what} header.frame_id '{frame_id}' starts with '/': tf2 frame ids must not "
            "(REP-105); outputs keep the input frame_id",
        )
    return None


def accel_units_warning(mean_norm_m_s2: float, gravity_m_s2: float) -> tuple[str, str] | None:
    """``(tag, message)`` when the mean |a| over the first samples is far from g."""
    if abs(mean_norm_m_s2 - 1.0) < 0.3:
        return (
            "accel_units",
            f"|linear_acceleration| averages {mean_norm_m_s2:.3g}: looks like units of g, "
            "ROS wants m/s^2 (attitude still works: only the direction is used; rest detection "
            "thresholds assume m/s^2)",
        )
    if mean_norm_m_s2 < 0.25 * gravity_m_s2:
        return (
            "accel_gravity_removed",
            f"|linear_acceleration| averages {mean_norm_m_s2:.3g} m/s^2, far below g: gravity "
            "seems removed; a tilt estimate needs the raw specific force (imu/data_raw)",
        )
    if abs(mean_norm_m_s2 / gravity_m_s2 - 1.0) > 0.3:
        return (
            "accel_norm",
            f"|linear_acceleration| averages {mean_norm_m_s2:.3g} m/s^2, far from "
            f"g = {gravity_m_s2:g}: check the accelerometer scale",
        )
    return None


def gyro_units_warning(norm_rad_s: float) -> tuple[str, str]:
    """``(tag, message)`` for an implausibly large angular rate."""
    return (
        "gyro_units",
        f"|angular_velocity| reached {norm_rad_s:.3g} rad/s (> {GYRO_IMPLAUSIBLE_RAD_S:g}): "
        "is the driver publishing deg/s? ROS wants rad/s",
    )


def mag_units_warning(mean_norm: float) -> tuple[str, str] | None:
    """``(tag, message)`` when the mean |B| is not a plausible Earth field in Tesla."""
    lo, hi = MAG_PLAUSIBLE_T
    if lo <= mean_norm <= hi:
        return None
    if 0.1 <= mean_norm <= 1.0:
        guess, fix = "Gauss", "multiply by 1e-4 (1 G = 1e-4 T)"
    elif 10.0 <= mean_norm <= 100.0:
        guess, fix = "microtesla", "multiply by 1e-6"
    elif mean_norm > 100.0:
        guess, fix = "raw counts or nanotesla", "apply the sensor's scale (nT: 1e-9)"
    else:
        guess, fix = ("an unexpected scale or a strong local field",
                      "check the driver's scale factor and for magnets near the sensor")
    return (
        "mag_units",
        f"|magnetic_field| averages {mean_norm:.3g}, outside the plausible {lo * 1e6:g}-"
        f"{hi * 1e6:g} uT (Earth's field: 25-65 uT): looks like {guess}. Heading still works "
        "(only directions are used), so /diagnostics stays OK; sensor_msgs/MagneticField is "
        f"Tesla: {fix}",
    )


#: Input warnings that do not affect the estimate: reported once in the log and under
#: ``input_warning.<tag>`` in /diagnostics, without raising its level (a Gauss magnetometer
#: would otherwise keep /diagnostics at WARN for ever).
INFORMATIONAL_WARNINGS = frozenset({"mag_units"})


def mag_frame_warning(mag_frame: str, imu_frame: str) -> tuple[str, str]:
    """``(tag, message)`` when the magnetometer and IMU frames differ."""
    return (
        "mag_frame_mismatch",
        f"magnetometer frame_id '{mag_frame}' differs from the IMU's '{imu_frame}': the filter "
        "assumes both vectors are in the same sensor frame (no tf lookup is done)",
    )


# -- results that must not look like one --------------------------------------------------------
#: Stamp rejections (out_of_order, duplicate_stamp, time_backwards) above this share of the IMU
#: messages make a replay unusable: the stamps decrease (or repeat) through most of the input.
STAMP_REJECT_UNUSABLE_FRACTION = 0.5
_STAMP_REASONS = (OUT_OF_ORDER, DUPLICATE_STAMP, TIME_BACKWARDS)


def _bad_number(value: object) -> bool:
    """None, NaN or Inf (a figure a summary cannot report)."""
    return value is None or (isinstance(value, float) and not math.isfinite(value))


def unusable_reason(summary: dict) -> str | None:
    """One line when a replay summary is no result to keep, else None.

    ``summary`` needs ``messages_in``, ``messages_processed``, ``messages_rejected`` (reason →
    count), ``resets`` and ``duration_s`` [s] (first to last processed stamp). Unusable: no
    IMU message processed; stamps that decrease or repeat through most of the input (more than
    :data:`STAMP_REJECT_UNUSABLE_FRACTION` of the messages rejected for their stamp, or the last
    processed stamp before the first); a duration that is None/NaN with messages processed.
    """
    n_in = int(summary.get("messages_in") or 0)
    processed = int(summary.get("messages_processed") or 0)
    rejected = {k: int(v) for k, v in (summary.get("messages_rejected") or {}).items() if v}
    resets = {k: int(v) for k, v in (summary.get("resets") or {}).items() if v}
    if processed == 0:
        detail = ", ".join(f"{v} {k}" for k, v in rejected.items()) or "none counted"
        return f"no IMU message usable: {n_in} of {n_in} rejected ({detail})"
    stamp = {k: rejected[k] for k in _STAMP_REASONS if k in rejected}
    duration = summary.get("duration_s")
    n_stamp = sum(stamp.values())
    decreasing = (n_stamp > STAMP_REJECT_UNUSABLE_FRACTION * n_in
                  or (not _bad_number(duration) and duration < 0.0))  # type: ignore[operator]
    if decreasing:
        what = ", ".join(f"{v} {k}" for k, v in stamp.items()) or "none"
        jumps = resets.get(RESET_TIME_JUMP_BACK, 0)
        return (f"stamps decrease: {n_stamp} of {n_in} rejected ({what})"
                + (f", {jumps} resets {RESET_TIME_JUMP_BACK}" if jumps else "")
                + "; no usable estimate (are the header stamps the driver's time?)")
    if _bad_number(duration):
        return f"no stamp span: duration {duration!r} with {processed} messages processed"
    return None


def input_type_problem(role: str, topic: str, expected: str,
                       advertised: list[str]) -> str | None:
    """One line when ``topic`` is advertised on the ROS graph only with types other than
    ``expected`` (e.g. a Vector3Stamped on the IMU input: the subscription never matches, and
    the node would only say "no IMU messages"); None when it matches or nobody advertises it.
    """
    if not advertised or expected in advertised:
        return None
    return (f"{role} input {topic} is advertised as {', '.join(sorted(advertised))}, but the "
            f"node subscribes {expected}: no message can arrive (remap the right topic, or "
            + ("set velocity_topic_type)" if role == "velocity" else "fix the publisher)"))
