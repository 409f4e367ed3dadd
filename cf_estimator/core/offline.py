"""Offline (acausal) estimation of a whole recording: forward, backward and forward again.

    result = estimate(gyro, accel, mag, rate_hz=200.0, offline=True)   # see batch.estimate

Nothing after a flight needs causality, so every sample may use the whole recording. Per
segment (see :func:`segments`), through the compiled step of the online filter:

1. **pass 1, forward, online** (the shipped filter from the first sample; decimated to about
   :data:`PASS1_RATE_HZ`: only its end matters): the attitude and the gyro-bias estimate at
   the end of the segment, learned over all of it.
2. **backward pass** over the time-reversed segment (reversed order, negated gyro, negated
   bias; :func:`reverse_rows`), started at the last sample from pass 1's final attitude and
   bias: converged from its first step. Its end is the attitude and bias at the first sample.
3. **forward pass** started at the first sample from the backward pass's attitude and bias:
   converged from the first sample on.

Passes 2 and 3 run with the parameters of :func:`refine_params`: no start-up phase (they start
converged) and no bias learning in motion (the bias comes from the whole recording; rest
phases still refine it). Both passes are converged at every sample, so they are fused with equal
weights (a normalised mean on the sphere): the complementary filter's lag errors (the low-pass
of the accelerometer correction, a residual bias) have opposite signs forwards and backwards
and cancel, which one pass alone cannot do. With a magnetometer, heading is taken from the
forward pass (the fused attitude turned about the world vertical to the forward heading;
inclination stays the fused one): measured on BROAD, the backward pass's heading is worse in
motion (see docs/offline.md).

Row k's outputs are the fused quaternion and the forward pass's internal signals (error,
clipping, bias, rest, magnetometer status, bias sigma). Memory is linear in N (a few (N, 4)
arrays and one (N, 11) array per segment).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from cf_estimator.core.filter import EXTRA_COLUMNS, ComplementaryFilter, state_extras
from cf_estimator.core.params import FilterParams

#: Intervals longer than this [s] split a recording into segments (the pipeline's default
#: ``max_dt_s``: over a longer gap the gyro rate is unknown).
OFFLINE_MAX_GAP_S = 0.5
#: Pass 1 runs on block means down to about this rate [Hz] (it only delivers its end state).
PASS1_RATE_HZ = 100.0
#: Row flags of a causal pass with velocity aiding (``flags`` of :func:`smooth_segment`): the
#: accelerometer row was velocity-aided ...
ROW_AIDED = 1
#: ... the velocity said the vehicle moves (not at rest: VelocityAiding.moving_now).
ROW_MOVING = 2
#: Fewer valid samples than this: pass 1 is not decimated.
_MIN_DECIMATED_ROWS = 200


def refine_params(params: FilterParams) -> FilterParams:
    """Parameters of the backward and second forward pass: converged starts (no start-up
    phase) and the bias from the whole recording (no integral learning in motion)."""
    return dataclasses.replace(params, startup_duration_s=0.0, k2=0.0, bias_learning_k2=0.0)


def segments(t_s: np.ndarray, gyro_rad_s: np.ndarray, max_gap_s: float = OFFLINE_MAX_GAP_S
             ) -> list[tuple[int, int]]:
    """[start, stop) row ranges processed on their own: split at intervals longer than
    ``max_gap_s`` [s] and at rows whose gyro is not finite (those rows belong to none)."""
    valid = np.isfinite(gyro_rad_s.sum(axis=1))
    breaks = np.zeros(len(t_s), dtype=bool)
    if len(t_s) > 1:
        breaks[1:] = np.diff(t_s) > max_gap_s
    out: list[tuple[int, int]] = []
    start = None
    for i in np.flatnonzero(breaks | ~valid).tolist() + [len(t_s)]:
        first = 0 if start is None else start
        if i > first:
            out.append((first, i))
        start = i + 1 if i < len(t_s) and not valid[i] else i
    return [(a, b) for a, b in out if np.all(valid[a:b])]


def reverse_rows(gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None, dt: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
    """The time-reversed recording, C-contiguous: row j of the reversed one is row N−1−j,
    with the gyro negated and shifted by one row (row k's rate acts over [t_{k−1}, t_k], so
    going back from t_k to t_{k−1} uses −ω_k: reversed row j gets −ω_{N−j} and dt_{N−j})."""
    gr = np.empty_like(gyro)
    gr[0] = -gyro[0]
    gr[1:] = -gyro[:0:-1]
    dtr = np.empty_like(dt)
    dtr[0] = 0.0
    dtr[1:] = dt[:0:-1]
    ar = np.ascontiguousarray(accel[::-1])
    mr = None if mag is None else np.ascontiguousarray(mag[::-1])
    return gr, ar, mr, dtr


def _run_rows(f: ComplementaryFilter, gyro: np.ndarray, accel: np.ndarray,
              mag: np.ndarray | None, dt: np.ndarray, start: int, q_out: np.ndarray,
              extra_out: np.ndarray | None, flags: np.ndarray | None) -> None:
    """``f.run_rows`` over rows start..N−1 as the causal pass's ``flags`` (N,) say (None: the
    state as it is): the state's aided flag set for each run of rows with :data:`ROW_AIDED`
    alike, and rest interrupted before every row with :data:`ROW_MOVING` (one row at a time
    there, :meth:`~cf_estimator.core.filter.ComplementaryFilter.interrupt_rest`). A bool array
    is :data:`ROW_AIDED` alone."""
    if flags is None:
        f.run_rows(gyro, accel, mag, dt, start, q_out, extra_out)
        return
    n = len(dt)
    edges = (np.flatnonzero(np.diff(flags[start:].astype(np.int8))) + start + 1).tolist() + [n]
    k = start
    for stop in edges:
        f.set_aided(bool(flags[k] & ROW_AIDED))
        moving = bool(flags[k] & ROW_MOVING)
        for a, b in [(i, i + 1) for i in range(k, stop)] if moving else [(k, stop)]:
            if moving:
                f.interrupt_rest()
            f.run_rows(gyro[:b], accel[:b], None if mag is None else mag[:b], dt[:b], a,
                       q_out[:b], None if extra_out is None else extra_out[:b])
        k = stop


def _pass(params: FilterParams, gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None,
          dt: np.ndarray, q_out: np.ndarray, extra_out: np.ndarray | None,
          q0: Sequence[float] | None = None, bias: Sequence[float] | None = None,
          bias_var: tuple[float, float] | None = None, backend: str | None = None,
          flags: np.ndarray | None = None) -> ComplementaryFilter | None:
    """One filter pass over rows 0..N−1 (dt[0] unused). Starts from ``q0`` (world frame) with
    ``bias`` [rad/s] and its variances (``bias_var``: the state's bias_var and bias_err_var),
    or else initialises at the first valid accelerometer row (rows before stay NaN). None if it
    never initialises. ``flags``: see :func:`_run_rows`."""
    f = ComplementaryFilter(params, backend=backend)
    start = 0
    if q0 is not None:
        f.initialize(q0, heading_known=True)
        start = 1
    else:
        while not f.initialized and start < len(dt):
            f.update(gyro[start], accel[start], 1.0, None if mag is None else mag[start])
            start += 1
        if not f.initialized:
            return None
    s = f._state  # noqa: SLF001 - the documented writable bias fields
    if bias is not None:
        s.bx, s.by, s.bz = (float(c) for c in bias)
    if bias_var is not None:
        s.bias_var, s.bias_err_var = (float(v) for v in bias_var)
    q_out[start - 1] = f.orientation_tuple()
    if extra_out is not None:
        extra_out[start - 1] = state_extras(s)
    if start < len(dt):
        _run_rows(f, gyro, accel, mag, dt, start, q_out, extra_out, flags)
    return f


def _block_means(gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None, dt: np.ndarray,
                 factor: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
    """Pass 1's input: blocks of ``factor`` rows ending at the last row (gyro and
    accelerometer averaged, the block's last valid magnetometer row, dt summed); the first row
    alone first (it initialises). :func:`_block_last` takes a flag column alike."""
    n = len(dt)
    m = (n - 1) // factor
    first = n - m * factor

    def blocks(a: np.ndarray) -> np.ndarray:
        return a[first:].reshape(m, factor, -1).mean(axis=1)

    g = np.ascontiguousarray(np.vstack([gyro[:first][-1:], blocks(gyro)]))
    a = np.ascontiguousarray(np.vstack([accel[:first][-1:], blocks(accel)]))
    mg = None if mag is None else np.ascontiguousarray(
        np.vstack([mag[first - 1:first], _last_valid_rows(mag[first:].reshape(m, factor, 3))]))
    d = np.concatenate([[0.0], dt[first:].reshape(m, factor).sum(axis=1)])
    return g, a, mg, d


def _block_last(flags: np.ndarray, factor: int) -> np.ndarray:
    """(M + 1,) the first row's flag, then each block's last row's (blocks as
    :func:`_block_means`)."""
    n = len(flags)
    first = n - ((n - 1) // factor) * factor
    return np.concatenate([flags[first - 1:first], flags[first + factor - 1::factor]])


def _last_valid_rows(blocks: np.ndarray) -> np.ndarray:
    """(M, 3) the last finite row of each (factor, 3) block, NaN where a block has none (a
    magnetometer slower than the IMU leaves NaN rows between its samples)."""
    valid = np.all(np.isfinite(blocks), axis=2)
    last = blocks.shape[1] - 1 - np.argmax(valid[:, ::-1], axis=1)
    out = blocks[np.arange(blocks.shape[0]), last]
    out[~valid.any(axis=1)] = np.nan
    return out


#: Rows per chunk of the backward pass and the fusion (bounds their temporaries).
CHUNK_ROWS = 1 << 16


def _backward_pass(params: FilterParams, gyro: np.ndarray, accel: np.ndarray,
                   mag: np.ndarray | None, dt: np.ndarray, q_out: np.ndarray,
                   q0: Sequence[float], bias: Sequence[float], bias_var: tuple[float, float],
                   backend: str | None = None, flags: np.ndarray | None = None
                   ) -> ComplementaryFilter:
    """The filter over the time-reversed rows (:func:`reverse_rows`), started at the last
    row from ``q0`` with ``bias`` (already negated) and its variances (``bias_var``: the
    state's bias_var and bias_err_var); writes ``q_out`` in the original row order. Runs in
    chunks of :data:`CHUNK_ROWS` reversed rows (no reversed copy of the whole recording)."""
    n = len(dt)
    f = ComplementaryFilter(params, backend=backend)
    f.initialize(q0, heading_known=True)
    s = f._state  # noqa: SLF001 - the documented writable bias fields
    s.bx, s.by, s.bz = (float(c) for c in bias)
    s.bias_var, s.bias_err_var = (float(v) for v in bias_var)
    q_out[n - 1] = f.orientation_tuple()
    buf = np.empty((min(CHUNK_ROWS + 1, n), 4))
    for j0 in range(1, n, CHUNK_ROWS):
        j1 = min(j0 + CHUNK_ROWS, n)  # reversed rows [j0, j1) = original rows N−j1 .. N−1−j0
        gr, ar, mr, dtr = reverse_rows(gyro[n - j1:n - j0 + 1], accel[n - j1:n - j0 + 1],
                                       None if mag is None else mag[n - j1:n - j0 + 1],
                                       dt[n - j1:n - j0 + 1])
        # the chunk's row 0 is the state already reached: run its rows 1..
        _run_rows(f, gr, ar, mr, dtr, 1, buf[:j1 - j0 + 1], None,
                  None if flags is None else flags[n - j1:n - j0 + 1][::-1])
        q_out[n - j1:n - j0] = buf[1:j1 - j0 + 1][::-1]
    return f


def _fuse(qf: np.ndarray, qb: np.ndarray, heading_from_forward: bool) -> None:
    """``qf`` ← normalised mean of the forward and backward quaternions (same sign first),
    optionally turned about the world vertical to the forward pass's heading (chunked)."""
    for i in range(0, len(qf), CHUNK_ROWS):
        f, b = qf[i:i + CHUNK_ROWS], qb[i:i + CHUNK_ROWS]
        sign = np.where(np.einsum("ij,ij->i", f, b) < 0.0, -1.0, 1.0)
        m = f + sign[:, None] * b
        m /= np.sqrt(np.einsum("ij,ij->i", m, m))[:, None]
        if heading_from_forward:
            # e = f ⊗ m⁻¹ (world frame); its heading half-angle (w, z) rotates m: Exp_z ⊗ m
            fw, fx, fy, fz = f.T
            mw, mx, my, mz = m.T
            ew = fw * mw + fx * mx + fy * my + fz * mz
            ez = -fw * mz - fx * my + fy * mx + fz * mw
            r = np.hypot(ew, ez)
            c, sn = ew / r, ez / r
            m = np.stack([c * mw - sn * mz, c * mx - sn * my, c * my + sn * mx,
                          c * mz + sn * mw], axis=1)
        f[:] = m


def smooth_segment(gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None,
                   t_s: np.ndarray, params: FilterParams, q: np.ndarray, extra: np.ndarray,
                   initial_orientation: Sequence[float] | None = None,
                   backend: str | None = None, flags: np.ndarray | None = None) -> None:
    """Offline estimate of one segment (C-contiguous (N, 3) rows, strictly increasing t_s)
    into ``q`` ((N, 4) q_world_from_sensor, NaN-filled: stays NaN when no accelerometer row
    is valid) and ``extra`` ((N, EXTRA_COLUMNS) forward-pass signals), both C-contiguous.
    ``flags`` (N,): what a causal pass with velocity aiding did per row (:data:`ROW_AIDED`:
    the vehicle's acceleration taken out of the accelerometer row; :data:`ROW_MOVING`: the
    velocity said the vehicle moves, so it was not at rest); every pass runs the rows so."""
    n = len(t_s)
    dt = np.diff(t_s, prepend=t_s[0])
    # pass 1: online, forward, decimated; only its final state is used
    rate = (n - 1) / (t_s[-1] - t_s[0]) if n > 1 else PASS1_RATE_HZ
    factor = max(1, int(rate / PASS1_RATE_HZ))
    if n // factor < _MIN_DECIMATED_ROWS:
        factor = 1
    g1, a1, m1, d1 = _block_means(gyro, accel, mag, dt, factor) if factor > 1 else (
        gyro, accel, mag, dt)
    flags1 = _block_last(flags, factor) if flags is not None and factor > 1 else flags
    f1 = _pass(params, g1, a1, m1, d1, np.empty((len(d1), 4)), None, initial_orientation,
               backend=backend, flags=flags1)
    if f1 is None:
        return
    s1 = f1._state  # noqa: SLF001
    refined = refine_params(params)
    # pass 2: backward from pass 1's end
    qb = np.empty((n, 4))
    fb = _backward_pass(refined, gyro, accel, mag, dt, qb, f1.orientation_tuple(),
                        (-s1.bx, -s1.by, -s1.bz), (s1.bias_var, s1.bias_err_var), backend,
                        flags)
    sb = fb._state  # noqa: SLF001
    # pass 3: forward from the backward pass's start
    _pass(refined, gyro, accel, mag, dt, q, extra, qb[0], (-sb.bx, -sb.by, -sb.bz),
          (sb.bias_var, sb.bias_err_var), backend, flags)
    _fuse(q, qb, params.use_mag and mag is not None)


def estimate_offline(gyro: np.ndarray, accel: np.ndarray, mag: np.ndarray | None,
                     t_s: np.ndarray, params: FilterParams | None = None,
                     initial_orientation: Sequence[float] | None = None,
                     backend: str | None = None, max_gap_s: float = OFFLINE_MAX_GAP_S,
                     flags: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """((N, 4) q, (N, EXTRA_COLUMNS) signals) over every segment of a recording (see
    :func:`segments`; rows outside segments: NaN q, zero signals). ``initial_orientation``
    starts the first segment's first pass; ``flags``: see :func:`smooth_segment`."""
    p = params if params is not None else FilterParams()
    n = len(t_s)
    q = np.full((n, 4), np.nan)
    extra = np.zeros((n, EXTRA_COLUMNS))
    for k, (a, b) in enumerate(segments(t_s, gyro, max_gap_s)):
        smooth_segment(gyro[a:b], accel[a:b], None if mag is None else mag[a:b], t_s[a:b], p,
                       q[a:b], extra[a:b], initial_orientation if k == 0 and a == 0 else None,
                       backend, None if flags is None else flags[a:b])
    return q, extra
