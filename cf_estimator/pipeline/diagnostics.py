"""Diagnostics: per-period statistics (incremental) and the OK/WARN/ERROR report.

:class:`WindowStats` accumulates a few figures per processed message (no lists, no dicts);
:func:`compose_report` turns them, the cumulative counters and the filter's status into a plain
:class:`DiagnosticsReport` that the node copies into a ``diagnostic_msgs/DiagnosticStatus`` and
the replay writes as it is. The keys of ``values`` are listed in docs/ros_interface.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from cf_estimator.pipeline.checks import INFORMATIONAL_WARNINGS

OK, WARN, ERROR = 0, 1, 2
LEVEL_NAMES = {OK: "OK", WARN: "WARN", ERROR: "ERROR"}

#: Fraction of clipped samples in a period above which the report warns (sustained disturbance).
CLIPPED_WARN_FRACTION = 0.8
#: Fraction of magnetometer samples rejected as disturbed above which the report warns.
MAG_REJECTED_WARN_FRACTION = 0.5


@dataclass(frozen=True)
class DiagnosticsReport:
    """One diagnostic status: level 0/1/2 (OK/WARN/ERROR), texts, and string key-values
    (numeric figures always parse as floats; undefined ones are ``"nan"``)."""

    level: int
    name: str
    message: str
    hardware_id: str
    values: list[tuple[str, str]] = field(default_factory=list)

    def value(self, key: str) -> str | None:
        """The value of ``key`` (None when absent)."""
        for k, v in self.values:
            if k == key:
                return v
        return None


class WindowStats:
    """Figures of the processed messages of one diagnostics period (updated per message)."""

    __slots__ = (
        "n", "n_dt", "dt_min", "dt_max", "dt_sum", "err_sum", "err_max", "n_err", "n_clipped",
        "proc_sum", "proc_max", "first_ns", "last_ns",
    )

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        """Start a new period."""
        self.n = 0
        self.n_dt = 0
        self.dt_min = math.inf
        self.dt_max = 0.0
        self.dt_sum = 0.0
        self.err_sum = 0.0
        self.err_max = 0.0
        self.n_err = 0
        self.n_clipped = 0
        self.proc_sum = 0.0
        self.proc_max = 0.0
        self.first_ns = -1
        self.last_ns = -1


#: Value of a figure that is undefined in a period (no messages, not initialised, offline):
#: still a number for any consumer that parses the values (``float("nan")``).
UNDEFINED = "nan"


def _f(x: float | None, digits: int = 6) -> str:
    """A float as text; None (undefined) → ``"nan"``, so a figure is always a number."""
    return UNDEFINED if x is None else f"{x:.{digits}g}"


def _delta(now: Mapping[str, int], prev: Mapping[str, int]) -> dict[str, int]:
    return {k: v - prev.get(k, 0) for k, v in now.items() if v - prev.get(k, 0)}


def compose_report(
    *,
    name: str,
    hardware_id: str,
    counters: Mapping[str, Any],
    previous: Mapping[str, Any],
    window: WindowStats,
    status: Any,
    initialized: bool,
    world_frame: str,
    use_mag: bool,
    rpy_rad: tuple[float, float, float] | None,
    input_warnings: Mapping[str, str],
    period_s: float | None,
    stamp_age_s: float | None,
    mag_age_s: float | None,
    mag_timeout_s: float,
    filter_backend: str = "",
    imu_topic: str = "",
) -> DiagnosticsReport:
    """Build the report of one period from cumulative ``counters`` and their ``previous`` copy.

    ``status`` is the filter's :class:`~cf_estimator.core.filter.FilterStatus` (None before
    initialisation); ``mag_age_s`` the stamp difference between the last processed IMU message
    and the last magnetometer sample the filter used; ``filter_backend`` which implementation
    runs the filter step ('compiled' or 'python', see :mod:`cf_estimator.core.kernel`);
    ``imu_topic`` the topic the IMU messages are awaited on (named in "no IMU" errors).
    Undefined figures are ``"nan"``, never empty.
    """
    errors: list[str] = []
    warns: list[str] = []
    d_recv = counters["received_imu"] - previous.get("received_imu", 0)
    d_proc = counters["processed"] - previous.get("processed", 0)
    d_rej = _delta(counters["rejected"], previous.get("rejected", {}))
    d_resets = _delta(counters["resets"], previous.get("resets", {}))
    d_gaps = counters["gaps"] - previous.get("gaps", 0)
    d_mag = {k: counters[k] - previous.get(k, 0) for k in
             ("received_mag", "mag_used", "mag_rejected", "mag_stale", "mag_invalid")}

    on = f" on {imu_topic}" if imu_topic else ""
    if counters["received_imu"] == 0:
        errors.append(f"no IMU messages received yet{on}")
    elif d_recv == 0:
        since = f"in the last {period_s:.3g} s" if period_s else "since the last report"
        errors.append(f"no IMU messages{on} {since}")
    elif d_proc == 0:
        errors.append(f"all {d_recv} IMU messages rejected ({_reasons(d_rej)})")
    elif d_rej:
        warns.append(f"{sum(d_rej.values())} of {d_recv} IMU messages rejected ({_reasons(d_rej)})")
    if d_resets:
        warns.append(f"filter reset ({_reasons(d_resets)})")
    if d_gaps:
        warns.append(f"{d_gaps} stamp gap(s) longer than max_dt_s not integrated")
    if initialized and status.phase == "recovering":
        warns.append("recovering from a large attitude error (accelerometer error stayed clipped)")
    if window.n_err and window.n_clipped > CLIPPED_WARN_FRACTION * window.n_err:
        warns.append(
            f"accelerometer error clipped in {100.0 * window.n_clipped / window.n_err:.0f}% of "
            "samples (sustained acceleration or vibration)"
        )
    # magnetometer messages came before and none this period: the sensor (or its driver, or
    # the link) stopped; a stopped sensor is not a disturbed field
    mag_stopped = (use_mag and counters["received_mag"] > 0 and d_mag["received_mag"] == 0
                   and d_recv > 0)
    if use_mag:
        if counters["received_mag"] == 0:
            warns.append("use_mag is true but no magnetometer messages received: yaw drifts")
        elif mag_stopped:
            age = f" (last used sample {mag_age_s:.3g} s old)" if mag_age_s is not None else ""
            warns.append("magnetometer stopped: no magnetometer message since the last report"
                         f"{age}: heading on the gyro alone, yaw drifts")
        elif mag_age_s is None or mag_age_s > mag_timeout_s:
            age = f"for {mag_age_s:.3g} s" if mag_age_s is not None else "yet"
            warns.append(
                f"no usable magnetometer sample {age} (stale {counters['mag_stale']}, invalid "
                f"{counters['mag_invalid']}, rejected {counters['mag_rejected']}): yaw drifts"
            )
        if initialized and status.heading_source == "gyro" and not mag_stopped:
            warns.append(
                "heading on the gyro alone: the magnetic field moves with the sensor as it turns "
                "(a magnet or a current-carrying wire on the vehicle?)" if status.mag_on_body else
                "heading on the gyro alone: the magnetic field is disturbed (off the reference "
                "or turning when the body does not)")
        seen = d_mag["mag_used"] + d_mag["mag_rejected"]
        if seen and d_mag["mag_rejected"] > MAG_REJECTED_WARN_FRACTION * seen:
            warns.append(
                f"magnetic disturbance: {d_mag['mag_rejected']} of {seen} magnetometer samples "
                "rejected"
            )
    serious = [tag for tag in input_warnings if tag not in INFORMATIONAL_WARNINGS]
    if serious:
        warns.append("suspicious input: " + ", ".join(serious))

    if errors:
        level, message = ERROR, "; ".join(errors + warns)
    elif warns:
        level, message = WARN, "; ".join(warns)
    else:
        level = OK
        phase = status.phase if initialized else "uninitialized"
        message = "starting up (high gain, no clip)" if phase == "startup" else phase
        if not use_mag:
            message += " (6-D: no magnetometer, yaw is gyro-only)"

    values: list[tuple[str, str]] = [
        ("world_frame", world_frame),
        ("filter_backend", filter_backend or "unknown"),
        ("initialized", str(initialized).lower()),
        ("phase", status.phase if initialized else "uninitialized"),
        ("mag_stopped", str(mag_stopped).lower()),
        ("imu_received", str(counters["received_imu"])),
        ("imu_processed", str(counters["processed"])),
        ("imu_rejected", str(sum(counters["rejected"].values()))),
    ]
    values += [(f"rejected.{k}", str(v)) for k, v in sorted(counters["rejected"].items())]
    values.append(("resets", str(sum(counters["resets"].values()))))
    values += [(f"reset.{k}", str(v)) for k, v in sorted(counters["resets"].items())]
    values.append(("gaps", str(counters["gaps"])))
    w = window
    span_s = (w.last_ns - w.first_ns) * 1e-9
    rate = (w.n - 1) / span_s if w.n >= 2 and span_s > 0.0 else 0.0
    values += [
        ("period_s", _f(period_s if period_s else None)),
        ("input_rate_hz", _f(rate, 5)),
        ("dt_min_s", _f(w.dt_min if w.n_dt else None)),
        ("dt_mean_s", _f(w.dt_sum / w.n_dt if w.n_dt else None)),
        ("dt_max_s", _f(w.dt_max if w.n_dt else None)),
        ("error_norm_mean_rad", _f(w.err_sum / w.n_err if w.n_err else None)),
        ("error_norm_max_rad", _f(w.err_max if w.n_err else None)),
        ("clipped_fraction", _f(w.n_clipped / w.n_err if w.n_err else None, 4)),
    ]
    bias = status.gyro_bias_rad_s if initialized else (0.0, 0.0, 0.0)
    values += [
        ("gyro_bias_x_rad_s", _f(bias[0])),
        ("gyro_bias_y_rad_s", _f(bias[1])),
        ("gyro_bias_z_rad_s", _f(bias[2])),
        ("gyro_bias_sigma_rad_s", _f(status.gyro_bias_sigma_rad_s if initialized else None)),
        ("gyro_bias_converged", str(bool(initialized and status.gyro_bias_converged)).lower()),
        ("bias_hypothesis", status.bias_hypothesis if initialized else "in_flight"),
        ("at_rest", str(bool(initialized and status.at_rest)).lower()),
        ("heading_rate_unverified",
         str(bool(initialized and status.heading_rate_unverified)).lower()),
        ("heading_recovering", str(bool(initialized and status.heading_recovering)).lower()),
        ("heading_source", status.heading_source if initialized else "none"),
        ("mag_disturbance", "none" if not (initialized and status.heading_source == "gyro")
         else "on_body" if status.mag_on_body else "field"),
        ("recovery_count", str(status.recovery_count if initialized else 0)),
    ]
    r = rpy_rad if rpy_rad is not None else (None, None, None)
    values += [
        ("roll_rad", _f(r[0])),
        ("pitch_rad", _f(r[1])),
        ("yaw_rad", _f(r[2])),
        ("use_mag", str(use_mag).lower()),
        ("heading_referenced", str(bool(initialized and status.heading_initialized)).lower()),
        ("mag_received", str(counters["received_mag"])),
        ("mag_used", str(counters["mag_used"])),
        ("mag_rejected", str(counters["mag_rejected"])),
        ("mag_stale", str(counters["mag_stale"])),
        ("mag_invalid", str(counters["mag_invalid"])),
        ("mag_dropped", str(counters["mag_dropped"])),
        ("mag_disabled", str(counters["mag_disabled"])),
        ("mag_age_s", _f(mag_age_s)),
        ("processing_time_mean_us", _f(1e6 * w.proc_sum / w.n if w.n else None, 4)),
        ("processing_time_max_us", _f(1e6 * w.proc_max if w.n else None, 4)),
        ("stamp_age_s", _f(stamp_age_s)),
    ]
    values += [(f"input_warning.{tag}", text) for tag, text in input_warnings.items()]
    return DiagnosticsReport(level, name, message, hardware_id, values)


def _reasons(counts: Mapping[str, int]) -> str:
    return ", ".join(f"{k}: {v}" for k, v in sorted(counts.items()))


def velocity_values(status: Any) -> list[tuple[str, str]]:
    """Key-values of the velocity aiding (a :class:`cf_estimator.core.velocity.VelocityStatus`):
    whether the last IMU sample was aided, velocity messages received / used / stale /
    rejected by reason, IMU samples aided and left unaided by a stale velocity, the heading
    offset between the filter's world frame and the velocity's and its standard deviation, the
    world axes aided now (``xy`` or ``none``), how long the current aided stretch has lasted
    and how long aiding took to begin after the first velocity sample [s], and how often an
    attitude error revealed while aided made the filter take hold again."""
    rejected = dict(status.rejected)
    stale = rejected.pop("too_old", 0)
    values = [
        ("velocity_aiding", status.mode),
        ("velocity_received", str(status.received)),
        ("velocity_used", str(status.used)),
        ("velocity_stale", str(stale)),
        ("velocity_rejected", str(sum(rejected.values()))),
    ]
    values += [(f"velocity_rejected.{k}", str(v)) for k, v in sorted(rejected.items()) if v]
    values += [
        ("velocity_reanchors", str(status.reanchors)),
        ("velocity_aided_samples", str(status.aided_samples)),
        ("velocity_aided_horizontal_samples", str(status.horizontal_samples)),
        ("velocity_stale_samples", str(status.stale_samples)),
        ("velocity_age_s", _f(status.age_s if math.isfinite(status.age_s) else None)),
        ("velocity_heading_known", str(bool(status.heading_known)).lower()),
        ("velocity_heading_offset_rad", _f(status.heading_offset_rad)),
        ("velocity_heading_sigma_rad", _f(status.heading_sigma_rad
                                          if math.isfinite(status.heading_sigma_rad) else None)),
        ("velocity_aided_axes", status.axes),
        ("velocity_aided_for_s", _f(status.aided_for_s)),
        ("velocity_time_to_aid_s", _f(_time_to_aid(status))),
        ("velocity_aligned", str(math.isfinite(status.aligned_t_s)).lower()),
        ("velocity_time_to_align_s", _f(_time_to_align(status))),
        ("velocity_moving", str(bool(status.moving_now)).lower()),
        ("velocity_attitude_errors", str(status.attitude_errors)),
    ]
    return values


def _time_to_align(status: Any) -> float | None:
    """Seconds from the first accepted velocity sample to the in-motion alignment the filter
    took its tilt and gyro bias from (None: not yet)."""
    t = status.aligned_t_s - status.first_velocity_t_s
    return t if math.isfinite(t) else None


def _time_to_aid(status: Any) -> float | None:
    """Seconds from the first accepted velocity sample to the first aided IMU sample (None:
    not aided yet)."""
    t = status.first_aided_t_s - status.first_velocity_t_s
    return t if math.isfinite(t) else None
