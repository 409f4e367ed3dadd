"""Rest means rest, and the bias is learned from any start (issue 16).

- Airborne, heavily vibrating recordings (phantom4) never pass for rest; real rest is still found
  (EuRoC ground phases, BROAD breaks).
- A steady turn is never absorbed as bias: with a magnetometer the turning field rules rest out;
  without one a turn that begins from a known bias is a turn however long it lasts; at a start
  during a fast turn the prior bounds the bias (REST_GATE_SIGMAS · bias_prior_sigma_rad_s per
  axis), and a slower one is flagged as heading_rate_unverified.
- Started in the air, the horizontal gyro bias is learned within 20 s.
- Low-rate streams: a glitch and an impact at rest are gone within 10 s at 10, 25 and 200 Hz.
- A compass that was wrong at the start comes back through the heading recovery.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cf_estimator import FilterParams, estimate
from cf_estimator.core.filter import ComplementaryFilter
from cf_estimator.core.step import BIAS_CONVERGED_SIGMA_RAD_S, REST_GATE_SIGMAS

G = 9.80665
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
FIELD_ENU = np.array([0.0, 25e-6, -43e-6])  # T: north, down-pointing


def _yaw(q: tuple) -> float:
    w, x, y, z = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _turn(rate_dps: float, use_mag: bool, still_s: float = 10.0, turn_s: float = 40.0,
          after_s: float = 20.0, rate_hz: float = 100.0, seed: int = 1):
    """Level; still for ``still_s``, then a steady yaw turn, then still again. Returns times,
    true yaw, estimated yaw, true yaw rate [rad/s] and the filter."""
    f = ComplementaryFilter(FilterParams(use_mag=use_mag))
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    n = int((still_s + turn_s + after_s) * rate_hz)
    t = np.arange(n) * dt
    w = np.where((t >= still_s) & (t < still_s + turn_s), math.radians(rate_dps), 0.0)
    yaw_true = np.cumsum(w) * dt
    yaw_est = np.empty(n)
    for k in range(n):
        c, s = math.cos(yaw_true[k]), math.sin(yaw_true[k])
        mag = np.array([c * FIELD_ENU[0] + s * FIELD_ENU[1], -s * FIELD_ENU[0] + c * FIELD_ENU[1],
                        FIELD_ENU[2]]) + rng.normal(0.0, 2e-7, 3)
        q = f.update(np.array([0.0, 0.0, w[k]]) + rng.normal(0.0, 0.002, 3),
                     np.array([0.0, 0.0, G]) + rng.normal(0.0, 0.02, 3), dt,
                     mag if use_mag else None)
        yaw_est[k] = _yaw(q)
    return t, yaw_true, yaw_est, w, f


@pytest.mark.parametrize("rate_dps", [10.0, 30.0])
def test_9d_steady_turn_keeps_the_heading(rate_dps):
    t, yaw_true, yaw_est, _, f = _turn(rate_dps, use_mag=True)
    err = np.degrees(np.abs([_wrap(a - b) for a, b in zip(yaw_est, yaw_true, strict=True)]))
    assert err[t > 3.0].max() < 3.0, "heading within 3 deg during and after the turn"
    assert not f.status().heading_rate_unverified


@pytest.mark.parametrize("rate_dps", [10.0, 30.0])
def test_6d_steady_turn_after_a_still_start_keeps_the_yaw_rate(rate_dps):
    t, _, yaw_est, w, f = _turn(rate_dps, use_mag=False)
    rate_est = np.diff(np.unwrap(yaw_est)) / np.diff(t)
    # 1 s means (sample-to-sample differences carry the gyro's own white noise)
    k = int(100.0)
    m_est = rate_est[: len(rate_est) // k * k].reshape(-1, k).mean(axis=1)
    m_true = w[1:][: len(rate_est) // k * k].reshape(-1, k).mean(axis=1)
    inside = np.all(np.diff(w[1:][: len(rate_est) // k * k].reshape(-1, k), axis=1) == 0, axis=1)
    assert np.degrees(np.abs(m_est - m_true)[inside]).max() < 0.2
    assert abs(f.gyro_bias_rad_s[2]) < 0.002, "the turn rate never became bias"


def test_start_during_a_fast_turn_respects_the_bias_prior():
    """6-D, powered on during a steady 20 deg/s turn: beyond REST_GATE_SIGMAS prior sigmas, so
    never taken as bias (the issue's case: 0.35 rad/s of bias after 2 s)."""
    p = FilterParams(use_mag=False)
    assert math.radians(20.0) > REST_GATE_SIGMAS * p.bias_prior_sigma_rad_s
    t, _, _, _, f = _turn(20.0, use_mag=False, still_s=0.0, turn_s=30.0, after_s=0.0)
    assert abs(f.gyro_bias_rad_s[2]) < 0.02
    assert not f.status().at_rest


def test_start_during_a_slow_turn_is_flagged_not_silently_trusted():
    """6-D, powered on during a 5 deg/s turn (inside the prior: indistinguishable from rest plus
    bias for an IMU alone): taken as bias, and diagnostics say the heading rate is unverified;
    with a magnetometer the turning field rules rest out."""
    *_, f6 = _turn(5.0, use_mag=False, still_s=0.0, turn_s=20.0, after_s=0.0)
    st = f6.status()
    assert st.at_rest and st.heading_rate_unverified
    *_, f9 = _turn(5.0, use_mag=True, still_s=0.0, turn_s=20.0, after_s=0.0)
    assert not f9.status().at_rest and abs(f9.gyro_bias_rad_s[2]) < 0.01


def test_a_still_phase_after_motion_verifies_the_heading_rate():
    *_, f = _turn(10.0, use_mag=False, still_s=5.0, turn_s=5.0, after_s=5.0)
    st = f.status()
    assert st.at_rest and not st.heading_rate_unverified


# -- real data --------------------------------------------------------------------------------
def _flights(name: str):
    from cf_estimator.bench.euroc import load_flights

    root = DATA / name
    if not root.is_dir():
        pytest.skip(f"{root} not present")
    return load_flights(root)


def test_phantom4_airborne_recordings_are_never_rest():
    """Every phantom4 recording starts and ends in the air (3-6 m/s² of rotor vibration)."""
    flights = _flights("phantom4")
    assert len(flights) >= 40
    rest = {}
    for f in flights:
        r = estimate(f.gyro_rad_s, f.accel_m_s2, None, timestamps_s=f.t_s,
                     params=FilterParams(use_mag=False))
        rest[f.name] = float(r.at_rest.mean())
    assert max(rest.values()) == 0.0, {k: v for k, v in rest.items() if v}


def test_euroc_ground_rest_is_still_found_and_the_bias_learned():
    for f in _flights("euroc"):
        r = estimate(f.gyro_rad_s, f.accel_m_s2, None, timestamps_s=f.t_s,
                     params=FilterParams(use_mag=False))
        first = r.at_rest[f.t_s < 20.0]
        assert first.any(), f.name
        k = int(np.flatnonzero(r.at_rest)[0]) + int(2 * f.rate_hz)
        assert r.gyro_bias_sigma_rad_s[k] < BIAS_CONVERGED_SIGMA_RAD_S, f.name
        # the dataset's own estimate: (-0.002, 0.021, 0.077) rad/s (never fed to the filter)
        assert abs(r.gyro_bias_rad_s[k, 2] - 0.077) < 0.008, f.name


def test_euroc_mid_air_start_learns_the_horizontal_bias_within_20_s():
    """Cropped to start in the air 20, 40, 60 s into each flight: the sensor's x axis is up, y
    and z are horizontal (the observable ones); their ground-rest bias (0.021, 0.077 rad/s).
    Over 20-30 s in the air (the estimate's mean: a single instant catches the loop's
    fluctuation, 0.004 rad/s on MH_03) y is within 0.015 rad/s on every crop; z settles
    0.007-0.015 rad/s below its ground-rest value on every crop (in every release since this
    test was written: the bias in flight, not a learning still under way), so z is held to a
    common value within 0.015 rad/s and every crop within 0.006 rad/s of it."""
    errors = []
    for start_s in (20.0, 40.0, 60.0):
        for f in _flights("euroc"):
            c = f.cropped(start_s)
            r = estimate(c.gyro_rad_s, c.accel_m_s2, None, timestamps_s=c.t_s,
                         params=FilterParams(use_mag=False))
            b = r.gyro_bias_rad_s[(c.t_s >= 20.0) & (c.t_s <= 30.0)].mean(axis=0)
            errors.append((c.name, b[1] - 0.021, b[2] - 0.077))
    assert len(errors) == 9
    assert max(abs(y) for _, y, _ in errors) < 0.015, errors
    z = np.array([e[2] for e in errors])
    assert abs(z.mean()) < 0.015 and np.abs(z - z.mean()).max() < 0.006, errors


def test_broad_breaks_are_still_rest():
    from cf_estimator.bench.broad import load_trial

    path = DATA / "broad" / "05_undisturbed_slow_rotation_with_breaks_B.hdf5"
    if not path.exists():
        pytest.skip(f"{path} not present")
    tr = load_trial(path)
    r = estimate(tr.gyro_rad_s, tr.accel_m_s2, None, rate_hz=tr.rate_hz,
                 params=FilterParams(use_mag=False))
    # breaks: the trial's non-movement samples after the start
    breaks = ~tr.movement
    assert r.at_rest[breaks].mean() > 0.5
    assert r.at_rest[tr.movement].mean() < 0.05


# -- low-rate streams -------------------------------------------------------------------------
@pytest.mark.parametrize("rate_hz", [10.0, 25.0, 200.0])
@pytest.mark.parametrize("glitch", ["gyro_then_impact", "impact_then_gyro"])
def test_glitch_and_impact_at_rest_are_gone_within_10_s(rate_hz, glitch):
    """At rest: one 1 rad/s gyro sample and one 14.7 g accelerometer sample (the fuzz suite's
    case at 10 Hz: the impact's block passed for still under its own noise and moved the learned
    ‖g‖, then the tilt stayed 5 deg off for seconds). Every rate: < 1 deg after 10 s."""
    f = ComplementaryFilter(FilterParams(use_mag=False))
    rng = np.random.default_rng(0)
    dt = 1.0 / rate_hz
    up = np.array([0.0, 0.0, 1.0])

    def good():
        return f.update(rng.normal(0.0, 0.003, 3), up * G + rng.normal(0.0, 0.03, 3), dt)

    for _ in range(int(3 * rate_hz)):
        good()
    bad = [(np.array([1.0, 0.0, 0.0]), up * G), (np.zeros(3), np.array([0.0, 1.0, 0.0]) * 14.7 * G)]
    for g, a in bad if glitch == "gyro_then_impact" else bad[::-1]:
        f.update(g, a, dt)
    tilts = []
    for _ in range(int(11 * rate_hz)):
        w, x, y, z = good()
        tilts.append(math.degrees(math.acos(min(1.0, 1.0 - 2.0 * (x * x + y * y)))))
    assert max(tilts[int(10 * rate_hz):]) < 1.0
    assert max(tilts[int(5 * rate_hz):]) < 1.0  # in fact within 5 s


# -- heading recovery -------------------------------------------------------------------------
def test_a_compass_wrong_at_start_comes_back_within_seconds():
    """Issue 19 item 2: the field 90 deg off for the first 3 s, then clean, still vehicle. The
    clean field turned when the gyro says the body did not: rejected (issue 22), until it has
    been steady as long as the wrong reference was in use (3 s); then re-learned, the heading
    error saturates, the heading recovery takes over after recovery_trigger_s and the heading is
    within 2 deg by 20 s (issue 22's target; it took 126 s at the saturation-limited rate)."""
    p = FilterParams()
    f = ComplementaryFilter(p)
    rng = np.random.default_rng(3)
    rate = 100.0
    dt = 1.0 / rate
    wrong = np.array([FIELD_ENU[1], 0.0, FIELD_ENU[2]])  # rotated by 90 deg about the vertical
    err = []
    for k in range(int(40 * rate)):
        m = (wrong if k < 3 * rate else FIELD_ENU) + rng.normal(0.0, 2e-7, 3)
        q = f.update(rng.normal(0.0, 0.002, 3), np.array([0.0, 0.0, G]) + rng.normal(0, 0.02, 3),
                     dt, m)
        err.append(abs(math.degrees(_wrap(_yaw(q)))))
    t = np.arange(len(err)) * dt
    err = np.array(err)
    assert err[t >= 20.0].max() < 2.0, err[t >= 20.0].max()
    assert err[(t > 3.5) & (t < 5.0)].min() > 80.0  # the clean field is not taken at once
    assert not f.status().heading_recovering
