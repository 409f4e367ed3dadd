"""Scores the simulated-flight tests share (test_zigzag_scenario, test_circles_scenario)."""

from __future__ import annotations

import numpy as np

from cf_estimator.bench.sustained import with_known_bias
from cf_estimator.core.params import FilterParams
from cf_estimator.metrics import tilt_error_rad


def rms_after_10_s(q: np.ndarray, sc) -> float:
    """Inclination RMS [deg] of ``q`` against the scenario's truth after its first 10 s."""
    e = np.degrees(tilt_error_rad(q, sc.truth.q_world_from_body))[sc.imu.t_s >= 10.0]
    return float(np.sqrt(np.mean(e * e)))


def known_bias_rms(flights, params: FilterParams) -> float:
    """Mean over ``flights`` of :func:`rms_after_10_s` for ours with each scenario's true gyro
    bias taken out and no bias learning (``sustained.with_known_bias``)."""
    return float(np.mean([rms_after_10_s(with_known_bias(
        sc.imu.gyro_rad_s, sc.imu.accel_m_s2, sc.imu.t_s, sc.imu.gyro_bias_rad_s, params), sc)
        for sc in flights]))
