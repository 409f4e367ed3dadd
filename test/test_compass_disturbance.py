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
from cf_estimator.core.filter import ComplementaryFilter
from cf_estimator.core.step import MAG_REJECTED, MAG_USED
from cf_estimator.scenarios.compass import (
    FIELD_ENU_T,
    GRAVITY_M_S2,
    MAG_RESIDUE,
    heading_error_deg,
    magnet_on_turning_sensor,
)

RATE_HZ = 100.0
FIELD_ENU = FIELD_ENU_T
G = GRAVITY_M_S2


def _rotating_with_magnet(seed: int, fraction: float, residue: float = MAG_RESIDUE):
    c = magnet_on_turning_sensor(seed, fraction, rate_hz=RATE_HZ, residue=residue)
    return c.t_s, c.gyro_rad_s, c.accel_m_s2, c.mag_T, c.q_true, c.magnet_on


_heading_error_deg = heading_error_deg


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("fraction", [0.3, 0.5, 1.0])
def test_a_magnet_on_a_turning_sensor_is_never_followed(fraction, seed):
    t, gyro, accel, mag, q, on = _rotating_with_magnet(seed, fraction)
    r = estimate(gyro, accel, mag, rate_hz=RATE_HZ, params=FilterParams())
    err = _heading_error_deg(r.quaternion, q)
    assert err[t > 2.0].max() < 5.0, err[on].max()  # throughout, the 60 s with the magnet too
    assert (r.mag_status[on] == MAG_USED).mean() < 0.02
    assert (r.mag_status[on] == MAG_REJECTED).mean() > 0.98
    back = t > 90.0  # removed at 80 s: the Earth field is used again
    assert (r.mag_status[back] == MAG_USED).mean() > 0.9 and err[back].max() < 3.0


@pytest.mark.parametrize("seed", [0, 1])
def test_a_magnet_seen_to_turn_with_the_body_is_not_reported_as_a_heading_error(seed):
    """Issue 27: a magnet on a turning sensor moves with the body, so it contradicts nothing;
    the heading's reported σ stays with the error the channel measured before (seed 0's first
    magnet samples passed the tests with a 52° innovation, which was held as the heading's
    error for the magnet's 60 s). The filter says so: ``mag_on_body`` within a few seconds.
    A perfect magnetometer here: what is checked is the σ the magnet leaves, an upper bound
    sample by sample; a calibrated sensor's residue turns the heading by a steady offset (seed
    1 at MAG_RESIDUE: 2° before the magnet comes) that no innovation shows, the yaw floor's to
    cover over many sensors (1°, fitted on BROAD; the pooled compass rows of `bench cross`
    judge that)."""
    t, gyro, accel, mag, q, on = _rotating_with_magnet(seed, 0.5, residue=0.0)
    f = ComplementaryFilter(FilterParams())
    on_body = []
    for k in range(t.size):
        f.update(gyro[k], accel[k], 1.0 / RATE_HZ, mag[k])
        on_body.append(bool(f.step_state.mag_on_body))
    on_body = np.array(on_body)
    settled = on & (t > 25.0)
    assert on_body[settled].mean() > 0.9
    assert not on_body[t < 20.0].any()  # before the magnet
    assert not on_body[t > 90.0].any()  # cleared once the Earth field is used again
    r = estimate(gyro, accel, mag, rate_hz=RATE_HZ, params=FilterParams())
    err = _heading_error_deg(r.quaternion, q)[settled]
    sigma = np.degrees(r.heading_sigma_rad[settled])
    assert np.median(sigma) < 3.0, np.median(sigma)
    assert (err < 2.0 * sigma).mean() > 0.95  # and still an upper bound


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
    # still, nothing tells a magnet beside it from a wrong heading: not 'on_body'
    assert dict(report.values)["mag_disturbance"] == "field"
    assert "moves with the sensor" not in report.message


def test_the_diagnostics_say_a_magnet_moves_with_the_sensor():
    """A magnet on a turning sensor, through the pipeline on real sensor_msgs: the WARN names
    the likely cause (something magnetic on the vehicle) and ``mag_disturbance`` is
    'on_body'; once it is gone and the field is used again, 'none'."""
    from test_pipeline import T0_NS, imu_msg, mag_msg

    from cf_estimator.pipeline.diagnostics import OK, WARN
    from cf_estimator.pipeline.pipeline import ImuPipeline

    t, gyro, accel, mag, _q, on = _rotating_with_magnet(0, 0.5)
    pipe = ImuPipeline()
    seen = {}
    for k in range(t.size):
        t_ns = T0_NS + int(round(t[k] * 1e9))
        pipe.on_mag(mag_msg(t_ns, tuple(mag[k])))
        pipe.on_imu(imu_msg(t_ns, tuple(gyro[k]), tuple(accel[k])))
        if k in (int(15.0 * RATE_HZ), int(50.0 * RATE_HZ), int(99.0 * RATE_HZ)):
            report = pipe.diagnostics()
            seen[round(t[k])] = (report.level, report.message,
                                 dict(report.values)["mag_disturbance"])
    assert seen[15][2] == "none" and seen[15][0] == OK
    level, message, disturbance = seen[50]
    assert on[int(50.0 * RATE_HZ)]
    assert level == WARN and disturbance == "on_body", seen[50]
    assert "moves with the sensor" in message
    assert seen[99][2] == "none"


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


MAGNET_TRIALS = ("29_disturbed_stationary_magnet_B", "30_disturbed_stationary_magnet_C",
                 "32_disturbed_attached_magnet_1cm", "34_disturbed_attached_magnet_3cm",
                 "36_disturbed_attached_magnet_5cm")


@pytest.mark.parametrize("name", MAGNET_TRIALS)
def test_every_broad_magnet_trial_within_vqf_online_plus_1_deg(name):
    """Issue 22's target per magnet trial (bench cross holds the group means): the 9-D total
    RMSE over the movement, shipped defaults, at most VQF online's + 1°. Today: 1.90 / 1.76 /
    2.17 / 3.29 / 1.82° against VQF's 2.38 / 2.57 / 7.67 / 3.35 / 2.39°."""
    from pathlib import Path

    from cf_estimator.bench import broad
    from cf_estimator.bench.evaluate import evaluate_trial

    pytest.importorskip("vqf")
    data = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "broad"
    if not data.is_dir():
        pytest.skip(f"{data} not present")
    path = broad.list_trials(data, [name])[0]
    _, _, res = evaluate_trial(path, broad.read_trial_info(data), FilterParams(), ("vqf",),
                               ("9d",))
    ours, vqf = res["cf_estimator_9d"]["total_rmse_deg"], res["vqf_9d"]["total_rmse_deg"]
    assert ours <= vqf + 1.0, (ours, vqf)
