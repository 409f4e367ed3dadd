"""The `uav` scenario: thrust-consistent truth, the gyro bias asked for, rotor vibration band."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import welch

from cf_estimator.cli.main import main
from cf_estimator.core import quaternion as quat
from cf_estimator.scenarios import (
    SCENARIOS,
    UAV_GYRO_BIAS_RAD_S,
    SensorModel,
    make_scenario,
    measure,
)

G = 9.80665
DRAG_PER_S = 0.35  # multirotor_flight's default


def _integrate_sequential(q0, t, gyro):
    """The project rule in plain floats: q_k = q_{k-1} ⊗ Exp(ω_k·dt_k) (independent code)."""
    w0, x0, y0, z0 = (float(c) for c in q0)
    out = np.empty((len(t), 4))
    out[0] = (w0, x0, y0, z0)
    for k in range(1, len(t)):
        dt = float(t[k] - t[k - 1])
        ax, ay, az = (float(c) * dt for c in gyro[k])
        angle = math.sqrt(ax * ax + ay * ay + az * az)
        s = math.sin(0.5 * angle) / angle if angle > 0 else 0.5
        bw, bx, by, bz = math.cos(0.5 * angle), s * ax, s * ay, s * az
        w0, x0, y0, z0 = (w0 * bw - x0 * bx - y0 * by - z0 * bz,
                          w0 * bx + x0 * bw + y0 * bz - z0 * by,
                          w0 * by - x0 * bz + y0 * bw + z0 * bx,
                          w0 * bz + x0 * by - y0 * bx + z0 * bw)
        n = math.sqrt(w0 * w0 + x0 * x0 + y0 * y0 + z0 * z0)
        w0, x0, y0, z0 = w0 / n, x0 / n, y0 / n, z0 / n
        out[k] = (w0, x0, y0, z0)
    return out


@pytest.fixture(scope="module")
def uav():
    return make_scenario("uav", seed=2)


def test_listed_and_simulated_by_the_cli(tmp_path, capsys):
    assert "uav" in SCENARIOS
    assert main(["simulate", "--list"]) == 0
    assert any(ln.startswith("uav ") and "200 Hz" in ln and "120 s" in ln
               for ln in capsys.readouterr().out.splitlines())
    out = tmp_path / "uav_bag"
    assert main(["simulate", "--scenario", "uav", "--duration", "40", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "scenario uav (seed 0): 40 s at 200 Hz" in text and "/imu/data_raw 8000" in text


def test_perfect_unbiased_vibration_free_gyro_reproduces_the_truth():
    sc = make_scenario("uav", seed=4, gyro_bias_rad_s=(0.0, 0.0, 0.0), vibration_m_s2=0.0,
                       gyro_vibration_rad_s=0.0, model=SensorModel.perfect())
    assert np.array_equal(sc.imu.gyro_rad_s, sc.truth.gyro_true_rad_s)
    q = _integrate_sequential(sc.truth.q_world_from_body[0], sc.imu.t_s, sc.imu.gyro_rad_s)
    assert np.abs(q - sc.truth.q_world_from_body).max() < 1e-9


def test_attitude_follows_thrust_and_accelerometer_sees_rotor_drag(uav):
    tr, ev = uav.truth, uav.events
    exact = measure(tr, uav.model, np.random.default_rng(0), exact=True)
    r = quat.to_matrix(tr.q_world_from_body)
    drag_body = np.einsum("nji,nj->ni", r, DRAG_PER_S * tr.velocity_world_m_s)  # Rᵀ·k·v
    thrust_body = exact.accel_m_s2 + drag_body  # specific thrust: along body z only
    assert np.abs(thrust_body[:, :2]).max() < 1e-9
    assert thrust_body[:, 2].min() > 0.6 * G
    # steady cruise: forward tilt atan(k·v/g), the accelerometer's body x reads −k·v (drag)
    speed = np.linalg.norm(tr.velocity_world_m_s[:, :2], axis=1)
    steady = ((np.linalg.norm(tr.accel_world_m_s2, axis=1) < 1e-4) & (speed > 3.0)
              & (np.abs(tr.velocity_world_m_s[:, 2]) < 1e-4))  # level, constant velocity
    assert steady.sum() > 1000
    tilt = np.arccos(np.clip(r[:, 2, 2], -1, 1))
    assert np.allclose(tilt[steady], np.arctan(DRAG_PER_S * speed[steady] / G), atol=2e-5)
    assert np.allclose(exact.accel_m_s2[steady, 0],
                       -DRAG_PER_S * speed[steady] * np.cos(tilt[steady]), atol=1e-3)
    # still and level on the ground before take-off; sustained forward flight afterwards
    ground = tr.t_s < ev["takeoff"]
    assert np.abs(tr.gyro_true_rad_s[ground]).max() == 0.0
    assert np.allclose(exact.accel_m_s2[ground], [0.0, 0.0, G])
    assert ev["rotors_on"] < ev["takeoff"] < ev["cruise"] < ev["landing"] < ev["touchdown"]
    flying = (tr.t_s > ev["cruise"]) & (tr.t_s < ev["landing"])
    assert np.mean(speed[flying] > 2.0) > 0.9 and np.degrees(tilt[flying]).max() < 35.0
    yaw = np.unwrap(quat.to_euler(tr.q_world_from_body)[:, 2])
    assert np.ptp(yaw[flying]) > np.deg2rad(90.0)  # turns
    height = np.cumsum(tr.velocity_world_m_s[:, 2]) / uav.rate_hz
    assert height.max() > 2.0 and abs(height[-1]) < 1e-6  # climbs, then lands where it started


def test_gyro_bias_is_what_was_asked(uav):
    assert uav.model.gyro_bias_rad_s == UAV_GYRO_BIAS_RAD_S == (0.06, -0.08, 0.1)
    b = uav.gyro_bias_true_rad_s
    assert np.array_equal(b[0], UAV_GYRO_BIAS_RAD_S)
    assert np.abs(b - np.asarray(UAV_GYRO_BIAS_RAD_S)).max() < 1e-3  # + a tiny random walk
    residual = (uav.imu.gyro_rad_s - uav.truth.gyro_true_rad_s - b
                - uav.imu.gyro_disturbance_rad_s)  # white noise only
    assert np.abs(residual.mean(axis=0)).max() < 1e-3
    asked = (0.1, 0.0, -0.2)
    other = make_scenario("uav", seed=2, duration_s=40.0, gyro_bias_rad_s=asked)
    assert np.array_equal(other.gyro_bias_true_rad_s[0], asked)
    with pytest.raises(ValueError, match="takes no option 'gyro_bias'"):
        make_scenario("uav", gyro_bias="big")
    with pytest.raises(ValueError, match="scenario 'static' takes no option"):
        make_scenario("static", gyro_bias_rad_s=(0, 0, 0))


def _band_fraction(x, rate, lo, hi):
    f, p = welch(x, fs=rate, nperseg=2048, axis=0)
    p = p.sum(axis=1)
    return p[(f >= lo) & (f <= hi)].sum() / p.sum()


def test_rotor_vibration_band_amplitude_and_phases():
    rate = 1000.0  # above twice the band: the spectrum is seen unaliased
    sc = make_scenario("uav", rate_hz=rate, seed=3, vibration_m_s2=2.5, gyro_vibration_rad_s=0.04)
    t, ev = sc.truth.t_s, sc.events
    acc, gyro = sc.imu.accel_disturbance_m_s2, sc.imu.gyro_disturbance_rad_s
    assert np.all(acc[t < ev["rotors_on"]] == 0.0) and np.all(gyro[t < ev["rotors_on"]] == 0.0)
    ground = (t > ev["rotors_on"] + 1.0) & (t < ev["takeoff"] - 0.5)  # rotors idling
    flight = (t > ev["cruise"]) & (t < ev["landing"])
    for x, rms in ((acc, 2.5), (gyro, 0.04)):
        for window in (ground, flight):
            assert _band_fraction(x[window], rate, 50.0, 200.0) > 0.99
            assert np.abs(x[window].mean(axis=0)).max() < 0.02 * rms  # zero-mean
        flight_rms = math.sqrt(np.mean(np.sum(x[flight] ** 2, axis=1)))
        ground_rms = math.sqrt(np.mean(np.sum(x[ground] ** 2, axis=1)))
        assert 0.8 * rms < flight_rms < 1.3 * rms
        assert 0.3 * rms < ground_rms < 0.7 * rms  # idle speed 0.7: amplitude ∝ speed²
