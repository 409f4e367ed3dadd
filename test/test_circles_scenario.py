"""The sustained-turn scenario (issue 22 item 1): multirotor figure-8s in the air, 1 kHz, a gyro
whose firmware has already removed its bias — the nano-quadrotor the issue measured on
recordings the team does not have (ours 1.87°, VQF online 1.37°; 0.4 °/s of bias learned on a
de-biased gyro, the clip engaged most of the time on the worst flight).

"A scenario counts when VQF and ours rank on it as they do on the real family it stands for":
up to the turn share (core/bias.py ``turn_share``) it did — VQF online 5.0° against ours 7.6°,
2.6 °/s learned from the turns. With the turn share ours is level with VQF here (5.1°); the
tests below now hold the fix, and the real family's check is with whoever holds it.
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


def test_the_turns_are_not_learned_as_bias(flights, ours):
    """The failure the issue saw: the turn's tilt, fixed on the body for a whole loop, was
    learned as gyro bias (the largest component 2.4-2.5 °/s on these seeds, the tilt RMS 7.6°
    against 4.0° with the bias known). While the vehicle turns about the vertical the learning
    raise is withheld: what is learned is well below that (issue 22's < 0.05 °/s is not met:
    the shipped loop's own slow learning still takes part of the turn for bias), and the online
    loop is within 40 % of the same loop with the bias known (91 % before)."""
    learned = [float(np.degrees(np.abs(r.gyro_bias_rad_s[-1]).max())) for r in ours]
    assert max(learned) < 1.8, learned  # deg/s, on a gyro whose bias is 0
    known = known_bias_rms(flights, P6)  # the true bias is zero here
    online = np.mean([rms_after_10_s(r.quaternion, sc) for r, sc in zip(ours, flights,
                                                                          strict=True)])
    assert online < 1.4 * known, (known, online)


def test_ours_within_5_percent_of_vqf_online_on_the_scenario(flights, ours):
    """Issue 22's target for the new simulated cases is inclination RMS at most VQF online's:
    missed here by 0.09° (ours 5.10°, VQF 5.01°; the seeds' standard errors 0.06° and 0.04°),
    where ours was 7.6° before the turn share. Held as a guard: within 5 %."""
    pytest.importorskip("vqf")
    from cf_estimator.bench.peers import run_vqf

    sim_vqf = np.mean([rms_after_10_s(run_vqf(sc.imu.gyro_rad_s, sc.imu.accel_m_s2, None,
                                               sc.rate_hz)["6d"], sc) for sc in flights])
    sim_ours = np.mean([rms_after_10_s(r.quaternion, sc) for r, sc in zip(ours, flights,
                                                                            strict=True)])
    assert sim_ours < 1.05 * sim_vqf, (sim_vqf, sim_ours)
