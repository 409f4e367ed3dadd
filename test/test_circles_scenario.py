"""The sustained-turn scenario (issue 22 item 1): multirotor figure-8s in the air, 1 kHz, a gyro
whose firmware has already removed its bias — the nano-quadrotor the issue measured on
recordings the team does not have (ours 1.87°, VQF online 1.37°; 0.4 °/s of bias learned on a
de-biased gyro, the clip engaged most of the time on the worst flight).

"A scenario counts when VQF and ours rank on it as they do on the real family it stands for":
the real family's ranking is the issue's table (not data we hold), so the ranking test below
states it as a constant; a fix that makes ours win here must be checked against that family by
whoever holds it, and this test changed with it.
"""

from __future__ import annotations

import numpy as np
import pytest
from scenario_scores import known_bias_rms, rms_after_10_s

from cf_estimator.core.batch import estimate
from cf_estimator.core.params import FilterParams
from cf_estimator.scenarios import make_scenario

P6 = FilterParams(use_mag=False)
SEEDS = (0, 1, 2)


@pytest.fixture(scope="module")
def flights():
    return [make_scenario("circles", seed=s) for s in SEEDS]


@pytest.fixture(scope="module")
def ours(flights):
    return [estimate(sc.imu.gyro_rad_s, sc.imu.accel_m_s2, None, timestamps_s=sc.imu.t_s,
                     params=P6) for sc in flights]


def test_the_vehicle_turns_steadily_from_the_first_sample_and_reverses_each_loop(flights):
    for sc in flights:
        a_h = np.linalg.norm(sc.truth.accel_world_m_s2[:, :2], axis=1)
        # centripetal 3 m/s * 0.6 rad/s = 1.8 m/s^2 held (drag adds a little) most of the time
        assert np.median(a_h) == pytest.approx(1.8, rel=0.1)
        assert np.mean(a_h > 1.5) > 0.8
        # no constant bias: what is left is the MEMS model's bias instability (< 0.1 deg/s)
        assert sc.rate_hz == 1000.0 and np.abs(sc.imu.gyro_bias_rad_s).max() < 2e-3
        # the turn direction reverses after the first loop (figure-8)
        yaw_rate = np.gradient(np.unwrap(_yaw(sc)), sc.truth.t_s)
        first = sc.events["first_reversal"]
        before = yaw_rate[(sc.truth.t_s > 2.0) & (sc.truth.t_s < first - 1.0)]
        after = yaw_rate[(sc.truth.t_s > first + 2.0) & (sc.truth.t_s < first + 8.0)]
        assert np.median(before) * np.median(after) < 0.0


def _yaw(sc) -> np.ndarray:
    w, x, y, z = sc.truth.q_world_from_body.T
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def test_a_bias_is_learned_from_the_turns_on_a_gyro_that_has_none(flights, ours):
    """The failure the issue saw: the turn's tilt, fixed on the body for a whole loop, is
    learned as gyro bias; with the bias known (zero) and no learning the same loop is far
    better."""
    learned = [float(np.degrees(np.abs(r.gyro_bias_rad_s[-1]).max())) for r in ours]
    assert np.mean(learned) > 1.0  # deg/s, on a gyro whose bias is 0
    known = known_bias_rms(flights, P6)  # the true bias is zero here
    online = np.mean([rms_after_10_s(r.quaternion, sc) for r, sc in zip(ours, flights,
                                                                          strict=True)])
    assert known < 0.7 * online, (known, online)


#: The real family's ranking (issue 22's table: the nano-quadrotor, VQF online 1.37° against
#: ours 1.87°): VQF ahead.
REAL_VQF_AHEAD = True


def test_ours_and_vqf_rank_on_the_scenario_as_on_the_real_nano_quadrotor(flights, ours):
    pytest.importorskip("vqf")
    from cf_estimator.bench.peers import run_vqf

    sim_vqf = np.mean([rms_after_10_s(run_vqf(sc.imu.gyro_rad_s, sc.imu.accel_m_s2, None,
                                               sc.rate_hz)["6d"], sc) for sc in flights])
    sim_ours = np.mean([rms_after_10_s(r.quaternion, sc) for r, sc in zip(ours, flights,
                                                                            strict=True)])
    assert (sim_vqf < sim_ours) == REAL_VQF_AHEAD, (sim_vqf, sim_ours)
