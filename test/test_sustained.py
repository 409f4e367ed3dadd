"""bench sustained: the IMU-only floor in a sustained acceleration (issue 22 item 3).

The floor formula on synthetic velocities with known answers; on the Phantom 4 recordings the
physics the document states (horizontal zig-zags leave an IMU-only filter far more to average
than vertical ones; velocity aiding removes it; with the reference's gyro bias the loop is far
better: what fails is the in-flight bias learning; the rotor drag shows the velocity only
roughly); the drag fit on a synthetic flight with a known drag; the CLI's usage errors.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import DATA_ROOT

from cf_estimator import metrics
from cf_estimator.bench import euroc, sustained
from cf_estimator.cli.main import main
from cf_estimator.core.batch import estimate
from cf_estimator.core.params import FilterParams

G = sustained.GRAVITY_M_S2


def _flight(t: np.ndarray, v: np.ndarray) -> euroc.Flight:
    n = t.size
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    acc = np.tile([0.0, 0.0, G], (n, 1))
    return euroc.Flight("synthetic", t, np.zeros((n, 3)), acc, q, 0, Path("."),
                        velocity_t_s=t, velocity_m_s=v)


def test_a_constant_acceleration_is_its_tilt_for_every_memory():
    t = np.arange(0.0, 30.0, 0.01)
    a = 3.0  # m/s² along a diagonal of the horizontal plane
    v = np.stack([a * t / math.sqrt(2), a * t / math.sqrt(2), np.zeros_like(t)], axis=1)
    f = _flight(t, v)
    for memory in sustained.MEMORIES_S:
        e = sustained.mean_acceleration_tilt_deg(f, memory)
        assert np.all(np.isnan(e[t < memory]))  # no velocity that far back yet
        np.testing.assert_allclose(e[t >= memory + 0.01], math.degrees(math.atan(a / G)),
                                   rtol=1e-6)


def test_a_zig_zag_averages_out_over_whole_periods_only():
    t = np.arange(0.0, 40.0, 0.01)
    period, amplitude = 5.0, 4.0  # v = A sin(ωt): peak acceleration A·ω
    v = np.stack([amplitude * np.sin(2 * np.pi * t / period), np.zeros_like(t),
                  np.zeros_like(t)], axis=1)
    f = _flight(t, v)
    late = t >= 10.0
    whole = sustained.mean_acceleration_tilt_deg(f, period)[late]
    half = sustained.mean_acceleration_tilt_deg(f, period / 2)[late]
    assert np.nanmax(whole) < 1e-6  # the mean acceleration over a period is zero
    # over half a period the mean acceleration reaches 2A/(T/2) = 4A/T
    assert np.nanmax(half) == pytest.approx(math.degrees(math.atan(4 * amplitude / period / G)),
                                            rel=1e-3)


def test_the_reference_bias_is_the_gyro_minus_the_reference_rate():
    t = np.arange(0.0, 20.0, 0.01)
    rate = np.array([0.1, -0.2, 0.3])  # rad/s, constant, sensor frame
    angle = np.linalg.norm(rate) * t
    axis = rate / np.linalg.norm(rate)
    q = np.column_stack([np.cos(angle / 2), np.outer(np.sin(angle / 2), axis)])
    bias = np.array([0.02, -0.01, 0.005])
    f = euroc.Flight("spin", t, np.tile(rate + bias, (t.size, 1)),
                     np.tile([0.0, 0.0, G], (t.size, 1)), q, 0, Path("."))
    np.testing.assert_allclose(sustained.reference_bias_rad_s(f), bias, atol=1e-6)


def test_the_reference_bias_run_takes_that_bias_out_and_learns_none():
    # a still, tilted sensor whose gyro reads only its bias: with the bias the reference
    # shows taken out the estimate stays on the reference; the same run without it drifts
    # until the accelerometer holds it at bias/k1 off
    t = np.arange(0.0, 30.0, 0.01)
    tilt = 0.3  # rad about x
    q = np.tile([np.cos(tilt / 2), np.sin(tilt / 2), 0.0, 0.0], (t.size, 1))
    up_sensor = np.array([0.0, np.sin(tilt), np.cos(tilt)])
    bias = np.array([0.02, -0.015, 0.0])
    f = euroc.Flight("still", t, np.tile(bias, (t.size, 1)), np.tile(G * up_sensor, (t.size, 1)),
                     q, 0, Path("."))
    params = FilterParams(rest_bias_learning=False)  # nothing measures the bias at rest
    late = t >= 10.0
    with_bias = metrics.inclination_error_deg(sustained.with_reference_bias(f, params), q)
    assert np.max(with_bias[late]) < 0.1
    off = dataclasses.replace(params, use_mag=False, k2=0.0, bias_learning_k2=0.0)
    plain = estimate(f.gyro_rad_s, f.accel_m_s2, None, timestamps_s=t, params=off).quaternion
    assert np.median(metrics.inclination_error_deg(plain, q)[late]) > 1.0


def test_the_score_windows_split_the_scored_samples():
    # an estimate 1 deg off the reference before SPLIT_S and 3 deg off after it
    t = np.arange(0.0, 40.0, 0.01)
    q_ref = np.tile([1.0, 0.0, 0.0, 0.0], (t.size, 1))
    tilt = np.radians(np.where(t < sustained.SPLIT_S, 1.0, 3.0))
    q = np.column_stack([np.cos(tilt / 2), np.sin(tilt / 2), np.zeros_like(t), np.zeros_like(t)])
    f = euroc.Flight("split", t, np.zeros((t.size, 3)), np.zeros((t.size, 3)), q_ref, 0, Path("."))
    early = sustained.score(f, q, (sustained.SETTLE_S, sustained.SPLIT_S))
    assert early == pytest.approx(1.0, abs=1e-9)
    assert sustained.score(f, q, (sustained.SPLIT_S, math.inf)) == pytest.approx(3.0, abs=1e-9)
    whole = sustained.score(f, q)
    assert 1.0 < whole < 3.0
    assert math.isnan(sustained.score(f, q, (50.0, 60.0)))


def test_the_drag_fit_finds_the_drag_it_was_given():
    t = np.arange(0.0, 60.0, 0.01)
    k, wind_force = 0.25, np.array([0.3, -0.2])  # 1/s; a steady wind's force [m/s²]
    v = np.stack([3.0 * np.sin(0.5 * t), 2.0 * np.cos(0.3 * t), 0.5 * np.sin(t)], axis=1)
    f = _flight(t, v)  # level, sensor = world
    acc = f.accel_m_s2.copy()
    acc[:, :2] = -k * v[:, :2] + wind_force
    fit = sustained.rotor_drag(dataclasses.replace(f, accel_m_s2=acc))
    assert fit.k_per_s == pytest.approx(k, rel=1e-3)
    assert fit.explained == pytest.approx(1.0, abs=1e-4)  # the axis: the mean force
    assert fit.velocity_error_m_s < 0.01
    # the swing is the RMS per axis about the mean, across the thrust axis (x and y here), of
    # the 1 s means (a little below the raw velocity's)
    centred = v[:, :2] - v[:, :2].mean(axis=0)
    raw = math.sqrt(np.mean(centred**2))
    assert 0.98 * raw < fit.velocity_swing_m_s < raw
    # no drag at all: nothing explained, and the velocity it implies is no velocity
    still = sustained.rotor_drag(f)
    assert still.k_per_s == pytest.approx(0.0, abs=1e-9)
    assert not math.isfinite(still.velocity_error_m_s)
    with pytest.raises(ValueError, match="no reference velocity"):
        sustained.rotor_drag(dataclasses.replace(f, velocity_t_s=None, velocity_m_s=None))


def test_drift_grows_with_the_memory():
    assert sustained.drift_deg(2.0, 0.5) == pytest.approx(0.5)
    assert sustained.drift_deg(10.0) == pytest.approx(10 * sustained.BIAS_RESIDUAL_DEG_S / 2)


def _family(name: str, n: int) -> list[euroc.Flight]:
    folder = DATA_ROOT / name
    if not folder.is_dir():
        pytest.skip(f"{folder} missing (../shared/data)")
    return euroc.load_flights(folder)[::4][:n]  # one IMU per flight


def test_horizontal_zig_zags_leave_an_imu_only_filter_far_more_than_vertical_ones():
    params = FilterParams()
    horizontal = sustained.analyse("phantom4_horizontal", _family("phantom4_horizontal", 8),
                                   params, with_vqf=False)
    vertical = sustained.analyse("phantom4", _family("phantom4", 10), params, with_vqf=False)
    assert horizontal.median_horizontal_accel_m_s2 > 3 * vertical.median_horizontal_accel_m_s2
    for memory in (0.5, 1.0, 2.0):
        assert horizontal.floor_deg[memory] > 2 * vertical.floor_deg[memory]
    # a longer memory averages more of the acceleration out
    floors = [horizontal.floor_deg[m] for m in sustained.MEMORIES_S]
    assert floors[-1] < floors[0] / 5
    # velocity aiding takes the acceleration out: below the online filter on both
    for row in (horizontal, vertical):
        assert row.measured_deg["cf_estimator_aided"] < row.measured_deg["cf_estimator"]
    # the loop itself is not what fails in the zig-zags: with the bias the reference shows
    # (learning off) it is below ours online there (0.70 of it; 0.42 before the running mean in
    # start-up), and below it on the vertical flights too; on the horizontal ones the in-flight
    # learned bias is still further off at the end (0.49 against 0.34 °/s on these; 0.76
    # against 0.38 °/s before the integral learned through the unit's own lag,
    # step.learning_input)
    assert (horizontal.measured_deg["cf_estimator_reference_bias"]
            < 0.85 * horizontal.measured_deg["cf_estimator"])
    assert (vertical.measured_deg["cf_estimator_reference_bias"]
            < vertical.measured_deg["cf_estimator"])
    assert horizontal.bias_error_end_deg_s > vertical.bias_error_end_deg_s
    # ... and most of what ours loses is in the first seconds after the in-air start
    early, late = horizontal.measured_split_deg["cf_estimator"]
    assert early > late
    assert set(horizontal.measured_split_deg) == set(horizontal.measured_deg)
    # the Xsens DOTs' biases, as the data README says: about 1-2 deg/s
    assert 0.8 < vertical.reference_bias_deg_s < 3.0
    assert 0.8 < horizontal.reference_bias_deg_s < 3.0
    # rotor drag: the Phantom's accelerometer sees its velocity across the thrust axis, at
    # about 0.2 /s (the simulator's 0.35 is above it), and more of that force on the
    # horizontal zig-zags, where the velocity swings more; the velocity it implies is off by
    # more than half the swing itself: no measurement an IMU-only filter could aid with
    for row in (horizontal, vertical):
        drag = row.rotor_drag
        assert drag is not None and 0.1 < drag.k_per_s < 0.3 < sustained.DRAG_PER_S
        assert drag.velocity_error_m_s > 0.5 * drag.velocity_swing_m_s
    assert horizontal.rotor_drag.explained > vertical.rotor_drag.explained
    assert horizontal.rotor_drag.velocity_swing_m_s > vertical.rotor_drag.velocity_swing_m_s
    table = sustained.format_table([horizontal, vertical])
    assert "phantom4_horizontal" in table and "IMU-only floor, memory 5 s" in table
    assert "cf_estimator_reference_bias" in table and "learned-bias error at the end" in table
    assert "rotor drag: across the thrust" in table


def test_cli_usage_errors_exit_2(tmp_path, capsys):
    assert main(["bench", "sustained", "--data", str(tmp_path), "--families", "nope"]) == 2
    assert "is not a directory" in capsys.readouterr().err
    assert main(["bench", "sustained", "--data", str(tmp_path), "--families", ","]) == 2
    assert "--families is empty" in capsys.readouterr().err


def test_vqf_learns_the_in_flight_bias_no_better_than_ours():
    """The table's VQF rows (its own bias estimate against the bias the reference shows): on
    the vertical zig-zags ours ends closer to it than VQF online (0.37 against 0.59 °/s over all
    40; EuRoC 0.05 against 3.07), and the rows are printed only when VQF ran."""
    pytest.importorskip("vqf")
    params = FilterParams()
    vertical = sustained.analyse("phantom4", _family("phantom4", 10), params, with_vqf=True)
    at_10, at_end = vertical.vqf_bias_error_deg_s
    assert math.isfinite(at_10) and math.isfinite(at_end)
    assert vertical.bias_error_end_deg_s < at_end
    assert "vqf online: learned-bias error at the end" in sustained.format_table([vertical])
    without = sustained.analyse("phantom4", _family("phantom4", 2), params, with_vqf=False)
    assert math.isnan(without.vqf_bias_error_deg_s[0])
    assert "vqf online" not in sustained.format_table([without])
