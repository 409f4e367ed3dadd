"""Simulated motion, sensor models and the thesis disturbances: IMU data with known truth.

Pure NumPy, no ROS. Quaternions wxyz ``q_world_from_body`` (ENU), sensor frame = body frame;
truth orientation is integrated from the body rates with ``q_k = q_{k-1} ⊗ Exp(ω_k·dt_k)``.
"""

from cf_estimator.scenarios.disturbances import (
    acceleration_manoeuvre,
    acceleration_profile,
    impact_times,
    impacts,
    rotor_vibration,
    vibration,
)
from cf_estimator.scenarios.library import (
    DEFAULT_DURATION_S,
    DEFAULT_RATE_HZ,
    SCENARIOS,
    UAV_GYRO_BIAS_RAD_S,
    Scenario,
    make_scenario,
)
from cf_estimator.scenarios.motion import (
    GRAVITY_M_S2,
    MultirotorFlight,
    Truth,
    from_body_rates,
    hover,
    multirotor_flight,
    random_rotation,
    static,
    uav_flight,
)
from cf_estimator.scenarios.sensors import ImuData, SensorModel, measure

__all__ = [
    "DEFAULT_DURATION_S",
    "DEFAULT_RATE_HZ",
    "GRAVITY_M_S2",
    "SCENARIOS",
    "UAV_GYRO_BIAS_RAD_S",
    "ImuData",
    "MultirotorFlight",
    "Scenario",
    "SensorModel",
    "Truth",
    "acceleration_manoeuvre",
    "acceleration_profile",
    "from_body_rates",
    "hover",
    "impact_times",
    "impacts",
    "make_scenario",
    "measure",
    "multirotor_flight",
    "random_rotation",
    "rotor_vibration",
    "static",
    "uav_flight",
    "vibration",
]
