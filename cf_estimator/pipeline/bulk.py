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
:func:`cf_estimator.core.filter.state_extras` (clipped, phase, the bias estimate's error σ,
magnetometer status, the loop's running gain, the aperiodic unit's world-frame state, the
heading error and the accelerometer noise per row: what the orientation covariance model
needs), and the error norm being ``sqrt(ex² + ey² + ez²)`` of the error vector
(core/step.py). body_frame's half turn
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

from cf_estimator.core.filter import EXTRA_COLUMNS, Extra
from cf_estimator.core.kernel import compiled_kernel
from cf_estimator.core.step import MAG_DISABLED, MAG_REJECTED, MAG_USED
from cf_estimator.pipeline import checks, columns
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
    values: Any = None  #: the IMU block's (n, IMU_DOUBLES) values (pipeline/columns.py)
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
    g0, a0 = columns.ANGULAR_VELOCITY.start, columns.LINEAR_ACCELERATION.start
    gx, gy, gz, ax, ay, az = (v[:, j] for j in (g0, g0 + 1, g0 + 2, a0, a0 + 1, a0 + 2))
    with np.errstate(over="ignore", invalid="ignore"):
        finite = np.isfinite(gx)  # all six finite (column by column: faster than axis=1)
        for c in (gy, gz, ax, ay, az):
            finite &= np.isfinite(c)
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
                 imu: Any, mag: Any, message: Callable[[int], Any],
                 arrays: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> None:
        self.kind, self.log_ns, self.row = kind, log_ns, row
        #: ``kind``, ``log_ns``, ``row`` as arrays when the reader has them (else made once)
        self._arrays = arrays
        self.imu, self.mag, self.message = imu, mag, message
        self._cols: dict[str, list[float]] = {}
        self._cov: dict[tuple[int, bytes | None], np.ndarray] = {}
        self._static: dict[str, np.ndarray] | None = None
        self._frames: dict[tuple[int, str | None], np.ndarray] = {}
        self._stamps: tuple[np.ndarray, np.ndarray] | None = None
        self._layout: dict[str, Any] | None = None
        self._gates: dict[tuple[Any, ...], tuple[np.ndarray, np.ndarray]] = {}

    def column(self, name: str) -> list[float]:
        """``gx gy gz ax ay az`` (IMU) or ``mx my mz`` (magnetometer) as a list of floats;
        a leading ``-``: negated (body_frame's half turn about x)."""
        col = self._cols.get(name)
        if col is None:
            neg = name.startswith("-")
            base = name.lstrip("-")
            g0, a0 = columns.ANGULAR_VELOCITY.start, columns.LINEAR_ACCELERATION.start
            m0 = columns.MAGNETIC_FIELD.start
            j = {"gx": g0, "gy": g0 + 1, "gz": g0 + 2, "ax": a0, "ay": a0 + 1, "az": a0 + 2,
                 "mx": m0, "my": m0 + 1, "mz": m0 + 2}[base]
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
        if self._arrays is not None:
            kind_a, log_a, row_a = self._arrays
        else:
            kind_a, log_a, row_a = self.kind, self.log_ns, self.row
        kind = np.asarray(kind_a, dtype=np.int8)
        row = np.asarray(row_a, dtype=np.intp)
        ok = np.zeros(n, dtype=bool)
        t_ns = np.zeros(n, dtype=np.int64)
        for blk, k, check in ((self.imu, IMU, _imu_ok), (self.mag, MAG, _mag_ok)):
            if blk is None:
                continue
            sel = np.flatnonzero(kind == k)
            r = row[sel]
            sec_all, nsec_all, plain_all = blk.arrays()
            t_ns[sel] = sec_all[r] * 1_000_000_000 + nsec_all[r]
            # the checks row by row over the block, then per event (no copy of its rows)
            ok[sel] = (plain_all & check(blk.values, sec_all, nsec_all))[r]
        self._static = st = {"kind": kind, "ok": ok, "t_ns": t_ns, "row": row,
                             "log_ns": np.asarray(log_a, dtype=np.int64)}
        return st

    def layout(self) -> dict[str, Any]:
        """Where the IMU and magnetometer events are (computed once; no pipeline state):
        ``imu_ev`` the IMU events' indices and, per IMU event, its ``imu_t`` (header stamp
        [ns]), ``imu_row``, ``imu_log`` (log time), ``imu_sec``/``imu_nsec`` and
        ``imu_prev_mag`` (the magnetometer event just before it among the IMU and
        magnetometer events, else -1); ``nz`` the IMU and magnetometer events' indices,
        ``nz_kind`` their kinds and ``mm_cum`` the running count of a magnetometer event
        followed by another one among them."""
        lay = self._layout
        if lay is not None:
            return lay
        st = self.static()
        kind = st["kind"]
        nz = np.flatnonzero(kind != OTHER)
        nz_kind = kind[nz]
        is_imu_nz = nz_kind == IMU
        imu_at = np.flatnonzero(is_imu_nz)  # in nz
        imu_ev = nz[imu_at]
        prev = np.where(imu_at > 0, nz[np.maximum(imu_at - 1, 0)], -1)
        prev_mag = np.where((prev >= 0) & (kind[np.maximum(prev, 0)] == MAG), prev, -1)
        mm = (nz_kind[:-1] == MAG) & (nz_kind[1:] == MAG)
        imu_row = st["row"][imu_ev]
        lay = {"imu_ev": imu_ev, "imu_t": st["t_ns"][imu_ev], "imu_row": imu_row,
               "imu_log": st["log_ns"][imu_ev], "imu_prev_mag": prev_mag, "nz": nz,
               "nz_kind": nz_kind,
               "mm_cum": np.concatenate(([0], np.cumsum(mm, dtype=np.int64)))}
        if self.imu is not None:
            sec, nsec = self.imu_stamps()
            lay["imu_sec"], lay["imu_nsec"] = sec[imu_row], nsec[imu_row]
        self._layout = lay
        return lay

    def gate(self, imu_frame: str | None, av_raw: bytes | None, la_raw: bytes | None,
             mag_frame: str | None, mag_allowed: bool, gap_ns: int | None
             ) -> tuple[np.ndarray, np.ndarray]:
        """Per event, what :func:`scan` asks of it but the first IMU message's interval (from
        the pipeline's last stamp): ``good`` (IMU: valid, frame ``imu_frame``, covariances
        ``av_raw``/``la_raw``; magnetometer: allowed, valid, frame ``mag_frame``; others:
        true) and, with each IMU message's interval from the IMU event before it (positive,
        at most ``gap_ns`` unless None), ``next_bad[i]``: the first index >= i failing them
        (len(kind) if none; n + 1 values). Computed once per key."""
        key = (imu_frame, av_raw, la_raw, mag_frame, mag_allowed, gap_ns)
        got = self._gates.get(key)
        if got is not None:
            return got
        st, lay = self.static(), self.layout()
        kind, ok = st["kind"], st["ok"]
        n = kind.shape[0]
        good = np.ones(n, dtype=bool)
        is_imu = kind == IMU
        if self.imu is not None:
            rows = st["row"]
            cov_ok = (self.same_covariance(columns.ANGULAR_VELOCITY_COVARIANCE.start, av_raw)
                      & self.same_covariance(columns.LINEAR_ACCELERATION_COVARIANCE.start,
                                             la_raw))
            imu_good = ok & self.frame_is(IMU, imu_frame)
            imu_good[is_imu] &= cov_ok[rows[is_imu]]
            good[is_imu] = imu_good[is_imu]
        is_mag = kind == MAG
        if mag_allowed:
            good[is_mag] = (ok & self.frame_is(MAG, mag_frame))[is_mag]
        else:
            good[is_mag] = False
        # the interval from the IMU message before (the first one's is the caller's)
        d = np.diff(lay["imu_t"])
        chain = d > 0
        if gap_ns is not None:
            chain &= d <= gap_ns
        seq = good.copy()
        seq[lay["imu_ev"][1:]] &= chain
        bad_at = np.where(seq, n, np.arange(n))
        next_bad = np.empty(n + 1, dtype=np.int64)
        next_bad[n] = n
        next_bad[:n] = np.minimum.accumulate(bad_at[::-1])[::-1]
        got = self._gates[key] = (good, next_bad)
        return got

    def imu_stamps(self) -> tuple[np.ndarray, np.ndarray]:
        """The IMU block's header ``sec`` and ``nanosec`` per row (int64 arrays)."""
        if self._stamps is None:
            sec, nsec, _plain = self.imu.arrays()
            self._stamps = (sec, nsec)
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
            else:  # the nine values' bits, column by column (a faster all(axis=1))
                bits = np.ascontiguousarray(self.imu.values).view("<u8")
                ref = np.frombuffer(raw, dtype="<u8").tolist()
                same = bits[:, start] == ref[0]
                for j in range(1, 9):
                    same &= bits[:, start + j] == ref[j]
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
    n_ev = len(ev.kind)
    stop = n_ev
    if limit_log_ns is not None:
        # log times are sorted in a chunk (the reader merges by log time)
        stop = bisect.bisect_left(ev.log_ns, limit_log_ns, start, n_ev)
    if stop <= start:
        return out
    lay = ev.layout()
    rules = p.rules
    mag_allowed = bool(rules.use_mag and heading
                       and p.mag_input.check_n >= checks.MAG_CHECK_SAMPLES)
    gap_ns = rules.reset_gap_ns if rules.reset_gap_on else None
    good, next_bad = ev.gate(p.imu_frame, p.angular_velocity_covariance.raw,
                             p.linear_acceleration_covariance.raw,
                             p.mag_input.frame if mag_allowed else None, mag_allowed, gap_ns)
    # the first event failing the checks: the static ones (events.gate) and, for the first
    # IMU message, the interval from the pipeline's last stamp (positive, no gap that resets)
    imu_ev, imu_t = lay["imu_ev"], lay["imu_t"]
    a = int(np.searchsorted(imu_ev, start))
    f = int(imu_ev[a]) if a < imu_ev.shape[0] else n_ev
    first_bad = int(next_bad[start])
    if f >= stop or first_bad < f:
        end = min(first_bad, stop)
    else:
        d0 = int(imu_t[a]) - int(p.clock.last_ns)
        if not (bool(good[f]) and d0 > 0 and (gap_ns is None or d0 <= gap_ns)):
            end = f
        else:
            end = min(int(next_bad[f + 1]), stop)
    if end <= start:
        return out
    # -- the bookkeeping over the run, in the pipeline's order ----------------------------------
    max_dt_ns, timeout = rules.max_dt_ns, rules.mag_timeout_ns
    dt_mean, gaps = p.clock.dt_mean, p.tally.gaps
    stale = 0
    w = p.window
    dt_min, dt_max, dt_sum, n_dt = w.dt_min, w.dt_max, w.dt_sum, w.n_dt
    last = p.clock.last_ns
    mag_block = ev.mag
    max_dt_fallback = min(p.pipeline_params.max_dt_s, 0.01)
    st = ev.static()
    b = int(np.searchsorted(imu_ev, end))  # the run's IMU messages: a..b-1
    n_imu = b - a
    rows = lay["imu_row"][a:b]
    t_imu = imu_t[a:b]
    nz, nz_kind = lay["nz"], lay["nz_kind"]
    ks, ke = (int(k) for k in np.searchsorted(nz, (start, end)))  # IMU and magnetometer
    n_mag = ke - ks - n_imu
    # magnetometer samples: each IMU message takes the pending sample (the magnetometer event
    # just before it, or the one pending at the start); a sample followed by another one
    # before an IMU message is superseded (dropped)
    mm_cum = lay["mm_cum"]
    dropped = int(mm_cum[ke - 1] - mm_cum[ks]) if ke - 1 > ks else 0
    if n_mag and pending is not None and int(nz_kind[ks]) == MAG:
        dropped += 1
    prev_ev = lay["imu_prev_mag"][a:b]
    prev_mag = prev_ev >= start  # the event before it in the run is a magnetometer sample
    first_takes_pending = n_imu > 0 and int(nz_kind[ks]) == IMU and pending is not None
    has = prev_mag.copy()
    mag_t = np.where(prev_mag, st["t_ns"][np.maximum(prev_ev, 0)], 0)
    mag = None
    if n_mag or first_takes_pending:
        mag = np.full((n_imu, 3), np.nan)
        if mag_block is not None and prev_mag.any():
            mrows = st["row"][prev_ev[prev_mag]]
            vals = mag_block.values[mrows, columns.MAGNETIC_FIELD]
            if not p.mag_correction.identity:  # as on_mag: calibration, then the flip
                vals = p.mag_correction.apply_rows(vals)
            if rules.flip:  # body_frame FLU <-> FRD, as on_mag turns the field
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
    if n_mag and int(nz_kind[ke - 1]) == MAG:
        last_ev = int(nz[ke - 1])
        r = int(st["row"][last_ev])
        mxs, mys, mzs = ev.column("mx"), ev.column("my"), ev.column("mz")
        if rules.flip:  # body_frame FLU <-> FRD, as on_mag turns the field
            mys, mzs = ev.column("-my"), ev.column("-mz")
        if p.mag_correction.identity:
            pending = (int(st["t_ns"][last_ev]), mxs[r], mys[r], mzs[r])
        else:  # as on_mag: the raw sample calibrated, then the flip
            raw = ev.column("mx")[r], ev.column("my")[r], ev.column("mz")[r]
            cx, cy, cz = p.mag_correction.apply(*raw)
            if rules.flip:
                cy, cz = -cy, -cz
            pending = (int(st["t_ns"][last_ev]), cx, cy, cz)
    elif n_imu:
        pending = None
    # intervals: the window statistics see the raw interval, the filter the mean one across
    # a gap (pipeline.on_imu's order of operations, its float arithmetic)
    d_ns = np.empty(n_imu, dtype=np.int64)  # the stamp differences, the first from ``last``
    if n_imu:
        d_ns[0] = int(t_imu[0]) - last
        np.subtract(t_imu[1:], t_imu[:-1], out=d_ns[1:])
    dt_arr = d_ns * 1e-9
    if n_imu:
        lo, hi = float(dt_arr.min()), float(dt_arr.max())
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
        for d, dt in zip(d_ns.tolist(), dt_arr.tolist(), strict=True):
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
            for dt in dt_arr.tolist():
                if dt_mean > 0.0:
                    dt_mean += 0.05 * (dt - dt_mean)
                else:
                    dt_mean = dt
        out.dt = dt_arr
    out.rows = rows
    out.t_ns = t_imu
    if ev.imu is not None:
        out.sec = lay["imu_sec"][a:b]
        out.nsec = lay["imu_nsec"][a:b]
    out.log_ns = lay["imu_log"][a:b]
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
    gyro = run.values[run.rows, columns.ANGULAR_VELOCITY]  # new (n, 3) arrays
    acc = run.values[run.rows, columns.LINEAR_ACCELERATION]
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
    ex, ey, ez = extra[:, Extra.ERROR].T
    en_arr = np.sqrt(ex * ex + ey * ey + ez * ez)
    clipped_col = extra[:, Extra.CLIPPED]
    heading = bool(state.heading_initialized)  # constant over the run
    last_mag = p.mag_input.last_used_ns
    ages: np.ndarray | None
    if mag is not None:
        has = ~np.isnan(mag[:, 0])
        status = extra[:, Extra.MAG_STATUS]
        used_arr = has & (status == MAG_USED)
        rejected_arr = has & (status == MAG_REJECTED)
        p.tally.mag_used += int(np.count_nonzero(used_arr))
        p.tally.mag_rejected += int(np.count_nonzero(rejected_arr))
        p.tally.mag_disabled += int(np.count_nonzero(has & (status == MAG_DISABLED)))
        used = used_arr.astype(np.float64)
        rejected = rejected_arr.astype(np.float64)
    else:
        used_arr = None
        used = rejected = np.zeros(n)
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
        ages = np.where(known, (run.t_ns - last_t) * 1e-9, 0.0)
        last_mag = int(run.mag_t_ns[int(last_at[-1])])
    elif last_mag is not None:
        ages = (run.t_ns - last_mag) * 1e-9
    else:
        ages = None
    tilts, yaws = p.covariance_model.rows(
        dt, clipped_col, extra[:, Extra.BIAS_SIGMA], extra[:, Extra.PHASE], en_arr,
        extra[:, Extra.LX], extra[:, Extra.LY], extra[:, Extra.NOISE_A2], heading,
        extra[:, Extra.YAW_ERROR], used, ages, extra[:, Extra.LOOP_K1], rejected, f.backend)
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
    w.n_clipped += int(np.count_nonzero(clipped_col != 0.0))
    if w.n == 0:
        w.first_ns = int(run.t_ns[0])
    w.n += n
    w.last_ns = int(run.t_ns[-1])
    # -- outputs ------------------------------------------------------------------------------
    if not p.output_frame.identity:  # core world -> published (nwu, true north), as on_imu
        q = p.output_frame.apply_array(q)
    rpy = _rpy(p, q, f.backend)
    p.last_rpy = tuple(rpy[-1].tolist())
    elapsed = perf_counter() - t0  # the run's processing time, shared by its messages
    w.proc_sum += elapsed
    if elapsed / n > w.proc_max:
        w.proc_max = elapsed / n
    return Committed(q, rpy, extra, en_arr, cov, p.angular_velocity_covariance.value,
                     p.linear_acceleration_covariance.value, gyro, acc)


def _rpy(p: ImuPipeline, q: np.ndarray, backend: str = "python") -> np.ndarray:
    """(n, 3) roll, pitch, yaw of each row of ``q`` (w, x, y, z) as ``on_imu`` computes them:
    the arguments with NumPy (the same IEEE operations, in the same order), ``math.atan2`` and
    ``math.asin`` per row (NumPy's own differ from them in the last bit on some rows; backend
    'compiled': ``_kernel.rpy_rows``, the same arithmetic and libm calls in C), then the
    unwrap, sequential by nature, when it is on."""
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
