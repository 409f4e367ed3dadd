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
on real and hostile bags (test/test_bulk_pipeline.py). It relies on: ``run_rows`` = repeated
``update`` (a magnetometer row of NaN = no sample), the extra columns of
:func:`cf_estimator.core.filter.state_extras`, and the error norm being
``sqrt(ex² + ey² + ez²)`` of the error vector (core/step.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from time import perf_counter
from typing import Any

import numpy as np

from cf_estimator.core.filter import EXTRA_COLUMNS
from cf_estimator.core.step import MAG_DISABLED, MAG_REJECTED, MAG_USED
from cf_estimator.pipeline import checks
from cf_estimator.pipeline.pipeline import _ACCEL_MAX2, _GYRO_MAX2, _TWO_PI, ImuPipeline

IMU, MAG, OTHER = 0, 1, 2  #: event kinds; OTHER (e.g. a reference) passes through
_GYRO_WARN2 = checks.GYRO_IMPLAUSIBLE_RAD_S**2


@dataclass
class Scan:
    """What :func:`scan` found: the ordinary run's rows and the state after it (uncommitted)."""

    end: int  #: index of the first event not in the run
    n_events: int = 0
    t_ns: list[int] = field(default_factory=list)
    sec: list[int] = field(default_factory=list)
    nsec: list[int] = field(default_factory=list)
    log_ns: list[int] = field(default_factory=list)
    rows: list[int] = field(default_factory=list)  #: row of each message in ``values``
    values: Any = None  #: the IMU block's (n, 37) values: gyro columns 13:16, accel 25:28
    mag: list[tuple[float, float, float] | None] = field(default_factory=list)
    mag_t_ns: list[int] = field(default_factory=list)  #: stamp of the row's mag sample
    dt: list[float] = field(default_factory=list)
    frame: str = ""
    state: dict[str, Any] = field(default_factory=dict)  #: pipeline fields to write back

    @property
    def n(self) -> int:
        return len(self.t_ns)


def _ordinary_start(pipe: ImuPipeline) -> bool:
    f = pipe._filter  # noqa: SLF001 - this module is the pipeline's own bulk path
    return (f.initialized and pipe._last_ns is not None and not pipe._pending_warnings
            and pipe._acc_n >= checks.ACCEL_CHECK_SAMPLES)


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
        self._cov: dict[tuple[int, bytes | None], list[bool]] = {}

    def column(self, name: str) -> list[float]:
        """``gx gy gz ax ay az`` (IMU) or ``mx my mz`` (magnetometer) as a list of floats."""
        col = self._cols.get(name)
        if col is None:
            j = {"gx": 13, "gy": 14, "gz": 15, "ax": 25, "ay": 26, "az": 27,
                 "mx": 0, "my": 1, "mz": 2}[name]
            block = self.mag if name[0] == "m" else self.imu
            col = self._cols[name] = block.values[:, j].tolist()
        return col

    def same_covariance(self, start: int, raw: bytes | None) -> list[bool]:
        """Per IMU row: its covariance starting at column ``start`` has the bytes ``raw``."""
        key = (start, raw)
        same = self._cov.get(key)
        if same is None:
            cov = np.ascontiguousarray(self.imu.values[:, start:start + 9]).view(np.uint8)
            if raw is None or len(raw) != 72:
                same = [False] * self.imu.n
            else:
                same = np.all(cov == np.frombuffer(raw, dtype=np.uint8), axis=1).tolist()
            self._cov[key] = same
        return same


def scan(pipe: ImuPipeline, ev: Events, start: int, limit_log_ns: int | None = None) -> Scan:
    """The longest run of ordinary events from ``ev`` index ``start``, stopping before an
    event logged at or after ``limit_log_ns``. Nothing of ``pipe`` changes."""
    p = pipe
    out = Scan(start)
    if not _ordinary_start(p):
        return out
    heading = bool(p._filter._state.heading_initialized)  # noqa: SLF001
    use_mag = p._use_mag
    imu_frame, mag_frame = p._imu_frame, p._mag_frame
    mag_ready = p._mag_n >= checks.MAG_CHECK_SAMPLES
    last = p._last_ns
    reset_on, reset_ns = p._reset_gap_on, p._reset_gap_ns
    max_dt_ns, timeout = p._max_dt_ns, p._mag_timeout_ns
    dt_mean, gaps = p._dt_mean, p._gaps
    pending = p._pending_mag
    dropped = stale = 0
    n_mag = 0
    w = p._window
    dt_min, dt_max, dt_sum, n_dt = w.dt_min, w.dt_max, w.dt_sum, w.n_dt
    isfinite = math.isfinite
    kinds, logs, rows = ev.kind, ev.log_ns, ev.row
    imu, mag_block = ev.imu, ev.mag
    if imu is not None:
        i_sec, i_nsec, i_frame, i_plain = imu.sec, imu.nsec, imu.frame, imu.plain
        gxs, gys, gzs = ev.column("gx"), ev.column("gy"), ev.column("gz")
        axs, ays, azs = ev.column("ax"), ev.column("ay"), ev.column("az")
        av_same = ev.same_covariance(16, p._av_cov.raw)
        la_same = ev.same_covariance(28, p._la_cov.raw)
    if mag_block is not None:
        m_sec, m_nsec, m_frame, m_plain = (mag_block.sec, mag_block.nsec, mag_block.frame,
                                           mag_block.plain)
        mxs, mys, mzs = ev.column("mx"), ev.column("my"), ev.column("mz")
    out_rows = out.rows
    i = start
    n_ev = len(kinds)
    while i < n_ev:
        kind = kinds[i]
        log_ns = logs[i]
        if limit_log_ns is not None and log_ns >= limit_log_ns:
            break
        if kind == OTHER:
            i += 1
            continue
        k = rows[i]
        if kind == MAG:
            if not use_mag or not heading or not mag_ready or not m_plain[k]:
                break
            t_m = m_sec[k] * 1_000_000_000 + m_nsec[k]
            mx, my, mz = mxs[k], mys[k], mzs[k]
            n2 = mx * mx + my * my + mz * mz
            if t_m == 0 or not isfinite(n2) or n2 == 0.0 or m_frame[k] != mag_frame:
                break
            if pending is not None:
                dropped += 1
            pending = (t_m, mx, my, mz)
            n_mag += 1
            i += 1
            continue
        if not i_plain[k]:
            break
        sec, nsec = i_sec[k], i_nsec[k]
        gx, gy, gz = gxs[k], gys[k], gzs[k]
        ax, ay, az = axs[k], ays[k], azs[k]
        if (sec == 0 and nsec == 0) or i_frame[k] != imu_frame:
            break
        if not (isfinite(gx) and isfinite(gy) and isfinite(gz) and isfinite(ax)
                and isfinite(ay) and isfinite(az)):
            break
        a2 = ax * ax + ay * ay + az * az
        g2 = gx * gx + gy * gy + gz * gz
        if a2 == 0.0 or g2 > _GYRO_MAX2 or a2 > _ACCEL_MAX2 or g2 > _GYRO_WARN2:
            break
        t_ns = sec * 1_000_000_000 + nsec
        d_ns = t_ns - last
        if d_ns <= 0 or (reset_on and d_ns > reset_ns):
            break
        if not (av_same[k] and la_same[k]):
            break
        if pending is not None and not heading:
            break
        # -- the message is ordinary: the pipeline's bookkeeping, in its order ------------------
        dt = d_ns * 1e-9
        if n_dt == 0 or dt < dt_min:
            dt_min = dt
        if dt > dt_max:
            dt_max = dt
        dt_sum += dt
        n_dt += 1
        if d_ns > max_dt_ns:
            gaps += 1
            dt = dt_mean if dt_mean > 0.0 else min(p._pp.max_dt_s, 0.01)
        elif dt_mean > 0.0:
            dt_mean += 0.05 * (dt - dt_mean)
        else:
            dt_mean = dt
        mag = None
        mag_t = 0
        if pending is not None:
            if abs(t_ns - pending[0]) <= timeout:
                mag = (pending[1], pending[2], pending[3])
                mag_t = pending[0]
            else:
                stale += 1
            pending = None
        out_rows.append(k)
        out.t_ns.append(t_ns)
        out.sec.append(sec)
        out.nsec.append(nsec)
        out.log_ns.append(log_ns)
        out.mag.append(mag)
        out.mag_t_ns.append(mag_t)
        out.dt.append(dt)
        last = t_ns
        i += 1
    out.end = i
    out.n_events = i - start
    out.frame = str(imu_frame)
    out.values = imu.values if imu is not None else None
    out.state = {
        "_last_ns": last, "_dt_mean": dt_mean, "_gaps": gaps, "_pending_mag": pending,
        "dropped": dropped, "stale": stale, "n_mag": n_mag,
        "window": (dt_min, dt_max, dt_sum, n_dt),
    }
    return out


@dataclass
class Committed:
    """The run's outputs (one row per IMU message), as ``on_imu`` would have returned them."""

    q_wxyz: np.ndarray  #: (n, 4) q_world_from_sensor
    rpy: list[tuple[float, float, float]]
    extra: np.ndarray  #: (n, EXTRA_COLUMNS): state_extras after each sample
    error_norm: list[float]
    covariance: tuple[float, ...]  #: orientation covariance of every row
    av_cov: tuple[float, ...]
    la_cov: tuple[float, ...]
    gyro: np.ndarray  #: (n, 3) the rows the filter got [rad/s] (= the output's input copy)
    accel: np.ndarray  #: (n, 3) [m/s²]


def commit(pipe: ImuPipeline, run: Scan, marks: Sequence[int] = (),
           on_mark: Callable[[int], None] | None = None) -> Committed:
    """Run the filter over ``run`` and update ``pipe`` as the per-message calls would.

    ``marks``: row indices after which ``on_mark(row)`` is called with the filter in the state
    it has after that row (the replay samples the bias estimate there).
    """
    t0 = perf_counter()
    p = pipe
    n = run.n
    f = p._filter  # noqa: SLF001
    sel = run.values[np.asarray(run.rows, dtype=np.intp)]
    gyro = np.ascontiguousarray(sel[:, 13:16])
    acc = np.ascontiguousarray(sel[:, 25:28])
    has_mag = any(m is not None for m in run.mag)
    mag = None
    if has_mag:
        mag = np.full((n, 3), np.nan)
        for k, m in enumerate(run.mag):
            if m is not None:
                mag[k] = m
    dt = np.array(run.dt, dtype=np.float64)
    q = np.empty((n, 4))
    extra = np.empty((n, EXTRA_COLUMNS))
    a = 0
    marked = set(marks)
    for b in [*(m + 1 for m in marks), n]:
        if b <= a:
            continue
        f.run_rows(gyro[a:b], acc[a:b], None if mag is None else mag[a:b], dt[a:b], 0,
                   q[a:b], extra[a:b])
        if on_mark is not None and b - 1 in marked:
            on_mark(b - 1)
        a = b
    # -- counters and statistics ------------------------------------------------------------
    st = run.state
    status = extra[:, 9].tolist()
    for k, m in enumerate(run.mag):
        if m is None:
            continue
        ms = status[k]
        if ms == MAG_USED:
            p._mag_used += 1
            p._last_mag_used_ns = run.mag_t_ns[k]
        elif ms == MAG_REJECTED:
            p._mag_rejected += 1
        elif ms == MAG_DISABLED:
            p._mag_disabled += 1
    p._mag_dropped += st["dropped"]
    p._mag_stale += st["stale"]
    p._received_mag += st["n_mag"]
    p._pending_mag = st["_pending_mag"]
    p._last_ns, p._dt_mean, p._gaps = st["_last_ns"], st["_dt_mean"], st["_gaps"]
    p._received_imu += n
    p._processed += n
    w = p._window
    w.dt_min, w.dt_max, w.dt_sum, w.n_dt = st["window"]
    ex, ey, ez = extra[:, 0], extra[:, 1], extra[:, 2]
    en = np.sqrt(ex * ex + ey * ey + ez * ez).tolist()
    err_sum, err_max = w.err_sum, w.err_max
    for e in en:
        err_sum += e
        if e > err_max:
            err_max = e
    w.err_sum, w.err_max = err_sum, err_max
    w.n_err += n
    w.n_clipped += int(np.count_nonzero(extra[:, 6]))
    if w.n == 0:
        w.first_ns = run.t_ns[0]
    w.n += n
    w.last_ns = run.t_ns[-1]
    # -- outputs ------------------------------------------------------------------------------
    heading = bool(f._state.heading_initialized)  # noqa: SLF001 - constant over the run
    cov = p._cov_referenced if heading else p._cov_unreferenced
    atan2, asin = math.atan2, math.asin
    unwrap = p._pp.rpy_unwrap
    prev = p._unwrap_prev
    rpy = []
    for qw, qx, qy, qz in q.tolist():
        roll = atan2(2.0 * (qw * qx + qy * qz), 1.0 - 2.0 * (qx * qx + qy * qy))
        sp = 2.0 * (qw * qy - qz * qx)
        pitch = asin(1.0 if sp > 1.0 else (-1.0 if sp < -1.0 else sp))
        yaw = atan2(2.0 * (qw * qz + qx * qy), 1.0 - 2.0 * (qy * qy + qz * qz))
        if unwrap:
            if prev is not None:
                roll += _TWO_PI * round((prev[0] - roll) / _TWO_PI)
                yaw += _TWO_PI * round((prev[2] - yaw) / _TWO_PI)
            prev = (roll, pitch, yaw)
        rpy.append((roll, pitch, yaw))
    if unwrap:
        p._unwrap_prev = prev
    p._last_rpy = rpy[-1]
    elapsed = perf_counter() - t0  # the run's processing time, shared by its messages
    w.proc_sum += elapsed
    if elapsed / n > w.proc_max:
        w.proc_max = elapsed / n
    return Committed(q, rpy, extra, en, cov, p._av_cov.value, p._la_cov.value, gyro, acc)
