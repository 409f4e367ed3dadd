"""A 1-2 Hz magnetometer is a compass, not a fault (issue 52): the tilt never depends on the
compass's rate, and the heading stays within a few degrees of a dense compass's.

PX4 logs ``vehicle_magnetometer`` at about 2 Hz by default. The rest detector compares the
field direction of consecutive 0.5 s blocks: with one sample a block, a sample's own noise
(0.01 rad on the shared ulogs) used to read as a turn, rest was lost (a still simulated vehicle:
97 % → 72 % of samples at rest) and with it the bias measurements, which moved the tilt. The
tolerance now includes the blocks' field-direction noise, measured like the gyro's.
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import DATA_ROOT

from cf_estimator import FilterParams, estimate
from cf_estimator.bag.logarrays import log_arrays
from cf_estimator.scenarios import make_scenario


def _up(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q.T
    return np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), w * w - x * x - y * y + z * z], 1)


def _yaw(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q.T
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def _every(t: np.ndarray, mag: np.ndarray, period_s: float) -> np.ndarray:
    """The magnetometer rows kept at most once per ``period_s`` (NaN elsewhere)."""
    out = np.full_like(mag, np.nan)
    last = -np.inf
    for r in np.flatnonzero(np.all(np.isfinite(mag), axis=1)):
        if t[r] - last >= period_s - 1e-9:
            out[r], last = mag[r], t[r]
    return out


@pytest.mark.parametrize("name", ["static", "uav"])
def test_a_2_hz_compass_leaves_rest_and_tilt_as_a_dense_one_does(name):
    sc = make_scenario(name, seed=0)
    t, qt = sc.imu.t_s, sc.truth.q_world_from_body
    runs = {}
    for label, mag in (("dense", sc.imu.mag_T), ("2 Hz", _every(t, sc.imu.mag_T, 0.5))):
        runs[label] = estimate(sc.imu.gyro_rad_s, sc.imu.accel_m_s2, mag, timestamps_s=t,
                               params=FilterParams())
    late = t >= 10.0
    rest = {k: r.at_rest[late].mean() for k, r in runs.items()}
    assert rest["2 Hz"] == pytest.approx(rest["dense"], abs=0.01), rest
    tilt = {k: np.degrees(np.sqrt(np.mean(np.arccos(np.clip(
        (_up(r.quaternion) * _up(qt)).sum(1), -1, 1))[late] ** 2))) for k, r in runs.items()}
    assert tilt["2 Hz"] == pytest.approx(tilt["dense"], abs=0.01), tilt
    heading = {k: np.degrees(np.sqrt(np.mean(np.angle(np.exp(1j * (
        _yaw(r.quaternion) - _yaw(qt))))[late] ** 2))) for k, r in runs.items()}
    assert heading["2 Hz"] < heading["dense"] + 1.0, heading


def test_a_real_ulogs_compass_thinned_to_2_hz_leaves_the_tilt_alone():
    path = DATA_ROOT / "ulogs" / "sample_px4_events.ulg"  # 15 Hz vehicle_magnetometer
    if not path.exists():
        pytest.skip(f"shared data missing: {path}")
    log = log_arrays(path)
    runs = {label: estimate(log.gyro_rad_s, log.accel_m_s2, mag, timestamps_s=log.t_s,
                            params=FilterParams(world_frame="ned"))
            for label, mag in (("dense", log.mag_T), ("2 Hz", _every(log.t_s, log.mag_T, 0.5)))}
    # measured: rest 76 % dense, 69 % at 2 Hz (23 % before the noise-aware tolerance)
    assert runs["2 Hz"].at_rest.mean() == pytest.approx(runs["dense"].at_rest.mean(), abs=0.1)
    up = {k: _up(r.quaternion) for k, r in runs.items()}
    ok = np.all(np.isfinite(up["dense"]), axis=1)
    diff = np.degrees(np.arccos(np.clip((up["dense"][ok] * up["2 Hz"][ok]).sum(1), -1, 1)))
    assert np.sqrt(np.mean(diff ** 2)) < 0.03  # measured 0.013 deg (0.1 before)
