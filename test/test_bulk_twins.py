"""The pipeline's compiled row loops against their Python references, bit for bit.

``_kernel.covariance_rows`` repeats :meth:`OrientationCovariance.steps` (core/covariance.py)
and ``_kernel.rpy_rows`` the roll/pitch/yaw of ``pipeline/process._rpy`` (``math.atan2`` and
``math.asin`` per row). A replay's outputs must not depend on the backend beyond the filter's own
bits, so equality here is of the bits (NaN included), not to a tolerance; inputs are drawn to
hit every branch: clipped runs, no bias estimate (NaN: the prior), settling phases, no loop
gain yet (<= 0 or NaN), magnetometer used or not, ages of NaN, -0.0 and "never", heading not
initialised, extreme magnitudes, strided columns.

Without the compiled kernel these tests skip — unless CF_ESTIMATOR_REQUIRE_KERNEL=1 (as in
test_kernel.py), which turns the skip into a failure.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from kernel_guard import require_kernel

from cf_estimator.core.covariance import OrientationCovariance
from cf_estimator.pipeline import ImuPipeline, process

require_kernel()


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.uint64)


def _model() -> OrientationCovariance:
    return OrientationCovariance(6.4e-5, 4e-4, 10.0, 0.1 * math.pi / 180.0, k1=0.35)


def _state(m: OrientationCovariance) -> tuple[float, ...]:
    return (m._clip_s, m._ms, m._yaw_err, m._cx, m._cy, m._yaw_lp, m._yaw_gap)  # noqa: SLF001


def _inputs(rng: np.random.Generator, n: int) -> dict:
    """One run's columns, as the bulk pipeline gives them (a row-major block: strided)."""
    block = np.empty((n, 13))
    dt = rng.choice([0.0025, 0.01, 1e-6, 0.5], n) * rng.uniform(0.5, 1.5, n)
    block[:, 0] = dt
    block[:, 1] = rng.random(n) < 0.3  # clipped (runs of them: the drift term grows)
    block[:, 2] = np.where(rng.random(n) < 0.2, np.nan, rng.uniform(0.0, 0.01, n))
    block[:, 3] = rng.choice([0.0, 1.0, 2.0, 3.0, np.nan], n)  # phase
    block[:, 4] = np.abs(rng.normal(0.0, 0.3, n))
    block[:, 5] = rng.normal(0.0, 0.05, n)  # lx
    block[:, 6] = rng.normal(0.0, 0.05, n)  # ly
    block[:, 7] = rng.uniform(0.0, 5.0, n)  # noise_a2
    block[:, 8] = rng.normal(0.0, 1.0, n)  # yaw error (a magnitude where x**2 != x*x too)
    used = rng.random(n) < 0.25
    block[:, 9] = used  # magnetometer used
    block[:, 10] = rng.choice([0.0, -0.0, 0.01, 3.0, np.nan], n)  # age
    block[:, 11] = rng.choice([0.35, 0.2, 0.0, -1.0, np.nan], n)  # loop gain
    block[:, 12] = ~used & (rng.random(n) < 0.3)  # magnetometer rejected (a disturbed field)
    return {"block": block}


def _run_both(m_c: OrientationCovariance, m_p: OrientationCovariance, block: np.ndarray,
              heading: bool, ages: bool) -> None:
    cols = [block[:, j] for j in range(13)]
    args = (cols[0], cols[1], cols[2], cols[3], cols[4], cols[5], cols[6], cols[7], heading,
            cols[8], cols[9], cols[10] if ages else None, cols[11], cols[12])
    t_c, y_c = m_c.rows(*args, backend="compiled")
    t_p, y_p = m_p.rows(*args, backend="python")
    assert np.array_equal(_bits(t_c), _bits(t_p))
    assert np.array_equal(_bits(y_c), _bits(y_p))
    assert np.array_equal(_bits(np.array(_state(m_c))), _bits(np.array(_state(m_p))))


@pytest.mark.parametrize("seed", range(6))
def test_compiled_covariance_rows_equal_the_python_steps_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    m_c, m_p = _model(), _model()
    for k in range(8):  # successive runs carry the state over
        block = _inputs(rng, int(rng.integers(1, 600)))["block"]
        _run_both(m_c, m_p, block, heading=bool(k % 4), ages=bool(k % 3))
    assert np.isfinite(m_c._ms)  # noqa: SLF001 - the state moved: a real comparison
    assert m_c._ms > 0.0  # noqa: SLF001
    assert m_c._yaw_lp != 0.0  # noqa: SLF001


def test_compiled_covariance_rows_take_libm_pow_not_a_product():
    # yaw_err ** 2 in Python is libm's pow, which differs from yaw_err * yaw_err here
    x = 0.037436064101607984
    assert x**2 != x * x
    m_c, m_p = _model(), _model()
    one = np.ones(1)
    for m, backend in ((m_c, "compiled"), (m_p, "python")):
        _t, y = m.rows(0.0025 * one, 0 * one, 0 * one, 2 * one, 0 * one, 0 * one, 0 * one,
                       0 * one, True, x * one, one, 0 * one, 0.35 * one, 0 * one,
                       backend=backend)
        assert y[0] == 4e-4 + x**2
        assert _bits(y)[0] != _bits(np.array([4e-4 + x * x]))[0]


def test_compiled_covariance_rows_overflow_as_python_does_and_keep_the_state():
    m_c, m_p = _model(), _model()
    one = np.ones(2)
    args = (0.0025 * one, 0 * one, 0 * one, 2 * one, 0 * one, 0 * one, 0 * one, 0 * one, True,
            np.array([1.0, 1e200]), one, None, 0.35 * one, 0 * one)
    before = _state(m_c)
    with pytest.raises(OverflowError):
        m_c.rows(*args, backend="compiled")
    with pytest.raises(OverflowError):
        m_p.rows(*args, backend="python")
    assert _state(m_c) == before == _state(m_p)


def test_compiled_covariance_rows_refuse_wrong_arrays():
    m = _model()
    one = np.ones(3)
    good = [0.0025 * one] + [one] * 7
    with pytest.raises(ValueError, match="yaw_error"):
        m.rows(*good, True, np.ones(2), one, None, one, one, backend="compiled")
    with pytest.raises(ValueError, match="mag_rejected"):
        m.rows(*good, True, one, one, None, one, np.ones(4), backend="compiled")
    with pytest.raises(ValueError, match="dt"):
        m.rows(np.ones(3, dtype=np.float32), *good[1:], True, one, one, None, one, one,
               backend="compiled")


def _quaternions(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(0.0, 1.0, (n, 4))
    q /= np.linalg.norm(q, axis=1)[:, None]
    q[::7] *= 1.0 + 1e-12  # 2(wy - zx) just beyond +-1: the clip
    q[1::11] = [1.0, 0.0, 0.0, 0.0]
    q[2::13] = [0.5 ** 0.5, 0.0, 0.5 ** 0.5, 0.0]  # pitch +90 deg: roll, yaw from zeros
    q[3::17] = [0.0, -0.0, 0.0, -0.0]
    q[4::19] = [np.nan, 0.0, 0.0, 1.0]
    q[5::23] = [np.inf, 1.0, -np.inf, 0.0]
    q[6::29] = [1e200, 1e200, 0.0, 1e-200]
    return q


@pytest.mark.parametrize("seed", range(3))
def test_compiled_rpy_rows_equal_math_atan2_and_asin_bit_for_bit(seed):
    q = _quaternions(np.random.default_rng(seed), 2000)
    pipe = ImuPipeline()
    with np.errstate(all="ignore"):
        ref = process._rpy(pipe, q, "python")  # noqa: SLF001 - the reference path
        got = process._rpy(pipe, q, "compiled")  # noqa: SLF001
    assert np.array_equal(_bits(got), _bits(ref))
    assert np.isnan(got).any() and np.isfinite(got).sum() > 1500  # both kinds compared
