"""The pipeline's rules, written once over arrays: a chunk of events in, outputs and counters out.

:func:`process` takes events in log order (:class:`cf_estimator.pipeline.events.Events`: a
replay's thousands, the live node's one) and applies every rule of
:class:`cf_estimator.pipeline.pipeline.ImuPipeline` (its module docstring lists them), through
what the protocol :class:`Pipeline` names of it. Most of a recording is *ordinary* — valid
values, increasing stamps without a gap that resets, the frame ids and covariances of the
message before, a magnetometer past its unit check, an initialised filter — and a run of
ordinary events goes through the stages at once (:func:`_run`): the time base, magnetometer
pairing, the filter over the rows, counters, covariance, frames, roll/pitch/yaw. An event that
is not ordinary ends the run and is taken alone (:func:`_exceptional`): what only it needs (a
rejection, a reset, a warning, a unit check, a velocity message) is done, then, when it goes on,
it runs through the same stages as a run of one. Either way every stage exists once; a chunk
gives the same outputs, counters and state, bit for bit, however it is cut.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Mapping
from dataclasses import dataclass, field
from time import perf_counter
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np

from cf_estimator.core.filter import EXTRA_COLUMNS, Extra, state_extras
from cf_estimator.core.kernel import compiled_kernel
from cf_estimator.core.step import MAG_DISABLED, MAG_REJECTED, MAG_USED
from cf_estimator.pipeline import checks, columns
from cf_estimator.pipeline.events import IMU, MAG, VELOCITY, Events
from cf_estimator.pipeline.linear_acceleration import gravity_free

if TYPE_CHECKING:
    from cf_estimator.core.filter import ComplementaryFilter
    from cf_estimator.core.magcal import MagCorrection
    from cf_estimator.core.params import FilterParams
    from cf_estimator.core.velocity import VelocityAiding
    from cf_estimator.pipeline.covariance import OrientationCovariance
    from cf_estimator.pipeline.diagnostics import WindowStats
    from cf_estimator.pipeline.frames import OutputFrame
    from cf_estimator.pipeline.params import PipelineParams
    from cf_estimator.pipeline.state import (
        ImuTime,
        InputCovariance,
        InputRules,
        MagInput,
        MessageCounts,
    )

Vec3 = tuple[float, float, float]
TWO_PI = 2.0 * math.pi
#: squared norms beyond any sensor's range [(rad/s)², (m/s²)²]: rejected (checks.*_MAX_*)
GYRO_MAX2 = checks.GYRO_MAX_RAD_S**2
ACCEL_MAX2 = checks.ACCEL_MAX_M_S2**2
_GYRO_WARN2 = checks.GYRO_IMPLAUSIBLE_RAD_S**2
#: the value checks' rejection reasons, in the order they are applied (code k: _REASONS[k])
_REASONS = (None, checks.ZERO_STAMP, checks.NONFINITE_GYRO, checks.NONFINITE_ACCEL,
            checks.ZERO_ACCEL, checks.IMPLAUSIBLE_GYRO, checks.IMPLAUSIBLE_ACCEL)


class Pipeline(Protocol):
    """What the rules read and change of the pipeline they run for
    (:class:`cf_estimator.pipeline.pipeline.ImuPipeline` is the one): its state objects, the
    parameters and parts in force, and the few actions a rule triggers (a rejection, a reset,
    a warning, a message handled alone)."""

    rules: InputRules
    tally: MessageCounts
    clock: ImuTime
    mag_input: MagInput
    window: WindowStats
    mag_correction: MagCorrection
    covariance_model: OrientationCovariance
    angular_velocity_covariance: InputCovariance
    linear_acceleration_covariance: InputCovariance
    imu_frame: str | None
    accel_check_n: int
    acc_sum: list[float]
    last_rpy: Vec3 | None

    @property
    def filter(self) -> ComplementaryFilter: ...
    @property
    def filter_params(self) -> FilterParams: ...
    @property
    def pipeline_params(self) -> PipelineParams: ...
    @property
    def output_frame(self) -> OutputFrame: ...
    @property
    def velocity_aiding(self) -> VelocityAiding | None: ...
    @property
    def input_warning_tags(self) -> Mapping[str, str]: ...
    def warn(self, tag_text: tuple[str, str] | None) -> None: ...
    def reject(self, reason: str) -> None: ...
    def reset(self, reason: str) -> None: ...
    def take_warnings(self) -> list[str]: ...
    def covariance_bytes(self) -> bytes | None: ...
    def output_frame_id(self, input_frame_id: str) -> str: ...
    def on_velocity(self, msg: Any) -> str | None: ...
    def note_internal_error(self) -> None: ...
    def process_message(self, msg: Any, imu: bool = True, log_ns: int = 0) -> list[Rows]: ...


@dataclass(slots=True)
class PipelineOutput:
    """Contents of the output messages for one processed IMU message.

    ``orientation_xyzw`` is q_world_from_sensor in **ROS order** (x, y, z, w), world frame from
    FilterParams.world_frame. ``orientation_covariance``: row-major 3x3 about the world x, y, z
    axes [rad^2]; element 0 is -1 while not initialized. The other vectors and covariances are
    copied from the input. ``rpy_rad``: aerospace ZYX roll, pitch, yaw [rad] of the same
    orientation. ``warnings``: warn-once messages first raised by this message (or by
    magnetometer / rejected messages since the last output), for the adapter to log.
    """

    stamp_sec: int
    stamp_nanosec: int
    frame_id: str
    orientation_xyzw: tuple[float, float, float, float]
    orientation_covariance: tuple[float, ...]
    angular_velocity: Vec3
    angular_velocity_covariance: tuple[float, ...]
    linear_acceleration: Vec3
    linear_acceleration_covariance: tuple[float, ...]
    rpy_rad: Vec3 | None
    initialized: bool
    warnings: list[str] = field(default_factory=list)
    #: ``publish_linear_acceleration``: (a_body, cov_body, a_world, cov_world), gravity removed
    #: [m/s², m²/s⁴ row-major] (pipeline/linear_acceleration.py); None when off or not
    #: initialized
    gravity_free: tuple[Vec3, tuple[float, ...], Vec3, tuple[float, ...]] | None = None


@dataclass(slots=True)
class Rows:
    """The outputs of a run of processed IMU messages, one row each.

    ``q_wxyz`` q_world_from_sensor in the published world frame, ``rpy`` roll, pitch, yaw
    [rad], ``covariance`` (n, 9) row-major about the world axes [rad²]; ``gyro`` [rad/s] and
    ``accel`` [m/s²] as the filter took them (body convention of the output) with their
    covariances ``av_cov``/``la_cov`` as published; ``extra`` the filter state after each row
    (:class:`cf_estimator.core.filter.Extra`), ``error_norm`` |e| [rad]; ``frame`` the output
    frame id; ``gravity_free`` per row (publish_linear_acceleration) or None; ``warnings``:
    warn-once texts raised since the last output, for the adapter to log."""

    sec: np.ndarray
    nsec: np.ndarray
    log_ns: np.ndarray
    frame: str
    q_wxyz: np.ndarray
    rpy: np.ndarray
    covariance: np.ndarray
    gyro: np.ndarray
    accel: np.ndarray
    av_cov: tuple[float, ...]
    la_cov: tuple[float, ...]
    extra: np.ndarray
    error_norm: np.ndarray
    gravity_free: list[Any] | None
    warnings: list[str]

    @property
    def n(self) -> int:
        return int(self.sec.shape[0])

    def output(self, k: int) -> PipelineOutput:
        """Row ``k`` as the contents of one output message."""
        qw, qx, qy, qz = self.q_wxyz[k].tolist()
        gx, gy, gz = self.gyro[k].tolist()
        ax, ay, az = self.accel[k].tolist()
        roll, pitch, yaw = self.rpy[k].tolist()
        return PipelineOutput(
            int(self.sec[k]), int(self.nsec[k]), self.frame, (qx, qy, qz, qw),
            tuple(self.covariance[k].tolist()), (gx, gy, gz), self.av_cov, (ax, ay, az),
            self.la_cov, (roll, pitch, yaw), True, self.warnings if k == 0 else [],
            None if self.gravity_free is None else self.gravity_free[k])


def imu_valid(gyro: np.ndarray, accel: np.ndarray, sec: np.ndarray, nsec: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per IMU row: it passes every value check of :func:`imu_reasons` (its stamp is not zero,
    0 < |a|² ≤ ACCEL_MAX2 and |g|² ≤ GYRO_MAX2: a NaN or Inf component makes its norm fail the
    comparison, an overflow is implausible), |accel|² [(m/s²)²] and |gyro|² [(rad/s)²]."""
    with np.errstate(over="ignore", invalid="ignore"):
        a2 = np.add.reduce(accel * accel, axis=1)  # (x² + y²) + z²; inf when huge
        g2 = np.add.reduce(gyro * gyro, axis=1)
        ok = (g2 <= GYRO_MAX2) & (a2 <= ACCEL_MAX2) & (a2 != 0.0) & ((sec | nsec) != 0)
    return ok, a2, g2


def imu_reasons(gyro: np.ndarray, accel: np.ndarray, a2: np.ndarray, g2: np.ndarray,
                sec: np.ndarray, nsec: np.ndarray) -> np.ndarray:
    """Per IMU row (its squared norms from :func:`imu_valid`): the value checks' verdict, 0
    (valid) or k (rejected for ``_REASONS[k]``): the first check failed in the order zero
    stamp, non-finite gyro, non-finite accelerometer, zero accelerometer, implausible gyro,
    implausible accelerometer."""
    code = np.zeros(gyro.shape[0], dtype=np.int8)
    fails = [(sec | nsec) == 0, ~np.isfinite(gyro).all(axis=1), ~np.isfinite(accel).all(axis=1),
             a2 == 0.0, g2 > GYRO_MAX2, a2 > ACCEL_MAX2]
    for k in range(len(fails), 0, -1):  # the first check failed wins
        code[fails[k - 1]] = k
    return code


_NONE = np.zeros(0, dtype=bool)


def _where(kind: np.ndarray, k: int) -> np.ndarray:
    """Indices of the events of kind ``k`` (a chunk of one: without NumPy's call overhead)."""
    if kind.shape[0] == 1:
        return _AT0 if int(kind[0]) == k else _AT_NONE
    return np.flatnonzero(kind == k)


_AT0 = np.zeros(1, dtype=np.intp)
_AT_NONE = np.zeros(0, dtype=np.intp)


def _frame_codes(frames: list[Any], codes: dict[Any, int] | None = None) -> np.ndarray:
    """Per row: a code of its frame id, the same for equal ones (``codes``: frame id → code,
    filled here)."""
    codes = {} if codes is None else codes
    if frames.count(frames[0]) == len(frames):  # one frame id throughout (the usual case)
        return np.full(len(frames), codes.setdefault(frames[0], len(codes)), dtype=np.int64)
    return np.array([codes.setdefault(f, len(codes)) for f in frames], dtype=np.int64)


def _block_rows(blk: Any, row: np.ndarray, at: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[Any]]:
    """The rows of a block of decoded messages that the chunk's events ``at`` refer to
    (``row``: each event's row in the block): values, header sec and nanosec, plain and the
    frame ids. A block of one message (the node's) is its own row: its arrays, not copies."""
    sec, nsec, plain = blk.arrays()
    if blk.n == 1:
        return blk.values, sec, nsec, plain, list(blk.frame)
    rows = row[at]
    return (blk.values[rows], sec[rows], nsec[rows], plain[rows],
            [blk.frame[r] for r in rows.tolist()])


class _Chunk:
    """The events ``start``..``stop`` of a chunk as the stages read them (range coordinates:
    event ``start + i`` is ``i``), IMU and magnetometer rows in the body convention paired
    with the world frame, the magnetometer calibrated."""

    def __init__(self, pipe: Pipeline, ev: Events, start: int, stop: int) -> None:
        kind_a, log_a, row_a = ev.arrays()
        self.ev, self.start = ev, start
        self.n = stop - start
        self.kind = kind_a[start:stop]
        self.log_ns = log_a[start:stop]
        row = row_a[start:stop]
        flip = pipe.rules.flip
        #: range indices of the IMU, magnetometer and velocity events (as lists and arrays)
        self.imu_at, self.mag_at, vel_at = (_where(self.kind, k) for k in (IMU, MAG, VELOCITY))
        self.imu_list, self.mag_list = self.imu_at.tolist(), self.mag_at.tolist()
        self.vel_list = vel_at.tolist()
        # IMU rows
        if self.imu_list:
            v, self.sec, self.nsec, self.imu_plain, self.imu_frame = _block_rows(
                ev.imu, row, self.imu_at)
            if flip and v is ev.imu.values:  # turned in place below: not the block's own row
                v = v.copy()
            self.imu_values = v
            g = v[:, columns.ANGULAR_VELOCITY]
            a = v[:, columns.LINEAR_ACCELERATION]
            if flip:  # body_frame FLU <-> FRD: a half turn about x
                g[:, 1:] = -g[:, 1:]
                a[:, 1:] = -a[:, 1:]
            self.gyro, self.accel = g, a
            self.t_ns = self.sec * 1_000_000_000 + self.nsec
            self.valid, self.a2, self.g2 = imu_valid(g, a, self.sec, self.nsec)
            #: a row that would be ordinary after the row before it was: decoded, valid,
            #: stamped after it without a gap that resets, its frame id and covariances, no
            #: gyro unit warning to raise (row 0: checked against the pipeline's state)
            m = len(self.imu_list)
            self.d_ns = np.zeros(m, dtype=np.int64)  #: the stamp interval from the row before
            if m > 1:
                np.subtract(self.t_ns[1:], self.t_ns[:-1], out=self.d_ns[1:])
                fcode = _frame_codes(self.imu_frame)
                bits = np.concatenate((v[:, columns.ANGULAR_VELOCITY_COVARIANCE],
                                       v[:, columns.LINEAR_ACCELERATION_COVARIANCE]),
                                      axis=1).view("<u8")
                chain = self.imu_plain & self.valid
                chain[1:] &= ((fcode[1:] == fcode[:-1]) & (self.d_ns[1:] > 0)
                              & (bits[1:] == bits[:-1]).all(axis=1))
                if pipe.rules.reset_gap_on:
                    chain[1:] &= self.d_ns[1:] <= pipe.rules.reset_gap_ns
                self.chain = chain
                self.quiet_gyro = self.g2 <= _GYRO_WARN2
        self._mag_rows(pipe, ev, row, flip)

    def covariance_bytes(self, j: int) -> bytes:
        """IMU row ``j``'s input covariances (angular velocity, then linear acceleration) as
        bytes."""
        v = self.imu_values[j]
        return (v[columns.ANGULAR_VELOCITY_COVARIANCE].tobytes()
                + v[columns.LINEAR_ACCELERATION_COVARIANCE].tobytes())

    def _mag_rows(self, pipe: Pipeline, ev: Events, row: np.ndarray, flip: bool) -> None:
        """The magnetometer rows: calibrated, then turned (as the field the filter takes)."""
        self.mag_codes: dict[Any, int] = {}  #: frame id -> its code in mag_fcode
        if self.mag_list:
            v, sec, nsec, self.mag_plain, self.mag_frame = _block_rows(ev.mag, row, self.mag_at)
            m = v[:, columns.MAGNETIC_FIELD].copy()  # its own: calibrated and turned below
            if not pipe.mag_correction.identity:
                m = pipe.mag_correction.apply_rows(m)
            if flip:
                m[:, 1:] = -m[:, 1:]
            self.mag = m
            self.mag_t_ns = sec * 1_000_000_000 + nsec
            with np.errstate(over="ignore", invalid="ignore"):
                self.mag_n2 = np.add.reduce(m * m, axis=1)  # (x² + y²) + z²
                self.mag_valid = ((self.mag_t_ns != 0) & np.isfinite(self.mag_n2)
                                  & (self.mag_n2 != 0.0))
            self.mag_fcode = _frame_codes(self.mag_frame, self.mag_codes)
        else:
            self.mag_valid = self.mag_plain = _NONE

    def mag_frame_code(self, frame: Any) -> int:
        """A magnetometer frame id's code in this chunk (-1: none of its rows has it)."""
        return self.mag_codes.get(frame, -1) if frame is not None else -1


def process(pipe: Pipeline, ev: Events, start: int = 0, stop: int | None = None
            ) -> list[Rows]:
    """Events ``start``..``stop`` of ``ev`` through ``pipe`` (see the module docstring): the
    outputs of the processed IMU messages, a :class:`Rows` per run. Never raises on data: an
    unexpected exception drops the messages it hit (counted ``internal_error``, its traceback
    kept for :meth:`ImuPipeline.take_internal_error`)."""
    stop = len(ev) if stop is None else stop
    c = _Chunk(pipe, ev, start, stop)
    tally = pipe.tally
    if c.imu_at.shape[0]:
        tally.received_imu += int(np.count_nonzero(c.imu_plain))
    if c.mag_at.shape[0]:
        tally.received_mag += int(np.count_nonzero(c.mag_plain))
    out: list[Rows] = []
    p = 0
    while p < c.n:
        try:
            e = _ordinary_end(pipe, c, p)
        except Exception:  # noqa: BLE001 - a bug: the event alone, where it is counted
            e = p
        if e > p:
            rows = _guarded(pipe, c, p, e, _run)
            p = e
        else:
            rows = _guarded(pipe, c, p, p + 1, _exceptional)
            p += 1
        if rows is not None:
            out.extend(rows)
    return out


def _guarded(pipe: Pipeline, c: _Chunk, p: int, e: int, stage: Any) -> list[Rows] | None:
    """``stage(pipe, c, p, e)``; an unexpected exception (a bug) drops the IMU messages of
    events p..e-1, each counted as ``internal_error``
    (:meth:`ImuPipeline.note_internal_error`)."""
    try:
        return stage(pipe, c, p, e)
    except Exception:  # noqa: BLE001 - the pipeline never raises on data
        for _ in range(bisect_left(c.imu_list, e) - bisect_left(c.imu_list, p)):
            pipe.note_internal_error()
        return None


def _first_false(mask: np.ndarray) -> int:
    """Index of the first False in ``mask`` (its length if none)."""
    if mask.all():  # the usual case, and an empty mask
        return int(mask.shape[0])
    return int(np.argmin(mask))


def _ordinary_end(pipe: Pipeline, c: _Chunk, p: int) -> int:
    """The end of the run of ordinary events from range index ``p`` (p itself when event p is
    not ordinary; see the module docstring). Nothing of ``pipe`` changes.

    The first IMU message of the run is checked against the pipeline's state (its last stamp,
    frame id and covariances, the unit checks done, an initialised filter); each one after it
    against the message before (:attr:`_Chunk.chain`): that one was ordinary too."""
    if c.kind[p] == VELOCITY:
        return p
    rules = pipe.rules
    f = pipe.filter
    end = c.n
    # velocity messages end a run (they go to the aiding between two IMU samples)
    v = bisect_left(c.vel_list, p)
    if v < len(c.vel_list):
        end = c.vel_list[v]
    ia = bisect_left(c.imu_list, p)
    ib = bisect_left(c.imu_list, end)
    if ib > ia:
        last = pipe.clock.last_ns
        d0 = int(c.t_ns[ia]) - last if last is not None else 0
        warned = "gyro_units" in pipe.input_warning_tags
        heading_may_start = (rules.use_mag and not f.step_state.heading_initialized
                             and (pipe.mag_input.pending is not None or bool(c.mag_list)))
        takes = _takes_mag(pipe, c, p, ia, ib) if heading_may_start else None
        if not (f.initialized and pipe.accel_check_n >= checks.ACCEL_CHECK_SAMPLES
                and d0 > 0 and (not rules.reset_gap_on or d0 <= rules.reset_gap_ns)
                and c.imu_plain[ia] and c.valid[ia] and c.imu_frame[ia] == pipe.imu_frame
                and c.covariance_bytes(ia) == pipe.covariance_bytes()
                and (warned or c.g2[ia] <= _GYRO_WARN2) and (takes is None or not takes[0])):
            end = c.imu_list[ia]  # the next IMU message starts, checks or breaks the chain
        elif ib - ia > 1:
            ok = c.chain[ia + 1:ib]
            if not warned:
                ok = ok & c.quiet_gyro[ia + 1:ib]
            if takes is not None:  # the heading may start: alone
                ok = ok & ~takes[1:]
            k = _first_false(ok)
            if k < ib - ia - 1:
                end = c.imu_list[ia + 1 + k]
    ma = bisect_left(c.mag_list, p)
    mb = bisect_left(c.mag_list, end)
    if mb > ma:
        ok = c.mag_plain[ma:mb]
        if rules.use_mag:
            mi = pipe.mag_input
            ok = ok & (~c.mag_valid[ma:mb] | (
                (c.mag_fcode[ma:mb] == c.mag_frame_code(mi.frame))
                & (mi.check_n >= checks.MAG_CHECK_SAMPLES)))
        k = _first_false(ok)
        if k < mb - ma:
            end = min(end, c.mag_list[ma + k])
    return end


def _takes_mag(pipe: Pipeline, c: _Chunk, p: int, ia: int, ib: int) -> np.ndarray:
    """Per IMU event ia..ib-1 (from range index p): a magnetometer sample is waiting for it."""
    valid = np.zeros(c.n + 1, dtype=np.int64)
    ma = bisect_left(c.mag_list, p)
    at = c.mag_at[ma:]
    valid[at[c.mag_valid[ma:]] + 1] = 1
    cum = np.cumsum(valid)  # cum[x]: valid magnetometer events before range index x
    imu = c.imu_at[ia:ib]
    before = np.empty(ib - ia, dtype=np.int64)
    before[0] = cum[p]
    before[1:] = cum[imu[:-1] + 1]
    takes = cum[imu] > before
    takes[0] |= pipe.mag_input.pending is not None
    return takes


def _exceptional(pipe: Pipeline, c: _Chunk, p: int, _e: int) -> list[Rows] | None:
    """Event ``p`` alone: what only it needs, then (when it goes on) the stages as a run of
    one."""
    kind = int(c.kind[p])
    if kind == VELOCITY:
        pipe.on_velocity(c.ev.message(c.start + p))
        return None
    if kind == IMU:
        j = bisect_left(c.imu_list, p)
        if not c.imu_plain[j]:  # not decoded in bulk: the message object, on its own
            return _message(pipe, c, p, imu=True)
        return _imu_alone(pipe, c, p, j)
    if kind == MAG:
        j = bisect_left(c.mag_list, p)
        if not c.mag_plain[j]:
            return _message(pipe, c, p, imu=False)
        if pipe.rules.use_mag and c.mag_valid[j]:
            _mag_checks(pipe, c, j)
        return _run(pipe, c, p, p + 1)
    return None


def _message(pipe: Pipeline, c: _Chunk, p: int, imu: bool) -> list[Rows] | None:
    """Event ``p`` as a message object (not decoded in bulk) through
    :meth:`ImuPipeline.process_message`."""
    rows = pipe.process_message(c.ev.message(c.start + p), imu=imu, log_ns=int(c.log_ns[p]))
    return rows or None


def _imu_alone(pipe: Pipeline, c: _Chunk, p: int, j: int) -> list[Rows] | None:
    """An IMU message that is not ordinary: the covariances it brings, the value and stamp
    checks (rejections, resets), the frame id and unit checks, then a run of one."""
    v = c.imu_values[j]
    pipe.angular_velocity_covariance.get(v[columns.ANGULAR_VELOCITY_COVARIANCE])
    pipe.linear_acceleration_covariance.get(v[columns.LINEAR_ACCELERATION_COVARIANCE])
    one = slice(j, j + 1)
    code = 0 if c.valid[j] else int(imu_reasons(c.gyro[one], c.accel[one], c.a2[one],
                                                 c.g2[one], c.sec[one], c.nsec[one])[0])
    if code:
        pipe.reject(_REASONS[code])
        return None
    t_ns = int(c.t_ns[j])
    last = pipe.clock.last_ns
    rules = pipe.rules
    if last is not None:
        d_ns = t_ns - last
        if d_ns <= 0:
            if d_ns == 0:
                pipe.reject(checks.DUPLICATE_STAMP)
                return None
            if -d_ns < rules.jump_back_ns:
                pipe.reject(checks.OUT_OF_ORDER)
                return None
            if not pipe.pipeline_params.reset_on_time_jump_back:
                pipe.reject(checks.TIME_BACKWARDS)
                return None
            pipe.reset(checks.RESET_TIME_JUMP_BACK)
        elif rules.reset_gap_on and d_ns > rules.reset_gap_ns:
            pipe.reset(checks.RESET_LONG_GAP)
    # what the input says about its conventions, once each
    frame = c.imu_frame[j]
    if frame != pipe.imu_frame:
        pipe.imu_frame = frame
        pipe.warn(checks.frame_id_warning(str(frame), "IMU"))
    if pipe.accel_check_n < checks.ACCEL_CHECK_SAMPLES:
        # |mean a|, not mean |a|: vibration adds to every |a| (13 m/s^2 on a quadrotor)
        # but averages out of the vector, which is gravity (plus a mean acceleration)
        ax, ay, az = c.accel[j].tolist()
        pipe.accel_check_n += 1
        pipe.acc_sum[0] += ax
        pipe.acc_sum[1] += ay
        pipe.acc_sum[2] += az
        if pipe.accel_check_n == checks.ACCEL_CHECK_SAMPLES:
            n = pipe.accel_check_n
            sx, sy, sz = pipe.acc_sum
            mean_norm = math.sqrt(sx**2 + sy**2 + sz**2) / n
            pipe.warn(checks.accel_units_warning(mean_norm, pipe.filter_params.gravity_m_s2))
    g2 = float(c.g2[j])
    if g2 > _GYRO_WARN2:
        pipe.warn(checks.gyro_units_warning(math.sqrt(g2)))
    return _run(pipe, c, p, p + 1)


def _mag_checks(pipe: Pipeline, c: _Chunk, j: int) -> None:
    """A valid magnetometer sample's frame id and unit checks (warn-once)."""
    mi = pipe.mag_input
    frame = c.mag_frame[j]
    if frame != mi.frame:
        mi.frame = frame
        pipe.warn(checks.frame_id_warning(str(frame), "magnetometer"))
        if pipe.imu_frame is not None and frame != pipe.imu_frame:
            pipe.warn(checks.mag_frame_warning(str(frame), pipe.imu_frame))
    if mi.check_n < checks.MAG_CHECK_SAMPLES:
        mi.check_n += 1
        mi.check_norm_sum += math.sqrt(float(c.mag_n2[j]))
        if mi.check_n == checks.MAG_CHECK_SAMPLES:
            pipe.warn(checks.mag_units_warning(mi.check_norm_sum / mi.check_n))


def _run(pipe: Pipeline, c: _Chunk, p: int, e: int) -> list[Rows] | None:
    """Events p..e-1 (ordinary, or one already checked by :func:`_exceptional`) through the
    stages: magnetometer samples, time base, filter, counters, covariance, outputs."""
    t0 = perf_counter()
    ia, ib = bisect_left(c.imu_list, p), bisect_left(c.imu_list, e)
    ma, mb = bisect_left(c.mag_list, p), bisect_left(c.mag_list, e)
    mag, mag_t = _mag_stage(pipe, c, p, ia, ib, ma, mb)
    n = ib - ia
    if n == 0:
        return None
    dt = _time_stage(pipe, c.t_ns[ia:ib], c.d_ns[ia:ib])
    gyro = np.ascontiguousarray(c.gyro[ia:ib])
    accel = np.ascontiguousarray(c.accel[ia:ib])
    q, extra, used, rejected, first = _filter_stage(pipe, c.t_ns[ia:ib], gyro, accel, mag, dt)
    return [_output_stage(pipe, c, ia, ib, dt, gyro, accel, q, extra, used, rejected, first,
                          mag_t, t0)]


def _mag_stage(pipe: Pipeline, c: _Chunk, p: int, ia: int, ib: int, ma: int, mb: int
               ) -> tuple[np.ndarray | None, np.ndarray]:
    """Magnetometer events ma..mb-1 (counted; the valid ones wait for the next IMU message,
    a sample replaced before one came is dropped) and the sample each IMU message ia..ib-1
    takes: (n, 3) rows (NaN: none; None: none at all) and their stamps [ns] (0: none)."""
    tally, mi, rules = pipe.tally, pipe.mag_input, pipe.rules
    n = ib - ia
    mag_t = np.zeros(n, dtype=np.int64)
    pending = mi.pending
    if mb > ma:
        if not rules.use_mag:
            tally.mag_disabled += mb - ma
            valid_at = c.mag_at[:0]
        else:
            valid = c.mag_valid[ma:mb]
            tally.mag_invalid += int(mb - ma - np.count_nonzero(valid))
            valid_at = c.mag_at[ma:mb][valid]  # range indices of the valid samples
            vj = np.flatnonzero(valid) + ma  # their rows
    else:
        valid_at = c.mag_at[:0]
    if n == 0:  # no IMU message in the run: the last valid sample waits, the others drop
        if valid_at.shape[0]:
            tally.mag_dropped += int(valid_at.shape[0]) - 1 + (pending is not None)
            r = int(vj[-1])
            m = c.mag[r].tolist()
            mi.pending = (int(c.mag_t_ns[r]), m[0], m[1], m[2])
        return None, mag_t
    if valid_at.shape[0] == 0:
        if pending is None:
            return None, mag_t
        # the waiting sample goes to the first IMU message
        mi.pending = None
        if not rules.use_mag:
            tally.mag_disabled += 1
            return None, mag_t
        if abs(int(c.t_ns[ia]) - pending[0]) > rules.mag_timeout_ns:
            tally.mag_stale += 1
            return None, mag_t
        mag = np.full((n, 3), np.nan)
        mag[0] = pending[1:4]
        mag_t[0] = pending[0]
        return mag, mag_t
    # each valid sample waits for the next IMU message; one followed by another first is
    # dropped (as is the waiting one when a sample comes before any IMU message)
    imu = c.imu_at[ia:ib]
    # for each valid sample: the index of the first IMU message after it (n: none)
    nxt = np.searchsorted(imu, valid_at)
    dropped = int(np.count_nonzero(nxt[:-1] == nxt[1:]))
    if pending is not None and int(valid_at[0]) < int(imu[0]):
        dropped += 1
        pending = None
    tally.mag_dropped += dropped
    # the sample each IMU message takes: the last valid one before it, after the one before
    last_of = np.flatnonzero(np.append(nxt[1:] != nxt[:-1], True))  # last sample per IMU
    takers = nxt[last_of]
    took = takers < n
    mag = np.full((n, 3), np.nan)
    has = np.zeros(n, dtype=bool)
    rows_taken = vj[last_of[took]]
    has[takers[took]] = True
    mag[takers[took]] = c.mag[rows_taken]
    mag_t[takers[took]] = c.mag_t_ns[rows_taken]
    if pending is not None and n and not has[0]:  # the waiting one goes to the first
        has[0] = True
        mag[0] = pending[1:4]
        mag_t[0] = pending[0]
    # the sample still waiting after the run
    if not took[-1]:
        r = int(vj[last_of[-1]])
        m = c.mag[r].tolist()
        mi.pending = (int(c.mag_t_ns[r]), m[0], m[1], m[2])
    else:
        mi.pending = None
    # stale: stamped too far from the IMU message it would go with
    fresh = np.abs(c.t_ns[ia:ib] - mag_t) <= rules.mag_timeout_ns
    tally.mag_stale += int(np.count_nonzero(has & ~fresh))
    has &= fresh
    if not has.any():
        return None, np.zeros(n, dtype=np.int64)
    mag[~has] = np.nan
    mag_t[~has] = 0
    return mag, mag_t


def _time_stage(pipe: Pipeline, t_ns: np.ndarray, d_ns: np.ndarray) -> np.ndarray:
    """The time base over the run's stamps [ns] (all accepted; ``d_ns`` their intervals from
    the row before, the first one's unused): the filter's interval per row [s] (0 for a first
    sample; the mean interval across a gap, counted), the diagnostics period's interval
    statistics."""
    clock, w, rules = pipe.clock, pipe.window, pipe.rules
    n = t_ns.shape[0]
    last = clock.last_ns
    clock.last_ns = int(t_ns[-1])
    if last is None:  # a first sample (always alone): no interval
        return np.zeros(1)
    d_ns = d_ns.copy()
    d_ns[0] = int(t_ns[0]) - last
    dt = d_ns * 1e-9
    dts = dt.tolist()
    lo, hi = min(dts), max(dts)
    if w.n_dt == 0 or lo < w.dt_min:
        w.dt_min = lo
    if hi > w.dt_max:
        w.dt_max = hi
    w.n_dt += n
    dt_sum = w.dt_sum
    for x in dts:  # the running sum in message order
        dt_sum += x
    w.dt_sum = dt_sum
    dt_mean = clock.dt_mean
    d_list = d_ns.tolist()
    if max(d_list) > rules.max_dt_ns:  # gaps: not integrated, the mean interval instead
        fallback = min(pipe.pipeline_params.max_dt_s, 0.01)
        out = []
        for d, x in zip(d_list, dts, strict=True):
            if d > rules.max_dt_ns:
                pipe.tally.gaps += 1
                x = dt_mean if dt_mean > 0.0 else fallback
            elif dt_mean > 0.0:
                dt_mean += 0.05 * (x - dt_mean)
            else:
                dt_mean = x
            out.append(x)
        dt = np.asarray(out, dtype=np.float64)
    else:
        for x in dts:
            if x == dt_mean:  # the mean interval itself: unchanged
                continue
            if dt_mean > 0.0:
                dt_mean += 0.05 * (x - dt_mean)
            else:
                dt_mean = x
    clock.dt_mean = dt_mean
    return dt


def _filter_stage(pipe: Pipeline, t_ns: np.ndarray, gyro: np.ndarray, accel: np.ndarray,
                  mag: np.ndarray | None, dt: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None, int]:
    """The filter over the rows (a first sample initialises it; velocity aiding, when there is
    one, gives each row its input): q (n, 4) in the core's world, the state after each row
    (``extra``), per row whether the magnetometer sample was used or rejected (counted; None
    when no row had one), and 1 when row 0 initialised the filter (else 0)."""
    f = pipe.filter
    n = gyro.shape[0]
    q = np.empty((n, 4))
    extra = np.empty((n, EXTRA_COLUMNS))
    tally = pipe.tally
    k0 = 0
    # per row: a magnetometer sample given, used, rejected (None: none at all)
    has = None if mag is None else ~np.isnan(mag[:, 0])
    used = None if has is None else np.zeros(n, dtype=bool)
    rejected = None if has is None else np.zeros(n, dtype=bool)
    if not f.initialized:  # the first sample initialises the attitude (always alone)
        m0 = tuple(mag[0].tolist()) if has is not None and has[0] else None  # type: ignore[index]
        q[0] = f.update(tuple(gyro[0].tolist()), tuple(accel[0].tolist()), 0.0, m0)
        extra[0] = state_extras(f.step_state)
        if m0 is not None:
            if f.step_state.heading_initialized:
                used[0] = True  # type: ignore[index]
            else:  # horizontal component too small to give a heading
                tally.mag_rejected += 1
        k0 = 1
    if k0 < n:
        aiding = pipe.velocity_aiding
        if aiding is None:
            f.run_rows(gyro, accel, mag, dt, k0, q, extra)
        else:
            g_rows, a_rows, dts = gyro.tolist(), accel.tolist(), dt.tolist()
            m_rows = mag.tolist() if mag is not None else None
            for k in range(k0, n):
                mk = tuple(m_rows[k]) if m_rows is not None and has[k] else None  # type: ignore[index]
                q[k], _accel = aiding.update_filter(f, int(t_ns[k]) * 1e-9, tuple(g_rows[k]),
                                                    tuple(a_rows[k]), dts[k], mk)
                extra[k] = state_extras(f.step_state)
        if has is not None:
            status = extra[k0:, Extra.MAG_STATUS]
            h = has[k0:]
            used[k0:] = h & (status == MAG_USED)  # type: ignore[index]
            rejected[k0:] = h & (status == MAG_REJECTED)  # type: ignore[index]
            tally.mag_rejected += int(np.count_nonzero(rejected[k0:]))  # type: ignore[index]
            tally.mag_disabled += int(np.count_nonzero(h & (status == MAG_DISABLED)))
    if used is not None:
        tally.mag_used += int(np.count_nonzero(used))
    return q, extra, used, rejected, k0


def _output_stage(pipe: Pipeline, c: _Chunk, ia: int, ib: int, dt: np.ndarray,
                  gyro: np.ndarray, accel: np.ndarray, q: np.ndarray, extra: np.ndarray,
                  used: np.ndarray | None, rejected: np.ndarray | None, first: int,
                  mag_t: np.ndarray,
                  t0: float) -> Rows:
    """Counters, the diagnostics period's error and time statistics, the orientation
    covariance, the published frame and roll/pitch/yaw of the run's rows (``first``: row 0
    initialised the filter and has no error to count)."""
    f = pipe.filter
    n = ib - ia
    t_ns = c.t_ns[ia:ib]
    e = extra[:, Extra.ERROR]
    en = np.sqrt(np.add.reduce(e * e, axis=1))  # √((ex² + ey²) + ez²), as the step has it
    clipped = extra[:, Extra.CLIPPED]
    # the diagnostics period's error statistics (not of a first sample: it has no error)
    w = pipe.window
    err_sum, err_max = w.err_sum, w.err_max
    for x in en[first:].tolist():  # the running sum in message order
        err_sum += x
        if x > err_max:  # NaN: never
            err_max = x
    w.err_sum, w.err_max = err_sum, err_max
    w.n_err += n - first
    w.n_clipped += int(np.count_nonzero(clipped[first:]))
    # the age of the last magnetometer sample used, per row [s]
    last_mag = pipe.mag_input.last_used_ns
    ages: np.ndarray | None
    if used is not None and used.any():
        last_at = np.maximum.accumulate(np.where(used, np.arange(n), -1))
        last_t = mag_t[np.maximum(last_at, 0)]
        known = last_at >= 0
        if last_mag is not None:
            last_t = np.where(known, last_t, last_mag)
            known[:] = True
        ages = np.where(known, (t_ns - last_t) * 1e-9, 0.0)  # 0.0: "never"
        last_mag = int(mag_t[int(last_at[-1])])
    elif last_mag is not None:
        ages = (t_ns - last_mag) * 1e-9
    else:
        ages = None
    pipe.mag_input.last_used_ns = last_mag
    heading = bool(f.step_state.heading_initialized)  # constant over a run
    if used is None:
        used_f = rejected_f = np.zeros(n)
    else:
        used_f, rejected_f = used.astype(np.float64), rejected.astype(np.float64)  # type: ignore[union-attr]
    tilts, yaws = pipe.covariance_model.rows(
        dt, clipped, extra[:, Extra.BIAS_SIGMA], extra[:, Extra.PHASE], en, extra[:, Extra.LX],
        extra[:, Extra.LY], extra[:, Extra.NOISE_A2], heading, extra[:, Extra.YAW_ERROR],
        used_f, ages, extra[:, Extra.LOOP_K1], rejected_f, f.backend)
    cov = np.zeros((n, 9))
    cov[:, 0] = tilts
    cov[:, 4] = tilts
    cov[:, 8] = yaws
    pipe.tally.processed += n
    if not pipe.output_frame.identity:  # core world -> published (nwu, true north)
        q = pipe.output_frame.apply_array(q)
    rpy = _rpy(pipe, q, f.backend)
    pipe.last_rpy = tuple(rpy[-1].tolist())
    frame = pipe.output_frame_id(str(c.imu_frame[ia]))
    av_cov = pipe.angular_velocity_covariance.value
    la_cov = pipe.linear_acceleration_covariance.value
    gfree = None
    if pipe.pipeline_params.publish_linear_acceleration:
        fp = pipe.filter_params
        gfree = [gravity_free((qr[1], qr[2], qr[3], qr[0]), tuple(a), tuple(cr), la_cov,
                              fp.gravity_m_s2, fp.world_frame)
                 for qr, a, cr in zip(q.tolist(), accel.tolist(), cov.tolist(), strict=True)]
    if w.n == 0:
        w.first_ns = int(t_ns[0])
    w.n += n
    w.last_ns = int(t_ns[-1])
    elapsed = perf_counter() - t0  # the run's processing time, shared by its messages
    w.proc_sum += elapsed
    if elapsed / n > w.proc_max:
        w.proc_max = elapsed / n
    return Rows(c.sec[ia:ib], c.nsec[ia:ib], c.log_ns[c.imu_at[ia:ib]], frame, q, rpy, cov,
                gyro, accel, av_cov, la_cov, extra, en, gfree, pipe.take_warnings())


def _rpy(p: Pipeline, q: np.ndarray, backend: str = "python") -> np.ndarray:
    """(n, 3) roll, pitch, yaw [rad] (aerospace ZYX) of each row of ``q`` (w, x, y, z): backend
    'compiled': ``_kernel.rpy_rows``, else ``math.atan2``/``math.asin`` per row (the same libm
    calls); then the unwrap, sequential by nature, when it is on."""
    out = np.empty((q.shape[0], 3))
    if backend == "compiled" and compiled_kernel is not None:
        compiled_kernel.rpy_rows(np.ascontiguousarray(q), out)
    else:
        qw, qx, qy, qz = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
        out[:, 0] = list(map(math.atan2, (2.0 * (qw * qx + qy * qz)).tolist(),
                             (1.0 - 2.0 * (qx * qx + qy * qy)).tolist()))
        sp = 2.0 * (qw * qy - qz * qx)
        sp = np.where(sp > 1.0, 1.0, np.where(sp < -1.0, -1.0, sp))
        out[:, 1] = list(map(math.asin, sp.tolist()))
        out[:, 2] = list(map(math.atan2, (2.0 * (qw * qz + qx * qy)).tolist(),
                             (1.0 - 2.0 * (qy * qy + qz * qz)).tolist()))
    if p.pipeline_params.rpy_unwrap:
        prev = p.clock.unwrap_prev
        rows = out.tolist()
        for k, (roll, pitch, yaw) in enumerate(rows):
            if prev is not None:
                roll += TWO_PI * round((prev[0] - roll) / TWO_PI)
                yaw += TWO_PI * round((prev[2] - yaw) / TWO_PI)
            prev = (roll, pitch, yaw)
            rows[k] = [roll, pitch, yaw]
        p.clock.unwrap_prev = prev
        out = np.asarray(rows, dtype=np.float64).reshape(-1, 3)
    return out
