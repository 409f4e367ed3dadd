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
    gyro: list[tuple[float, float, float]] = field(default_factory=list)
    accel: list[tuple[float, float, float]] = field(default_factory=list)
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


def scan(pipe: ImuPipeline, events: Sequence[tuple[int, int, Any]], start: int,
         limit_log_ns: int | None = None) -> Scan:
    """The longest run of ordinary events from ``events[start]`` (``(kind, log_ns, msg)``,
    kind :data:`IMU` or :data:`MAG`), stopping before an event logged at or after
    ``limit_log_ns``. Nothing of ``pipe`` changes."""
    p = pipe
    out = Scan(start)
    if not _ordinary_start(p):
        return out
    heading = bool(p._filter._state.heading_initialized)  # noqa: SLF001
    use_mag = p._use_mag
    imu_frame, mag_frame = p._imu_frame, p._mag_frame
    mag_ready = p._mag_n >= checks.MAG_CHECK_SAMPLES
    av_raw, la_raw = p._av_cov.raw, p._la_cov.raw
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
    i = start
    n_ev = len(events)
    while i < n_ev:
        kind, log_ns, msg = events[i]
        if limit_log_ns is not None and log_ns >= limit_log_ns:
            break
        if kind == OTHER:
            i += 1
            continue
        if kind == MAG:
            if not use_mag or not heading or not mag_ready:
                break
            st = msg.header.stamp
            t_m = st.sec * 1_000_000_000 + st.nanosec
            m = msg.magnetic_field
            mx, my, mz = float(m.x), float(m.y), float(m.z)
            n2 = mx * mx + my * my + mz * mz
            if t_m == 0 or not isfinite(n2) or n2 == 0.0 or msg.header.frame_id != mag_frame:
                break
            if pending is not None:
                dropped += 1
            pending = (t_m, mx, my, mz)
            n_mag += 1
            i += 1
            continue
        h = msg.header
        st = h.stamp
        sec, nsec = st.sec, st.nanosec
        av, la = msg.angular_velocity, msg.linear_acceleration
        gx, gy, gz = float(av.x), float(av.y), float(av.z)
        ax, ay, az = float(la.x), float(la.y), float(la.z)
        if (sec == 0 and nsec == 0) or h.frame_id != imu_frame:
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
        if msg.angular_velocity_covariance.tobytes() != av_raw or \
                msg.linear_acceleration_covariance.tobytes() != la_raw:
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
        out.t_ns.append(t_ns)
        out.sec.append(sec)
        out.nsec.append(nsec)
        out.log_ns.append(log_ns)
        out.gyro.append((gx, gy, gz))
        out.accel.append((ax, ay, az))
        out.mag.append(mag)
        out.mag_t_ns.append(mag_t)
        out.dt.append(dt)
        last = t_ns
        i += 1
    out.end = i
    out.n_events = i - start
    out.frame = str(imu_frame)
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
    gyro = np.array(run.gyro, dtype=np.float64).reshape(n, 3)
    acc = np.array(run.accel, dtype=np.float64).reshape(n, 3)
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
    return Committed(q, rpy, extra, en, cov, p._av_cov.value, p._la_cov.value)
