"""Scenarios: truth, sensor models and the thesis disturbances (Habliuk 2023) behave as said."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from cf_estimator.core.quaternion import from_euler as quat_from_euler_zyx
from cf_estimator.scenarios import (
    SCENARIOS,
    SensorModel,
    acceleration_manoeuvre,
    from_body_rates,
    hover,
    impacts,
    make_scenario,
    measure,
    random_rotation,
    static,
    uav_flight,
    vibration,
)

G = 9.80665


# ---------------------------------------------------------------- independent reference maths


def _qmul(p, q):
    pw, px, py, pz = p
    qw, qx, qy, qz = q
    return (
        pw * qw - px * qx - py * qy - pz * qz,
        pw * qx + px * qw + py * qz - pz * qy,
        pw * qy - px * qz + py * qw + pz * qx,
        pw * qz + px * qy - py * qx + pz * qw,
    )


def _integrate_sequential(q0, t, gyro):
    """The project rule, sample by sample in plain floats: q_k = q_{k-1} ⊗ Exp(ω_k·dt_k)."""
    q = tuple(float(x) for x in q0)
    out = [q]
    for k in range(1, len(t)):
        dt = float(t[k] - t[k - 1])
        wx, wy, wz = (float(x) * dt for x in gyro[k])
        angle = math.sqrt(wx * wx + wy * wy + wz * wz)
        s = math.sin(0.5 * angle) / angle if angle > 0 else 0.5
        q = _qmul(q, (math.cos(0.5 * angle), s * wx, s * wy, s * wz))
        n = math.sqrt(sum(c * c for c in q))
        q = tuple(c / n for c in q)
        out.append(q)
    return np.array(out)


def _rotate_world_to_body(q, v):
    """q* ⊗ v ⊗ q via quaternion products (independent of the package's matrices)."""
    out = np.empty((len(q), 3))
    for i, (qi, vi) in enumerate(zip(q, v, strict=True)):
        conj = (qi[0], -qi[1], -qi[2], -qi[3])
        r = _qmul(_qmul(conj, (0.0, *vi)), qi)
        out[i] = r[1:]
    return out


def _runs(mask):
    """(start index, length) of contiguous True runs."""
    m = np.concatenate(([False], mask, [False])).astype(int)
    d = np.diff(m)
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    return starts, ends - starts


# ---------------------------------------------------------------- truth and perfect sensors


@pytest.mark.parametrize(
    "make",
    [
        lambda: random_rotation(30.0, 1000.0, np.random.default_rng(3), 4.0),
        lambda: uav_flight(90.0, 200.0, np.random.default_rng(4)),
        lambda: make_scenario("thesis", rate_hz=500.0, seed=5).truth,
    ],
    ids=["random_rotation", "uav_flight", "thesis"],
)
def test_perfect_gyro_integrated_by_the_project_rule_reproduces_truth(make):
    truth = make()
    imu = measure(truth, SensorModel(), np.random.default_rng(0), exact=True)
    q = _integrate_sequential(truth.q_world_from_body[0], imu.t_s, imu.gyro_rad_s)
    assert np.abs(q - truth.q_world_from_body).max() < 1e-9


def test_integration_rule_holds_for_variable_dt():
    rng = np.random.default_rng(7)
    t = np.cumsum(rng.uniform(0.001, 0.02, 3000))
    w = rng.normal(0.0, 2.0, (3000, 3))
    q0 = np.array([0.3, -0.5, 0.7, 0.4]) / np.linalg.norm([0.3, -0.5, 0.7, 0.4])
    truth = from_body_rates(t, w, q0)
    assert np.abs(_integrate_sequential(q0, t, w) - truth.q_world_from_body).max() < 1e-9


def test_random_rotation_goes_upside_down_and_through_180_yaw():
    truth = random_rotation(60.0, 200.0, np.random.default_rng(3), 3.0)
    q = truth.q_world_from_body
    body_z_world_z = 1 - 2 * (q[:, 1] ** 2 + q[:, 2] ** 2)
    assert body_z_world_z.min() < -0.9 and body_z_world_z.max() > 0.5
    yaw = truth.euler_zyx_rad()[:, 2]
    assert np.any(np.abs(np.diff(yaw)) > np.pi)  # wrapped across ±180°
    assert np.linalg.norm(truth.gyro_true_rad_s, axis=1).max() <= 3.0 + 1e-9
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-12)


def test_perfect_accelerometer_at_rest_reads_rotated_plus_g():
    q0 = quat_from_euler_zyx(0.4, -0.3, 2.5)
    truth = static(5.0, 200.0, q0)
    imu = measure(truth, SensorModel(), np.random.default_rng(0), exact=True)
    expected = _rotate_world_to_body(truth.q_world_from_body, np.tile([0.0, 0.0, G], (1000, 1)))
    assert np.abs(imu.accel_m_s2 - expected).max() < 1e-12
    level = measure(static(1.0, 200.0), SensorModel(), np.random.default_rng(0), exact=True)
    assert np.allclose(level.accel_m_s2, [0.0, 0.0, G], atol=1e-12)
    assert np.all(imu.gyro_rad_s == 0.0)


def test_perfect_accelerometer_in_flight_is_specific_force():
    truth = uav_flight(40.0, 100.0, np.random.default_rng(1))
    imu = measure(truth, SensorModel(), np.random.default_rng(0), exact=True)
    expected = _rotate_world_to_body(
        truth.q_world_from_body, truth.accel_world_m_s2 + np.array([0.0, 0.0, G])
    )
    assert np.abs(imu.accel_m_s2 - expected).max() < 1e-10


@pytest.mark.parametrize("dip_deg", [60.0, -35.0])
def test_perfect_magnetometer_has_configured_norm_and_dip_for_every_sample(dip_deg):
    model = SensorModel(earth_field_T=48e-6, dip_rad=np.deg2rad(dip_deg))
    truth = random_rotation(20.0, 200.0, np.random.default_rng(2))
    imu = measure(truth, model, np.random.default_rng(0), exact=True)
    assert np.allclose(np.linalg.norm(imu.mag_T, axis=1), 48e-6, rtol=1e-12)
    q = truth.q_world_from_body
    conj = q * np.array([1.0, -1.0, -1.0, -1.0])
    m_world = _rotate_world_to_body(conj, imu.mag_T)  # rotate body → world with q
    dip = np.arctan2(-m_world[:, 2], np.hypot(m_world[:, 0], m_world[:, 1]))
    assert np.abs(dip - np.deg2rad(dip_deg)).max() < 1e-9
    assert np.abs(m_world[:, 0]).max() < 1e-15  # field points north (ENU y), no east component


def test_flight_is_smooth_and_bounded():
    for seed in range(4):
        truth = uav_flight(120.0, 200.0, np.random.default_rng(seed))
        a = np.linalg.norm(truth.accel_world_m_s2, axis=1)
        assert a.max() <= 5.0
        q = truth.q_world_from_body
        tilt = np.degrees(np.arccos(np.clip(1 - 2 * (q[:, 1] ** 2 + q[:, 2] ** 2), -1, 1)))
        assert 10.0 < tilt.max() <= 35.0
        yaw = np.unwrap(truth.euler_zyx_rad()[:, 2])
        assert np.ptp(yaw) > np.radians(30)  # at least one turn
        assert np.abs(np.diff(truth.gyro_true_rad_s, axis=0)).max() < 0.05  # rad/s per 5 ms
        assert np.abs(np.diff(truth.accel_world_m_s2, axis=0)).max() < 0.1  # m/s² per 5 ms
        assert truth.accel_world_m_s2[200:1400, 2].max() > 0.5  # take-off accelerates upwards
        # velocity is the integral of the acceleration
        v = truth.velocity_world_m_s
        dv = np.cumsum(0.5 * (truth.accel_world_m_s2[1:] + truth.accel_world_m_s2[:-1]), 0) / 200
        assert np.abs(v[1:] - v[0] - dv).max() < 0.01


# ---------------------------------------------------------------- sensor errors


def test_sensor_noise_and_bias_follow_the_model():
    truth = static(60.0, 1000.0)
    model = SensorModel(gyro_bias_rad_s=(0.01, -0.02, 0.03), gyro_bias_walk_rad_s2_sqrt_hz=0.0,
                        accel_bias_m_s2=(0.1, 0.0, -0.1))
    imu = measure(truth, model, np.random.default_rng(0))
    gyro_err = imu.gyro_rad_s - np.array([0.01, -0.02, 0.03])
    assert np.allclose(gyro_err.mean(0), 0.0, atol=1e-4)
    assert np.allclose(gyro_err.std(0), model.gyro_noise_density_rad_s_sqrt_hz * np.sqrt(1000),
                       rtol=0.02)
    acc_err = imu.accel_m_s2 - np.array([0.1, 0.0, G - 0.1])
    assert np.allclose(acc_err.std(0), model.accel_noise_density_m_s2_sqrt_hz * np.sqrt(1000),
                       rtol=0.02)
    assert np.allclose(acc_err.mean(0), 0.0, atol=1e-3)
    assert np.allclose(imu.gyro_bias_rad_s, [0.01, -0.02, 0.03])
    drawn = measure(truth, SensorModel.thesis(gyro_bias_walk_rad_s2_sqrt_hz=0.0),
                    np.random.default_rng(1))
    assert np.all(drawn.gyro_bias_rad_s == drawn.gyro_bias_rad_s[0])
    assert 0 < np.abs(drawn.gyro_bias_rad_s[0]).max() < 5 * np.radians(10 / 3600)
    perfect = measure(truth, SensorModel.perfect(), np.random.default_rng(0))
    exact = measure(truth, SensorModel(), np.random.default_rng(0), exact=True)
    assert np.array_equal(perfect.accel_m_s2, exact.accel_m_s2)
    assert np.array_equal(perfect.gyro_rad_s, exact.gyro_rad_s)


# ---------------------------------------------------------------- thesis disturbances


def test_impacts_match_thesis_numbers():
    t = np.arange(60000) / 1000.0
    d = impacts(t, 5.0, rng=np.random.default_rng(0))
    assert np.all(d[:, 1:] == 0.0)  # along +x only
    assert d[:, 0].min() == 0.0  # unipolar
    starts, lengths = _runs(d[:, 0] > 0)
    assert len(starts) == 60
    assert np.isclose(d[:, 0].max(), 15 * G) and np.all(d[d[:, 0] > 0, 0] == 15 * G)
    assert np.all((lengths >= 10) & (lengths <= 15 + 1))  # 10-15 ms at 1 kHz (±1 sample)
    assert lengths.max() - lengths.min() >= 3  # durations drawn per impact
    spacing = np.diff(t[starts])
    assert np.allclose(spacing, 60.0 / 80.0, atol=1.5e-3)  # 80 per minute
    assert np.isclose(t[starts[0]], 5.0)


def test_half_sine_impacts_peak_at_15_g():
    t = np.arange(60000) / 1000.0
    d = impacts(t, 1.0, shape="half_sine", duration_s=0.011, direction_body=(0, 0, -1))
    assert np.all(d[:, :2] == 0.0) and d[:, 2].max() <= 0.0
    starts, lengths = _runs(d[:, 2] < 0)
    assert len(starts) == 60 and np.all(np.abs(lengths - 10) <= 1)
    assert -d[:, 2].min() <= 15 * G and -d[:, 2].min() > 0.98 * 15 * G


def test_impacts_reject_a_rate_too_low_for_10_ms_pulses():
    with pytest.raises(ValueError, match="sample rate"):
        impacts(np.arange(20000) / 200.0, 1.0)


def test_vibration_sweep_has_6_g_amplitude_and_20_to_120_hz():
    t = np.arange(40000) / 1000.0
    d = vibration(t, 5.0, 30.0)
    x = d[:, 0]
    assert np.all(d[:, 1:] == 0.0)
    assert np.abs(x).max() <= 6 * G * (1 + 1e-12)
    assert np.abs(x).max() > 0.999 * 6 * G
    inside = (t >= 5.0) & (t < 35.0)
    assert np.all(x[~inside] == 0.0)
    # every cycle reaches most of 6 g between the tapers (1 kHz: ≥ cos(π·120/1000) = 0.93)
    core = (t >= 5.1) & (t < 34.9)
    crossings = np.flatnonzero(np.diff(np.signbit(x[core]).astype(int)) != 0)
    for a, b in zip(crossings[:-1], crossings[1:], strict=True):
        assert np.abs(x[core][a + 1 : b + 1]).max() > 0.9 * 6 * G
    # instantaneous frequency from zero crossings stays within 20-120 Hz and sweeps upwards
    xc, tcore = x[core], t[core]
    frac = xc[crossings] / (xc[crossings] - xc[crossings + 1])  # linear sub-sample crossing
    tc = tcore[crossings] + frac * 1e-3
    f_inst = 0.5 / np.diff(tc)
    assert f_inst.min() > 19.0 and f_inst.max() < 121.0
    assert np.median(f_inst[:20]) < 25.0 and np.median(f_inst[-20:]) > 110.0
    # spectrum: (almost) all energy inside the band
    spec = np.abs(np.fft.rfft(x)) ** 2
    f = np.fft.rfftfreq(len(x), 1e-3)
    band = (f >= 20.0) & (f <= 120.0)
    assert spec[band].sum() / spec.sum() > 0.99


def test_stepped_vibration_dwells_at_20_40_to_120_hz():
    t = np.arange(13000) / 1000.0
    d = vibration(t, 0.5, 12.0, mode="stepped", direction_body=(0, 1, 0))[:, 1]
    for i, f_expected in enumerate([20, 40, 60, 80, 100, 120]):
        seg = d[(t >= 0.5 + 2 * i + 0.2) & (t < 0.5 + 2 * i + 1.8)]
        f = np.fft.rfftfreq(len(seg), 1e-3)
        assert abs(f[np.argmax(np.abs(np.fft.rfft(seg)))] - f_expected) <= 1.0
        assert np.abs(seg).max() > 0.93 * 6 * G


def test_vibration_rejects_an_aliasing_sample_rate():
    with pytest.raises(ValueError, match="alias"):
        vibration(np.arange(4000) / 200.0, 1.0, 5.0)


def test_acceleration_manoeuvre_gains_25_m_s_in_5_s():
    base = hover(30.0, 1000.0, np.random.default_rng(0))
    truth = acceleration_manoeuvre(base, 10.0)
    added = truth.accel_world_m_s2 - base.accel_world_m_s2
    t = truth.t_s
    assert np.all(added[:, 2] == 0.0)
    inside = (t >= 10.0) & (t < 15.0)
    assert np.allclose(np.linalg.norm(added[inside], axis=1), 5.0)
    assert np.all(added[~inside] == 0.0)
    dv = np.sum(added, axis=0) * 1e-3
    assert np.isclose(np.linalg.norm(dv), 25.0, rtol=1e-9)
    dv_truth = truth.velocity_world_m_s[-1] - truth.velocity_world_m_s[0]
    assert np.isclose(np.linalg.norm(dv_truth), 25.0, rtol=1e-12)
    # along the body's heading, attitude untouched
    q = base.q_world_from_body[10000]
    fwd = _rotate_world_to_body([(q[0], -q[1], -q[2], -q[3])], [(1.0, 0.0, 0.0)])[0]
    assert np.isclose(np.arctan2(dv[1], dv[0]), np.arctan2(fwd[1], fwd[0]))
    assert np.array_equal(truth.q_world_from_body, base.q_world_from_body)
    # with ramps the speed change is still 25 m/s
    smooth = acceleration_manoeuvre(base, 10.0, ramp_s=0.5)
    v = smooth.velocity_world_m_s
    assert np.isclose(np.linalg.norm(v[-1] - v[0]), 25.0)
    assert np.abs(np.diff(smooth.accel_world_m_s2, axis=0)).max() < 0.02


def test_acceleration_scenario_accelerometer_sees_the_manoeuvre():
    sc = make_scenario("acceleration", seed=1)
    t = sc.truth.t_s
    start, end, label = sc.disturbance_windows[0]
    assert label == "acceleration" and (start, end) == (10.0, 15.0)
    a = sc.truth.accel_world_m_s2
    window = (t >= start) & (t < end)
    dv = a[window].sum(axis=0) / sc.rate_hz  # ∫ a dt over the 5 s window
    assert abs(np.linalg.norm(dv) - 25.0) < 1e-9
    exact = measure(sc.truth, sc.model, np.random.default_rng(0), exact=True)
    assert np.all(np.abs(np.linalg.norm(exact.accel_m_s2[window], axis=1) - np.hypot(5, G))
                  < 1e-9)


# ---------------------------------------------------------------- library


def test_thesis_scenario_has_three_disturbances_in_sequence_with_quiet_gaps():
    sc = make_scenario("thesis", seed=0)
    labels = [w[2] for w in sc.disturbance_windows]
    assert labels == ["impacts", "vibration", "acceleration"]
    for (_, end, _), (start, _, _) in zip(sc.disturbance_windows, sc.disturbance_windows[1:],
                                           strict=False):
        assert start - end >= 5.0
    d = sc.imu.accel_disturbance_m_s2
    t = sc.truth.t_s
    in_any = np.zeros(len(t), bool)
    for start, end, _ in sc.disturbance_windows:
        in_any |= (t >= start) & (t < end)
    assert np.all(d[~in_any] == 0.0)
    assert len(_runs(d[:, 0] > 10 * G)[0]) == 60
    assert sc.disturbance_windows[-1][1] <= sc.duration_s
    assert np.isclose(np.linalg.norm(sc.truth.velocity_world_m_s[-1]), 25.0)


def test_same_seed_gives_identical_data_and_different_seeds_differ():
    for name in SCENARIOS:
        a = make_scenario(name, seed=11)
        b = make_scenario(name, seed=11)
        c = make_scenario(name, seed=12)
        for field in ("gyro_rad_s", "accel_m_s2", "mag_T"):
            assert np.array_equal(getattr(a.imu, field), getattr(b.imu, field)), (name, field)
            assert not np.array_equal(getattr(a.imu, field), getattr(c.imu, field)), (name, field)
        assert np.array_equal(a.truth.q_world_from_body, b.truth.q_world_from_body)


def test_unknown_scenario_name_raises_listing_the_names():
    with pytest.raises(ValueError) as err:
        make_scenario("vibrations")
    for name in SCENARIOS:
        assert name in str(err.value)
    assert set(SCENARIOS) >= {"static", "flight", "impacts", "vibration", "acceleration", "thesis"}


def test_too_short_duration_or_too_low_rate_is_rejected():
    with pytest.raises(ValueError, match="duration"):
        make_scenario("thesis", duration_s=60.0)
    with pytest.raises(ValueError, match="sample rate"):
        make_scenario("vibration", rate_hz=200.0)


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_all_arrays_finite_and_shapes_consistent(name):
    sc = make_scenario(name, seed=3)
    n = sc.truth.n_samples
    assert n == round(sc.duration_s * sc.rate_hz)
    assert sc.name == name and sc.description
    assert np.array_equal(sc.imu.t_s, sc.truth.t_s)
    assert np.allclose(np.diff(sc.truth.t_s), 1.0 / sc.rate_hz)
    arrays = {
        "q": (sc.truth.q_world_from_body, 4),
        "w": (sc.truth.gyro_true_rad_s, 3),
        "a": (sc.truth.accel_world_m_s2, 3),
        "v": (sc.truth.velocity_world_m_s, 3),
        "gyro": (sc.imu.gyro_rad_s, 3),
        "accel": (sc.imu.accel_m_s2, 3),
        "mag": (sc.imu.mag_T, 3),
        "bias": (sc.imu.gyro_bias_rad_s, 3),
    }
    for key, (arr, width) in arrays.items():
        assert arr.shape == (n, width), key
        assert np.all(np.isfinite(arr)), key
    assert np.allclose(np.linalg.norm(sc.truth.q_world_from_body, axis=1), 1.0, atol=1e-12)
    for start, end, _ in sc.disturbance_windows:
        assert 0.0 <= start < end <= sc.duration_s


def test_thesis_scenario_at_1_khz_generates_quickly():
    t0 = time.perf_counter()
    sc = make_scenario("thesis", rate_hz=1000.0, duration_s=120.0, seed=0)
    elapsed = time.perf_counter() - t0
    assert sc.truth.n_samples == 120000
    assert elapsed < 3.0
