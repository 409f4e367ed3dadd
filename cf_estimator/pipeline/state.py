"""The pipeline's public state, one object per concern, kept by
:class:`cf_estimator.pipeline.pipeline.ImuPipeline` and changed by its rules
(:mod:`cf_estimator.pipeline.process`).

- :class:`MessageCounts` — cumulative counts of what came in and what became of it;
- :class:`ImuTime` — the IMU time base (cleared by every reset);
- :class:`MagInput` — the magnetometer sample waiting for the next IMU step and its checks;
- :class:`InputRules` — the time and magnetometer rules derived from the parameters in force;
- :class:`InputCovariance` — an input covariance as the outputs carry it (cached by its bytes).

Plain mutable objects with slots: the hot path increments their attributes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from cf_estimator.pipeline.messages import covariance9

Vec3 = tuple[float, float, float]


@dataclass(slots=True)
class MessageCounts:
    """Cumulative message counts since the pipeline was created (never reset)."""

    received_imu: int = 0  #: IMU messages received
    processed: int = 0  #: IMU messages that produced an output
    gaps: int = 0  #: intervals longer than max_dt_s, not integrated
    received_mag: int = 0  #: magnetometer messages received
    mag_used: int = 0  #: magnetometer samples the heading channel used
    mag_rejected: int = 0  #: ... that it rejected (disturbed field)
    mag_stale: int = 0  #: samples older than mag_timeout_s at the next IMU step
    mag_invalid: int = 0  #: samples with NaN/Inf components
    mag_dropped: int = 0  #: samples replaced before an IMU step used them, or dropped by a reset
    mag_disabled: int = 0  #: samples passed while use_mag is false


@dataclass(slots=True)
class ImuTime:
    """The IMU time base: last accepted stamp [ns] (None before the first, or after a reset),
    mean sample interval [s] (0: none yet), the last published roll/pitch/yaw [rad] that
    ``rpy_unwrap`` continues from (None: none)."""

    last_ns: int | None = None
    dt_mean: float = 0.0
    unwrap_prev: Vec3 | None = None


@dataclass(slots=True)
class MagInput:
    """The latest valid magnetometer sample ``pending`` = (t_ns, x, y, z) [ns, input units]
    waiting for the next IMU step (None: none), the stamp [ns] of the last one the filter used,
    the unit/frame check's sample count and sum of norms, and the magnetometer's frame id."""

    pending: tuple[int, float, float, float] | None = None
    last_used_ns: int | None = None
    check_n: int = 0
    check_norm_sum: float = 0.0
    frame: str | None = None


@dataclass(slots=True)
class InputRules:
    """The parameters' rules in the units the paths compare in: intervals [ns], flags."""

    max_dt_ns: int = 0  #: a longer interval is a gap (max_dt_s)
    reset_gap_on: bool = False  #: reset_after_gap_s > 0
    reset_gap_ns: int = 0  #: reset after a gap this long (reset_after_gap_s)
    jump_back_ns: int = 0  #: time_jump_back_threshold_s
    mag_timeout_ns: int = 0  #: mag_timeout_s
    use_mag: bool = True  #: FilterParams.use_mag
    flip: bool = False  #: input vectors turned FLU <-> FRD (body_frame against world_frame)


class InputCovariance:
    """One input covariance (an IMU message's angular velocity or linear acceleration one) as
    the output carries it: row-major 9-tuple, turned FLU <-> FRD when ``flip``. Input
    covariances rarely change: the last tuple is reused while the bytes are equal."""

    __slots__ = ("flip", "raw", "value")

    def __init__(self) -> None:
        self.raw: bytes | None = None
        self.value: tuple[float, ...] = ()
        self.flip = False  #: FLU <-> FRD: D C D with D = diag(1, -1, -1)

    def _convert(self, cov: Any) -> tuple[float, ...]:
        c = covariance9(cov)
        if not self.flip or c[0] == -1.0:  # -1: "not provided", kept as is
            return c
        return (c[0], -c[1], -c[2], -c[3], c[4], c[5], -c[6], c[7], c[8])

    def get(self, cov: Any) -> tuple[float, ...]:
        tobytes = getattr(cov, "tobytes", None)  # array.array (rclpy) and NumPy (rosbags)
        if tobytes is None:
            return self._convert(cov)
        raw = tobytes()
        if raw != self.raw:
            self.value = self._convert(cov)
            self.raw = raw
        return self.value
