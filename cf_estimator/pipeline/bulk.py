"""The pipeline over arrays: a run of ordinary messages through :class:`ImuPipeline` at once.

:meth:`ImuPipeline.on_imu` / ``on_mag`` handle one message with every rule of the pipeline. Most
of a recording is ordinary — an initialised filter, valid values, increasing stamps, the same
frame ids and covariances, a magnetometer that is valid — and for such a run the rules reduce to
bookkeeping. :func:`scan` walks the messages from a position and stops at the first one that is
not ordinary (or at ``limit_log_ns``: the replay's next diagnostics tick); :func:`commit` then
runs the filter over the run's rows with :meth:`ComplementaryFilter.run_rows` (the same step
as ``update``, sample by sample, through the kernel interface) and updates the pipeline's
counters, statistics and state exactly as the per-message calls would have. Everything that is
not ordinary is left to ``on_imu`` / ``on_mag``: rejections, resets, gaps beyond the reset
threshold, first samples, warnings.

Equality with the per-message path (same outputs, counters, diagnostics, bit for bit) is tested
on real and hostile bags (test/test_bulk_decode.py). It relies on: ``run_rows`` = repeated
``update`` (a magnetometer row of NaN = no sample), the extra columns of
:func:`cf_estimator.core.filter.state_extras` (clipped, phase, bias sigma,
magnetometer status, the aperiodic unit's world-frame state, the heading error and the
accelerometer noise per row: what the orientation covariance model needs), and the error norm
being ``sqrt(ex² + ey² + ez²)`` of the error vector (core/step.py). body_frame's half turn
is applied as ``on_imu``/``on_mag`` apply it; with velocity aiding the pipeline runs per
message.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from time import perf_counter
from typing import Any

import numpy as np

from cf_estimator.core.filter import EXTRA_COLUMNS
from cf_estimator.core.step import MAG_DISABLED, MAG_REJECTED, MAG_USED
from cf_estimator.pipeline import checks
from cf_estimator.pipeline.pipeline import ACCEL_MAX2, GYRO_MAX2, TWO_PI, ImuPipeline

IMU, MAG, OTHER = 0, 1, 2  #: event kinds; OTHER (e.g. a reference) passes through
_GYRO_WARN2 = checks.GYRO_IMPLAUSIBLE_RAD_S**2


@dataclass
class Scan:
    """What :func:`scan` found: the ordinary run's rows and the state after it (uncommitted)."""

    end: int  #: index of the first event not in the run
    n_events: int = 0
    t_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))  #: stamps
    sec: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    nsec: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    log_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    #: row of each message in ``values``
    rows: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.intp))
    values: Any = None  #: the IMU block's (n, 37) values: gyro columns 13:16, accel 25:28
    #: (n, 3) the magnetometer sample each row gives the filter (NaN: none), None: none at all
    mag: np.ndarray | None = None
    #: stamp of the row's magnetometer sample (0: none)
    mag_t_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    dt: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: the filter's interval [s]
    frame: str = ""
    state: dict[str, Any] = field(default_factory=dict)  #: pipeline fields to write back

    @property
    def n(self) -> int:
        return int(self.t_ns.shape[0])


def _ordinary_start(pipe: ImuPipeline) -> bool:
    return (pipe.filter.initialized and pipe.clock.last_ns is not None
            and not pipe.has_pending_warnings
            and pipe.accel_check_n >= checks.ACCEL_CHECK_SAMPLES
            and not pipe.has_velocity_aiding)  # velocity aiding: per message


def _imu_ok(v: np.ndarray, sec: np.ndarray, nsec: np.ndarray) -> np.ndarray:
    """``on_imu``'s value checks, vectorized with its own arithmetic (same results)."""
    gx, gy, gz, ax, ay, az = (v[:, j] for j in (13, 14, 15, 25, 26, 27))
    with np.errstate(over="ignore", invalid="ignore"):
        finite = np.all(np.isfinite(v[:, [13, 14, 15, 25, 26, 27]]), axis=1)
        a2 = ax * ax + ay * ay + az * az
        g2 = gx * gx + gy * gy + gz * gz
        return (finite & ~((sec == 0) & (nsec == 0)) & (a2 != 0.0) & (g2 <= GYRO_MAX2)
                & (a2 <= ACCEL_MAX2) & (g2 <= _GYRO_WARN2))


def _mag_ok(v: np.ndarray, sec: np.ndarray, nsec: np.ndarray) -> np.ndarray:
    """``on_mag``'s validity checks, vectorized with its own arithmetic."""
    mx, my, mz = v[:, 0], v[:, 1], v[:, 2]
    with np.errstate(over="ignore", invalid="ignore"):
        n2 = mx * mx + my * my + mz * mz
        return ((sec * 1_000_000_000 + nsec) != 0) & np.isfinite(n2) & (n2 != 0.0)


class Events:
    """Consecutive IMU, magnetometer and other messages in log order, as arrays.

    ``kind[i]`` (:data:`IMU`, :data:`MAG`, :data:`OTHER`), ``log_ns[i]``, ``row[i]`` = its row
    in ``imu`` / ``mag`` (blocks of decoded messages: ``values`` (n, 37 | 12) float64,
    ``sec``, ``nsec``, ``frame``, ``plain`` per row; see :class:`cf_estimator.bag.cdr.Block`);
    ``message(i)``: message i as an object, for the per-message path.
    """

    def __init__(self, kind: Sequence[int], log_ns: Sequence[int], row: Sequence[int],
                 imu: Any, mag: Any, message: Callable[[int], Any]) -> None:
        self.kind, self.log_ns, self.row = kind, log_ns, row
        self.imu, self.mag, self.message = imu, mag, message
        self._cols: dict[str, list[float]] = {}
        self._cov: dict[tuple[int, bytes | None], np.ndarray] = {}
        self._static: dict[str, np.ndarray] | None = None
        self._frames: dict[tuple[int, str | None], np.ndarray] = {}
        self._stamps: tuple[np.ndarray, np.ndarray] | None = None

    def column(self, name: str) -> list[float]:
        """``gx gy gz ax ay az`` (IMU) or ``mx my mz`` (magnetometer) as a list of floats;
        a leading ``-``: negated (body_frame's half turn about x)."""
        col = self._cols.get(name)
        if col is None:
            neg = name.startswith("-")
            base = name.lstrip("-")
            j = {"gx": 13, "gy": 14, "gz": 15, "ax": 25, "ay": 26, "az": 27,
                 "mx": 0, "my": 1, "mz": 2}[base]
            block = self.mag if base[0] == "m" else self.imu
            values = block.values[:, j]
            col = self._cols[name] = (-values if neg else values).tolist()
        return col

    def static(self) -> dict[str, np.ndarray]:
        """Per-event arrays that do not depend on the pipeline's state (computed once):
        ``imu_ok`` (plain layout, non-zero stamp, finite, plausible and non-zero vectors — the
        checks of ``on_imu`` in its own arithmetic), ``mag_ok`` (``on_mag``'s validity),
        ``t_ns`` (header stamps [ns] of IMU and magnetometer events), per event."""
        st = self._static
        if st is not None:
            return st
        n = len(self.kind)
        kind = np.asarray(self.kind, dtype=np.int8)
        row = np.asarray(self.row, dtype=np.intp)
        ok = np.zeros(n, dtype=bool)
        t_ns = np.zeros(n, dtype=np.int64)
        for blk, k, check in ((self.imu, IMU, _imu_ok), (self.mag, MAG, _mag_ok)):
            if blk is None:
                continue
            sel = np.flatnonzero(kind == k)
            r = row[sel]
            sec = np.asarray(blk.sec, dtype=np.int64)[r]
            nsec = np.asarray(blk.nsec, dtype=np.int64)[r]
            t_ns[sel] = sec * 1_000_000_000 + nsec
            plain = np.asarray(blk.plain, dtype=bool)[r]
            ok[sel] = plain & check(blk.values[r], sec, nsec)
        self._static = st = {"kind": kind, "ok": ok, "t_ns": t_ns, "row": row,
                             "log_ns": np.asarray(self.log_ns, dtype=np.int64)}
        return st

    def imu_stamps(self) -> tuple[np.ndarray, np.ndarray]:
        """The IMU block's header ``sec`` and ``nanosec`` per row (int64 arrays)."""
        if self._stamps is None:
            blk = self.imu
            self._stamps = (np.asarray(blk.sec, dtype=np.int64),
                            np.asarray(blk.nsec, dtype=np.int64))
        return self._stamps

    def frame_is(self, kind: int, frame: str | None) -> np.ndarray:
        """Per event: of ``kind`` and with header frame id ``frame``."""
        key = (kind, frame)
        out = self._frames.get(key)
        if out is None:
            blk = self.imu if kind == IMU else self.mag
            out = np.zeros(len(self.kind), dtype=bool)
            if blk is not None:
                st = self.static()
                frames = blk.frame
                if frames and frames[0] == frame and frames.count(frame) == len(frames):
                    same = np.ones(len(frames), dtype=bool)
                else:
                    same = np.asarray([f == frame for f in frames], dtype=bool)
                sel = np.flatnonzero(st["kind"] == kind)
                out[sel] = same[st["row"][sel]]
            self._frames[key] = out
        return out

    def same_covariance(self, start: int, raw: bytes | None) -> np.ndarray:
        """Per IMU row: its covariance starting at column ``start`` has the bytes ``raw``."""
        key = (start, raw)
        same = self._cov.get(key)
        if same is None:
            if raw is None or len(raw) != 72:
                same = np.zeros(self.imu.n, dtype=bool)
            else:
                cov = np.ascontiguousarray(self.imu.values[:, start:start + 9]).view("<u8")
                same = np.all(cov == np.frombuffer(raw, dtype="<u8"), axis=1)
            self._cov[key] = same
        return same


def scan(pipe: ImuPipeline, ev: Events, start: int, limit_log_ns: int | None = None) -> Scan:
    """The longest run of ordinary events from ``ev`` index ``start``, stopping before an
    event logged at or after ``limit_log_ns``. Nothing of ``pipe`` changes.

    Where the run ends is found with NumPy (the static checks, the frame ids, covariances and
    stamp order); the bookkeeping that is sequential by nature (the mean interval, gaps,
    pairing magnetometer samples with IMU messages) runs over the run's messages in order.
    """
    p = pipe
    out = Scan(start)
    if not _ordinary_start(p):
        return out
    heading = bool(p.filter.step_state.heading_initialized)
    pending = p.mag_input.pending
    if pending is not None and not heading:
        return out
    st = ev.static()
    n_ev = len(ev.kind)
    stop = n_ev
    if limit_log_ns is not None:
        # log times are sorted in a chunk (the reader merges by log time)
        stop = bisect.bisect_left(ev.log_ns, limit_log_ns, start, n_ev)
    if stop <= start:
        return out
    kind = st["kind"][start:stop]
    good = np.ones(stop - start, dtype=bool)
    is_imu = kind == IMU
    is_mag = kind == MAG
    ok = st["ok"][start:stop]
    if ev.imu is not None and is_imu.any():
        good &= ~is_imu | (ok & ev.frame_is(IMU, p.imu_frame)[start:stop])
        av = ev.same_covariance(16, p.angular_velocity_covariance.raw)
        la = ev.same_covariance(28, p.linear_acceleration_covariance.raw)
        rows = st["row"][start:stop]
        imu_pos = np.flatnonzero(is_imu)
        cov_ok = np.ones(stop - start, dtype=bool)
        cov_ok[imu_pos] = av[rows[imu_pos]] & la[rows[imu_pos]]
        good &= cov_ok
        # stamps increase from message to message, without a gap that resets the filter
        t = st["t_ns"][start:stop][imu_pos]
        d = np.diff(t, prepend=np.int64(p.clock.last_ns))
        t_ok = d > 0
        if p.rules.reset_gap_on:
            t_ok &= d <= p.rules.reset_gap_ns
        seq_ok = np.ones(stop - start, dtype=bool)
        seq_ok[imu_pos] = t_ok
        good &= seq_ok
    if is_mag.any():
        if not (p.rules.use_mag and heading and p.mag_input.check_n >= checks.MAG_CHECK_SAMPLES):
            good &= ~is_mag
        else:
            good &= ~is_mag | (ok & ev.frame_is(MAG, p.mag_input.frame)[start:stop])
    bad = np.flatnonzero(~good)
    end = start + (int(bad[0]) if bad.size else stop - start)
    if end <= start:
        return out
    # -- the bookkeeping over the run, in the pipeline's order ----------------------------------
    max_dt_ns, timeout = p.rules.max_dt_ns, p.rules.mag_timeout_ns
    dt_mean, gaps = p.clock.dt_mean, p.tally.gaps
    stale = 0
    w = p.window
    dt_min, dt_max, dt_sum, n_dt = w.dt_min, w.dt_max, w.dt_sum, w.n_dt
    last = p.clock.last_ns
    mag_block = ev.mag
    if mag_block is not None:
        mxs, mys, mzs = ev.column("mx"), ev.column("my"), ev.column("mz")
        if p.rules.flip:  # body_frame FLU <-> FRD, as on_mag turns the field
            mys, mzs = ev.column("-my"), ev.column("-mz")
    max_dt_fallback = min(p.pipeline_params.max_dt_s, 0.01)
    rel_kind = st["kind"][start:end]
    nz = np.flatnonzero(rel_kind != OTHER)  # IMU and magnetometer events (run positions)
    k_nz = rel_kind[nz]
    t_run = st["t_ns"][start:end]
    imu_at = np.flatnonzero(k_nz == IMU)  # in nz
    imu_rel = nz[imu_at]
    n_imu = int(imu_rel.shape[0])
    rows = st["row"][start:end][imu_rel]
    t_imu = t_run[imu_rel]
    # magnetometer samples: each IMU message takes the pending sample (the magnetometer event
    # just before it, or the one pending at the start); a sample followed by another one
    # before an IMU message is superseded (dropped)
    is_mag_nz = k_nz == MAG
    n_mag = int(np.count_nonzero(is_mag_nz))
    dropped = int(np.count_nonzero(is_mag_nz[:-1] & is_mag_nz[1:]))
    if n_mag and pending is not None and bool(is_mag_nz[0]):
        dropped += 1
    prev_mag = np.zeros(n_imu, dtype=bool)
    inner = imu_at > 0
    prev_mag[inner] = is_mag_nz[imu_at[inner] - 1]
    mag_ev = np.where(prev_mag, nz[np.maximum(imu_at - 1, 0)], -1)  # run position, or -1
    first_takes_pending = n_imu > 0 and int(imu_at[0]) == 0 and pending is not None
    has = prev_mag.copy()
    mag_t = np.where(prev_mag, t_run[mag_ev], 0)
    mag = None
    if n_mag or first_takes_pending:
        mag = np.full((n_imu, 3), np.nan)
        if mag_block is not None and prev_mag.any():
            mrows = st["row"][start:end][mag_ev[prev_mag]]
            vals = mag_block.values[mrows, 0:3]
            if p.rules.flip:  # body_frame FLU <-> FRD, as on_mag turns the field
                vals = np.column_stack([vals[:, 0], -vals[:, 1], -vals[:, 2]])
            mag[prev_mag] = vals
        if first_takes_pending:
            assert pending is not None
            has[0] = True
            mag_t[0] = pending[0]
            mag[0] = pending[1:4]
        # stale: logged too far from the IMU message it would go with
        fresh = np.abs(t_imu - mag_t) <= timeout
        stale = int(np.count_nonzero(has & ~fresh))
        has &= fresh
        mag[~has] = np.nan
        mag_t = np.where(has, mag_t, 0)
        if not has.any():
            mag = None
    # the pending sample after the run: the last magnetometer event when no IMU message
    # followed it
    if n_mag and bool(is_mag_nz[-1]):
        r = int(st["row"][start + int(nz[-1])])
        pending = (int(t_run[int(nz[-1])]), mxs[r], mys[r], mzs[r])
    elif n_imu:
        pending = None
    # intervals: the window statistics see the raw interval, the filter the mean one across
    # a gap (pipeline.on_imu's order of operations, its float arithmetic)
    d_ns = np.diff(t_imu, prepend=np.int64(last))
    dt_arr = d_ns * 1e-9
    dt_raw = dt_arr.tolist()
    if n_imu:
        lo, hi = min(dt_raw), max(dt_raw)
        if n_dt == 0 or lo < dt_min:
            dt_min = lo
        if hi > dt_max:
            dt_max = hi
        n_dt += n_imu
        last = int(t_imu[-1])
    if n_imu:  # the running sum in message order (add.accumulate is sequential: same bits)
        dt_sum = float(np.add.accumulate(np.concatenate(([dt_sum], dt_arr)))[-1])
    if n_imu and int(d_ns.max()) > max_dt_ns:
        dts = []
        for d, dt in zip(d_ns.tolist(), dt_raw, strict=True):
            if d > max_dt_ns:
                gaps += 1
                dt = dt_mean if dt_mean > 0.0 else max_dt_fallback
            elif dt_mean > 0.0:
                dt_mean += 0.05 * (dt - dt_mean)
            else:
                dt_mean = dt
            dts.append(dt)
        out.dt = np.asarray(dts, dtype=np.float64)
    else:
        # the mean interval: unchanged by intervals equal to it (regular stamps), else in order
        if not (dt_mean > 0.0 and n_imu and bool(np.all(dt_arr == dt_mean))):
            for dt in dt_raw:
                if dt_mean > 0.0:
                    dt_mean += 0.05 * (dt - dt_mean)
                else:
                    dt_mean = dt
        out.dt = dt_arr
    out.rows = rows
    out.t_ns = t_imu
    if ev.imu is not None:
        out.sec = ev.imu_stamps()[0][rows]
        out.nsec = ev.imu_stamps()[1][rows]
    out.log_ns = st["log_ns"][start:end][imu_rel]
    out.mag = mag
    out.mag_t_ns = mag_t
    out.end = end
    out.n_events = end - start
    out.frame = p.output_frame_id(str(p.imu_frame))
    out.values = ev.imu.values if ev.imu is not None else None
    out.state = {
        "last_ns": last, "dt_mean": dt_mean, "gaps": gaps, "pending_mag": pending,
        "dropped": dropped, "stale": stale, "n_mag": n_mag,
        "window": (dt_min, dt_max, dt_sum, n_dt),
    }
    return out


@dataclass
class Committed:
    """The run's outputs (one row per IMU message), as ``on_imu`` would have returned them."""

    q_wxyz: np.ndarray  #: (n, 4) q_world_from_sensor
    rpy: np.ndarray  #: (n, 3) roll, pitch, yaw [rad]
    extra: np.ndarray  #: (n, EXTRA_COLUMNS): state_extras after each sample
    error_norm: np.ndarray  #: (n,)
    covariance: np.ndarray  #: (n, 9) orientation covariance of each row (pipeline/covariance.py)
    av_cov: tuple[float, ...]
    la_cov: tuple[float, ...]
    gyro: np.ndarray  #: (n, 3) the rows the filter got [rad/s] (= the output's input copy)
    accel: np.ndarray  #: (n, 3) [m/s²]


def commit(pipe: ImuPipeline, run: Scan) -> Committed:
    """Run the filter over ``run`` and update ``pipe`` as the per-message calls would (the
    state after each row, the bias estimate among it, is in ``Committed.extra``)."""
    t0 = perf_counter()
    p = pipe
    n = run.n
    f = p.filter
    sel = run.values[run.rows]
    gyro = np.ascontiguousarray(sel[:, 13:16])
    acc = np.ascontiguousarray(sel[:, 25:28])
    if p.rules.flip:  # body_frame FLU <-> FRD, as on_imu turns the vectors
        gyro[:, 1:] = -gyro[:, 1:]
        acc[:, 1:] = -acc[:, 1:]
    mag = run.mag
    dt = run.dt
    q = np.empty((n, 4))
    extra = np.empty((n, EXTRA_COLUMNS))
    # the filter over the run (the covariance model's inputs and the bias estimate after each
    # row are columns of extra)
    f.run_rows(gyro, acc, mag, dt, 0, q, extra)
    state = f.step_state
    # -- counters, statistics and the covariance model ----------------------------------------
    st = run.state
    ex, ey, ez = extra[:, 0], extra[:, 1], extra[:, 2]
    en_arr = np.sqrt(ex * ex + ey * ey + ez * ez)
    en = en_arr.tolist()
    clipped_col = extra[:, 6] != 0.0
    heading = bool(state.heading_initialized)  # constant over the run
    model = p.covariance_model
    last_mag = p.mag_input.last_used_ns
    ages: Any
    if mag is not None:
        has = ~np.isnan(mag[:, 0])
        status = extra[:, 9]
        used_arr = has & (status == MAG_USED)
        p.tally.mag_used += int(np.count_nonzero(used_arr))
        p.tally.mag_rejected += int(np.count_nonzero(has & (status == MAG_REJECTED)))
        p.tally.mag_disabled += int(np.count_nonzero(has & (status == MAG_DISABLED)))
        used = used_arr.tolist()
    else:
        used_arr = None
        used = [False] * n
    if used_arr is not None and used_arr.any():
        # the stamp of the last sample used up to each row (the one before the run: -1)
        last_at = np.maximum.accumulate(np.where(used_arr, np.arange(n), -1))
        last_t = run.mag_t_ns[np.maximum(last_at, 0)]
        known = last_at >= 0
        if last_mag is not None:
            last_t = np.where(known, last_t, last_mag)
            known[:] = True
        # (t - last) * 1e-9 as the per-message path computes it; unknown: 0.0, what the
        # model takes for "never" (age or 0.0)
        ages = np.where(known, (run.t_ns - last_t) * 1e-9, 0.0).tolist()
        last_mag = int(run.mag_t_ns[int(last_at[-1])])
    elif last_mag is not None:
        ages = ((run.t_ns - last_mag) * 1e-9).tolist()
    else:
        ages = [None] * n
    tilts, yaws = model.steps(dt.tolist(), clipped_col.tolist(), extra[:, 10].tolist(),
                              extra[:, 7].tolist(), en, extra[:, 11].tolist(),
                              extra[:, 12].tolist(), extra[:, 14].tolist(), heading,
                              extra[:, 13].tolist(), used, ages, extra[:, 18].tolist())
    cov = np.zeros((n, 9))
    cov[:, 0] = tilts
    cov[:, 4] = tilts
    cov[:, 8] = yaws
    p.mag_input.last_used_ns = last_mag
    p.tally.mag_dropped += st["dropped"]
    p.tally.mag_stale += st["stale"]
    p.tally.received_mag += st["n_mag"]
    p.mag_input.pending = st["pending_mag"]
    p.clock.last_ns, p.clock.dt_mean, p.tally.gaps = st["last_ns"], st["dt_mean"], st["gaps"]
    p.tally.received_imu += n
    p.tally.processed += n
    w = p.window
    w.dt_min, w.dt_max, w.dt_sum, w.n_dt = st["window"]
    # the running sum in message order (add.accumulate is sequential: the same bits)
    w.err_sum = float(np.add.accumulate(np.concatenate(([w.err_sum], en_arr)))[-1])
    if n:
        finite = en_arr[~np.isnan(en_arr)]
        if finite.size and float(finite.max()) > w.err_max:
            w.err_max = float(finite.max())
    w.n_err += n
    w.n_clipped += int(np.count_nonzero(clipped_col))
    if w.n == 0:
        w.first_ns = int(run.t_ns[0])
    w.n += n
    w.last_ns = int(run.t_ns[-1])
    # -- outputs ------------------------------------------------------------------------------
    if not p.output_frame.identity:  # core world -> published (nwu, true north), as on_imu
        q = p.output_frame.apply_array(q)
    rpy = _rpy(p, q)
    p.last_rpy = tuple(rpy[-1].tolist())
    elapsed = perf_counter() - t0  # the run's processing time, shared by its messages
    w.proc_sum += elapsed
    if elapsed / n > w.proc_max:
        w.proc_max = elapsed / n
    return Committed(q, rpy, extra, en_arr, cov, p.angular_velocity_covariance.value,
                     p.linear_acceleration_covariance.value, gyro, acc)


def _rpy(p: ImuPipeline, q: np.ndarray) -> np.ndarray:
    """(n, 3) roll, pitch, yaw of each row of ``q`` (w, x, y, z) as ``on_imu`` computes them:
    the arguments with NumPy (the same IEEE operations, in the same order), ``math.atan2`` and
    ``math.asin`` per row (NumPy's own differ from them in the last bit on some rows), then
    the unwrap, sequential by nature, when it is on."""
    qw, qx, qy, qz = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    out = np.empty((q.shape[0], 3))
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
