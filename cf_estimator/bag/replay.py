"""Replay a recorded bag through :class:`cf_estimator.pipeline.ImuPipeline` — the node's code path.

Nothing here processes IMU data: every input message goes to ``ImuPipeline.on_imu``/``on_mag``
in log-time order (IMU and magnetometer interleaved exactly as recorded) and every
``PipelineOutput`` is written as the live node would publish it:

* ``/imu/data`` (sensor_msgs/Imu) and ``/imu/rpy`` (geometry_msgs/Vector3Stamped, when the
  pipeline's ``publish_rpy`` is set and an attitude exists) with the output's header — the input
  IMU message's stamp and frame_id — at the input message's log time;
* ``/diagnostics`` (diagnostic_msgs/DiagnosticArray) every ``diagnostics_period_s`` (1 s) of bag
  time, as the node's timer would fire under ``use_sim_time`` during ``ros2 bag play --clock``:
  stamped with the tick time, reporting the state before the first message at or after the tick.
  One report per tick that falls inside the recording; a recording gap gives one report, not a
  burst.

With a reference topic the estimate is scored against it (see :func:`error_statistics`).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from cf_estimator import __version__
from cf_estimator.bag import cdr, io, ulog
from cf_estimator.bag.metrics import (
    MAX_INTERPOLATION_GAP_S,
    covariance_consistency,
    error_statistics,
    reference_quaternion,
)
from cf_estimator.core import quaternion as quat
from cf_estimator.core.filter import ComplementaryFilter, Extra
from cf_estimator.core.kernel import resolve_backend
from cf_estimator.core.offline import ROW_AIDED, ROW_MOVING
from cf_estimator.core.params import FilterParams
from cf_estimator.core.step import BIAS_CONVERGED_SIGMA_RAD_S
from cf_estimator.pipeline import ImuPipeline, PipelineParams, checks, frames, px4
from cf_estimator.pipeline.events import IMU, MAG, OTHER, VELOCITY, Events, message_events
from cf_estimator.pipeline.process import Rows
from cf_estimator.schema import as_dict

OUT_IMU_TOPIC = "/imu/data"
OUT_RPY_TOPIC = "/imu/rpy"
#: publish_linear_acceleration: gravity-free acceleration, body and world frame
OUT_ACCEL_TOPIC = "/imu/linear_acceleration"
OUT_ACCEL_WORLD_TOPIC = "/imu/linear_acceleration_world"
OUT_DIAGNOSTICS_TOPIC = "/diagnostics"
HEADING_ALIGNMENTS = ("auto", "none", "first", "mean")


@dataclass
class ReplayOptions:
    """How to replay (topic names None = auto-detect by message type)."""

    imu_topic: str | None = None
    mag_topic: str | None = None  #: "none" = replay without magnetometer
    #: velocity aiding input (TwistStamped or Odometry); None = none (never auto-detected)
    velocity_topic: str | None = None
    reference_topic: str | None = None
    storage: str = "mcap"
    copy_inputs: bool = False
    overwrite: bool = False
    heading_alignment: str = "auto"
    progress: bool | None = None  #: None: a tqdm bar on stderr only when stderr is a terminal
    offline: bool = False  #: write the offline (acausal) estimate (_offline_orientations)
    #: decode IMU/magnetometer messages in bulk with NumPy (same values; False: one by one)
    bulk_decode: bool = True
    #: with bulk_decode, the decoded rows straight to the pipeline (False: as message objects
    #: first, then to the pipeline; the same outputs, bit for bit)
    bulk_pipeline: bool = True
    #: called with the number of messages read since the last call (a fleet's progress bar)
    on_messages: Callable[[int], None] | None = None
    #: PX4 ulog: the multi_id to use where a topic has several (None: the lowest, said)
    instance: int | None = None
    #: names of the parameters the user set (a parameter file): PX4 input changes only the
    #: others to PX4's conventions (None: those that differ from the default count as set)
    explicit_params: frozenset[str] | None = None


@dataclass
class ReplaySeries:
    """Per-output time series of the replay (header stamps) for statistics and plots."""

    t_s: np.ndarray  #: header stamp of each output [s, bag clock]
    q_wxyz: np.ndarray  #: (N, 4) estimate, NaN rows before initialisation
    rpy_rad: np.ndarray  #: (N, 3), NaN before initialisation
    clipped: np.ndarray  #: (N,) saturation unit active at that sample
    error_norm_rad: np.ndarray  #: (N,) |e| of the accelerometer channel
    bias_t_s: np.ndarray  #: stamps of the bias samples (decimated to <= 50 Hz) [s]
    gyro_bias_rad_s: np.ndarray  #: (M, 3) gyro-bias estimate at bias_t_s [rad/s, sensor frame]
    gyro_bias_sigma_rad_s: np.ndarray  #: (M,) σ of its error [rad/s] (bias.error_sigma)
    at_rest: np.ndarray  #: (N,) bool per IMU sample: the filter's still phase
    ref_t_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    ref_q_wxyz: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    #: offline replay: (N, 3) the online filter's roll, pitch, yaw [rad] beside the offline ones
    online_rpy_rad: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    #: (N,) reported tilt variance cov[0] + cov[4] [rad²] (the online filter's; NaN before init)
    tilt_var_rad2: np.ndarray = field(default_factory=lambda: np.zeros(0))
    #: (N,) reported yaw variance cov[8] [rad²]
    yaw_var_rad2: np.ndarray = field(default_factory=lambda: np.zeros(0))


@dataclass
class ReplayResult:
    summary: dict[str, Any]
    series: ReplaySeries
    output: Path | None
    scored: dict[str, np.ndarray] | None = None  #: per reference sample: t_s, errors [rad]


class ReplayError(Exception):
    """A user-facing replay failure (bad bag, bad topic, bad output path)."""


class UnusableInput(io.BagError):
    """The bag was read but gives no usable estimate (:func:`checks.unusable_reason`): exit 1,
    no output written."""


# ---------------------------------------------------------------------------------------------
# error statistics


# ---------------------------------------------------------------------------------------------
# replay


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


class _Progress:
    def __init__(self, total: int, enabled: bool | None, desc: str,
                 on_messages: Callable[[int], None] | None = None) -> None:
        self._on_messages = on_messages
        if on_messages is not None:
            enabled = True  # the caller's bar shows it
        elif enabled is None:
            enabled = sys.stderr.isatty()
        self._bar = None
        if enabled and on_messages is None:
            from tqdm import tqdm

            self._bar = tqdm(total=total, unit="msg", unit_scale=True, desc=desc,
                             file=sys.stderr, leave=False, dynamic_ncols=True)
        self._pending = 0

    def tick(self) -> None:
        if self._bar is not None or self._on_messages is not None:
            self._pending += 1
            if self._pending >= 2000:
                self._flush()

    def add(self, n: int) -> None:
        """``n`` messages read at once."""
        if self._bar is not None or self._on_messages is not None:
            self._pending += n
            if self._pending >= 2000:
                self._flush()

    def _flush(self) -> None:
        if self._bar is not None:
            self._bar.update(self._pending)
        if self._on_messages is not None:
            self._on_messages(self._pending)
        self._pending = 0

    def close(self) -> None:
        self._flush()
        if self._bar is not None:
            self._bar.close()


def resolve_heading_alignment(choice: str, mag_in_use: bool) -> str:
    """``auto`` → ``none`` when the magnetometer references heading (9-D), else ``first``."""
    if choice not in HEADING_ALIGNMENTS:
        raise ReplayError(
            f"unknown heading alignment {choice!r}; choose one of {', '.join(HEADING_ALIGNMENTS)}"
        )
    if choice != "auto":
        return choice
    return "none" if mag_in_use else "first"


@dataclass
class ReplayVariant:
    """One parameter set to replay (several variants share one pass over the input bag)."""

    name: str = "replay"
    filter_params: FilterParams | None = None
    pipeline_params: PipelineParams | None = None
    output_path: str | os.PathLike[str] | None = None


#: Bias samples kept for plots at most this often [s of stamp time] (status() costs ~20 us).
_BIAS_SAMPLE_PERIOD_S = 0.02


class _Col:
    """One per-output series of a replay: a run's values at once (:meth:`add`: an array, no
    Python object per row), or given whole (``values``; None in a ``width``-wide series: no
    value, NaN)."""

    __slots__ = ("_blocks", "_cur", "_width", "_dtype")

    def __init__(self, width: int = 0, values: list[Any] | None = None,
                 dtype: type = float) -> None:
        self._blocks: list[np.ndarray] = []
        self._cur: list[Any] = values if values is not None else []
        self._width, self._dtype = width, dtype

    def add(self, block: np.ndarray) -> None:
        """Values of several outputs at once (rows of ``block``)."""
        if self._cur:
            self._blocks.append(self._stack(self._cur))
            self._cur = []
        self._blocks.append(block)

    def _stack(self, values: list[Any]) -> np.ndarray:
        if self._width:
            nan = (np.nan,) * self._width
            return np.array([x if x is not None else nan for x in values],
                            dtype=float).reshape(-1, self._width)
        return np.asarray(values, dtype=self._dtype)

    def __len__(self) -> int:
        return sum(b.shape[0] for b in self._blocks) + len(self._cur)

    def array(self) -> np.ndarray:
        """The whole series as one array ((n,) or (n, width))."""
        parts = [*self._blocks, self._stack(self._cur)]
        return parts[0] if len(parts) == 1 else np.concatenate(parts)

    def values(self) -> list[Any]:
        """The values, row by row (tuples in a ``width``-wide series)."""
        if not self._blocks:
            return list(self._cur)
        return [tuple(r) if isinstance(r, list) else r for r in self.array().tolist()]


class _RecordingFilter(ComplementaryFilter):
    """The pipeline's filter, recording what the pipeline passes it (accepted samples only),
    how the velocity aiding ran each row and where it resets: the offline replay runs
    :mod:`cf_estimator.core.offline` on them."""

    def __init__(self, params: FilterParams) -> None:
        super().__init__(params)
        self.rows: list[tuple[float, ...]] = []  #: gyro (3), accel (3), mag (3, NaN = none)
        #: per row, offline.ROW_AIDED / ROW_MOVING as the velocity aiding ran it (0: unaided)
        self.flags: list[int] = []
        self.starts: list[int] = [0]  #: row index of each reset
        self._in_update = False
        self._moving = False  # interrupt_rest was called before the next update

    def reset(self) -> None:
        super().reset()
        # a reset by the pipeline (not the one inside initialisation) starts a segment
        if getattr(self, "rows", None) and not self._in_update and \
                self.starts[-1] != len(self.rows):
            self.starts.append(len(self.rows))

    def interrupt_rest(self) -> None:
        super().interrupt_rest()
        self._moving = True

    def _update(self, gyro_rad_s: Any, accel_m_s2: Any, dt_s: float, mag: Any = None) -> Any:
        """Record the row the step takes (after the aiding's input), then step."""
        m = tuple(mag) if mag is not None else (math.nan, math.nan, math.nan)
        self.rows.append((*gyro_rad_s, *accel_m_s2, *m))
        self.flags.append((ROW_AIDED if self.step_state.aided else 0)
                          | (ROW_MOVING if self._moving else 0))
        self._moving = False
        self._in_update = True
        try:
            return super()._update(gyro_rad_s, accel_m_s2, dt_s, mag)
        finally:
            self._in_update = False

    def run_rows(self, gyro_rad_s: np.ndarray, accel_m_s2: np.ndarray, mag: np.ndarray | None,
                 dt_s: np.ndarray, start: int, q_out: np.ndarray,
                 extra_out: np.ndarray | None = None) -> None:
        """Record rows ``start``.. (unaided: the aiding steps through :meth:`_update`), then
        step them."""
        n = gyro_rad_s.shape[0] - start
        m = mag[start:] if mag is not None else np.full((n, 3), math.nan)
        self.rows.extend(map(tuple, np.concatenate(
            (gyro_rad_s[start:], accel_m_s2[start:], m), axis=1).tolist()))
        flag = ROW_AIDED if self.step_state.aided else 0
        self.flags.extend([flag | (ROW_MOVING if self._moving else 0)] + [flag] * (n - 1))
        self._moving = False
        super().run_rows(gyro_rad_s, accel_m_s2, mag, dt_s, start, q_out, extra_out)


def _offline_orientations(t_s: np.ndarray, rec: _RecordingFilter, params: FilterParams,
                          max_dt_s: float) -> tuple[np.ndarray, int]:
    """((N, 4) offline q_world_from_sensor per processed message, number of segments): the
    pipeline's accepted samples, split at its resets and at gaps over ``max_dt_s`` (where it
    did not integrate), each segment through :func:`cf_estimator.core.offline.smooth_segment`,
    its rows run as the velocity aiding ran them (aided, not at rest)."""
    from cf_estimator.core.filter import EXTRA_COLUMNS
    from cf_estimator.core.offline import smooth_segment

    rows = np.asarray(rec.rows, dtype=float).reshape(-1, 9)
    n = rows.shape[0]
    q = np.full((n, 4), np.nan)
    bounds = set(rec.starts) | {0, n}
    if n > 1:
        bounds |= set((np.flatnonzero(np.diff(t_s) > max_dt_s) + 1).tolist())
    edges = sorted(bounds)
    use_mag = params.use_mag and bool(np.any(np.isfinite(rows[:, 6])))
    flags = np.asarray(rec.flags, dtype=np.int8) if any(rec.flags) else None
    count = 0
    for a, b in zip(edges[:-1], edges[1:], strict=True):
        if b <= a:
            continue
        count += 1
        g, acc = np.ascontiguousarray(rows[a:b, 0:3]), np.ascontiguousarray(rows[a:b, 3:6])
        mg = np.ascontiguousarray(rows[a:b, 6:9]) if use_mag else None
        smooth_segment(g, acc, mg, t_s[a:b], params, q[a:b], np.zeros((b - a, EXTRA_COLUMNS)),
                       flags=flags[a:b] if flags is not None else None)
    return q, count


class _Run:
    """The per-variant state of a replay pass: pipeline, output bag, collected series."""

    def __init__(self, variant: ReplayVariant, opts: ReplayOptions, topics: list[str],
                 types: dict[str, str | None], factory: Callable[[], Any] | None) -> None:
        self.variant = variant
        self.fparams = variant.filter_params or FilterParams()
        self.pparams = variant.pipeline_params or PipelineParams()
        self.pipe = factory() if factory else ImuPipeline(self.fparams, self.pparams)
        self.period_ns = int(round(self.pparams.diagnostics_period_s * 1e9))
        self.publish_rpy = bool(self.pparams.publish_rpy)
        self.publish_accel = bool(self.pparams.publish_linear_acceleration)
        self.out_path = Path(variant.output_path) if variant.output_path is not None else None
        self.bag: io.OutputBag | None = None
        self.t = _Col()  #: header stamp [s] per output
        self.q = _Col(4)  #: w, x, y, z per output (None: no attitude)
        self.rpy = _Col(3)
        self.clipped = _Col(dtype=bool)
        self.enorm = _Col()
        self.bias_t = _Col()  #: the bias samples: stamp [s], estimate (3) and sigma
        self.bias = _Col(3)
        self.bias_sigma = _Col()
        self.rest = _Col(dtype=bool)
        self.tilt_var = _Col()
        self.yaw_var = _Col()
        self.next_bias_t = -math.inf
        self.warnings: list[str] = []
        self._seen: set[str] = set()
        self.n_diag = 0
        self.next_diag_ns: int | None = None
        self.copy_inputs = opts.copy_inputs
        self.offline = opts.offline
        self.online_rpy: list[Any] = []
        self.held: list[tuple[int, str, str, Any]] = []  #: offline: outputs written at the end
        self.outputs: list[tuple[int, Any]] = []
        self.offline_segments = 0
        if self.offline:
            self.recorder = _RecordingFilter(frames.core_params(self.fparams))
            self.pipe.replace_filter(self.recorder)  # same filter, recording its input
        if self.out_path is not None:
            self.bag = io.OutputBag(self.out_path, storage=opts.storage, overwrite=opts.overwrite)
            self.bag.add_topic(OUT_IMU_TOPIC, io.IMU_TYPE)
            if self.publish_rpy:
                self.bag.add_topic(OUT_RPY_TOPIC, io.VECTOR3_STAMPED_TYPE)
            self.bag.add_topic(OUT_DIAGNOSTICS_TOPIC, io.DIAGNOSTIC_ARRAY_TYPE)
            if self.publish_accel:
                self.bag.add_topic(OUT_ACCEL_TOPIC, io.ACCEL_WITH_COVARIANCE_STAMPED_TYPE)
                self.bag.add_topic(OUT_ACCEL_WORLD_TOPIC, io.ACCEL_WITH_COVARIANCE_STAMPED_TYPE)
            if opts.copy_inputs:
                for t in topics:
                    self.bag.add_topic(t, types[t] or "")
            self.bag.set_custom_data("cf_estimator.mode", "offline" if self.offline else "online")

    def tick(self, log_ns: int) -> None:
        """The node's diagnostics timer (bag clock): one report per elapsed period."""
        if self.next_diag_ns is None:
            self.next_diag_ns = log_ns + self.period_ns
            return
        if log_ns >= self.next_diag_ns:
            if self.bag is not None:
                report = self.pipe.diagnostics(self.next_diag_ns * 1e-9)
                if self.offline:
                    msg = io.diagnostics_message(self.next_diag_ns, [report])
                    self.held.append((self.next_diag_ns, OUT_DIAGNOSTICS_TOPIC,
                                      io.DIAGNOSTIC_ARRAY_TYPE, msg))
                else:  # the bytes rosbags would serialize (bag/cdr.py)
                    self.bag.write_raw(OUT_DIAGNOSTICS_TOPIC, io.DIAGNOSTIC_ARRAY_TYPE,
                                       self.next_diag_ns,
                                       cdr.diagnostic_array_cdr(self.next_diag_ns, [report]))
            self.n_diag += 1
            missed = (log_ns - self.next_diag_ns) // self.period_ns
            self.next_diag_ns += self.period_ns * (missed + 1)

    def events(self, ev: Events) -> None:
        """IMU, magnetometer, velocity and other messages (log order) through the pipeline,
        a diagnostics period's worth at a time (:meth:`tick` between them)."""
        i, n = 0, len(ev)
        logs = ev.log_ns
        while i < n:
            self.tick(logs[i])
            # the events before the next report (log times are sorted in a chunk)
            stop = bisect.bisect_left(logs, self.next_diag_ns, i, n) if \
                self.next_diag_ns is not None else n
            stop = max(stop, i + 1)
            for rows in self.pipe.process(ev, i, stop):
                self.write(rows)
            self._internal_error()
            i = stop

    def _internal_error(self) -> None:
        bug = self.pipe.take_internal_error()
        if bug is not None:  # counted as internal_error in the summary; said once here
            print("cf-estimator: internal error (a bug, please report it): the message "
                  f"was dropped, the replay goes on\n{bug}", file=sys.stderr)

    def write(self, rows: Rows) -> None:
        """A run's outputs: the output messages (held until the end when offline) and the
        series."""
        ts = rows.sec + rows.nsec * 1e-9  # s + ns * 1e-9 per row
        marks = []
        next_bias = self.next_bias_t
        t_list = ts.tolist()
        n = len(t_list)
        # stamps increase in a run: the next bias sample is the first stamp at or after
        # next_bias
        k = bisect.bisect_left(t_list, next_bias)
        while k < n:
            marks.append(k)
            next_bias = t_list[k] + _BIAS_SAMPLE_PERIOD_S
            k = bisect.bisect_left(t_list, next_bias, k + 1)
        self.next_bias_t = next_bias
        if marks:  # the bias estimate after each marked row
            self.bias_t.add(ts[marks])
            self.bias.add(rows.extra[marks, Extra.GYRO_BIAS])
            self.bias_sigma.add(rows.extra[marks, Extra.BIAS_SIGMA])
        bag = self.bag
        log_ns = rows.log_ns
        if self.offline:  # written at the end, with the offline orientation
            self.outputs.extend((int(log_ns[k]), rows.output(k)) for k in range(n))
        elif bag is not None:  # every output message of the run encoded in place at once
            sec, nsec = rows.sec, rows.nsec
            topics = [(OUT_IMU_TOPIC, io.IMU_TYPE, cdr.imu_cdr_size(rows.frame))]
            if self.publish_rpy:
                topics.append((OUT_RPY_TOPIC, io.VECTOR3_STAMPED_TYPE,
                               cdr.vector3_stamped_size(rows.frame)))
            rec, payloads = io.record_rows(n, [size for _t, _m, size in topics])
            cdr.imu_cdr_rows(sec, nsec, rows.frame, rows.q_wxyz[:, [1, 2, 3, 0]],
                             rows.covariance, rows.gyro, rows.av_cov, rows.accel, rows.la_cov,
                             out=payloads[0])
            if self.publish_rpy:
                cdr.vector3_stamped_rows(sec, nsec, rows.frame, rows.rpy, out=payloads[1])
            bag.write_records(log_ns, topics, rec)
            if rows.gravity_free is not None:
                for k in range(n):
                    self._write_accel(bag, int(log_ns[k]), rows.output(k))
        self.t.add(ts)
        self.q.add(rows.q_wxyz)
        self.rpy.add(rows.rpy)
        self.clipped.add(rows.extra[:, Extra.CLIPPED] != 0.0)
        self.enorm.add(rows.error_norm)
        self.rest.add(rows.extra[:, Extra.AT_REST] != 0.0)
        self.tilt_var.add(rows.covariance[:, 0] + rows.covariance[:, 4])
        self.yaw_var.add(rows.covariance[:, 8])
        for text in rows.warnings:
            if text not in self._seen:
                self._seen.add(text)
                self.warnings.append(text)

    def finish_offline(self) -> None:
        """Offline: replace every output's orientation by the offline estimate, then write the
        held outputs and diagnostics in log-time order."""
        t = self.t.array()
        q, self.offline_segments = _offline_orientations(t, self.recorder,
                                                         frames.core_params(self.fparams),
                                                         self.pparams.max_dt_s)
        q = self.pipe.output_frame.apply_array(q)  # published world frame, as online
        self.online_rpy = self.rpy.values()  # what the online filter said, for the plots
        self.q = _Col(4, [tuple(r) if np.all(np.isfinite(r)) else None for r in q.tolist()])
        rpy = quat.to_euler(q)
        self.rpy = _Col(3, [tuple(r) if np.all(np.isfinite(r)) else None for r in rpy.tolist()])
        for (log_ns, out), qi, ri in zip(self.outputs, self.q.values(), self.rpy.values(),
                                         strict=True):
            if qi is not None:
                w, x, y, z = qi
                out = dataclasses.replace(out, orientation_xyzw=(x, y, z, w), rpy_rad=ri)
            self.held.append((log_ns, OUT_IMU_TOPIC, io.IMU_TYPE, out))
        self.outputs = []
        bag = self.bag
        if bag is not None:
            for log_ns, topic, msgtype, item in sorted(self.held, key=lambda h: h[0]):
                if topic == OUT_IMU_TOPIC:
                    bag.write_raw(topic, msgtype, log_ns, cdr.imu_cdr(item))
                    if self.publish_rpy and item.rpy_rad is not None:
                        bag.write_raw(OUT_RPY_TOPIC, io.VECTOR3_STAMPED_TYPE, log_ns,
                                      cdr.vector3_stamped_cdr(item.stamp_sec, item.stamp_nanosec,
                                                              item.frame_id, item.rpy_rad))
                    if self.publish_accel and item.initialized:
                        self._write_accel(bag, log_ns, self._offline_accel(item))
                else:
                    bag.write(topic, msgtype, log_ns, item)
        self.held = []

    def _offline_accel(self, out: Any) -> Any:
        """The gravity-free acceleration of an output whose orientation the offline pass
        replaced (the online covariance kept)."""
        from cf_estimator.pipeline.linear_acceleration import gravity_free

        fp = self.pipe.filter_params
        return dataclasses.replace(out, gravity_free=gravity_free(
            out.orientation_xyzw, out.linear_acceleration, out.orientation_covariance,
            out.linear_acceleration_covariance, fp.gravity_m_s2, fp.world_frame))

    def _write_accel(self, bag: Any, log_ns: int, out: Any) -> None:
        """imu/linear_acceleration (body axes, the output's frame id) and ..._world (frame id
        tf_parent_frame): geometry_msgs/AccelWithCovarianceStamped, gravity removed."""
        if out.gravity_free is None:
            return
        a_b, c_b, a_w, c_w = out.gravity_free
        bag.write(OUT_ACCEL_TOPIC, io.ACCEL_WITH_COVARIANCE_STAMPED_TYPE, log_ns,
                  io.accel_with_covariance_message(out.stamp_sec, out.stamp_nanosec,
                                                   out.frame_id, a_b, c_b))
        bag.write(OUT_ACCEL_WORLD_TOPIC, io.ACCEL_WITH_COVARIANCE_STAMPED_TYPE, log_ns,
                  io.accel_with_covariance_message(out.stamp_sec, out.stamp_nanosec,
                                                   self.pparams.tf_parent_frame, a_w, c_w))

    def abort(self) -> None:
        if self.bag is not None:
            self.bag.abort()


def _add_reference(ref_type: str | None, msg: Any, ref_t: list[float],
                   ref_q: list[tuple[float, float, float, float]]) -> None:
    """A reference message's stamp and normalised (w, x, y, z), when it has an orientation."""
    h = msg.header.stamp
    q = reference_quaternion(ref_type or "", msg)
    nq = math.sqrt(sum(c * c for c in q))
    if math.isfinite(nq) and nq > 0.5:
        ref_t.append(h.sec + h.nanosec * 1e-9)
        ref_q.append((q[0] / nq, q[1] / nq, q[2] / nq, q[3] / nq))


def replay_bag(
    input_path: str | os.PathLike[str],
    output_path: str | os.PathLike[str] | None,
    filter_params: FilterParams | None = None,
    pipeline_params: PipelineParams | None = None,
    options: ReplayOptions | None = None,
    *,
    pipeline_factory: Callable[[], Any] | None = None,
) -> ReplayResult:
    """Replay ``input_path`` through a fresh ``ImuPipeline``; write ``output_path`` (if given).

    Raises :class:`cf_estimator.bag.io.BagError` / :class:`ReplayError` with one-line messages
    naming the file. The output bag appears only when everything was written.
    """
    variant = ReplayVariant("replay", filter_params, pipeline_params, output_path)
    return replay_variants(input_path, [variant], options, pipeline_factory=pipeline_factory)[0]


@dataclass(frozen=True)
class _Topics:
    """The input topics a replay reads (None: not read) and their message types."""

    imu: str
    mag: str | None
    reference: str | None
    reference_type: str | None
    velocity: str | None
    names: list[str]  #: the topics to read, each once (the reference may be the IMU topic)
    types: dict[str, str | None]

    def in_summary(self) -> dict[str, str | None]:
        """The summary's ``topics`` entry."""
        return {"imu": self.imu, "mag": self.mag, "reference": self.reference,
                **({"velocity": self.velocity} if self.velocity else {})}


def _select_topics(bag: Any, opts: ReplayOptions, px4_in: _Px4Input | None) -> _Topics:
    """The IMU (required), magnetometer, reference and velocity topics by the options (a
    ulog's vehicle_attitude is the reference unless another one was asked for)."""
    imu = bag.select_topic("IMU", opts.imu_topic, [io.IMU_TYPE], required=True,
                           option="--imu-topic")
    assert imu is not None
    mag = None
    if opts.mag_topic is None or opts.mag_topic.lower() != "none":
        mag = bag.select_topic("magnetometer", opts.mag_topic, [io.MAG_TYPE], required=False,
                               option="--mag-topic")
    ref = None
    if px4_in is not None and px4_in.reference:
        ref = px4_in.reference_topic  # the autopilot's own estimate, beside ours
    elif opts.reference_topic is not None and opts.reference_topic.lower() != "none":
        ref = bag.select_topic("reference", opts.reference_topic,
                               (*io.REFERENCE_TYPES, io.IMU_TYPE), required=True,
                               option="--reference-topic")
    vel = None
    if opts.velocity_topic is not None:
        vel = bag.select_topic("velocity", opts.velocity_topic, io.VELOCITY_TYPES,
                               required=True, option="--velocity-topic")
    names = list(dict.fromkeys(t for t in (imu, mag, ref, vel) if t))
    return _Topics(imu, mag, ref, bag.msgtype_of(ref) if ref else None, vel, names,
                   {t: bag.msgtype_of(t) for t in names})


@dataclass
class _Reading:
    """What the one pass over the input counted and collected for every variant."""

    n_imu: int = 0
    n_mag: int = 0
    n_ref: int = 0  #: reference messages (not counted again when the reference is the IMU)
    n_vel: int = 0
    first_log_ns: int | None = None
    last_log_ns: int | None = None
    ref_t: list[float] = field(default_factory=list)  #: reference stamps [s]
    ref_q: list[tuple[float, float, float, float]] = field(default_factory=list)

    @property
    def n_read(self) -> int:
        """Messages read on the replayed topics."""
        return self.n_imu + self.n_mag + self.n_ref + self.n_vel

    def logged(self, first_ns: int, last_ns: int) -> None:
        """Extend the read span of log times [ns]."""
        if self.first_log_ns is None:
            self.first_log_ns = first_ns
        self.last_log_ns = last_ns


def _read_in_bulk(bag: Any, topics: _Topics, runs: Sequence[_Run], reading: _Reading,
                  progress: _Progress) -> None:
    """Chunks of decoded messages through every run's pipeline at once (pipeline/process.py);
    references as arrays where the reader has them."""
    table = {t: k for t, k in ((topics.velocity, VELOCITY), (topics.mag, MAG),
                               (topics.imu, IMU)) if t}
    for chunk in bag.chunks(topics.names):
        reading.logged(chunk.log_ns[0], chunk.log_ns[-1])
        arrays = None
        if hasattr(chunk, "kind_array"):  # the mcap reader's: arrays, no list to convert back
            kind_arr = chunk.kind_array(table, OTHER)
            kinds = kind_arr.tolist()
            arrays = (kind_arr, chunk.log_ns_array, chunk.row_array)
        else:
            kinds = [table.get(t, OTHER) for t in chunk.topic]
        reading.n_imu += kinds.count(IMU)
        reading.n_mag += kinds.count(MAG)
        reading.n_vel += kinds.count(VELOCITY)
        ev = Events(kinds, chunk.log_ns, chunk.row, chunk.blocks.get(io.IMU_TYPE),
                    chunk.blocks.get(io.MAG_TYPE), chunk.msg, arrays)
        for run in runs:
            run.events(ev)
        ref = topics.reference
        fast_ref = getattr(chunk, "references", None)  # a ulog's, as arrays
        if ref is not None and fast_ref is not None and ref != topics.imu:
            reading.n_ref += fast_ref(ref, reading.ref_t, reading.ref_q)
        elif ref is not None:
            for i, t in enumerate(chunk.topic):
                if t == ref:
                    if t != topics.imu:
                        reading.n_ref += 1
                    _add_reference(topics.reference_type, chunk.msg(i), reading.ref_t,
                                   reading.ref_q)
        progress.add(len(chunk))


#: Messages read as objects handed to the pipelines at once (without copied inputs).
_MESSAGE_CHUNK = 1024


def _read_messages(bag: Any, topics: _Topics, runs: Sequence[_Run], copy: bool,
                   decode_bulk: bool, reading: _Reading, progress: _Progress) -> None:
    """Message objects in log-time order to every run's pipeline, a chunk at a time (with
    ``copy``, each input message into the output bags first, one message a chunk: the copies
    and the outputs are written in log-time order)."""
    table = {t: k for t, k in ((topics.velocity, VELOCITY), (topics.mag, MAG),
                               (topics.imu, IMU)) if t}
    items: list[tuple[int, int, Any]] = []

    def flush() -> None:
        if items:
            ev = message_events(items)
            for r in runs:
                r.events(ev)
            items.clear()

    for m in bag.messages(topics.names, bulk=decode_bulk):
        log_ns = m.log_time_ns
        reading.logged(log_ns, log_ns)
        if copy:
            for r in runs:
                r.tick(log_ns)
            jazzy = bag.to_jazzy(m.msg, m.msgtype)
            for r in runs:
                if r.bag is not None:
                    r.bag.write(m.topic, m.msgtype, log_ns, jazzy)
        kind = table.get(m.topic, OTHER)
        items.append((kind, log_ns, m.msg))
        if kind == IMU:
            reading.n_imu += 1
        elif kind == MAG:
            reading.n_mag += 1
        elif kind == VELOCITY:
            reading.n_vel += 1
        if m.topic == topics.reference:
            if m.topic != topics.imu:
                reading.n_ref += 1
            _add_reference(topics.reference_type, m.msg, reading.ref_t, reading.ref_q)
        if copy or len(items) >= _MESSAGE_CHUNK:
            flush()
        progress.tick()
    flush()


def replay_variants(
    input_path: str | os.PathLike[str],
    variants: Sequence[ReplayVariant],
    options: ReplayOptions | None = None,
    *,
    pipeline_factory: Callable[[], Any] | None = None,
) -> list[ReplayResult]:
    """Replay one input bag through one fresh pipeline per variant, reading the bag once."""
    opts = options or ReplayOptions()
    t_wall = time.perf_counter()
    in_path = Path(input_path)
    if opts.storage not in io.STORAGES:
        raise ReplayError(f"unknown storage {opts.storage!r}; choose mcap or sqlite3")
    resolve_heading_alignment(opts.heading_alignment, True)  # validate early
    for v in variants:
        if v.output_path is not None:
            io.check_output_path(Path(v.output_path), overwrite=opts.overwrite, inputs=[in_path])

    with io.open_bag(in_path, ulog_instance=opts.instance) as bag:
        px4_in = _px4_input(bag, opts, variants)
        if px4_in is not None:
            variants = px4_in.variants
        topics = _select_topics(bag, opts, px4_in)
        # a truncated bag read as far as readable (bag/salvage.py): said once, in the warnings
        in_notes = list(getattr(bag, "notes", ())) if px4_in is None else []
        total = bag.count(topics.names)
        in_format = bag.format
        runs: list[_Run] = []
        progress: _Progress | None = None
        reading = _Reading()
        try:
            for v in variants:
                runs.append(_Run(v, opts, topics.names, topics.types, pipeline_factory))
            progress = _Progress(total, opts.progress, in_path.name, opts.on_messages)
            copy = opts.copy_inputs and any(r.bag is not None for r in runs)
            # IMU and magnetometer decoded in bulk (bag/cdr.py) and through the pipelines in
            # chunks, except when the inputs are copied: those need rosbags' message objects
            decode_bulk = not copy and opts.bulk_decode
            if decode_bulk and opts.bulk_pipeline:
                _read_in_bulk(bag, topics, runs, reading, progress)
            else:
                _read_messages(bag, topics, runs, copy, decode_bulk, reading, progress)
            if reading.n_imu == 0:
                raise io.BagError(f"{in_path}: topic {topics.imu!r} yielded no messages")
            if reading.n_read < total:
                # e.g. garbage inside an mcap chunk written without CRC: the reader skips
                # records silently; an output would look complete with data missing
                raise io.BagError(
                    f"{in_path}: read {reading.n_read} of the {total} messages its "
                    "index lists on the replayed topics: the bag is corrupt"
                )
        except BaseException:
            if progress is not None:
                progress.close()
            for r in runs:
                r.abort()
            raise
        progress.close()
        try:
            for r in runs:
                if r.offline:
                    r.finish_offline()
        except BaseException:
            for r in runs:
                r.abort()
            raise

    wall = time.perf_counter() - t_wall
    try:
        results = [_result(r, in_path, in_format, topics, reading, opts, px4_in, wall)
                   for r in runs]
        for res in results:
            res.summary["warnings"][:0] = in_notes
    except BaseException:
        for r in runs:
            r.abort()
        raise
    # nothing that looks like a good result is left behind: an unusable run writes no output
    reason = next((why for why in (checks.unusable_reason(res.summary) for res in results)
                   if why), None)
    if reason is not None:
        for r in runs:
            r.abort()
        raise UnusableInput(f"{in_path}: {reason}")
    for r in runs:
        if r.bag is not None:
            r.bag.commit()
    return results


def _result(r: _Run, in_path: Path, in_format: str, topics: _Topics, reading: _Reading,
            opts: ReplayOptions, px4_in: _Px4Input | None, wall: float) -> ReplayResult:
    """One variant's summary (the replay JSON), series and scored reference."""
    if px4_in is not None:
        r.warnings[:0] = px4_in.notes
    r_ref_t, r_ref_q = reading.ref_t, reading.ref_q
    autopilot_ref = px4_in is not None and topics.reference in px4_in.estimate_topics
    if autopilot_ref:
        r_ref_t, r_ref_q = px4_in.reference_in_output(r, reading.ref_t, reading.ref_q)
    series = _series(r, r_ref_t, r_ref_q)
    counters = _jsonable(dict(r.pipe.counters))
    stamps = series.t_s
    duration = float(stamps[-1] - stamps[0]) if stamps.size > 1 else 0.0
    init = np.all(np.isfinite(series.q_wxyz), axis=1)
    clip_frac = float(np.mean(series.clipped[init])) if init.any() else None
    final_bias = (
        [float(c) for c in r.pipe.filter.gyro_bias_rad_s] if r.pipe.initialized else None
    )
    status = r.pipe.filter.status() if r.pipe.initialized else None
    bias_t = r.bias_t.array()
    converged = r.bias_sigma.array() < BIAS_CONVERGED_SIGMA_RAD_S
    mag_in_use = topics.mag is not None and r.fparams.use_mag
    first, last = reading.first_log_ns, reading.last_log_ns
    summary: dict[str, Any] = {
        "variant": r.variant.name,
        "mode": "offline" if r.offline else "online",
        "input": str(in_path),
        "input_format": in_format,
        "output": str(r.out_path) if r.out_path is not None else None,
        "storage": opts.storage if r.out_path is not None else None,
        "topics": topics.in_summary(),
        "messages_in": reading.n_imu,
        "mag_messages_in": reading.n_mag,
        "reference_messages_in": reading.n_ref,
        "messages_processed": int(counters.get("processed", len(r.t))),
        "messages_rejected": counters.get("rejected", {}),
        "gaps": counters.get("gaps"),
        "resets": counters.get("resets"),
        "outputs_written": dict(r.bag.counts) if r.bag is not None else {},
        "diagnostics_reports": r.n_diag,
        "duration_s": duration,
        "bag_duration_s": (last - first) * 1e-9 if first is not None and last is not None
        else 0.0,
        "imu_rate_hz": (stamps.size - 1) / duration if duration > 0 else None,
        "clipped_fraction": clip_frac,
        "final_gyro_bias_rad_s": final_bias,
        "final_gyro_bias_sigma_rad_s": status.gyro_bias_sigma_rad_s if status else None,
        "gyro_bias_converged": status.gyro_bias_converged if status else False,
        "gyro_bias_converged_after_s": (
            float(bias_t[int(np.argmax(converged))] - bias_t[0])
            if converged.any() else None),
        "still_fraction": float(np.mean(series.at_rest[init])) if init.any() else None,
        **({"velocity": _velocity_summary(r.pipe, reading.n_vel)} if topics.velocity else {}),
        "counters": counters,
        "warnings": r.warnings,
        **({"offline": {"segments": r.offline_segments,
                        "note": "orientations from cf_estimator.core.offline (acausal); "
                                "the pipeline's guards chose the samples; /diagnostics "
                                "and the bias report the online filter"}}
           if r.offline else {}),
        # what reproduces the run: the effective parameters, the version, the backend
        "parameters": {"filter": as_dict(r.fparams), "pipeline": as_dict(r.pparams)},
        "version": __version__,
        "filter_backend": resolve_backend(),
        "wall_time_s": wall,
        "messages_per_s": (reading.n_imu + reading.n_mag + reading.n_ref) / wall
        if wall > 0 else None,
    }
    scored = None
    align: str | None = None
    if topics.reference is not None:
        align = resolve_heading_alignment(opts.heading_alignment, mag_in_use)
        if autopilot_ref and opts.heading_alignment == "auto" and px4_in.heading_unknown:
            align = "mean"  # the autopilot's north is not in the log (px4_in's note says so)
        stats, scored = error_statistics(series.t_s, series.q_wxyz, series.ref_t_s,
                                         series.ref_q_wxyz, align)
        stats["topic"] = topics.reference
        if autopilot_ref:
            stats["kind"] = "autopilot"
            stats["label"] = autopilot_label(topics.reference)
        if not r.offline and scored and stats.get("kind") != "autopilot":
            # the reported sigma against a ground truth (not against another estimate)
            stats["covariance"] = covariance_consistency(series, scored, mag_in_use)
        summary["reference"] = stats
        summary["rmse_deg"] = stats.get("rmse_deg")
    if px4_in is not None:
        summary[px4_in.kind] = px4_in.summary(r, series, align if topics.reference else None)
    return ReplayResult(_jsonable(summary), series, r.out_path, scored)


def autopilot_label(topic: str) -> str:
    """The label of a comparison with the autopilot's own estimate (``topic`` of the log)."""
    return (f"agreement with the autopilot's estimate ({topic}, itself an estimate), not "
            "ground truth")


AUTOPILOT_LABEL = autopilot_label(ulog.ATTITUDE_TOPIC)
#: Below this share of the log's duration covered by the IMU, the replay says so.
IMU_COVERAGE_WARN_FRACTION = 0.5


@dataclass
class _Px4Input:
    """What an autopilot's flight log (a PX4 ulog, an ArduPilot DataFlash log) changes in a
    replay: the conventions, the comparison with the autopilot's estimate, notes."""

    bag: Any
    variants: list[ReplayVariant]
    changed: list[str]
    reference: bool  #: compare with the log's attitude (vehicle_attitude, ATT)
    notes: list[str]
    span: tuple[float, float, float]  #: first, last IMU stamp, log duration [s]
    kind: str = "px4"  #: the summary's key: ``px4`` or ``ardupilot``
    reference_topic: str = ulog.ATTITUDE_TOPIC  #: the log's attitude compared by default
    #: the log's topics that are the autopilot's estimates (FRD → NED quaternions)
    estimate_topics: tuple[str, ...] = (ulog.ATTITUDE_TOPIC,)
    heading_unknown: bool = False  #: the autopilot's north (declination) is not in the log
    scored_until_s: float | None = None  #: the comparison ends here [s] (a flip or crash)

    def reference_in_output(self, r: _Run, ref_t: Sequence[float], ref_q: Sequence[Any]
                            ) -> tuple[list[float], list[Any]]:
        """The autopilot's attitude (FRD → NED) in the run's output frames, within the IMU's
        span and before a flip or crash."""
        t = np.asarray(ref_t, dtype=float)
        q = np.asarray(ref_q, dtype=float).reshape(-1, 4)
        lo, hi, _dur = self.span
        if self.scored_until_s is not None:
            hi = min(hi, self.scored_until_s)
        keep = (t >= lo - MAX_INTERPOLATION_GAP_S) & (t <= hi + MAX_INTERPOLATION_GAP_S)
        if self.scored_until_s is not None:
            keep &= t <= self.scored_until_s
        t, q = t[keep], q[keep]
        dec = self.bag.declination_at(t) if self.kind == "ardupilot" else None
        if dec is not None:  # the autopilot's true north -> ours (magnetic_declination_rad)
            turn = -(dec - r.pparams.magnetic_declination_rad)  # NED yaw: about +z down
            q = quat.multiply(quat.from_euler(0.0, 0.0, turn), q)
        world = r.fparams.world_frame
        qo = px4.attitude_in_output_frames(q, world,
                                           px4.output_body(r.pparams.body_frame, world))
        if qo is None:
            text = (f"{self.reference_topic} is not compared: no conversion into world frame "
                    f"{world}")
            if text not in r.warnings:
                r.warnings.append(text)
            return [], []
        return t.tolist(), [tuple(x) for x in qo.tolist()]

    def summary(self, r: _Run, series: ReplaySeries | None = None,
                align: str | None = None) -> dict[str, Any]:
        lo, hi, dur = self.span
        out = {"conventions_applied": list(self.changed),
               "instances": dict(self.bag.instances),
               "truncated": bool(self.bag.truncated), "imu_first_s": lo, "imu_last_s": hi,
               "log_duration_s": dur,
               "output_frames": f"{px4.output_body(r.pparams.body_frame, r.fparams.world_frame)}"
                                f" body -> {r.fparams.world_frame} world"}
        if self.kind == "px4":
            applied = [self.bag.mag_bias_text] if self.bag.mag_bias_ga is not None else []
            out["conventions_applied"] += applied
            out["magnetometer_bias"] = self.bag.mag_bias_text or None
            return out
        out.update({"vehicle": self.bag.vehicle or None, "magnetometer": self.bag.mag_text,
                    "upside_down_s": self.bag.upside_down_s,
                    "scored_until_s": self.scored_until_s,
                    "heading_alignment": align})
        if series is not None:
            out["estimates"] = self._other_estimates(r, series, align or "none")
        return out

    def _other_estimates(self, r: _Run, series: ReplaySeries, align: str
                         ) -> dict[str, dict[str, Any]]:
        """Ours against each of the log's other attitude estimates (AHR2, EKF1, NKF1, XKF1),
        the same way as against the reference: inclination and heading RMS / max [deg]."""
        out: dict[str, dict[str, Any]] = {}
        for topic in self.estimate_topics:
            stream = self.bag.streams.get(topic)
            if stream is None or stream.t_ns.shape[0] == 0:
                continue
            t_ref, q_ref = self.reference_in_output(r, (stream.t_ns * 1e-9).tolist(),
                                                    stream.values.tolist())
            if not t_ref:
                continue
            stats, _ = error_statistics(series.t_s, series.q_wxyz, np.asarray(t_ref),
                                        np.asarray(q_ref).reshape(-1, 4), align)
            if stats.get("rmse_deg"):
                out[topic] = {"samples_scored": stats["samples_scored"],
                              "inclination_rmse_deg": stats["rmse_deg"]["inclination"],
                              "inclination_max_deg": stats["max_deg"]["inclination"],
                              "heading_rmse_deg": stats["rmse_deg"]["heading"]}
        return out


def _px4_input(bag: Any, opts: ReplayOptions, variants: Sequence[ReplayVariant]
               ) -> _Px4Input | None:
    """An autopilot's flight log (a PX4 ulog, an ArduPilot DataFlash log): its conventions
    (FRD body, NED world, the log's declination) for every parameter the user did not set, the
    log's attitude as the comparison (unless another reference was asked for), and the
    reader's notes; None for a bag."""
    from cf_estimator.bag.dataflash import DataflashBag

    if not isinstance(bag, ulog.UlogBag | DataflashBag):
        return None
    ardupilot = isinstance(bag, DataflashBag)
    from_log, decl_note = bag.log_defaults() if ardupilot else (None, "")
    out, changed = [], []
    for v in variants:
        fp, pp, changed = px4.apply_px4_conventions(
            v.filter_params or FilterParams(), v.pipeline_params or PipelineParams(),
            opts.explicit_params, bag.parameters, from_log=from_log,
            declination_name="COMPASS_DEC" if ardupilot else px4.PX4_DECLINATION_PARAM)
        out.append(dataclasses.replace(v, filter_params=fp, pipeline_params=pp))
    notes = list(bag.notes)
    lo, hi, dur = bag.imu_coverage()
    if dur > 0 and (hi - lo) < IMU_COVERAGE_WARN_FRACTION * dur:
        notes.append(f"{bag.imu_topic} covers only {hi - lo:.1f} s ({lo:.1f} s to {hi:.1f} s "
                     f"since boot) of the {dur:.1f} s log: the estimate and the comparison "
                     "cover that span only")
    mag_used = out[0].filter_params.use_mag and opts.mag_topic != "none" if out else False
    if decl_note and mag_used:
        notes.append(decl_note)
    want_ref = opts.reference_topic is None and bag.count([bag.reference_topic]) > 0
    if not ardupilot:
        return _Px4Input(bag, out, changed, want_ref, notes, (lo, hi, dur))
    from cf_estimator.bag import dataflash

    return _Px4Input(bag, out, changed, want_ref, notes, (lo, hi, dur), kind="ardupilot",
                     reference_topic=dataflash.ATTITUDE_TOPIC,
                     estimate_topics=(dataflash.ATTITUDE_TOPIC, *dataflash.ESTIMATE_TOPICS),
                     heading_unknown=bool(decl_note) and bag.declination is None,
                     scored_until_s=bag.scored_until_s())


def _velocity_summary(pipe: Any, n_vel: int) -> dict[str, Any]:
    """The velocity aiding's counters and heading offset for the replay JSON."""
    aiding = pipe.velocity_aiding
    if aiding is None:
        return {"messages_in": n_vel, "aiding": "off"}
    st = aiding.status()
    return {
        "messages_in": n_vel, "aiding_at_end": st.mode, "used": st.used,
        "stale": st.rejected.get("too_old", 0),
        "rejected": {k: v for k, v in st.rejected.items() if v and k != "too_old"},
        "reanchors": st.reanchors, "aided_samples": st.aided_samples,
        "unaided_stale_samples": st.stale_samples, "heading_known": st.heading_known,
        "heading_offset_rad": st.heading_offset_rad,
        "heading_sigma_rad": st.heading_sigma_rad if math.isfinite(st.heading_sigma_rad)
        else None,
        "aided_axes_at_end": st.axes,
        "aided_horizontal_samples": st.horizontal_samples,
        "aided_fraction": st.aided_samples / max(1, pipe.counters.get("processed", 0)),
        "aided_horizontal_fraction": st.horizontal_samples
        / max(1, pipe.counters.get("processed", 0)),
        "time_to_aid_s": _finite_or_none(st.first_aided_t_s - st.first_velocity_t_s),
        "time_to_align_s": _finite_or_none(st.aligned_t_s - st.first_velocity_t_s),
        "aided_for_s_at_end": st.aided_for_s,
    }


def _finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def _series(r: _Run, ref_t: Sequence[float], ref_q: Sequence[Any]) -> ReplaySeries:
    return ReplaySeries(
        t_s=r.t.array(),
        q_wxyz=r.q.array(),
        rpy_rad=r.rpy.array(),
        clipped=r.clipped.array(),
        error_norm_rad=r.enorm.array(),
        bias_t_s=r.bias_t.array(),
        gyro_bias_rad_s=r.bias.array(),
        gyro_bias_sigma_rad_s=r.bias_sigma.array(),
        at_rest=r.rest.array(),
        online_rpy_rad=np.array([x if x is not None else (np.nan,) * 3 for x in r.online_rpy],
                                dtype=float).reshape(-1, 3),
        ref_t_s=np.asarray(ref_t, dtype=float),
        ref_q_wxyz=np.asarray(ref_q, dtype=float).reshape(-1, 4),
        tilt_var_rad2=r.tilt_var.array(),
        yaw_var_rad2=r.yaw_var.array(),
    )
