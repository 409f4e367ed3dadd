"""Offline API: whole recordings as arrays in, orientations and internal signals out.

    result = estimate(gyro_rad_s, accel_m_s2, mag, rate_hz=200.0)
    result.quaternion        # (N, 4) w, x, y, z: q_world_from_sensor (ENU unless params say NED)

Sample 0 (or the first sample with a valid accelerometer) initialises the attitude; rows
before that are NaN. Row k is integrated over dt_k = t_k − t_{k−1} with sample k's gyro.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from cf_estimator.core import quaternion as quat
from cf_estimator.core.batched import BatchedFilter
from cf_estimator.core.covariance import (
    TILT_FLOOR_RAD2,
    UNREFERENCED_YAW_RAD2,
    YAW_FLOOR_RAD2,
    OrientationCovariance,
)
from cf_estimator.core.filter import EXTRA_COLUMNS, ComplementaryFilter, Extra, state_extras
from cf_estimator.core.input_checks import warn_units
from cf_estimator.core.kernel import resolve_backend
from cf_estimator.core.params import FilterParams
from cf_estimator.core.step import BIAS_CONVERGED_SIGMA_RAD_S, MAG_REJECTED, MAG_USED
from cf_estimator.core.velocity import VelocityAiding, VelocityStatus


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
    #: (N,) σ of the bias estimate's error [rad/s] (bias.error_sigma)
    gyro_bias_sigma_rad_s: np.ndarray
    #: (N,) bool: the sample was velocity-aided (None: no velocity given)
    velocity_aided: np.ndarray | None = None
    #: the velocity aiding's counters and heading offset at the end (None: no velocity given)
    velocity_status: VelocityStatus | None = None
    #: the parameters the filter ran with (the covariance model reads k1, gravity, bias prior)
    params: FilterParams | None = None
    #: (N, EXTRA_COLUMNS) the (forward) pass's signals the covariance model reads
    extra: np.ndarray | None = field(default=None, repr=False)
    _cov: np.ndarray | None = field(default=None, repr=False, compare=False)

    @property
    def gyro_bias_converged(self) -> np.ndarray:
        """(N,) bool: the bias estimate's standard deviation is below
        :data:`~cf_estimator.core.step.BIAS_CONVERGED_SIGMA_RAD_S`."""
        return self.gyro_bias_sigma_rad_s < BIAS_CONVERGED_SIGMA_RAD_S

    def orientation_covariance(self, tilt0_rad2: float = TILT_FLOOR_RAD2,
                               yaw0_rad2: float = YAW_FLOOR_RAD2,
                               unreferenced_yaw_rad2: float = UNREFERENCED_YAW_RAD2
                               ) -> np.ndarray:
        """(N, 9) ``orientation_covariance`` per sample [rad²] (row-major 3×3 about the world
        x, y, z axes; NaN before initialisation): the node's model
        (:mod:`cf_estimator.core.covariance`) on this run's signals; the floors default to the
        node's (``orientation_covariance_rad2``, ``yaw_covariance_rad2``,
        ``unreferenced_yaw_covariance_rad2``). A magnetometer sample counts as the IMU
        sample's stamp. With ``offline=True`` it describes the causal pass (the acausal
        estimate is at least as good)."""
        defaults = (tilt0_rad2, yaw0_rad2, unreferenced_yaw_rad2) == (
            TILT_FLOOR_RAD2, YAW_FLOOR_RAD2, UNREFERENCED_YAW_RAD2)
        if defaults and self._cov is not None:
            return self._cov
        if self.extra is None or self.params is None:
            raise ValueError("this result carries no filter signals (built by hand?)")
        cov = covariance_rows(self.extra, self.t_s, self.quaternion, self.params, tilt0_rad2,
                              yaw0_rad2, unreferenced_yaw_rad2)
        if defaults:
            self._cov = cov
        return cov

    @property
    def tilt_sigma_rad(self) -> np.ndarray:
        """(N,) σ of the inclination error [rad]: √(cov[0] + cov[4]) of
        :meth:`orientation_covariance` (default floors): the expected e² of a 2-D error."""
        c = self.orientation_covariance()
        return np.sqrt(c[:, 0] + c[:, 4])

    @property
    def heading_sigma_rad(self) -> np.ndarray:
        """(N,) σ of the heading error [rad]: √cov[8] of :meth:`orientation_covariance`
        (``unreferenced_yaw_covariance_rad2`` while no magnetometer sample has fixed it)."""
        return np.sqrt(self.orientation_covariance()[:, 8])

    def euler_rad(self) -> np.ndarray:
        """(N, 3) roll, pitch, yaw [rad] (aerospace ZYX) of :attr:`quaternion`."""
        return quat.to_euler(self.quaternion)

    def to_dataframe(self) -> Any:
        """The per-sample results as a pandas DataFrame (pandas is optional: ``ImportError``
        naming it when absent), one row per sample, indexed by ``t_s`` [s]: quaternion
        ``qw qx qy qz`` (q_world_from_sensor), ``roll_rad pitch_rad yaw_rad`` (ZYX),
        ``cov_xx_rad2 cov_yy_rad2 cov_zz_rad2`` (the diagonal of
        :meth:`orientation_covariance`), ``bias_x/y/z_rad_s``, ``bias_sigma_rad_s``, the flags
        ``clipped``, ``at_rest``, ``phase``, ``mag_status`` (codes as documented on the
        fields) and, with velocity aiding, ``velocity_aided``."""
        import importlib

        try:
            # optional, by name: never a dependency of the package or the node (package.xml)
            pd = importlib.import_module("pandas")
        except ImportError:
            raise ImportError("EstimateResult.to_dataframe needs pandas (pip install pandas)"
                              ) from None
        rpy = self.euler_rad()
        cov = self.orientation_covariance()
        cols: dict[str, np.ndarray] = {
            "qw": self.quaternion[:, 0], "qx": self.quaternion[:, 1],
            "qy": self.quaternion[:, 2], "qz": self.quaternion[:, 3],
            "roll_rad": rpy[:, 0], "pitch_rad": rpy[:, 1], "yaw_rad": rpy[:, 2],
            "cov_xx_rad2": cov[:, 0], "cov_yy_rad2": cov[:, 4], "cov_zz_rad2": cov[:, 8],
            "bias_x_rad_s": self.gyro_bias_rad_s[:, 0], "bias_y_rad_s": self.gyro_bias_rad_s[:, 1],
            "bias_z_rad_s": self.gyro_bias_rad_s[:, 2],
            "bias_sigma_rad_s": self.gyro_bias_sigma_rad_s,
            "clipped": self.clipped, "at_rest": self.at_rest, "phase": self.phase,
            "mag_status": self.mag_status,
        }
        if self.velocity_aided is not None:
            cols["velocity_aided"] = self.velocity_aided
        return pd.DataFrame(cols, index=pd.Index(self.t_s, name="t_s"))


def covariance_rows(extra: np.ndarray, t_s: np.ndarray, q: np.ndarray, params: FilterParams,
                    tilt0_rad2: float = TILT_FLOOR_RAD2, yaw0_rad2: float = YAW_FLOOR_RAD2,
                    unreferenced_yaw_rad2: float = UNREFERENCED_YAW_RAD2) -> np.ndarray:
    """(N, 9) orientation covariance [rad²] of a run from its ``extra`` rows (the node's model,
    :class:`~cf_estimator.core.covariance.OrientationCovariance`, row by row from the first
    row with a finite ``q``; NaN before)."""
    n = extra.shape[0]
    out = np.full((n, 9), np.nan)
    ok = np.flatnonzero(np.isfinite(q[:, 0]))
    if ok.size == 0:
        return out
    model = OrientationCovariance(tilt0_rad2, yaw0_rad2, unreferenced_yaw_rad2,
                                  params.bias_prior_sigma_rad_s, params.k1, params.gravity_m_s2,
                                  params.r1)
    start = int(ok[0])
    x = extra[start:]
    ts = t_s[start:].tolist()
    dts = np.diff(t_s[start:], prepend=t_s[start]).tolist()
    ex, ey, ez = x[:, Extra.ERROR].T
    en = np.sqrt(ex ** 2 + ey ** 2 + ez ** 2).tolist()
    clipped = (x[:, Extra.CLIPPED] != 0.0).tolist()
    phase, sigma = x[:, Extra.PHASE].tolist(), x[:, Extra.BIAS_SIGMA].tolist()
    status = x[:, Extra.MAG_STATUS].tolist()
    lx, ly = x[:, Extra.LX].tolist(), x[:, Extra.LY].tolist()
    yaw_err, na2 = x[:, Extra.YAW_ERROR].tolist(), x[:, Extra.NOISE_A2].tolist()
    loop_k1 = x[:, Extra.LOOP_K1].tolist()
    heading = False
    last: float | None = None
    rows = []
    step = model.step
    for k in range(n - start):
        used = status[k] == MAG_USED
        rejected = status[k] == MAG_REJECTED
        if used:
            heading = True
            last = ts[k]
        sb = sigma[k]
        rows.append(step(dts[k], clipped[k], None if sb != sb else sb, phase[k], en[k], lx[k],
                         ly[k], na2[k], heading, yaw_err[k], used,
                         None if last is None else ts[k] - last, loop_k1[k], rejected))
    out[start:] = rows
    return out


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
            extra_out[start - 1] = _init_extras(f, mg is not None and start - 1 >= 0
                                                and bool(np.all(np.isfinite(mg[start - 1]))))
        f.run_rows(gyro, acc, mg, np.diff(t, prepend=t[0]), start, q_out, extra_out)


def _init_extras(f: ComplementaryFilter, with_mag: bool) -> tuple:
    """The extra row of the initialising sample: its magnetometer sample, when it set the
    heading, counts as used (as the pipeline counts it for the covariance)."""
    row = list(state_extras(f._state))  # noqa: SLF001 - read-only
    if with_mag and f._state.heading_initialized:  # noqa: SLF001
        row[9] = MAG_USED
    return tuple(row)


def velocity_arrays(velocity: tuple[ArrayLike, ArrayLike]) -> tuple[np.ndarray, np.ndarray]:
    """(t_v [s] (M,), v [m/s] (M, 3)) float arrays from ``estimate``'s ``velocity`` argument
    (ValueError on wrong shapes; bad values are left to the aiding, which rejects and counts
    them)."""
    try:
        t_v, v = velocity
    except (TypeError, ValueError):
        raise ValueError("velocity must be a pair (t_v_s of shape (M,), v_world_m_s of shape "
                         "(M, 3))") from None
    t_arr = np.asarray(t_v, dtype=float).reshape(-1)
    v_arr = np.asarray(v, dtype=float)
    if v_arr.ndim != 2 or v_arr.shape[1] != 3 or v_arr.shape[0] != t_arr.shape[0]:
        raise ValueError(f"velocity: t_v_s has shape {np.shape(t_v)} and v_world_m_s "
                         f"{v_arr.shape}; expected (M,) and (M, 3)")
    return t_arr, v_arr


def run_aided(f: ComplementaryFilter, aiding: VelocityAiding, gyro: np.ndarray, acc: np.ndarray,
              mg: np.ndarray | None, t: np.ndarray, t_v: np.ndarray, v: np.ndarray,
              latency_s: float, q_out: np.ndarray, extra_out: np.ndarray | None,
              aided_out: np.ndarray, accel_out: np.ndarray | None = None,
              moving_out: np.ndarray | None = None) -> None:
    """:func:`_run_filter` with velocity aiding, one sample at a time: velocity sample j is
    offered once the IMU stamp reaches t_v[j] + latency_s (its arrival); each IMU sample's
    accelerometer goes through :meth:`VelocityAiding.aided_accel` (writes aided_out (N,) bool
    and, if given, accel_out (N, 3): the accelerometer rows the filter was given, and
    moving_out (N,) bool: the rows the velocity said the vehicle moves, not at rest)."""
    order = np.argsort(t_v + latency_s, kind="stable")
    arrival = (t_v + latency_s)[order].tolist()
    tv_rows, v_rows = t_v[order].tolist(), v[order].tolist()
    nv, jv = len(arrival), 0
    init_row = -1
    g_rows, a_rows = gyro.tolist(), acc.tolist()
    m_rows = mg.tolist() if mg is not None else None
    ts = t.tolist()
    dts = np.diff(t, prepend=t[0]).tolist()
    for i in range(len(ts)):
        while jv < nv and arrival[jv] <= ts[i]:
            aiding.add_velocity(tv_rows[jv], v_rows[jv])
            jv += 1
        m = m_rows[i] if m_rows is not None else None
        if i == 0 or not f.initialized:  # initialisation (or a given initial orientation)
            if not f.initialized:
                f.update(g_rows[i], a_rows[i], 1.0, m)
            if not f.initialized:
                continue
            init_row = i
            a_in = a_rows[i]
            aiding.aided_accel(ts[i], g_rows[i], a_in, 1e-9, f.orientation_tuple(),
                               f.aiding_estimates())
        else:
            _q, a_in = aiding.update_filter(f, ts[i], g_rows[i], a_rows[i], dts[i], m)
        q_out[i] = f.orientation_tuple()
        aided_out[i] = aiding.active
        if moving_out is not None:
            moving_out[i] = i != init_row and aiding.moving_now
        if accel_out is not None:
            accel_out[i] = a_in
        if extra_out is not None:
            extra_out[i] = (_init_extras(f, m is not None and all(math.isfinite(c) for c in m))
                            if i == init_row else state_extras(f._state))  # noqa: SLF001


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
    velocity: tuple[ArrayLike, ArrayLike] | None = None,
    velocity_latency_s: float = 0.0,
    mag_hard_iron_t: Sequence[float] | None = None,
    mag_soft_iron: Sequence[float] | None = None,
) -> EstimateResult:
    """Run the filter over a recording.

    gyro_rad_s, accel_m_s2, mag: (N, 3) in the sensor frame (mag in any unit; NaN rows =
    no sample). Give ``rate_hz`` or ``timestamps_s`` [s]. ``initial_orientation`` (w, x, y, z),
    if given, replaces the initialisation from the first samples. ``backend``: see
    :mod:`cf_estimator.core.kernel`. ``offline``: the acausal estimate of
    :mod:`cf_estimator.core.offline` (every sample uses the whole recording; intervals over
    ``OFFLINE_MAX_GAP_S`` and non-finite gyro rows split it into segments).

    ``velocity``: optional aiding, ``(t_v_s (M,), v_world_m_s (M, 3))``: stamps [s] on the IMU's
    time base and velocities [m/s] in the filter's world frame (ENU or NED by
    ``params.world_frame``; heading tied by ``params.velocity_heading``), see
    :mod:`cf_estimator.core.velocity`. ``velocity_latency_s``: each velocity sample becomes
    available that long after its stamp (transport delay, as GNSS; alignment is by stamps).
    Offline, the aided specific force of a causal pass is fed to the acausal estimate.

    ``mag_hard_iron_t`` (3 floats, the unit of ``mag``: Tesla as the node's) and
    ``mag_soft_iron`` (9 floats, 3x3 row-major): the magnetometer calibration, applied to
    ``mag`` before the filter as the node and the replay apply the parameters of the same
    names (``m = S (m_raw - h)``, :mod:`cf_estimator.core.magcal`; ``cf-estimator
    calibrate-mag`` fits them). Invalid values raise :class:`ParameterError`.
    """
    if mag is not None and (mag_hard_iron_t is not None or mag_soft_iron is not None):
        from cf_estimator.core.magcal import IDENTITY9, check_calibration, correct_mag

        h, s = check_calibration((0.0, 0.0, 0.0) if mag_hard_iron_t is None else mag_hard_iron_t,
                                 IDENTITY9 if mag_soft_iron is None else mag_soft_iron)
        mag = correct_mag(mag, h, s)
    gyro, acc, mg = _rows(gyro_rad_s, accel_m_s2, mag)
    n = gyro.shape[0]
    t = sample_times(n, rate_hz, timestamps_s)
    f = ComplementaryFilter(params, initial_orientation=initial_orientation, backend=backend)
    warn_units(gyro, acc, f.params.gravity_m_s2)  # deg/s or g: warned once per call site
    aided = moving = status = None
    if velocity is not None:
        t_v, v = velocity_arrays(velocity)
        if not (np.isfinite(velocity_latency_s) and velocity_latency_s >= 0.0):
            raise ValueError(f"velocity_latency_s must be >= 0, got {velocity_latency_s!r}")
        aiding = VelocityAiding(f.params)
        out_q = np.full((n, 4), np.nan)
        extra = np.zeros((n, EXTRA_COLUMNS))
        aided = np.zeros(n, dtype=bool)
        moving = np.zeros(n, dtype=bool)
        acc_used = acc.copy()
        run_aided(f, aiding, gyro, acc, mg, t, t_v, v, velocity_latency_s, out_q, extra, aided,
                  acc_used, moving)
        status = aiding.status()
        acc = acc_used
    if offline:
        from cf_estimator.core.offline import ROW_AIDED, ROW_MOVING, estimate_offline

        flags = None if aided is None or moving is None else (
            aided * ROW_AIDED + moving * ROW_MOVING).astype(np.int8)
        out_q, extra = estimate_offline(gyro, acc, mg, t, f.params, initial_orientation, backend,
                                        flags=flags)
    elif velocity is None:
        out_q = np.full((n, 4), np.nan)
        extra = np.zeros((n, EXTRA_COLUMNS))
        _run_filter(f, gyro, acc, mg, t, out_q, extra)
    return EstimateResult(
        t, out_q, extra[:, Extra.ERROR], extra[:, Extra.CLIPPED] != 0.0, extra[:, Extra.BIAS],
        extra[:, Extra.PHASE].astype(np.int8), extra[:, Extra.AT_REST] != 0.0,
        extra[:, Extra.MAG_STATUS].astype(np.int8), extra[:, Extra.BIAS_SIGMA], aided, status,
        f.params, extra,
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
