"""The peers run as their authors recommend (issue 53 item 7): x-io Fusion with its README's
settings and its gyroscope offset module, each mechanism shown at work against ``Ahrs()`` as
constructed (rejection off, no offset module), so that a set-up that silently fell back to the
defaults fails here.

Simple cases at 100 Hz, a still sensor in ENU: a constant gyro bias (the offset module learns
it), a 1 s horizontal acceleration of 0.5 g (acceleration rejection ignores it), a field turned
by 30° for 2 s (magnetic rejection ignores it).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cf_estimator.core import quaternion as quat

pytest.importorskip("imufusion")

from cf_estimator.bench import peers  # noqa: E402

G = 9.80665
RATE_HZ = 100.0


def _still(n: int, yaw_deg: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """n samples of a level, still sensor at ``yaw_deg`` (ENU): gyro, acc, mag [uT], q true."""
    q = quat.from_euler(0.0, 0.0, math.radians(yaw_deg))
    qi = quat.conjugate(q)
    acc = quat.rotate(qi, [0.0, 0.0, G])
    mag = quat.rotate(qi, [0.0, 20.0, -40.0])  # north = +y, dip down
    return np.zeros((n, 3)), np.tile(acc, (n, 1)), np.tile(mag, (n, 1)), q


def _yaw_deg(q: np.ndarray) -> np.ndarray:
    return np.degrees(np.unwrap([quat.to_euler(x)[2] for x in q]))


def _tilt_deg(q: np.ndarray) -> np.ndarray:
    """Angle between the estimated and the true (level) "up", per sample."""
    up = np.array([quat.rotate(quat.conjugate(x), [0.0, 0.0, 1.0]) for x in q])
    return np.degrees(np.arccos(np.clip(up[:, 2], -1.0, 1.0)))


def test_fusion_settings_are_its_readmes() -> None:
    assert peers.FUSION_SETTINGS == {
        "convention": "NWU", "gain": 0.5, "gyroscope_range_deg_s": 2000.0,
        "acceleration_rejection_deg": 10.0, "magnetic_rejection_deg": 10.0,
        "rejection_timeout_s": 5.0}


def test_fusion_finds_a_still_attitude_in_enu() -> None:
    g, a, m, q = _still(1000, yaw_deg=30.0)
    out = peers.run_fusion(g, a, m, RATE_HZ)
    assert np.degrees(quat.angle_between(out[-1], q)) < 0.1


def test_fusion_offset_module_removes_a_constant_gyro_bias() -> None:
    g, a, _m, _q = _still(int(60 * RATE_HZ))
    g[:, 2] = math.radians(1.0)  # 1 deg/s about the vertical, which 6-D cannot see otherwise
    last_10_s = slice(-int(10 * RATE_HZ), None)

    def drift(out: np.ndarray) -> float:
        yaw = _yaw_deg(out[last_10_s])
        return abs(yaw[-1] - yaw[0])

    assert drift(peers.run_fusion(g, a, None, RATE_HZ, recommended=False)) > 9.0
    # still for 3 s, then a 0.02 Hz high-pass: learned well within a minute
    assert drift(peers.run_fusion(g, a, None, RATE_HZ)) < 0.2


def test_fusion_acceleration_rejection_ignores_a_burst() -> None:
    g, a, _m, _q = _still(int(20 * RATE_HZ))
    burst = slice(int(10 * RATE_HZ), int(11 * RATE_HZ))  # after the 3 s start-up ramp
    a[burst, 0] += 0.5 * G  # the accelerometer 26.6 deg off gravity for 1 s
    after_start = slice(int(5 * RATE_HZ), None)
    off = _tilt_deg(peers.run_fusion(g, a, None, RATE_HZ, recommended=False))[after_start]
    on = _tilt_deg(peers.run_fusion(g, a, None, RATE_HZ))[after_start]
    assert off.max() > 5.0  # gain 0.5 follows the burst
    assert on.max() < 0.5


def test_fusion_magnetic_rejection_ignores_a_disturbed_field() -> None:
    g, a, m, _q = _still(int(20 * RATE_HZ))
    turned = quat.rotate(quat.from_euler(0.0, 0.0, math.radians(30.0)), m[0])
    window = slice(int(10 * RATE_HZ), int(12 * RATE_HZ))
    m[window] = turned  # a magnet near the sensor for 2 s
    after_start = slice(int(5 * RATE_HZ), None)

    def heading_error(out: np.ndarray) -> float:
        return float(np.max(np.abs(_yaw_deg(out[after_start]))))

    assert heading_error(peers.run_fusion(g, a, m, RATE_HZ, recommended=False)) > 5.0
    assert heading_error(peers.run_fusion(g, a, m, RATE_HZ)) < 0.5


def test_madgwick_port_steps_as_ahrs_does() -> None:
    """The float port of ahrs' Madgwick (updateIMU/updateMARG) gives ahrs' quaternions, sample
    for sample, on a noisy moving sensor — with a magnetometer, without, and with gaps."""
    pytest.importorskip("ahrs")
    from ahrs.filters import Madgwick

    rng = np.random.default_rng(4)
    n = 400
    g = rng.normal(0.0, 0.5, (n, 3))
    a = rng.normal(0.0, 2.0, (n, 3)) + [0.0, 0.0, G]
    m = rng.normal(0.0, 3.0, (n, 3)) + [0.0, 20.0, -40.0]
    m[::7] = np.nan  # no magnetometer sample on these rows: updateIMU
    g[5] = 0.0  # a zero gyro sample: ahrs returns q unchanged
    for mag in (m, None):
        out = peers.run_madgwick(g, a, mag, RATE_HZ)
        ref = Madgwick(frequency=RATE_HZ, gain=peers.MADGWICK_ROS_GAIN)
        ref.gain = peers.MADGWICK_ROS_GAIN
        q = peers.initial_nwu(a[0], None if mag is None else mag[0])
        expected = [q]
        for i in range(1, n):
            if mag is not None and np.all(np.isfinite(mag[i])):
                q = ref.updateMARG(q, g[i], a[i], mag[i])
            else:
                q = ref.updateIMU(q, g[i], a[i])
            expected.append(q)
        expected = quat.multiply(peers.Q_ENU_FROM_NWU, np.array(expected))
        assert float(np.max(np.abs(out - expected))) < 1e-12
