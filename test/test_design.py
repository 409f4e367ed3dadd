"""Tests of the design formulas (cf_estimator.analysis.design) and the ``design`` CLI command.

Seed numbers are reproduced from the seeds' own formulas; where the papers' printed arithmetic
differs from those formulas the test says so (DESIGN.md: "trust the formulas").
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from cf_estimator.analysis import design, thesis
from cf_estimator.analysis.axis import AxisFilter, AxisParams
from cf_estimator.cli.main import main
from cf_estimator.core.params import FilterParams

K1, K2 = 0.03, 0.001  # Ryzhkov & Karpenko's gains
DRIFT = 5e-4  # Ryzhkov & Karpenko's drift angular velocity [rad/s]
REPO = Path(__file__).resolve().parents[1]


def simulate(params: AxisParams, gyro: np.ndarray | float, accel_angle: np.ndarray, dt: float,
             initial_angle: float = 0.0) -> np.ndarray:
    """AxisFilter estimate per sample with true angle 0 (so the estimate is the error)."""
    f = AxisFilter(params, angle_rad=initial_angle)
    g = np.broadcast_to(np.asarray(gyro, dtype=float), accel_angle.shape)
    return np.array([f.update(w, a, dt) for w, a in zip(g.tolist(), accel_angle.tolist(),
                                                           strict=True)])


# -------------------------------------------------------- loop parameters (Ryzhkov & Karpenko)


def test_natural_frequency_and_period_seed_000():
    # Seed 000, parameter choice: "k2 = 0.001, n = sqrt(k2) = 0.0312" -- the square root is
    # 0.03162; the paper's 0.0312 is a slip. Its period 2*pi/n = 198.7 s uses the right n.
    n = design.natural_frequency(K2)
    assert n == pytest.approx(0.0316228, rel=1e-5)
    assert abs(n - 0.0312) > 4e-4
    assert design.natural_period_s(K2) == pytest.approx(198.7, abs=0.05)


def test_damping_definitions():
    # Seed 000: xi = k1/n ("relative coefficient of damping"); the classical zeta is xi/2, so the
    # seed's "xi = 1" loop oscillates (zeta = 0.5), as the seed itself remarks.
    assert design.seed_damping(K1, K2) == pytest.approx(0.948683, rel=1e-6)
    assert design.classical_damping(K1, K2) == pytest.approx(0.474342, rel=1e-6)
    with pytest.raises(ValueError, match="k2 = 0"):
        design.seed_damping(K1, 0.0)


@pytest.mark.parametrize(("n", "xi"), [(0.0316, 1.0), (0.05, 2.0), (0.2, 3.5), (1.0, 0.3)])
def test_inverse_round_trip(n, xi):
    k1, k2 = design.gains_from_natural_frequency(n, xi)
    assert k1 == pytest.approx(xi * n) and k2 == pytest.approx(n * n)
    assert design.natural_frequency(k2) == pytest.approx(n, rel=1e-12)
    assert design.seed_damping(k1, k2) == pytest.approx(xi, rel=1e-12)
    k1p, k2p = design.gains_from_period(design.natural_period_s(k2), xi)
    assert (k1p, k2p) == (pytest.approx(k1, rel=1e-12), pytest.approx(k2, rel=1e-12))


def test_inverse_rejects_bad_input():
    for bad in [(0.0, 1.0), (-1.0, 1.0), (0.1, 0.0), (0.1, -2.0)]:
        with pytest.raises(ValueError):
            design.gains_from_natural_frequency(*bad)
    with pytest.raises(ValueError):
        design.gains_from_period(0.0)


def test_settling_time_exact_matches_simulation():
    # Exact: last time |h'(t)| >= 2 %, h' the initial-error response. The envelope form
    # ln(50)/(zeta n) = 2 ln 50 / k1 ignores phase and amplitude and is 9 % longer here.
    ts = design.settling_time_s(K1, K2)
    assert ts == pytest.approx(239.46, abs=0.05)
    assert design.envelope_settling_time_s(K1, K2) == pytest.approx(2 * math.log(50) / K1)
    assert abs(float(design.initial_error_response(K1, K2, ts))) == pytest.approx(0.02, rel=1e-6)
    t = np.linspace(ts + 1e-6, 5 * ts, 20001)
    assert np.all(np.abs(design.initial_error_response(K1, K2, t)) < 0.02)
    # AxisFilter with an initial error of 0.1 rad: error/0.1 follows h'(t).
    dt = 0.05
    err = simulate(AxisParams(k1=K1, k2=K2), 0.0, np.zeros(int(600 / dt)), dt, initial_angle=0.1)
    outside = np.nonzero(np.abs(err) >= 0.02 * 0.1)[0]
    assert (outside[-1] + 1) * dt == pytest.approx(ts, abs=1.0)


# ------------------------------------------------------------------ drift (Ryzhkov & Karpenko)


def test_impulse_peak_17_7_s():
    # DESIGN.md: the clip must exceed about 2*bias*17.7 s; 17.7 s = max of the impulse response
    # of 1/(s^2 + 0.03 s + 0.001). Closed form vs a brute-force grid of h(t).
    hmax, t_peak = design.impulse_response_peak(K1, K2)
    assert hmax == pytest.approx(17.70, abs=0.005)
    t = np.linspace(0.0, 2000.0, 2_000_001)
    h = design.impulse_response_d(K1, K2, t)
    assert np.abs(h).max() == pytest.approx(hmax, rel=1e-7)
    assert t[np.argmax(np.abs(h))] == pytest.approx(t_peak, abs=1e-3)


@pytest.mark.parametrize(("k1", "k2"), [(0.1, 0.0025), (0.5, 0.001), (0.03, 0.0001)])
def test_impulse_peak_closed_form_critical_and_overdamped(k1, k2):
    hmax, _ = design.impulse_response_peak(k1, k2)
    t = np.linspace(0.0, 30.0 / design.envelope_settling_time_s(k1, k2) ** -1, 400_001)
    assert np.abs(design.impulse_response_d(k1, k2, t)).max() == pytest.approx(hmax, rel=1e-6)


def test_drift_peak_seed_000():
    # Seed 000: "delta_wdr ~ w_dr/n = 5e-4/0.03 = 0.85 deg". The exact peak of
    # s/(s^2+k1 s+k2)*(w/s) is 0.507 deg; the rough w/n is 0.906 deg (w/k1: 0.955 deg), so the
    # printed 0.85 deg matches none of them.
    exact = math.degrees(design.drift_peak_error_rad(K1, K2, DRIFT))
    assert exact == pytest.approx(0.507, abs=0.0005)
    assert math.degrees(design.rough_peak_error_rad(K2, DRIFT)) == pytest.approx(0.906, abs=5e-4)
    assert math.degrees(DRIFT / K1) == pytest.approx(0.955, abs=5e-4)
    assert abs(exact - 0.85) > 0.3


def test_drift_peak_agrees_with_axis_filter():
    dt = 0.01
    err = simulate(AxisParams(k1=K1, k2=K2), DRIFT, np.zeros(int(150 / dt)), dt)
    peak = design.drift_peak(K1, K2, DRIFT)
    assert np.abs(err).max() == pytest.approx(peak.magnitude, rel=0.01)
    assert (np.argmax(np.abs(err)) + 1) * dt == pytest.approx(peak.time_s, abs=0.5)
    assert abs(err[-1]) < 0.3 * peak.magnitude  # the integral learns the drift: error returns


def test_drift_peak_with_aperiodic_unit():
    # T -> 0 recovers the closed form; a T = 3 s lag (needs T < k1/k2 = 30 s) agrees with the
    # AxisFilter (aperiodic unit inside the loop) and raises the peak.
    base = design.drift_peak_error_rad(K1, K2, DRIFT)
    assert design.drift_peak_error_rad(K1, K2, DRIFT, 1e-6) == pytest.approx(base, rel=1e-6)
    lagged = design.drift_peak_error_rad(K1, K2, DRIFT, 3.0)
    assert lagged > base * 1.02
    dt = 0.01
    err = simulate(AxisParams(k1=K1, k2=K2, aperiodic_time_constant_s=3.0), DRIFT,
                   np.zeros(int(150 / dt)), dt)
    assert np.abs(err).max() == pytest.approx(lagged, rel=0.01)
    with pytest.raises(ValueError, match="unstable"):
        design.drift_peak_error_rad(K1, K2, DRIFT, 30.0)


# ---------------------------------------------------------------- acceleration (Ryzhkov & Karpenko)


def test_accel_event_seed_000():
    # Seed 000: 0.2 g for 5 s; "w_e = k2*W*tau = 1e-3, delta_e,max ~ w_e/n = 1e-3/0.03 = 1.9 deg".
    # Exact peak of (k1 s+k2)/D to the 0.2 rad, 5 s pulse: 1.73 deg (the k1 path dominates, so
    # the short-event k1*(a/g)*tau = 1.72 deg is close). The seed's own rough form gives 1.81 deg
    # with n = 0.0316; its 1.9 deg comes from rounding n to 0.03.
    exact = math.degrees(design.accel_event_peak_error_rad(K1, K2, 0.2, 5.0))
    assert exact == pytest.approx(1.726, abs=0.001)
    short = math.degrees(design.accel_event_short_approx_rad(K1, 0.2, 5.0))
    assert short == pytest.approx(1.719, abs=0.001)
    w_e = design.seed_equivalent_rate_rad_s(K2, 0.2, 5.0)
    assert w_e == pytest.approx(1e-3)
    assert math.degrees(design.rough_peak_error_rad(K2, w_e)) == pytest.approx(1.812, abs=0.001)
    assert math.degrees(w_e / 0.03) == pytest.approx(1.91, abs=0.005)  # the printed 1.9 deg
    # Without a filter the error is the pulse itself: 0.2 rad = 11.46 deg (seed: 11.46 deg).
    assert math.degrees(0.2) == pytest.approx(11.46, abs=0.005)


def test_accel_event_agrees_with_axis_filter():
    dt = 0.01
    n_on, n_total = int(5.0 / dt), int(80.0 / dt)
    accel = np.where(np.arange(n_total) < n_on, 0.2, 0.0)
    err = simulate(AxisParams(k1=K1, k2=K2), 0.0, accel, dt)
    assert np.abs(err).max() == pytest.approx(
        design.accel_event_peak_error_rad(K1, K2, 0.2, 5.0), rel=0.01)


@pytest.mark.parametrize(("k1", "k2", "tau"), [(K1, K2, 5.0), (0.1, 0.0025, 20.0),
                                               (0.5, 0.001, 2.0), (2.0, 4.0, 0.3)])
def test_accel_event_engine_matches_closed_form(k1, k2, tau):
    # y(t) = A(g(t) - g(t - tau)), g = 1 - h'(t) the step response of (k1 s + k2)/D: brute
    # force on a fine grid with the closed-form h' vs the state-space engine (covers the
    # underdamped, critical and overdamped cases).
    horizon = tau + 3 * design.envelope_settling_time_s(k1, k2)
    t = np.union1d(np.linspace(0.0, horizon, 400_001), [tau])  # the peak may sit at t = tau
    g = 1.0 - design.initial_error_response(k1, k2, t)
    g_late = np.where(t > tau, 1.0 - design.initial_error_response(k1, k2, np.maximum(t - tau, 0)),
                      0.0)
    brute = np.abs(0.2 * (g - g_late)).max()
    assert design.accel_event_peak_error_rad(k1, k2, 0.2, tau) == pytest.approx(brute, rel=1e-6)


def test_accel_event_with_aperiodic_unit_agrees_with_axis_filter():
    dt = 0.01
    accel = np.where(np.arange(int(80 / dt)) < int(5 / dt), 0.2, 0.0)
    err = simulate(AxisParams(k1=K1, k2=K2, aperiodic_time_constant_s=3.0), 0.0, accel, dt)
    assert np.abs(err).max() == pytest.approx(
        design.accel_event_peak_error_rad(K1, K2, 0.2, 5.0, 3.0), rel=0.01)


# ------------------------------------------------------------------- vibration (Ryzhkov & Karpenko)


def test_vibration_seed_000():
    # Seed 000: 0.1 g at 10 Hz (62.8 1/s), "almost completely eliminated". Exact |H(j w)|*A
    # equals A*k1/(2 pi f) = 4.77e-5 rad (0.16') to 1e-5 relative at this frequency.
    exact = design.vibration_peak_error_rad(K1, K2, 0.1, 10.0)
    approx = design.vibration_approx_rad(K1, 0.1, 10.0)
    assert approx == pytest.approx(0.1 * 0.03 / (2 * math.pi * 10.0))
    assert exact == pytest.approx(approx, rel=1e-4)
    assert design.rad_to_arcmin(exact) == pytest.approx(0.164, abs=0.001)
    # Near n the approximation breaks down (|H| -> 1 while A*k1/(2 pi f) grows without bound):
    # at 0.002 Hz it is off by a factor 2.
    low = design.vibration_peak_error_rad(K1, K2, 0.1, 0.002)
    assert low <= 0.1 * 1.2
    assert design.vibration_approx_rad(K1, 0.1, 0.002) > 2 * low


def test_vibration_agrees_with_axis_filter():
    # Steady amplitude = half the peak-to-peak over the last 2 s (removes the switch-on offset).
    dt, f = 0.001, 10.0
    t = np.arange(1, int(20 / dt) + 1) * dt
    err = simulate(AxisParams(k1=K1, k2=K2), 0.0, 0.1 * np.cos(2 * math.pi * f * t), dt)
    last = err[-int(2 / dt):]
    amplitude = 0.5 * (last.max() - last.min())
    assert amplitude == pytest.approx(design.vibration_peak_error_rad(K1, K2, 0.1, f), rel=0.05)


# ------------------------------------------------------- thesis first-order filter (Habliuk 2023)


def alpha_filter(accel_angle: np.ndarray, gyro: float, tau: float, dt: float) -> np.ndarray:
    """Seed 001, eq. (1): phi_n = alpha (phi_{n-1} + dt*gyro) + (1 - alpha) phi_acc_n,
    alpha = tau/(tau + dt): the first-order filter W(s) = s/(T s + 1) with T = tau."""
    alpha = tau / (tau + dt)
    out = np.empty(accel_angle.size)
    phi = 0.0
    for i, a in enumerate(accel_angle.tolist()):
        phi = alpha * (phi + dt * gyro) + (1 - alpha) * a
        out[i] = phi
    return out


def test_thesis_first_order_acceleration_error():
    # Seed 003, eq. (6): u_acc ~ (a/g) tau/T; a/g ~ 1, tau = 5 s, T = 100 s -> printed 2.87 deg;
    # the formula gives 0.05 rad = 2.865 deg (the thesis rounded up). The exact peak of the
    # first-order lag to the 5 s unit pulse is (1 - e^(-tau/T)) = 2.79 deg: the thesis formula
    # overestimates by about tau/(2T) = 2.5 %.
    approx = math.degrees(design.first_order_accel_error_approx_rad(1.0, 5.0, 100.0))
    exact = math.degrees(design.first_order_accel_error_exact_rad(1.0, 5.0, 100.0))
    assert approx == pytest.approx(2.87, abs=0.01)
    assert approx == pytest.approx(math.degrees(0.05))
    assert exact == pytest.approx(2.79, abs=0.005)
    dt = 0.01
    accel = np.where(np.arange(int(20 / dt)) < int(5 / dt), 1.0, 0.0)
    sim = np.abs(alpha_filter(accel, 0.0, 100.0, dt)).max()
    assert math.degrees(sim) == pytest.approx(exact, rel=0.01)
    assert abs(math.degrees(sim) - approx) > 0.05
    # The same filter is AxisFilter with k1 = 1/T, k2 = 0 (Komplementär-Filter notes:
    # alpha = 1/(1 + k1 dt)).
    axis = simulate(AxisParams(k1=0.01, k2=0.0), 0.0, accel, dt)
    assert np.abs(axis).max() == pytest.approx(sim, rel=1e-9)


def test_thesis_first_order_static_drift_error():
    # Seed 003: u_st ~ T * drift; drift 10 deg/h, written as ~5e-5 1/s (printed garbled as
    # "5*10^-25"), T = 100 s -> 0.29 deg. With the exact 10 deg/h = 4.85e-5 rad/s it is 0.278 deg.
    assert math.degrees(design.first_order_static_drift_error_rad(100.0, 5e-5)) == pytest.approx(
        0.29, abs=0.005)
    exact_drift = thesis.THESIS_GYRO_DRIFT_RAD_S
    assert exact_drift == pytest.approx(4.848e-5, rel=1e-3)
    static = design.first_order_static_drift_error_rad(100.0, exact_drift)
    assert math.degrees(static) == pytest.approx(0.278, abs=0.0005)
    dt = 0.1
    sim = alpha_filter(np.zeros(int(2000 / dt)), exact_drift, 100.0, dt)
    assert sim[-1] == pytest.approx(static, rel=1e-3)
    # The PI loop with k2 = 0 is that filter (k1 = 1/T): its drift "peak" is the static T*omega.
    assert design.drift_peak_error_rad(0.01, 0.0, exact_drift) == pytest.approx(static)


def test_drift_without_integral_but_with_lag_overshoots():
    # k2 = 0 with an aperiodic unit: (Ts+1)/(T s^2 + s + k1) overshoots its final 1/k1.
    peak = design.drift_peak(1.0, 0.0, 1.0, 5.0)
    assert peak.magnitude > 2.0 and math.isfinite(peak.time_s)
    dt = 0.001
    err = simulate(AxisParams(k1=1.0, k2=0.0, aperiodic_time_constant_s=5.0), 1.0,
                   np.zeros(int(30 / dt)), dt)
    assert np.abs(err).max() == pytest.approx(peak.magnitude, rel=0.01)


# ------------------------------------------------------------------------- saturation guidance


def test_min_saturation_limit():
    # DESIGN.md: L_min ~ 2 * bias * 17.7 s for the seed gains.
    assert design.min_saturation_limit_rad(K1, K2, 1e-3) == pytest.approx(2 * 1e-3 * 17.704,
                                                                           rel=1e-4)


def test_clipped_accel_error_agrees_with_axis_filter():
    # Thesis manoeuvre a/g = 5/9.80665 for 5 s with a 0.02 rad clip: k1 L tau + k2 L tau^2/2
    # = 3.25e-3 rad = 11.2' (DESIGN.md: "a clipped loop ~11'"). Unclipped it is ~20x larger.
    a = math.atan(5 / 9.80665)
    est = design.clipped_accel_error_rad(K1, K2, 0.02, a, 5.0)
    assert design.rad_to_arcmin(est) == pytest.approx(11.17, abs=0.01)
    dt = 0.01
    accel = np.where(np.arange(int(60 / dt)) < int(5 / dt), a, 0.0)
    err = simulate(AxisParams(k1=K1, k2=K2, saturation_limit_rad=0.02), 0.0, accel, dt)
    assert np.abs(err).max() == pytest.approx(est, rel=0.01)
    assert design.accel_event_peak_error_rad(K1, K2, a, 5.0) > 20 * est


def test_clipped_recovery_time():
    # gamma0 = 0.1 rad (Ryzhkov & Karpenko's initial angle), L = 0.02 rad: 0.1/(0.03*0.02) =
    # 166.7 s with the proportional path alone (checked with k2 = 0); the integral shortens it
    # to 74.4 s.
    t_p = design.clipped_recovery_time_s(K1, 0.02, 0.1)
    assert t_p == pytest.approx(166.67, abs=0.01)
    dt = 0.05
    err = simulate(AxisParams(k1=K1, k2=0.0, saturation_limit_rad=0.02), 0.0,
                   np.zeros(int(300 / dt)), dt, initial_angle=0.1)
    t_small = (np.argmax(np.abs(err) < 0.02) + 1) * dt  # error back inside the clip
    assert t_small == pytest.approx(design.clipped_recovery_time_s(K1, 0.02, 0.1 - 0.02), abs=1.0)
    t_pi = design.clipped_recovery_time_s(K1, 0.02, 0.1, K2)
    assert t_pi == pytest.approx(74.40, abs=0.01)
    err = simulate(AxisParams(k1=K1, k2=K2, saturation_limit_rad=0.02), 0.0,
                   np.zeros(int(300 / dt)), dt, initial_angle=0.1)
    t_cross = (np.argmax(err < 0.0) + 1) * dt  # first zero crossing (then it overshoots)
    assert t_pi < t_cross < 1.5 * t_pi
    assert err.min() < -0.005


# ---------------------------------------------------------------------- thesis check (Habliuk 2023)


def test_thesis_limits():
    # Seed 003 requirements: fixed base <= 28.8 arcmin; impacts and vibration <= 90 arcmin.
    assert thesis.THESIS_LIMITS_ARCMIN == {"fixed_base": 28.8, "disturbed": 90.0}


def test_thesis_check_seed_gains_without_clip():
    t0 = time.perf_counter()
    rows = {r.name: r for r in thesis.thesis_check(K1, K2)}
    assert time.perf_counter() - t0 < 3.0
    # (a) fixed base: 10 deg/h * 17.70 s = 8.58e-4 rad = 2.95'.
    assert rows["fixed_base"].peak_arcmin == pytest.approx(2.951, abs=0.001)
    assert rows["fixed_base"].passed
    # (b) impacts: atan(15) = 1.50 rad for 12.5 ms every 0.75 s pulls the slow loop to ~90'.
    assert rows["impacts_half-sine"].peak_arcmin == pytest.approx(87.8, abs=0.5)
    assert rows["impacts_rect"].peak_arcmin == pytest.approx(95.4, abs=0.5)
    assert not rows["impacts_rect"].passed
    assert rows["vibration"].passed and rows["vibration"].peak_arcmin < 5.0
    # (c) the manoeuvre: atan(0.51) = 0.472 rad for 5 s -> ~244' (DESIGN.md: ~260' with the
    # small-angle a/g = 0.51 rad instead of atan).
    assert rows["manoeuvre"].peak_arcmin == pytest.approx(244.2, abs=0.5)
    assert not rows["manoeuvre"].passed


def test_thesis_check_seed_gains_with_clip():
    rows = {r.name: r for r in thesis.thesis_check(K1, K2, saturation_limit_rad=0.02)}
    assert all(r.passed for r in rows.values())
    assert rows["impacts_half-sine"].peak_arcmin == pytest.approx(1.3, abs=0.1)  # DESIGN: 1.2'
    assert rows["manoeuvre"].peak_arcmin == pytest.approx(11.2, abs=0.1)


def test_thesis_fixed_base_simulated_when_clip_engages():
    # A clip below the drift peak makes the fixed-base case nonlinear: it is simulated, and the
    # clipped loop's peak is larger than the linear one.
    linear = thesis.thesis_fixed_base(K1, K2)
    clipped = thesis.thesis_fixed_base(K1, K2, saturation_limit_rad=2e-4)
    assert "simulation" in clipped.method and "exact" in linear.method
    assert clipped.peak_arcmin > linear.peak_arcmin


def test_thesis_impacts_rejects_unknown_shape():
    with pytest.raises(ValueError, match="shape"):
        thesis.thesis_impacts(K1, K2, shape="triangle")


# ------------------------------------------------------------------------------------- CLI


def test_cli_json_seed_numbers(capsys):
    code = main(["design", "--k1", "0.03", "--k2", "0.001", "--aperiodic", "0", "--drift", "5e-4",
                 "--accel-g", "0.2", "--accel-duration", "5", "--json"])
    assert code == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("n", "xi", "zeta", "period_s", "settling_time_s", "k1", "k2",
                "drift_peak_error_deg", "accel_peak_error_deg"):
        assert key in out
    assert out["n"] == pytest.approx(0.031623, rel=1e-4)
    assert out["xi"] == pytest.approx(0.94868, rel=1e-4)
    assert out["zeta"] == pytest.approx(0.47434, rel=1e-4)
    assert out["period_s"] == pytest.approx(198.69, abs=0.01)
    assert out["drift_peak_error_deg"] == pytest.approx(0.507, abs=0.001)
    assert out["drift_rough_error_deg"] == pytest.approx(0.906, abs=0.001)
    assert out["accel_peak_error_deg"] == pytest.approx(1.73, abs=0.005)
    assert out["accel_no_filter_error_deg"] == pytest.approx(11.46, abs=0.005)
    assert "vibration_peak_error_deg" not in out and "thesis" not in out


def test_cli_json_omits_unrequested(capsys):
    assert main(["design", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert "drift_peak_error_deg" not in out and "accel_peak_error_deg" not in out
    shipped = FilterParams()  # issue 13.8: every value defaults to the shipped parameters
    assert out["k1"] == shipped.k1 and out["k2"] == shipped.k2
    assert out["aperiodic_time_constant_s"] == shipped.aperiodic_time_constant_s
    assert out["saturation_rad"] == shipped.saturation_limit_rad
    assert out["gains_from"] == "shipped parameters"


def test_cli_inverse(capsys):
    assert main(["design", "--n", "0.05", "--xi", "2", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["k1"] == pytest.approx(0.1) and out["k2"] == pytest.approx(0.0025)
    assert out["zeta"] == pytest.approx(1.0)
    assert main(["design", "--period", "198.6918", "--json"]) == 0  # xi defaults to the paper's 1
    out = json.loads(capsys.readouterr().out)
    assert out["k2"] == pytest.approx(0.001, rel=1e-5) and out["xi"] == pytest.approx(1.0)
    assert main(["design", "--n", "0.05"]) == 0
    text = capsys.readouterr().out
    assert "k1                         0.05 1/s" in text and "0.0025 1/s^2" in text


def test_cli_text_table_with_guidance_and_thesis(capsys):
    assert main(["design", "--k1", "0.03", "--k2", "0.001", "--aperiodic", "0", "--drift", "5e-4",
                 "--accel-g", "0.2", "--accel-duration", "5",
                 "--vib-amplitude-g", "0.1", "--vib-frequency", "10", "--bias", "1e-3",
                 "--saturation", "0.02", "--thesis"]) == 0
    text = capsys.readouterr().out
    assert "0.5072 deg" in text and "0.9059 deg" in text  # drift exact vs omega/n
    assert "1.726 deg" in text and "11.46 deg" in text
    assert "TOO LOW" in text  # 0.02 rad < 2 * 1e-3 * 17.7 s = 0.0354 rad
    assert "overall: PASS" in text and text.count("PASS") == 6


def test_cli_thesis_json(capsys):
    """Issue 13.8: bare ``design --thesis`` checks the shipped filter (clip and lag included),
    which meets the thesis requirement; the papers' bare loop does not."""
    assert main(["design", "--thesis", "--json"]) == 0
    th = json.loads(capsys.readouterr().out)["thesis"]
    assert th["saturation_rad"] == FilterParams().saturation_limit_rad
    assert th["aperiodic_time_constant_s"] == FilterParams().aperiodic_time_constant_s
    assert th["passed"] is True
    assert main(["design", "--k1", "0.03", "--k2", "0.001", "--saturation", "0", "--aperiodic",
                 "0", "--thesis", "--json"]) == 0
    th = json.loads(capsys.readouterr().out)["thesis"]
    assert th["passed"] is False and th["saturation_rad"] is None
    assert {c["name"]: c["passed"] for c in th["checks"]}["manoeuvre"] is False


@pytest.mark.parametrize(("argv", "needle"), [
    (["--k1", "-1"], "negative"),
    (["--k2", "0", "--drift", "1e-4"], "n = sqrt(k2) is 0"),
    (["--accel-g", "0.2"], "--accel-duration"),
    (["--n", "0.05", "--xi", "0"], "--xi"),
    (["--period", "-3"], "--period"),
    (["--k1", "0.03", "--n", "0.1"], "either"),
    (["--aperiodic", "400"], "unstable"),
    (["--k1", "0.001", "--k2", "0.001"], "the shipped value"),
    (["--vib-frequency", "20"], "--vib-amplitude-g"),
])
def test_cli_bad_arguments_exit_2_one_line(capsys, argv, needle):
    assert main(["design", *argv]) == 2
    cap = capsys.readouterr()
    assert cap.out == ""
    lines = cap.err.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and lines[0].startswith("cf-estimator: error:")


@pytest.mark.parametrize("argv", [["--k1", "abc"], ["--k2", "nan"], ["--drift", "inf"]])
def test_cli_non_numbers_are_usage_errors(capsys, argv):
    with pytest.raises(SystemExit) as exc:
        main(["design", *argv])
    assert exc.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.startswith("cf-estimator design: error: argument")


def _env() -> dict[str, str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), env.get("PYTHONPATH")]))
    return env


def test_console_module_runs():
    proc = subprocess.run([sys.executable, "-m", "cf_estimator.cli.main", "design", "--k1",
                           "0.03", "--k2", "0.001", "--json"],
                          capture_output=True, text=True, env=_env(), timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["period_s"] == pytest.approx(198.69, abs=0.01)


def test_console_entry_point_error_is_one_line():
    # The console script's entry point is cf_estimator.cli.main:main.
    code = "import sys; from cf_estimator.cli.main import main; sys.exit(main())"
    proc = subprocess.run([sys.executable, "-c", code, "design", "--accel-g", "0.2"],
                          capture_output=True, text=True, env=_env(), timeout=60, check=False)
    assert proc.returncode == 2
    assert proc.stdout == ""
    assert proc.stderr.strip().splitlines() == [
        "cf-estimator: error: --accel-g and --accel-duration go together (give both or neither)"]


def test_cli_names_where_the_shipped_loop_departs_from_w_s(capsys):
    """``design`` says which loop runs where W(s) = k1 + k2/s does not (issue 50 item 5), and
    its figures are the step's: the learning raise at full bias uncertainty is bias.py's."""
    from types import SimpleNamespace

    from cf_estimator.core import bias
    from cf_estimator.core.ops import FloatOps
    from cf_estimator.core.state import StepState

    assert main(["design", "--json"]) == 0
    rows = {r["when"]: r["loop"] for r in json.loads(capsys.readouterr().out)["shipped_loop"]}
    assert set(rows) == {"start-up, rest, recovery", "bias uncertain (no still phase)",
                         "velocity swing sigma_V", "clip", "aperiodic unit"}
    p = FilterParams()
    s = StepState(0.0, False)
    s.bias_var = p.bias_prior_sigma_rad_s ** 2  # no still phase yet: the whole prior
    s.pv_var = 1e-12  # no velocity swing
    view = SimpleNamespace(**{f: getattr(p, f) for f in p.__dataclass_fields__})
    k1, k2 = bias.learning_gains(s, view, FloatOps)
    assert k2 == pytest.approx(p.bias_learning_k2)
    assert f"2*sqrt(k2) = {k1:.3g} 1/s" in rows["bias uncertain (no still phase)"]
    assert f"startup_k1 = {p.startup_k1:g} 1/s" in rows["start-up, rest, recovery"]
    assert main(["design"]) == 0
    assert "where the shipped filter departs from this W(s)" in capsys.readouterr().out
