"""The thesis's disturbances in 3-D (Habliuk 2023): the saturation unit meets the ±90′ limit.

Simulated with realistic gyro noise and bias, accelerometer noise and bias, and real tilt motion
(cf_estimator.scenarios): 60 unipolar 15 g impacts of 10–15 ms at 80/min; 6 g vibration swept
20–120 Hz along an oblique axis; 25 m/s reached in 5 s. Shipped defaults, with and without the
clip at equal k1, k2. "Induced" error = estimate on disturbed data vs the same filter on the same
data without the disturbance, which separates the disturbance from the accelerometer-bias floor.
"""

from __future__ import annotations

import numpy as np
import pytest

from cf_estimator import FilterParams, estimate
from cf_estimator.core import quaternion as quat
from cf_estimator.scenarios import make_scenario

LIMIT_ARCMIN = (
    90.0  # thesis: "Measurement accuracy ±90 [arc]minutes at multiple impacts, vibration"
)


def inclination_arcmin(q_est: np.ndarray, q_ref: np.ndarray) -> np.ndarray:
    d = quat.multiply(q_est, quat.conjugate(q_ref))
    return np.degrees(2 * np.arccos(np.clip(np.hypot(d[:, 0], d[:, 3]), 0.0, 1.0))) * 60


def run(sc, accel, params):
    return estimate(sc.imu.gyro_rad_s, accel, sc.imu.mag_T, timestamps_s=sc.imu.t_s, params=params)


@pytest.mark.parametrize("name", ["impacts", "vibration", "acceleration"])
def test_clip_cuts_the_disturbance_error_tenfold_and_meets_the_thesis_limit(name):
    sc = make_scenario(name, seed=0)
    clipped = FilterParams()
    unclipped = FilterParams(use_saturation=False)
    assert clipped.k1 == unclipped.k1 and clipped.k2 == unclipped.k2
    settled = sc.imu.t_s > 5.0
    peaks = {}
    for label, params in (("clip", clipped), ("no clip", unclipped)):
        est = run(sc, sc.imu.accel_m_s2, params).quaternion
        total = inclination_arcmin(est, sc.truth.q_world_from_body)[settled]
        if sc.imu.accel_disturbance_m_s2 is not None:  # impacts, vibration: sensor-only disturbance
            clean = run(sc, sc.imu.accel_m_s2 - sc.imu.accel_disturbance_m_s2, params).quaternion
            induced = inclination_arcmin(est, clean)[settled]
        else:  # the manoeuvre is real motion: all of the error above the floor is its doing
            induced = total
        peaks[label] = (total.max(), induced.max())
    assert peaks["clip"][0] < LIMIT_ARCMIN
    if name == "vibration":
        # Zero-mean vibration: the seed's error e = (a/‖g‖) × ĝ is linear in the acceleration, so
        # the aperiodic unit averages it out with or without the clip (with e = â × ĝ, i.e.
        # normalised by |a|, the same oblique vibration rectified into 1880′ without the clip).
        assert peaks["no clip"][0] < LIMIT_ARCMIN
        assert peaks["clip"][1] < 2 * peaks["no clip"][1] + 5.0  # the clip does not make it worse
    else:  # unipolar impacts (a DC component) and the sustained manoeuvre: the clip decides
        assert peaks["clip"][1] * 10 <= peaks["no clip"][1]
        assert peaks["no clip"][1] > LIMIT_ARCMIN
