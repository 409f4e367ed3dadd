"""The horizontal zig-zag scenario (issue 22 item 1): a simulated flight that fails as the real
horizontal campaign does, so a fix can be developed and checked on it.

"A scenario counts when VQF and ours rank on it as they do on the real family it stands for":
the ranking on ``../shared/data/phantom4_horizontal`` is computed here, live, beside the
scenario's, so the test follows the filter when it gets better (it does not pin today's loss).
So is the diagnosis: on both, the loop with the right gyro bias is far better than ours online
(what fails is the bias learned in the air).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scenario_scores import known_bias_rms, rms_after_10_s

from cf_estimator.core.batch import estimate
from cf_estimator.core.params import FilterParams
from cf_estimator.scenarios import make_scenario

P6 = FilterParams(use_mag=False)
SEEDS = (0, 1, 2, 3)
HORIZONTAL = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "phantom4_horizontal"


@pytest.fixture(scope="module")
def flights():
    return [make_scenario("zigzag", seed=s) for s in SEEDS]


def _ours(flights, params=P6) -> float:
    return float(np.mean([rms_after_10_s(estimate(
        sc.imu.gyro_rad_s, sc.imu.accel_m_s2, None, timestamps_s=sc.imu.t_s,
        params=params).quaternion, sc) for sc in flights]))


def test_the_zigzags_accelerate_most_of_the_time_from_the_first_sample(flights):
    for sc in flights:
        a_h = np.linalg.norm(sc.truth.accel_world_m_s2[:, :2], axis=1)
        v_h = np.linalg.norm(sc.truth.velocity_world_m_s[:, :2], axis=1)
        assert np.median(a_h) > 2.0  # the Phantom's campaign: median 4 m/s² over 1 s
        assert v_h.max() > 4.0 and sc.truth.t_s[0] == 0.0
        # in the air at the first sample: the accelerometer reads the thrust (rotor vibration on)
        assert np.std(sc.imu.accel_m_s2[:50, 0]) > 0.5
        # backwards on every other leg: the velocity along the first leg changes sign
        first = sc.truth.velocity_world_m_s[np.argmax(v_h > 3.0), :2]
        along = sc.truth.velocity_world_m_s[:, :2] @ (first / np.linalg.norm(first))
        assert along.min() < -3.0 < 3.0 < along.max()


def test_the_in_flight_bias_learning_is_what_fails_as_on_the_real_flights(flights):
    """The failure found on the real flights (docs/decisions/0006-*.md): the
    learned bias is wrong by tenths of a degree per second, and the same loop with the right
    bias and no learning is far better (real horizontal campaign: 2.26 deg against 5.37; the
    real side is checked live in the ranking test below)."""
    sc = flights[3]
    r = estimate(sc.imu.gyro_rad_s, sc.imu.accel_m_s2, None, timestamps_s=sc.imu.t_s, params=P6)
    err = np.degrees(np.abs(r.gyro_bias_rad_s[-1] - sc.imu.gyro_bias_rad_s[-1]))
    assert err.max() > 0.3
    assert known_bias_rms(flights, P6) < KNOWN_BIAS_SHARE * _ours(flights)


#: With the right bias the loop's error is below this share of ours online, on the scenario and
#: on the real horizontal campaign alike (real 0.42, scenario 0.57 when written; 0.70 and 0.76
#: since the running mean in start-up; 0.73 and 0.90 since the loop gain follows the velocity
#: swing, bias.loop_gain: the scenario's remaining loss is mostly the vertical bias component a
#: level 6-D flight cannot observe, and it now shows less of the loss than the real flights).
KNOWN_BIAS_SHARE = 0.95


@pytest.mark.skipif(not HORIZONTAL.is_dir(), reason=f"{HORIZONTAL} not present")
def test_ours_and_vqf_rank_on_the_scenario_as_on_the_real_horizontal_campaign(flights):
    """Issue 22: a scenario counts when VQF and ours rank on it as on the real family. With the
    running mean in start-up ours leads on both (real 3.25° against VQF 4.05°, the mean's
    standard error 0.23°; scenario 4.9° against 5.1°; with the swing-set loop gain 3.11° and
    3.96°); after the loop-lag change the real
    campaign was a tie while the scenario had ours behind. A tie counts as either ranking; a
    real lead beyond its noise that the scenario does not show fails here."""
    pytest.importorskip("vqf")
    from cf_estimator.bench import euroc
    from cf_estimator.bench import euroc_eval as ev
    from cf_estimator.bench.cross import standard_error
    from cf_estimator.bench.peers import run_vqf

    real = ev.run_euroc(euroc.load_flights(HORIZONTAL), P6, ["vqf"], ev.SETTLE_S)
    real_ours = real.mean("cf_estimator", "inclination_rms_deg")
    real_vqf = real.mean("vqf", "inclination_rms_deg")
    assert np.isfinite(real_ours) and np.isfinite(real_vqf)
    noise = standard_error([per["cf_estimator"]["inclination_rms_deg"]
                            for per in real.flights.values()])
    sim_vqf = float(np.mean([rms_after_10_s(run_vqf(sc.imu.gyro_rad_s, sc.imu.accel_m_s2, None,
                                                     sc.rate_hz)["6d"], sc) for sc in flights]))
    sim_ours = _ours(flights)
    tie = abs(real_ours - real_vqf) < noise
    assert tie or (sim_ours < sim_vqf) == (real_ours < real_vqf), (
        sim_ours, sim_vqf, real_ours, real_vqf, noise)


@pytest.mark.skipif(not HORIZONTAL.is_dir(), reason=f"{HORIZONTAL} not present")
def test_the_right_bias_helps_on_the_real_campaign_as_on_the_scenario():
    from cf_estimator.bench import euroc, sustained

    real = euroc.load_flights(HORIZONTAL)[::4]  # one IMU per path
    ours = np.mean([sustained.score(f, estimate(f.gyro_rad_s, f.accel_m_s2, None,
                                                timestamps_s=f.t_s, params=P6).quaternion)
                    for f in real])
    known = np.mean([sustained.score(f, sustained.with_reference_bias(f, P6)) for f in real])
    assert known < KNOWN_BIAS_SHARE * ours, (known, ours)
