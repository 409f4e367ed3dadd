"""A compass that is wrong for a long time is a disturbance, not a new truth (issue 22 item 4).

A magnet fixed to the sensor (a hard-iron offset of 0.3-1x the Earth field appearing mid-run
while the body turns) is rejected for as long as it is there: the heading runs on the gyro, the
status says so, and the reference is never re-learned from it. A field that comes back is used
again; a compass wrong at power-on is still replaced (test_rest_means_rest.py).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from cf_estimator import FilterParams, estimate
from cf_estimator.core import quaternion as quat
from cf_estimator.core.filter import ComplementaryFilter
from cf_estimator.core.step import MAG_REJECTED, MAG_USED

G = 9.80665
FIELD_ENU = np.array([0.0, 25e-6, -43e-6])  # T: north, pointing down
RATE_HZ = 100.0


def _rotating_with_magnet(seed: int, fraction: float, on_s: tuple[float, float] = (20.0, 80.0),
                          duration_s: float = 100.0):
    """Handheld-like turning (yaw rates up to ~1 rad/s, roll/pitch ±0.3 rad), 5 s still at the
    start; a hard-iron offset of ``fraction`` × |B| (random sensor-frame direction) during
    ``on_s``. Returns t, gyro, accel, mag (sensor frame), the true q (w, x, y, z) and the mask."""
    rng = np.random.default_rng(seed)
    n = int(duration_s * RATE_HZ)
    t = np.arange(n) / RATE_HZ
    yaw, roll, pitch = np.zeros(n), np.zeros(n), np.zeros(n)
    moving = np.clip((t - 5.0) / 2.0, 0.0, 1.0)
    for _ in range(3):
        f, ph, amp = rng.uniform(0.05, 0.3), rng.uniform(0, 2 * np.pi), rng.uniform(0.3, 0.8)
        yaw += amp / (2 * np.pi * f) * (np.sin(2 * np.pi * f * t + ph) - np.sin(ph))
        roll += 0.1 * np.sin(2 * np.pi * rng.uniform(0.1, 0.5) * t + rng.uniform(0, 6.3))
        pitch += 0.1 * np.sin(2 * np.pi * rng.uniform(0.1, 0.5) * t + rng.uniform(0, 6.3))
    q = quat.from_euler(roll * moving, pitch * moving, yaw * moving)  # (N, 4) w, x, y, z
    # body rates from consecutive orientations: dq = q_k* ⊗ q_k+1
    dq = quat.multiply(quat.conjugate(q[:-1]), q[1:])
    dq *= np.sign(dq[:, :1])
    w = np.vstack([2.0 * dq[:, 1:] * RATE_HZ, np.zeros((1, 3))])
    gyro = w + rng.normal(0.0, 0.003, (n, 3))
    accel = quat.rotate(quat.conjugate(q), np.array([0.0, 0.0, G])) + rng.normal(0, 0.03, (n, 3))
    mag = quat.rotate(quat.conjugate(q), FIELD_ENU) + rng.normal(0.0, 2e-7, (n, 3))
    h = rng.normal(size=3)
    h *= fraction * np.linalg.norm(FIELD_ENU) / np.linalg.norm(h)
    on = (t >= on_s[0]) & (t < on_s[1])
    mag[on] += h
    return t, gyro, accel, mag, q, on


def _heading_error_deg(q_est: np.ndarray, q_true: np.ndarray) -> np.ndarray:
    ye, yt = quat.to_euler(q_est)[:, 2], quat.to_euler(q_true)[:, 2]
    return np.degrees(np.abs((ye - yt + np.pi) % (2 * np.pi) - np.pi))


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("fraction", [0.5, 1.0])
def test_a_magnet_on_a_turning_sensor_is_never_followed(fraction, seed):
    t, gyro, accel, mag, q, on = _rotating_with_magnet(seed, fraction)
    r = estimate(gyro, accel, mag, rate_hz=RATE_HZ, params=FilterParams())
    err = _heading_error_deg(r.quaternion, q)
    assert err[t > 2.0].max() < 5.0, err[on].max()  # throughout, the 60 s with the magnet too
    assert (r.mag_status[on] == MAG_USED).mean() < 0.02
    assert (r.mag_status[on] == MAG_REJECTED).mean() > 0.98
    back = t > 90.0  # removed at 80 s: the Earth field is used again
    assert (r.mag_status[back] == MAG_USED).mean() > 0.9 and err[back].max() < 3.0


def test_a_weak_magnet_stays_bounded():
    """0.3x the Earth field is the hardest case (its pull is within a few times a calibration's
    leftover): the heading stays within 7 deg on these seeds (5.8 deg at worst on 8 seeds
    measured; the last release followed it by 12-34 deg)."""
    for seed in (0, 1, 2, 3):
        t, gyro, accel, mag, q, on = _rotating_with_magnet(seed, 0.3)
        r = estimate(gyro, accel, mag, rate_hz=RATE_HZ, params=FilterParams())
        assert _heading_error_deg(r.quaternion, q)[t > 2.0].max() < 7.0, seed


def test_the_status_says_the_heading_runs_on_the_gyro_while_disturbed():
    t, gyro, accel, mag, q, on = _rotating_with_magnet(1, 1.0)
    f = ComplementaryFilter(FilterParams())
    sources = []
    for k in range(t.size):
        f.update(gyro[k], accel[k], 1.0 / RATE_HZ, mag[k])
        sources.append(f.status().heading_source)
    sources = np.array(sources)
    assert (sources[on] == "gyro").mean() > 0.98
    assert (sources[(t > 10.0) & (t < 20.0)] == "magnetometer").all()
    assert (sources[t > 90.0] == "magnetometer").mean() > 0.9


def test_the_diagnostics_warn_while_the_heading_is_on_the_gyro():
    """The pipeline (node, replay) on real sensor_msgs: a field that turned 60 deg while the
    body is still -> WARN 'heading on the gyro alone', heading_source 'gyro'; never OK."""
    from test_pipeline import DT_NS, MAG_T, T0_NS, run

    from cf_estimator.pipeline.diagnostics import WARN
    from cf_estimator.pipeline.pipeline import ImuPipeline

    pipe = ImuPipeline()
    run(pipe, 500, mag=MAG_T)
    assert dict(pipe.diagnostics().values)["heading_source"] == "magnetometer"
    c, s = math.cos(math.radians(60.0)), math.sin(math.radians(60.0))
    turned = (c * MAG_T[0] - s * MAG_T[1], s * MAG_T[0] + c * MAG_T[1], MAG_T[2])
    run(pipe, 300, start_ns=T0_NS + 500 * DT_NS, mag=turned)
    report = pipe.diagnostics()
    assert report.level == WARN and "heading on the gyro alone" in report.message
    assert dict(report.values)["heading_source"] == "gyro"


def test_a_jump_of_the_field_direction_alone_is_rejected():
    """Same norm and dip, direction turned 60 deg about the vertical while the body is still:
    the field turned when the gyro says the body did not (the norm/dip tests alone pass it)."""
    f = ComplementaryFilter(FilterParams())
    rng = np.random.default_rng(5)
    c, s = math.cos(math.radians(60.0)), math.sin(math.radians(60.0))
    turned = np.array([c * FIELD_ENU[0] - s * FIELD_ENU[1], s * FIELD_ENU[0] + c * FIELD_ENU[1],
                       FIELD_ENU[2]])
    statuses = []
    for k in range(int(15 * RATE_HZ)):
        m = (FIELD_ENU if k < 10 * RATE_HZ else turned) + rng.normal(0.0, 2e-7, 3)
        f.update(rng.normal(0.0, 0.002, 3), np.array([0.0, 0.0, G]) + rng.normal(0, 0.02, 3),
                 1.0 / RATE_HZ, m)
        statuses.append(f.status().mag_status)
    after = statuses[int(10.1 * RATE_HZ):]
    assert after.count("rejected") == len(after)  # 5 s on: not re-learned (in use for 10 s)
