"""The filter's parts tested one by one, on data (issue 16 item 6).

- state: every field owned by exactly one part, documented, in the compiled twin's order;
- rest/motion classifier (core/stillness.py) alone, on real recordings: airborne phantom4
  blocks are never rest, EuRoC's ground phase is; a steady turn with a magnetometer is motion;
- bias estimator (core/bias.py): the Kalman fusion at rest, the gains while uncertain (withheld
  in a turn), the anti-windup (widened by the samples' scatter, unaided) and the bound;
- the aperiodic unit (core/step.py) kept at most 0.75/k1 inside a raised loop, and what the
  integral learns from it (R̄ᵀ·l: a sensor-fixed error along its own axis, faded by a turn).
"""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from cf_estimator.core import bias, state, stillness
from cf_estimator.core.filter import step_params
from cf_estimator.core.kernel import compiled_available, compiled_kernel
from cf_estimator.core.ops import FloatOps
from cf_estimator.core.params import FilterParams

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
G = 9.80665


# -- state ------------------------------------------------------------------------------------
def test_every_field_has_one_owner_a_kind_and_a_meaning():
    names = [f.name for f in state.ALL_FIELDS]
    assert len(names) == len(set(names)) == len(state.StepState.FIELDS)
    for f in state.ALL_FIELDS:
        assert f.kind in ("float", "bool", "int") and f.doc, f
    owners = {f.name: g for g, fields in state.GROUPS.items() for f in fields}
    assert owners["bx"] == owners["bias_var"] == "bias"
    assert owners["at_rest"] == owners["blk_n"] == owners["g_ref"] == "classifier"
    assert owners["z_m"] == owners["mag_recovering"] == "heading"


@pytest.mark.skipif(not compiled_available(), reason="the compiled kernel is not built")
def test_compiled_twin_holds_the_same_fields_in_the_same_order():
    assert list(compiled_kernel.State.FIELDS) == state.StepState.FIELDS


# -- classifier ------------------------------------------------------------------------------
def _classify_recording(gyro, accel, t, mag=None, bias_var=None, params=None):
    """Only the classifier (no loop, no bias learning): at_rest per sample."""
    p = step_params(params or FilterParams(use_mag=mag is not None))
    s = state.StepState(0.0, False)
    s.bias_var = (p.bias_prior_sigma_rad_s ** 2) if bias_var is None else bias_var
    rest = np.zeros(len(t), bool)
    dts = np.diff(t, prepend=t[0] - np.median(np.diff(t)))
    for k in range(len(t)):
        stillness.classify(s, p, tuple(gyro[k]), tuple(accel[k]),
                           None if mag is None else tuple(mag[k]), float(dts[k]), FloatOps)
        rest[k] = s.at_rest
    return rest


def _flights(name):
    from cf_estimator.bench.euroc import load_flights

    if not (DATA / name).is_dir():
        pytest.skip(f"{DATA / name} not present")
    return load_flights(DATA / name)


def test_classifier_alone_never_takes_airborne_phantom4_blocks_for_rest():
    for f in _flights("phantom4")[::4]:  # every 4th recording: one per path, all IMUs cycled
        assert not _classify_recording(f.gyro_rad_s, f.accel_m_s2, f.t_s).any(), f.name


def test_classifier_alone_finds_the_euroc_ground_phase():
    for f in _flights("euroc"):
        n = int(np.searchsorted(f.t_s, 20.0))
        rest = _classify_recording(f.gyro_rad_s[:n], f.accel_m_s2[:n], f.t_s[:n])
        assert rest.mean() > 0.05, f.name


def test_classifier_takes_a_steady_turn_with_a_magnetometer_for_motion():
    """10 deg/s about the vertical, constant specific force: with an open gate (prior bias
    variance) the gyro and the accelerometer alone would call it rest; the field turns."""
    rate, n = 100.0, 2000
    t = np.arange(n) / rate
    w = math.radians(10.0)
    gyro = np.tile([0.0, 0.0, w], (n, 1))
    accel = np.tile([0.0, 0.0, G], (n, 1))
    yaw = w * t
    field = np.stack([25e-6 * np.sin(yaw), 25e-6 * np.cos(yaw), np.full(n, -43e-6)], axis=1)
    assert _classify_recording(gyro, accel, t).any(), "without the field: rest (the gate's job)"
    assert not _classify_recording(gyro, accel, t, mag=field).any()


def test_classifier_returns_the_block_mean_as_the_measurement():
    p = step_params(FilterParams(use_mag=False))
    s = state.StepState(0.0, False)
    s.bias_var = 0.01
    rng = np.random.default_rng(0)
    b = np.array([0.01, -0.02, 0.03])
    found = []
    for _ in range(300):
        m = stillness.classify(s, p, tuple(b + rng.normal(0, 0.002, 3)),
                               (0.0, 0.0, G), None, 0.01, FloatOps)
        if m.measure:
            found.append((m.mean_x, m.mean_y, m.mean_z, m.variance))
    assert found, "rest reached within 3 s"
    mx, my, mz, var = found[-1]
    assert np.allclose([mx, my, mz], b, atol=0.001)
    assert 0 < var < (0.002 ** 2) * 2 / 10  # ~ sigma^2 / n for a 50-sample block


# -- bias estimator ---------------------------------------------------------------------------
def _bias_state(var: float, err_var: float | None = None) -> state.StepState:
    """A state whose bias variance is ``var`` and its error's ``err_var`` (default the same: as
    right after a still-block measurement)."""
    s = state.StepState(0.0, False)
    s.bias_var = var
    s.bias_err_var = var if err_var is None else err_var
    return s


def test_fuse_rest_is_the_scalar_kalman_update():
    s = _bias_state(0.01)
    m = stillness.RestMeasurement(True, 0.05, -0.02, 0.0, 0.0001, False)
    bias.fuse_rest(s, m, FloatOps)
    k = 0.01 / (0.01 + 0.0001)
    assert s.bx == pytest.approx(k * 0.05) and s.by == pytest.approx(k * -0.02)
    assert s.bias_var == pytest.approx(0.01 * 0.0001 / 0.0101)
    assert s.bias_unverified, "a power-on still phase without a magnetometer"
    s.moved = True
    bias.fuse_rest(s, m, FloatOps)
    assert not s.bias_unverified
    before = (s.bx, s.bias_var, s.bias_err_var)
    bias.fuse_rest(s, m._replace(measure=False), FloatOps)
    assert (s.bx, s.bias_var, s.bias_err_var) == before


def test_the_bias_error_variance_takes_every_measurement_and_shrinks_twice_as_fast():
    """bias_err_var (bias.error_sigma): the same prior and random walk as bias_var; a still
    block's update with the gain bias_var chose leaves (1 - k)^2 err + k^2 r (the Kalman
    posterior when both agree); while the integral learns it falls at twice the schedule's
    rate (the error decays with the loop's slow mode k2/k1, its variance twice as fast)."""
    s = state.StepState(0.0, False)
    p = step_params(FilterParams(bias_prior_sigma_rad_s=0.1))
    bias.add_process_noise(s, p, 0.01, FloatOps)  # the first step: the prior, both
    walk = bias.BIAS_RANDOM_WALK_RAD_S_SQRT_S ** 2 * 0.01
    assert s.bias_var == s.bias_err_var == pytest.approx(0.01 + walk, rel=1e-12)
    m = stillness.RestMeasurement(True, 0.05, -0.02, 0.0, 0.0001, False)
    bias.fuse_rest(s, m, FloatOps)
    assert s.bias_err_var == pytest.approx(s.bias_var, rel=1e-9)  # both the Kalman posterior
    s = _bias_state(0.01, 0.0004)  # learned: the error already below the schedule
    bias.fuse_rest(s, m, FloatOps)
    k = 0.01 / (0.01 + 0.0001)
    assert s.bias_err_var == pytest.approx((1 - k) ** 2 * 0.0004 + k * k * 0.0001, rel=1e-12)
    s = _bias_state(0.01, 0.01)
    f = (0.01, 0.0, 0.0)
    bias.integrate(s, p, f, 0.35, 0.05, True, True, 0.01, FloatOps)
    x = 0.01 * 0.05 / 0.35
    assert s.bias_var == pytest.approx(0.01 / (1 + x), rel=1e-12)
    assert s.bias_err_var == pytest.approx(0.01 / (1 + 2 * x), rel=1e-12)
    assert bias.error_sigma(s, FloatOps) == pytest.approx(math.sqrt(0.01 / (1 + 2 * x)))
    before = (s.bias_var, s.bias_err_var)
    bias.integrate(s, p, f, 0.35, 0.05, True, False, 0.01, FloatOps)  # too large to learn from
    assert (s.bias_var, s.bias_err_var) == before


def test_learning_gains_follow_the_bias_uncertainty():
    p = step_params(FilterParams())
    k1, k2 = bias.learning_gains(_bias_state(p.bias_prior_sigma_rad_s ** 2), p, FloatOps)
    assert k2 == p.bias_learning_k2 and k1 == pytest.approx(2 * math.sqrt(p.bias_learning_k2))
    k1, k2 = bias.learning_gains(_bias_state(1e-10), p, FloatOps)
    assert (k1, k2) == (p.k1, p.k2)


def test_a_velocity_swing_caps_the_raised_learning_at_sigma_b_over_sigma_v():
    p = step_params(FilterParams())
    var = p.bias_prior_sigma_rad_s ** 2
    s = _bias_state(var)
    s.pv_var = 0.25  # sigma_V = 0.5 rad s: legs of about +-5 m/s
    k1, k2 = bias.learning_gains(s, p, FloatOps)
    assert k2 == pytest.approx(math.sqrt(var) / 0.5) and k2 < p.bias_learning_k2
    assert k1 == pytest.approx(2 * math.sqrt(k2))
    s.pv_var = 1e-6  # hovering: the cap is far above the raise
    assert bias.learning_gains(s, p, FloatOps)[1] == p.bias_learning_k2
    s = _bias_state(1e-10)
    s.pv_var = 100.0  # the cap never takes k2 below the shipped gain, nor k1 below 2 sqrt(k2)
    assert bias.learning_gains(s, p, FloatOps) == (2.0 * math.sqrt(p.k2), p.k2)


def test_the_loop_gain_falls_with_the_velocity_swing_and_rises_with_the_gyro_drift():
    """bias.loop_gain: k1 = sqrt(d / sigma_V), d = sigma_e + GYRO_SCALE_UNCERTAINTY * |w| with
    sigma_e the bias estimate's error (bias.error_sigma, not the schedule's sigma_b), at most the
    configured k1: a hover keeps the thesis's loop, legs of metres per second lower it, a fast
    rotation (the gyro's scale error) raises it again."""
    p = step_params(FilterParams())
    s = _bias_state(1e-6)  # sigma_b = 1e-3 rad/s: a learned bias
    s.pv_var = 2.5e-5  # sigma_V = 0.005 rad s: a hover
    assert bias.learning_gains(s, p, FloatOps)[0] == p.k1
    s.pv_var = 0.25  # sigma_V = 0.5 rad s: zig-zag legs of +-5 m/s
    k1 = bias.learning_gains(s, p, FloatOps)[0]
    assert k1 == pytest.approx(max(math.sqrt(1e-3 / 0.5), 2.0 * math.sqrt(p.k2)))
    assert k1 < 0.5 * p.k1
    s.pv_var = 4e-4  # sigma_V = 0.02 rad s: a gentle flight
    slow = bias.learning_gains(s, p, FloatOps)[0]
    assert slow == pytest.approx(math.sqrt(1e-3 / 0.02)) and slow < p.k1
    s.rate_lp = 3.0  # a hand-held sensor turned fast: the gyro's scale error drifts the attitude
    fast = bias.loop_gain(s, p, FloatOps)  # sigma_b = 1e-3, sigma_V = 0.02 as above
    assert fast == pytest.approx(min(p.k1, math.sqrt((1e-3 + bias.GYRO_SCALE_UNCERTAINTY * 3.0)
                                                     / 0.02)))
    assert fast > slow
    # the schedule still says 0.01 rad/s, the error is 1e-3 rad/s: the drift is the error's
    s = _bias_state(1e-4, 1e-6)
    s.pv_var = 4e-4
    assert bias.loop_gain(s, p, FloatOps) == pytest.approx(slow)


def test_a_turn_about_the_vertical_withholds_the_learning_raise():
    """bias.turn_share: the raise falls as (k1²/(k1² + ω²))² with the turn rate ω; a rate the
    size of a gyro bias barely touches it; the shipped loop's own gains are never taken away."""
    p = step_params(FilterParams())
    var = 0.0025  # sigma_b = 0.05 rad/s
    s = _bias_state(var)
    raised = bias.learning_gains(s, p, FloatOps)
    assert bias.turn_share(s, p, FloatOps) == 1.0 and raised[1] > p.k2
    s.turn_hold = 0.05  # the size of a bias still to be learned: the raise barely moves
    assert 0.95 < bias.turn_share(s, p, FloatOps) < 1.0
    for sign in (1.0, -1.0):  # a figure-8's either loop (the held size of either)
        s.turn_hold = abs(sign * 0.6)
        share = bias.turn_share(s, p, FloatOps)
        assert share == pytest.approx((p.k1 ** 2 / (p.k1 ** 2 + 0.36)) ** 2) and share < 0.1
        k1, k2 = bias.learning_gains(s, p, FloatOps)
        assert k2 == pytest.approx(max(p.k2, raised[1] * share)) and k2 < 0.1 * raised[1]
    s = _bias_state(1e-10)
    s.turn_hold = 3.0  # a fast turn never takes the gains below the shipped ones
    assert bias.learning_gains(s, p, FloatOps) == (p.k1, p.k2)


def test_the_turn_rate_is_the_rotation_about_the_estimated_vertical():
    """step.classify_motion low-passes the bias-corrected rate projected on the estimated up:
    a yaw on a level body counts fully, a roll not at all, a yaw on a body rolled 90° not at
    all (it is then a rotation about a horizontal axis)."""
    from cf_estimator.core.step import TURN_LOWPASS_TIME_CONSTANT_S, classify_motion, up_direction

    p = step_params(FilterParams())
    cases = (((0.0, 0.0, 0.5), (1.0, 0.0, 0.0, 0.0), 0.5),
             ((0.5, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), 0.0),
             ((0.0, 0.0, 0.5), (math.sqrt(0.5), math.sqrt(0.5), 0.0, 0.0), 0.0))
    for gyro, q, turn in cases:
        s = _bias_state(1e-4)
        s.qw, s.qx, s.qy, s.qz = q
        accel = (0.0, 0.0, G)
        dt = 0.01
        for _ in range(int(10 * TURN_LOWPASS_TIME_CONSTANT_S / dt)):
            classify_motion(s, p, gyro, accel, None, up_direction(s), False, dt, FloatOps)
        assert s.turn_rate_lp == pytest.approx(turn, abs=1e-3), (gyro, q)


def test_a_figure_8_reversal_keeps_the_turn_held_over_the_loops_memory():
    """step.classify_motion holds |turn_rate_lp| in turn_hold, decaying over 1/k1: when a turn
    reverses, the signed low-pass passes through zero, the held size does not (the loop's error
    still holds the lean of the turn just flown), and it fades as 1/k1 once the turning stops."""
    from cf_estimator.core.step import classify_motion, up_direction

    p = step_params(FilterParams())
    s = _bias_state(1e-4)
    dt, accel = 0.01, (0.0, 0.0, G)

    def fly(rate: float, seconds: float) -> list[tuple[float, float]]:
        out = []
        for _ in range(int(round(seconds / dt))):
            classify_motion(s, p, (0.0, 0.0, rate), accel, None, up_direction(s), False, dt,
                            FloatOps)
            out.append((s.turn_rate_lp, s.turn_hold))
        return out

    fly(1.5, 20.0)  # a sustained turn
    assert s.turn_hold == pytest.approx(1.5, abs=1e-3)
    reversal = fly(-1.5, 3.0)
    lp_min = min(abs(lp) for lp, _ in reversal)
    assert lp_min < 0.05  # the signed low-pass crosses zero ...
    assert min(h for _, h in reversal) > 0.5  # ... the held size does not
    assert all(h >= abs(lp) for lp, h in reversal)
    fly(0.0, 10.0 / p.k1)  # straight for ten of the loop's memories: the turn is forgotten
    assert s.turn_hold < 0.01


def test_the_velocity_swing_is_the_disagreement_integrated_and_high_passed():
    s = _bias_state(0.01)
    dt = 0.01
    for _ in range(int(10 * bias.SWING_TIME_CONSTANT_S / dt)):  # a steady 0.1 rad along x
        s.time_s += dt
        bias.observe_velocity_swing(s, 0.1, 0.0, dt, FloatOps)
    # the leaky integral settles at w * T (a steady disagreement is no swing for ever)
    assert s.pvx == pytest.approx(0.1 * bias.SWING_TIME_CONSTANT_S, rel=0.01) and s.pvy == 0.0
    assert s.pv_var == pytest.approx(s.pvx ** 2, rel=0.05)
    # a zig-zag whose velocity swings by +-dv: sigma_V about its RMS over g
    s = _bias_state(0.01)
    for k in range(6000):
        s.time_s += dt
        bias.observe_velocity_swing(s, 0.3 * math.copysign(1.0, math.sin(k * dt * math.pi / 3)),
                                    0.0, dt, FloatOps)
    # legs of 3 s at 0.3 rad (a/g): the velocity over g swings by +-0.45 s, RMS ~ 0.26-0.5
    assert 0.2 < math.sqrt(s.pv_var) < 0.6


def test_integral_learns_only_from_a_bias_sized_error_and_is_bounded():
    p = step_params(FilterParams())
    s = _bias_state(0.01)
    bias.integrate(s, p, (0.0, 0.1, 0.0), 1.8, 0.8, True, True, 0.01, FloatOps)
    assert s.by == pytest.approx(-0.01 * 0.8 * 0.1) and s.bias_var < 0.01
    by, var = s.by, s.bias_var
    bias.integrate(s, p, (0.0, 0.1, 0.0), 1.8, 0.8, True, False, 0.01, FloatOps)  # too large
    assert (s.by, s.bias_var) == (by, var)
    s.bz = 7.0
    bias.clamp(s, SimpleNamespace(bias_prior_sigma_rad_s=0.1), FloatOps)
    assert s.bz == 0.5  # five standard deviations of the prior


def test_the_learning_limit_is_widened_by_the_sample_scatter_only_unaided():
    s = _bias_state(0.01)
    s.g_ref, s.noise_a2 = G, 0.0  # no scatter measured (yet): the glitch guard alone
    assert bias.learning_limit_rad(s, FloatOps) == bias.BIAS_LEARNING_MAX_ERROR_RAD
    s.noise_a2 = 3 * 4.0 ** 2  # the DOTs' rotor vibration, 4 m/s^2 per axis
    wide = bias.learning_limit_rad(s, FloatOps)
    assert wide == pytest.approx(bias.BIAS_LEARNING_MAX_ERROR_RAD
                                 + bias.BIAS_LEARNING_NOISE_SIGMAS * math.sqrt(48.0) / G)
    assert wide > 2.0  # wider than any tilt error a leg's acceleration makes
    s.aided = True  # aided: the error's mean does not swing, the narrow gate stays
    assert bias.learning_limit_rad(s, FloatOps) == bias.BIAS_LEARNING_MAX_ERROR_RAD


def _unit_weight(s, p, tight: bool) -> float:
    """The aperiodic unit's weight on one sample of a unit world-x error (dt = 0.01 s)."""
    from cf_estimator.core.step import aperiodic

    s.qw, s.qx, s.qy, s.qz = 1.0, 0.0, 0.0, 0.0
    s.lx = s.ly = s.lz = 0.0
    s.ex, s.ey, s.ez = 1.0, 0.0, 0.0
    aperiodic(s, p, 1.0, False, tight, 0.01, FloatOps)
    return s.lx


def test_the_unit_inside_a_raised_loop_is_kept_at_most_0_75_over_k1():
    from cf_estimator.core.step import LOOP_LAG_FRACTION

    p = step_params(FilterParams())
    dt = 0.01
    s = _bias_state(p.bias_prior_sigma_rad_s ** 2)  # in flight, bias unknown: k1 raised
    k1, k2 = bias.learning_gains(s, p, FloatOps)
    assert k1 > 1.5  # 2*sqrt(0.8)
    t = LOOP_LAG_FRACTION / k1
    assert _unit_weight(s, p, False) == pytest.approx(dt / (t + dt))
    # the damping the bound keeps: T s^3 + s^2 + k1 s + k1^2/4 at T k1 = 3/4 -> zeta 0.5
    roots = np.roots([t, 1.0, k1, k1 * k1 / 4.0])
    assert min(-r.real / abs(r) for r in roots) == pytest.approx(0.5, abs=1e-6)
    # ... where the shipped 2 s unit rang
    roots = np.roots([p.aperiodic_time_constant_s, 1.0, k1, k1 * k1 / 4.0])
    assert min(-r.real / abs(r) for r in roots) < 0.1
    # under the tight clip (a manoeuvre) and with the bias known: the thesis's unit
    T = p.aperiodic_time_constant_s
    assert _unit_weight(s, p, True) == pytest.approx(dt / (T + dt))
    s = _bias_state(1e-10)
    assert _unit_weight(s, p, False) == pytest.approx(dt / (T + dt))


def test_the_unit_bound_takes_a_loop_without_gains():
    """k1 = k2 = bias_learning_k2 = 0 is a valid (gyro-only) set: no bound, no division by 0."""
    p = step_params(FilterParams(k1=0.0, k2=0.0, bias_learning_k2=0.0))
    s = _bias_state(p.bias_prior_sigma_rad_s ** 2)
    assert bias.learning_gains(s, p, FloatOps) == (0.0, 0.0)
    T = p.aperiodic_time_constant_s
    assert _unit_weight(s, p, False) == pytest.approx(0.01 / (T + 0.01))


def _turning_unit(omega: float, lag: float, e_sensor: tuple, seconds: float, dt: float = 0.01):
    """A body yawing at ``omega`` [rad/s] with a constant sensor-frame error ``e_sensor`` [rad]:
    the unit low-passes its world image over ``lag`` [s]; returns the state, (f, g) at the end."""
    from cf_estimator.core.step import _rotate, learning_input

    s = state.StepState(0.0, False)
    weight = dt / (lag + dt)
    f = g = (0.0, 0.0, 0.0)
    for k in range(int(seconds / dt)):
        half = 0.5 * omega * k * dt
        s.qw, s.qx, s.qy, s.qz = math.cos(half), 0.0, 0.0, math.sin(half)
        wx, wy, wz = _rotate(s.qw, s.qx, s.qy, s.qz, *e_sensor)
        s.lx, s.ly, s.lz = (s.lx + weight * (wx - s.lx), s.ly + weight * (wy - s.ly),
                            s.lz + weight * (wz - s.lz))
        f = _rotate(s.qw, -s.qx, -s.qy, -s.qz, s.lx, s.ly, s.lz)
        g = learning_input(s, (s.lx, s.ly, s.lz), weight, FloatOps)
    return s, f, g


def test_the_bias_learns_a_sensor_fixed_error_along_its_own_axis_faded_by_the_turn():
    """step.learning_input: R̄ᵀ·l, R̄ low-passed as the unit. Turning at ω with the unit's lag T,
    a sensor-fixed error comes back along its own axis, scaled by 1/(1 + (ωT)²); f = Rᵀ·l, what
    the proportional path corrects by, comes back turned by atan(ωT) about the vertical (the
    other way in the opposite turn). Not turning, both are the error itself."""
    e = (0.0, 0.02, 0.0)
    lag = 2.0
    for omega in (1.5, -1.5, 0.6):
        _, f, g = _turning_unit(omega, lag, e, 30.0)
        scale = 1.0 / (1.0 + (omega * lag) ** 2)
        assert g == pytest.approx((0.0, 0.02 * scale, 0.0), abs=2e-4 * scale)
        turned = math.atan2(f[1], f[0]) - math.atan2(e[1], e[0])
        assert turned == pytest.approx(-math.atan(omega * lag), abs=0.02)
        assert math.hypot(f[0], f[1]) == pytest.approx(0.02 / math.hypot(1.0, omega * lag),
                                                       rel=0.02)
    _, f, g = _turning_unit(0.0, lag, e, 30.0)
    assert g == pytest.approx(f) and g == pytest.approx(e)


def test_a_heading_correction_leaves_the_learning_input_as_it_was():
    """step.turn_heading turns R̄'s world rows with the attitude and the unit: R̄ᵀ·l (and f) do
    not change, so the magnetometer never teaches the tilt's bias."""
    from cf_estimator.core.step import _rotate, learning_input, turn_heading

    s, _, _ = _turning_unit(1.0, 2.0, (0.01, 0.02, 0.005), 10.0)
    before = s.copy()
    turn_heading(s, 0.7, FloatOps)
    assert (s.rxx, s.rxy) != pytest.approx((before.rxx, before.rxy))
    g0 = learning_input(before, (before.lx, before.ly, before.lz), 0.0, FloatOps)
    g1 = learning_input(s, (s.lx, s.ly, s.lz), 0.0, FloatOps)
    assert g1 == pytest.approx(g0, abs=1e-12)
    f0 = _rotate(before.qw, -before.qx, -before.qy, -before.qz, before.lx, before.ly, before.lz)
    assert _rotate(s.qw, -s.qx, -s.qy, -s.qz, s.lx, s.ly, s.lz) == pytest.approx(f0, abs=1e-12)


def test_rotation_elements_are_the_quaternions_matrix_for_floats_and_arrays():
    """ops.rotation_elements (R̄'s input and the aiding's P): R(q) row-major, as
    quaternion.to_matrix, one quaternion at a time or many at once."""
    from cf_estimator.core import quaternion
    from cf_estimator.core.ops import rotation_elements

    q = np.random.default_rng(3).normal(size=(50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    expected = quaternion.to_matrix(q).reshape(50, 9)
    for k in range(50):
        assert rotation_elements(*(float(c) for c in q[k])) == pytest.approx(expected[k],
                                                                             abs=1e-15)
    assert np.stack(rotation_elements(*q.T), axis=1) == pytest.approx(expected, abs=1e-15)


def test_realign_clears_every_lagged_rotation_field_and_the_unit():
    """ComplementaryFilter.realign: the unit's memory and R̄ (state.LAGGED_ROTATION: nine
    fields, rows x, y, z) start again with the outside tilt."""
    from cf_estimator.core.filter import ComplementaryFilter

    assert [f.name for f in state.LAGGED_ROTATION] == [
        f"r{row}{col}" for row in "xyz" for col in "xyz"]
    f = ComplementaryFilter(FilterParams(use_mag=False))
    f.update((0.0, 0.0, 0.0), (0.5, 0.0, G), 0.01)
    for _ in range(300):  # turning while the accelerometer disagrees: R̄ and l are set
        f.update((0.0, 0.0, 0.8), (0.5, 0.3, G), 0.01)
    s = f.step_state
    assert all(getattr(s, field.name) != 0.0 for field in state.LAGGED_ROTATION)
    assert (s.lx, s.ly) != (0.0, 0.0)
    f.realign((0.01, 0.0, 0.0), (0.0, 0.0, 0.0))
    s = f.step_state
    assert all(getattr(s, field.name) == 0.0 for field in state.LAGGED_ROTATION)
    assert (s.lx, s.ly, s.lz) == (0.0, 0.0, 0.0)


def test_the_named_extra_columns_are_the_fields_state_extras_writes():
    """filter.Extra (what estimate(), the bulk pipeline and the replay read) names the columns
    state_extras writes, in its order; the compiled run writes the same row."""
    from cf_estimator.core.filter import EXTRA_COLUMNS, ComplementaryFilter, Extra, state_extras

    f = ComplementaryFilter(FilterParams())
    f.update((0.0, 0.0, 0.0), (0.3, 0.0, G), 0.01, (0.0, 2e-5, -4e-5))
    for _ in range(200):
        f.update((0.01, 0.2, 0.3), (0.5, 0.3, G), 0.01, (0.0, 2e-5, -4e-5))
    s = f.step_state
    row = state_extras(s)
    assert len(row) == EXTRA_COLUMNS
    assert row[Extra.ERROR] == (s.ex, s.ey, s.ez) and row[Extra.BIAS] == (s.bx, s.by, s.bz)
    assert (row[Extra.CLIPPED], row[Extra.PHASE], row[Extra.AT_REST], row[Extra.MAG_STATUS]) == (
        s.clipped, s.phase, s.at_rest, s.mag_status)
    assert row[Extra.BIAS_SIGMA] == math.sqrt(s.bias_err_var) > 0.0
    assert (row[Extra.LX], row[Extra.LY], row[Extra.YAW_ERROR], row[Extra.NOISE_A2],
            row[Extra.LOOP_K1]) == (s.lx, s.ly, s.yaw_error_rad, s.noise_a2, s.loop_k1)
    assert row[Extra.GYRO_BIAS] == pytest.approx(tuple(f.gyro_bias_rad_s), abs=0.0)
