"""IMU sensor model: gyro, accelerometer and magnetometer readings from a :class:`Truth`.

The sensor frame is the body frame (identity mounting). Models, per sample k with dt = 1/rate:

* gyro ``ω_m = ω_b + b_g(t) + n_g``: constant bias ``b_g0`` (explicit or drawn per run from
  N(0, ``gyro_bias_std_rad_s``²) per axis) plus a random walk with density
  ``gyro_bias_walk_rad_s2_sqrt_hz``; white noise std = density·√(1/dt).
* accelerometer (specific force) ``f_m = Rᵀ(a_world − g_world) + b_a + n_a``, with
  ``g_world = (0, 0, −g)`` in ENU, so at rest the reading is ``Rᵀ·(0, 0, +g)``.
* magnetometer ``m_m = Rᵀ·B·(0, cos dip, −sin dip) + n_m`` [T] (ENU: north, pointing down).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from cf_estimator.core.quaternion import to_matrix as quat_to_matrix
from cf_estimator.scenarios.integration import FloatArray
from cf_estimator.scenarios.motion import GRAVITY_M_S2, Truth

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class SensorModel:
    """Error model of a typical UAV MEMS IMU (BMI088 / ICM-42688 class), all per axis.

    Attributes:
        gyro_noise_density_rad_s_sqrt_hz: gyro white noise [rad/s/√Hz]; default 0.015 °/s/√Hz.
        gyro_bias_std_rad_s: std of the constant gyro bias drawn per run [rad/s]; default 0.1 °/s
            (a residual after a start-up calibration; uncalibrated parts are ~0.5–1 °/s).
        gyro_bias_rad_s: explicit constant gyro bias [rad/s] (body frame); overrides the draw.
        gyro_bias_walk_rad_s2_sqrt_hz: bias random walk density [rad/s²/√Hz = rad/s/√s];
            default 2e-5 (≈ 0.013 °/s of drift after 2 min).
        accel_noise_density_m_s2_sqrt_hz: accelerometer white noise [m/s²/√Hz]; default 1.5e-3
            (≈ 150 µg/√Hz).
        accel_bias_std_m_s2: std of the constant accelerometer bias drawn per run [m/s²];
            default 0.02 (2 mg: a calibrated part; tilt error ≈ bias/g ≈ 7′).
        accel_bias_m_s2: explicit constant accelerometer bias [m/s²]; overrides the draw.
        mag_noise_std_T: magnetometer white noise, std per sample [T]; default 0.3 µT.
        earth_field_T: Earth field magnitude B [T]; default 50 µT.
        dip_rad: inclination of the field below the horizontal [rad]; default 60°.
        gravity_m_s2: gravity magnitude g [m/s²]; default 9.80665.
    """

    gyro_noise_density_rad_s_sqrt_hz: float = float(np.deg2rad(0.015))
    gyro_bias_std_rad_s: float = float(np.deg2rad(0.1))
    gyro_bias_rad_s: Vec3 | None = None
    gyro_bias_walk_rad_s2_sqrt_hz: float = 2e-5
    accel_noise_density_m_s2_sqrt_hz: float = 1.5e-3
    accel_bias_std_m_s2: float = 0.02
    accel_bias_m_s2: Vec3 | None = None
    mag_noise_std_T: float = 0.3e-6
    earth_field_T: float = 50e-6
    dip_rad: float = float(np.deg2rad(60.0))
    gravity_m_s2: float = GRAVITY_M_S2

    @classmethod
    def perfect(cls, **overrides: float) -> SensorModel:
        """Noise-free, bias-free sensors (same field, dip and gravity as the defaults)."""
        fields = {
            "gyro_noise_density_rad_s_sqrt_hz": 0.0,
            "gyro_bias_std_rad_s": 0.0,
            "gyro_bias_walk_rad_s2_sqrt_hz": 0.0,
            "accel_noise_density_m_s2_sqrt_hz": 0.0,
            "accel_bias_std_m_s2": 0.0,
            "mag_noise_std_T": 0.0,
        }
        fields.update(overrides)
        return cls(**fields)

    @classmethod
    def thesis(cls, **overrides: float) -> SensorModel:
        """The defaults with the thesis's gyro drift: bias std 10 °/h (Habliuk 2023, 2.6)."""
        fields: dict = {"gyro_bias_std_rad_s": float(np.deg2rad(10.0 / 3600.0))}
        fields.update(overrides)
        return cls(**fields)

    def field_world_T(self) -> FloatArray:
        """Earth magnetic field in ENU [T]: ``B·(0, cos dip, −sin dip)``."""
        return self.earth_field_T * np.array([0.0, np.cos(self.dip_rad), -np.sin(self.dip_rad)])

    def gravity_world_m_s2(self) -> FloatArray:
        """Gravity vector in ENU [m/s²]: ``(0, 0, −g)``."""
        return np.array([0.0, 0.0, -self.gravity_m_s2])


@dataclass(frozen=True, eq=False)
class ImuData:
    """Simulated IMU samples, all in the sensor (= body) frame.

    Attributes:
        t_s: sample times (N,) [s] (shared by all three sensors).
        gyro_rad_s: angular velocity (N, 3) [rad/s].
        accel_m_s2: specific force (N, 3) [m/s²] (+g on the up axis at rest).
        mag_T: magnetic field (N, 3) [T].
        gyro_bias_rad_s: the true gyro bias (N, 3) [rad/s] that went into ``gyro_rad_s``
            (constant + random walk), for evaluating bias estimates; None if unknown.
        accel_bias_m_s2: the true constant accelerometer bias (3,) [m/s²]; None if unknown.
        accel_disturbance_m_s2: the sensor-frame specific-force disturbance (N, 3) [m/s²] that
            was added to ``accel_m_s2`` (impacts, vibration); None if none was added.
        gyro_disturbance_rad_s: the disturbance (N, 3) [rad/s] added to ``gyro_rad_s`` (rotor
            vibration); None if none was added. Not part of ``gyro_bias_rad_s``.
    """

    t_s: FloatArray
    gyro_rad_s: FloatArray
    accel_m_s2: FloatArray
    mag_T: FloatArray
    gyro_bias_rad_s: FloatArray | None = None
    accel_bias_m_s2: FloatArray | None = None
    accel_disturbance_m_s2: FloatArray | None = None
    gyro_disturbance_rad_s: FloatArray | None = None

    def __post_init__(self) -> None:
        n = np.shape(self.t_s)[0]
        for name in ("gyro_rad_s", "accel_m_s2", "mag_T", "gyro_bias_rad_s",
                     "accel_disturbance_m_s2", "gyro_disturbance_rad_s"):
            value = getattr(self, name)
            if value is not None and np.shape(value) != (n, 3):
                raise ValueError(f"ImuData.{name} must have shape ({n}, 3), got {np.shape(value)}")

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return int(self.t_s.shape[0])

    def with_accel_disturbance(self, disturbance_m_s2: FloatArray) -> ImuData:
        """Copy with a sensor-frame specific-force disturbance (N, 3) [m/s²] added to the
        accelerometer only (the gyro and magnetometer are untouched); the disturbance is also
        accumulated in ``accel_disturbance_m_s2``."""
        d = np.asarray(disturbance_m_s2, dtype=float)
        if d.shape != self.accel_m_s2.shape:
            raise ValueError(f"disturbance must have shape {self.accel_m_s2.shape}, got {d.shape}")
        total = d if self.accel_disturbance_m_s2 is None else self.accel_disturbance_m_s2 + d
        return dataclasses.replace(self, accel_m_s2=self.accel_m_s2 + d,
                                   accel_disturbance_m_s2=total)

    def with_gyro_disturbance(self, disturbance_rad_s: FloatArray) -> ImuData:
        """Copy with a sensor-frame rate disturbance (N, 3) [rad/s] added to the gyro only,
        also accumulated in ``gyro_disturbance_rad_s``."""
        d = np.asarray(disturbance_rad_s, dtype=float)
        if d.shape != self.gyro_rad_s.shape:
            raise ValueError(f"disturbance must have shape {self.gyro_rad_s.shape}, got {d.shape}")
        total = d if self.gyro_disturbance_rad_s is None else self.gyro_disturbance_rad_s + d
        return dataclasses.replace(self, gyro_rad_s=self.gyro_rad_s + d,
                                   gyro_disturbance_rad_s=total)


def _bias(explicit: Vec3 | None, std: float, rng: np.random.Generator) -> FloatArray:
    if explicit is not None:
        return np.asarray(explicit, dtype=float).reshape(3)
    return rng.normal(0.0, std, 3) if std > 0 else np.zeros(3)


def measure(
    truth: Truth, model: SensorModel, rng: np.random.Generator, *, exact: bool = False
) -> ImuData:
    """Sample the IMU along ``truth`` with the errors of ``model``.

    ``exact=True`` gives perfect sensors (no noise, no bias, no random walk; ``rng`` is not used),
    whatever the model says; the model's gravity, field and dip still apply. The random draws are
    made in a fixed order (gyro bias, accel bias, gyro walk, gyro noise, accel noise, mag noise),
    so the same ``rng`` state gives the same data.
    """
    t = truth.t_s
    n = t.shape[0]
    r = quat_to_matrix(truth.q_world_from_body)  # (N, 3, 3) world_from_body
    specific_force_world = truth.accel_world_m_s2 - model.gravity_world_m_s2()
    accel = np.einsum("nji,nj->ni", r, specific_force_world)  # Rᵀ·(a − g)
    mag = np.einsum("nji,j->ni", r, model.field_world_T())  # Rᵀ·B
    gyro = truth.gyro_true_rad_s.copy()
    if exact:
        return ImuData(t.copy(), gyro, accel, mag, np.zeros((n, 3)), np.zeros(3))
    dt = np.empty(n)
    dt[1:] = np.diff(t)
    dt[0] = dt[1] if n > 1 else 1.0
    sqrt_dt = np.sqrt(dt)[:, None]
    b_g0 = _bias(model.gyro_bias_rad_s, model.gyro_bias_std_rad_s, rng)
    b_a = _bias(model.accel_bias_m_s2, model.accel_bias_std_m_s2, rng)
    bias_g = np.tile(b_g0, (n, 1))
    if model.gyro_bias_walk_rad_s2_sqrt_hz > 0:
        steps = rng.standard_normal((n, 3)) * (model.gyro_bias_walk_rad_s2_sqrt_hz * sqrt_dt)
        steps[0] = 0.0
        bias_g += np.cumsum(steps, axis=0)
    gyro += bias_g
    if model.gyro_noise_density_rad_s_sqrt_hz > 0:
        gyro += rng.standard_normal((n, 3)) * (model.gyro_noise_density_rad_s_sqrt_hz / sqrt_dt)
    accel += b_a
    if model.accel_noise_density_m_s2_sqrt_hz > 0:
        accel += rng.standard_normal((n, 3)) * (model.accel_noise_density_m_s2_sqrt_hz / sqrt_dt)
    if model.mag_noise_std_T > 0:
        mag += rng.standard_normal((n, 3)) * model.mag_noise_std_T
    return ImuData(t.copy(), gyro, accel, mag, bias_g, b_a)
