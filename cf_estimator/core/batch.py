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
from cf_estimator.core.filter import EXTRA_COLUMNS, ComplementaryFilter, state_extras
from cf_estimator.core.input_checks import warn_units
from cf_estimator.core.kernel import resolve_backend
from cf_estimator.core.params import FilterParams
from cf_estimator.core.step import BIAS_CONVERGED_SIGMA_RAD_S


@dataclass
class EstimateResult:
    """Per-sample outputs of :func:`estimate` (N samples)."""

    t_s: np.ndarray  #: (N,) sample times [s]
    quaternion: np.ndarray  #: (N, 4) q_world_from_sensor (w, x, y, z); NaN before init
    error_rad: np.ndarray  #: (N, 3) raw error e = (a/‖g‖) × ĝ, sensor frame
    clipped: np.ndarray  #: (N,) bool: saturation active
    gyro_bias_rad_s: np.ndarray  #: (N, 3) bias estimate, sensor frame
    phase: np.ndarray  #: (N,) int: 0 uninitialized, 1 startup, 2 running, 3 recovering
    at_rest: np.ndarray  #: (N,) bool: still (block statistics); the bias is learned from the gyro
    mag_status: np.ndarray  #: (N,) int: 0 none, 1 used, 2 rejected, 3 disabled
    gyro_bias_sigma_rad_s: np.ndarray  #: (N,) standard deviation of the bias estimate [rad/s]

    @property
    def gyro_bias_converged(self) -> np.ndarray:
        """(N,) bool: the bias estimate's standard deviation is below
        :data:`~cf_estimator.core.step.BIAS_CONVERGED_SIGMA_RAD_S`."""
        return self.gyro_bias_sigma_rad_s < BIAS_CONVERGED_SIGMA_RAD_S

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


def _rows(gyro_rad_s: ArrayLike, accel_m_s2: ArrayLike, mag: ArrayLike | None
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(N, 3) C-contiguous float64 copies of the inputs (shapes checked)."""
    gyro = _as_rows("gyro_rad_s", gyro_rad_s, None)
    assert gyro is not None
    acc = _as_rows("accel_m_s2", accel_m_s2, gyro.shape[0])
    mg = _as_rows("mag", mag, gyro.shape[0])
    return (np.ascontiguousarray(gyro), np.ascontiguousarray(acc),
            None if mg is None else np.ascontiguousarray(mg))


def _run_filter(f: ComplementaryFilter, gyro: np.ndarray, acc: np.ndarray, mg: np.ndarray | None,
                t: np.ndarray, q_out: np.ndarray, extra_out: np.ndarray | None) -> None:
    """Initialise ``f`` at the first valid accelerometer row (unless it is initialised: then row
    0 is its start), then run every later row; q_out rows before initialisation stay NaN."""
    start = 0
    while not f.initialized and start < len(t):
        f.update(gyro[start], acc[start], 1.0, None if mg is None else mg[start])
        start += 1
    if f.initialized:
        if start == 0:  # an initial orientation was given: sample 0 has nothing to integrate
            start = 1
        q_out[start - 1] = f.orientation_tuple()
        if extra_out is not None:
            extra_out[start - 1] = state_extras(f._state)  # noqa: SLF001 - read-only
        f.run_rows(gyro, acc, mg, np.diff(t, prepend=t[0]), start, q_out, extra_out)


def estimate(
    gyro_rad_s: ArrayLike,
    accel_m_s2: ArrayLike,
    mag: ArrayLike | None = None,
    *,
    rate_hz: float | None = None,
    timestamps_s: ArrayLike | None = None,
    params: FilterParams | None = None,
    initial_orientation: Sequence[float] | None = None,
    backend: str | None = None,
    offline: bool = False,
) -> EstimateResult:
    """Run the filter over a recording.

    gyro_rad_s, accel_m_s2, mag: (N, 3) in the sensor frame (mag in any unit; NaN rows =
    no sample). Give ``rate_hz`` or ``timestamps_s`` [s]. ``initial_orientation`` (w, x, y, z),
    if given, replaces the initialisation from the first samples. ``backend``: see
    :mod:`cf_estimator.core.kernel`. ``offline``: the acausal estimate of
    :mod:`cf_estimator.core.offline` (every sample uses the whole recording; intervals over
    ``OFFLINE_MAX_GAP_S`` and non-finite gyro rows split it into segments).
    """
    gyro, acc, mg = _rows(gyro_rad_s, accel_m_s2, mag)
    n = gyro.shape[0]
    t = sample_times(n, rate_hz, timestamps_s)
    f = ComplementaryFilter(params, initial_orientation=initial_orientation, backend=backend)
    warn_units(gyro, acc, f.params.gravity_m_s2)  # deg/s or g: warned once per call site
    if offline:
        from cf_estimator.core.offline import estimate_offline

        out_q, extra = estimate_offline(gyro, acc, mg, t, f.params, initial_orientation, backend)
    else:
        out_q = np.full((n, 4), np.nan)
        extra = np.zeros((n, EXTRA_COLUMNS))
        _run_filter(f, gyro, acc, mg, t, out_q, extra)
    return EstimateResult(
        t, out_q, extra[:, 0:3], extra[:, 6] != 0.0, extra[:, 3:6],
        extra[:, 7].astype(np.int8), extra[:, 8] != 0.0, extra[:, 9].astype(np.int8),
        extra[:, 10],
    )


def estimate_many(
    params: Sequence[FilterParams],
    gyro_rad_s: ArrayLike,
    accel_m_s2: ArrayLike,
    mag: ArrayLike | None = None,
    *,
    rate_hz: float | None = None,
    timestamps_s: ArrayLike | None = None,
    on_candidate: Callable[[int, np.ndarray], None] | None = None,
    backend: str | None = None,
) -> np.ndarray | None:
    """Run P parameter sets over one recording (same inputs and conventions as :func:`estimate`).

    Returns (P, N, 4) q_world_from_sensor (NaN before init). With ``on_candidate``, nothing is
    returned: ``on_candidate(p, q_N4)`` is called once per parameter set, in order, with its
    (N, 4) quaternions (the array may be reused afterwards: copy what you keep).

    The compiled backend runs one parameter set at a time over the whole recording; the Python
    backend advances all P together with :class:`BatchedFilter` (NumPy arrays of shape (P,)).
    """
    if not params:
        raise ValueError("estimate_many needs at least one parameter set")
    if len({p.world_frame for p in params}) != 1:
        raise ValueError("all parameter sets of a batch must share world_frame")
    gyro, acc, mg = _rows(gyro_rad_s, accel_m_s2, mag)
    n = gyro.shape[0]
    t = sample_times(n, rate_hz, timestamps_s)
    if resolve_backend(backend) == "compiled":
        out = None if on_candidate is not None else np.full((len(params), n, 4), np.nan)
        q = np.empty((n, 4))
        for k, p in enumerate(params):
            q.fill(np.nan)
            _run_filter(ComplementaryFilter(p, backend="compiled"), gyro, acc, mg, t, q, None)
            if on_candidate is not None:
                on_candidate(k, q)
            else:
                out[k] = q  # type: ignore[index]
        return out
    bf = BatchedFilter(params)
    out = np.full((bf.size, n, 4), np.nan)
    for i, g, a, m, dt in iterate_samples(gyro, acc, mg, t):
        qp = bf.update(g, a, dt if bf.initialized else 1.0, m)
        if qp is not None:
            out[:, i] = qp
    if on_candidate is None:
        return out
    for k in range(bf.size):
        on_candidate(k, out[k])
    return None
