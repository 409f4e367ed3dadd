"""Offline API: whole recordings as arrays in, orientations and internal signals out.

    result = estimate(gyro_rad_s, accel_m_s2, mag, rate_hz=200.0)
    result.quaternion        # (N, 4) w, x, y, z: q_world_from_sensor (ENU unless params say NED)

Sample 0 (or the first sample with a valid accelerometer) initialises the attitude; rows
before that are NaN. Row k is integrated over dt_k = t_k − t_{k−1} with sample k's gyro.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from cf_estimator.core import quaternion as quat
from cf_estimator.core.batched import BatchedFilter
from cf_estimator.core.filter import ComplementaryFilter
from cf_estimator.core.params import FilterParams


@dataclass
class EstimateResult:
    """Per-sample outputs of :func:`estimate` (N samples)."""

    t_s: np.ndarray  #: (N,) sample times [s]
    quaternion: np.ndarray  #: (N, 4) q_world_from_sensor (w, x, y, z); NaN before init
    error_rad: np.ndarray  #: (N, 3) raw error e = (a/‖g‖) × ĝ, sensor frame
    clipped: np.ndarray  #: (N,) bool: saturation active
    gyro_bias_rad_s: np.ndarray  #: (N, 3) bias estimate, sensor frame
    phase: np.ndarray  #: (N,) int: 0 uninitialized, 1 startup, 2 running, 3 recovering
    at_rest: np.ndarray  #: (N,) bool
    mag_status: np.ndarray  #: (N,) int: 0 none, 1 used, 2 rejected, 3 disabled

    def euler_rad(self) -> np.ndarray:
        """(N, 3) roll, pitch, yaw [rad] (aerospace ZYX) of :attr:`quaternion`."""
        return quat.to_euler(self.quaternion)


def sample_times(n: int, rate_hz: float | None, timestamps_s: ArrayLike | None) -> np.ndarray:
    """Sample times [s] from a rate or explicit stamps (strictly increasing, else ValueError)."""
    if (rate_hz is None) == (timestamps_s is None):
        raise ValueError("give exactly one of rate_hz or timestamps_s")
    if rate_hz is not None:
        if not (np.isfinite(rate_hz) and rate_hz > 0):
            raise ValueError(f"rate_hz must be positive, got {rate_hz!r}")
        return np.arange(n) / float(rate_hz)
    t = np.asarray(timestamps_s, dtype=float).reshape(-1)
    if t.shape[0] != n:
        raise ValueError(f"timestamps_s has {t.shape[0]} entries for {n} samples")
    if not np.all(np.isfinite(t)):
        raise ValueError("timestamps_s contains NaN/Inf")
    bad = np.flatnonzero(np.diff(t) <= 0.0)
    if bad.size:
        raise ValueError(
            f"timestamps_s must increase strictly (first problem at index {bad[0] + 1})"
        )
    return t


def _as_rows(name: str, a: ArrayLike | None, n: int | None) -> np.ndarray | None:
    if a is None:
        return None
    arr = np.asarray(a, dtype=float)
    if arr.ndim != 2 or arr.shape[1] != 3 or (n is not None and arr.shape[0] != n):
        raise ValueError(f"{name} must have shape (N, 3); got {arr.shape}")
    return arr


def iterate_samples(
    gyro_rad_s: ArrayLike, accel_m_s2: ArrayLike, mag: ArrayLike | None, t_s: np.ndarray
) -> Iterator[tuple[int, tuple, tuple, tuple | None, float]]:
    """(index, gyro, accel, mag or None, dt) per sample; dt of sample 0 is 0 (initialisation)."""
    gyro = _as_rows("gyro_rad_s", gyro_rad_s, None)
    assert gyro is not None
    acc = _as_rows("accel_m_s2", accel_m_s2, gyro.shape[0])
    mg = _as_rows("mag", mag, gyro.shape[0])
    dts = np.diff(t_s, prepend=t_s[0]).tolist()
    g_rows = [tuple(r) for r in gyro.tolist()]
    a_rows = [tuple(r) for r in acc.tolist()]  # type: ignore[union-attr]
    m_rows = [tuple(r) for r in mg.tolist()] if mg is not None else [None] * len(g_rows)
    for i, (g, a, m, dt) in enumerate(zip(g_rows, a_rows, m_rows, dts, strict=True)):
        yield i, g, a, m, dt


def estimate(
    gyro_rad_s: ArrayLike,
    accel_m_s2: ArrayLike,
    mag: ArrayLike | None = None,
    *,
    rate_hz: float | None = None,
    timestamps_s: ArrayLike | None = None,
    params: FilterParams | None = None,
    initial_orientation: Sequence[float] | None = None,
) -> EstimateResult:
    """Run the filter over a recording.

    gyro_rad_s, accel_m_s2, mag: (N, 3) in the sensor frame (mag in any unit; NaN rows =
    no sample). Give ``rate_hz`` or ``timestamps_s`` [s]. ``initial_orientation`` (w, x, y, z),
    if given, replaces the initialisation from the first samples.
    """
    n = np.asarray(gyro_rad_s).shape[0]
    t = sample_times(n, rate_hz, timestamps_s)
    f = ComplementaryFilter(params, initial_orientation=initial_orientation)
    out_q = np.full((n, 4), np.nan)
    out_e = np.zeros((n, 3))
    out_b = np.zeros((n, 3))
    out_clip = np.zeros(n, dtype=bool)
    out_phase = np.zeros(n, dtype=np.int8)
    out_rest = np.zeros(n, dtype=bool)
    out_mag = np.zeros(n, dtype=np.int8)
    for i, g, a, m, dt in iterate_samples(gyro_rad_s, accel_m_s2, mag, t):
        if not f.initialized or dt > 0.0:
            q = f.update(g, a, dt if f.initialized else 1.0, m)
        else:  # sample 0 with a given initial orientation: nothing to integrate yet
            q = f.orientation_tuple()
        if q is None:
            continue
        state = f._state  # read-only access to the live state, for speed
        out_q[i] = q
        out_e[i] = (state.ex, state.ey, state.ez)
        out_b[i] = (state.bx, state.by, state.bz)
        out_clip[i] = state.clipped
        out_phase[i] = state.phase
        out_rest[i] = state.at_rest
        out_mag[i] = state.mag_status
    return EstimateResult(t, out_q, out_e, out_clip, out_b, out_phase, out_rest, out_mag)


def estimate_many(
    params: Sequence[FilterParams],
    gyro_rad_s: ArrayLike,
    accel_m_s2: ArrayLike,
    mag: ArrayLike | None = None,
    *,
    rate_hz: float | None = None,
    timestamps_s: ArrayLike | None = None,
    on_sample: Callable[[int, np.ndarray], None] | None = None,
    store: bool = True,
) -> np.ndarray | None:
    """Run P parameter sets over one recording with :class:`BatchedFilter`.

    Returns (P, N, 4) quaternions (NaN before init) when ``store``; ``on_sample(i, q_P4)``
    is called per sample otherwise (or as well), which keeps memory flat for long runs.
    """
    n = np.asarray(gyro_rad_s).shape[0]
    t = sample_times(n, rate_hz, timestamps_s)
    bf = BatchedFilter(params)
    out = np.full((bf.size, n, 4), np.nan) if store else None
    for i, g, a, m, dt in iterate_samples(gyro_rad_s, accel_m_s2, mag, t):
        q = bf.update(g, a, dt if bf.initialized else 1.0, m)
        if q is None:
            continue
        if out is not None:
            out[:, i] = q
        if on_sample is not None:
            on_sample(i, q)
    return out
