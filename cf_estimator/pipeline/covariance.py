"""Orientation covariance from the filter's reported state (what a downstream EKF should weigh).

The filter does not propagate a covariance; this model turns the state it reports after each
step into variances [rad²] about the world x, y, z axes (diagonal of ``orientation_covariance``,
row-major 3×3). Documented in docs/ros_interface.md ("Covariance"):

- tilt (roll, pitch): ``v0 + e_t² + (σ_b·t_clip)²``. ``v0`` = ``orientation_covariance_rad2``
  (the floor when converged); ``e_t`` = the raw error norm [rad] while the filter is in its
  start-up or recovery phase (its tilt is still being pulled in: the error is the best
  evidence of how wrong it is), else 0; ``t_clip`` [s] = how long the error has been clipped
  without a break (the accelerometer is distrusted: tilt is gyro-integrated for that long, its
  drift bounded by the bias uncertainty ``σ_b`` [rad/s]).
- yaw, heading referenced by the magnetometer: ``y0 + e_y² + (σ_b·t_mag)²``. ``y0`` =
  ``yaw_covariance_rad2``; ``e_y`` = the last heading error the magnetometer channel measured
  [rad] (the error it is still correcting: a 120° error reports ≈ 120°, falling as the heading
  comes back); ``t_mag`` [s] = time since the last magnetometer sample the filter used (a
  dropout or a rejected disturbance grows the variance with the gyro drift).
- yaw, not referenced (``use_mag`` false, or no usable sample yet):
  ``unreferenced_yaw_covariance_rad2``.

Each variance is capped at π² (an angle error is at most π), or at its configured floor (yaw:
also the unreferenced variance) if larger. Plain floats: it runs per message.
"""

from __future__ import annotations

import math

from cf_estimator.core.step import PHASE_RECOVERING, PHASE_STARTUP

_PI2 = math.pi * math.pi


class OrientationCovariance:
    """Per-message covariance model (see the module docstring); ``reset`` with the filter."""

    __slots__ = ("_clip_s", "_yaw_err", "tilt0", "yaw0", "yaw_unref", "bias_prior")

    def __init__(self, tilt0_rad2: float, yaw0_rad2: float, yaw_unreferenced_rad2: float,
                 bias_prior_sigma_rad_s: float) -> None:
        self.tilt0 = tilt0_rad2
        self.yaw0 = yaw0_rad2
        self.yaw_unref = yaw_unreferenced_rad2
        self.bias_prior = bias_prior_sigma_rad_s
        self.reset()

    def reset(self) -> None:
        """Forget the clip duration and the last heading error (a filter reset)."""
        self._clip_s = 0.0
        self._yaw_err = 0.0

    def update(self, dt_s: float, state: object, mag_used: bool, mag_age_s: float | None
               ) -> tuple[float, ...]:
        """Covariance after one filter step. ``state``: the filter's step state (phase,
        error_norm, clipped, bias_var, heading_initialized, yaw_error_rad); ``mag_used``: the
        step used a magnetometer sample; ``mag_age_s``: time since the last used one (None:
        never)."""
        s = state
        bv = s.bias_var  # type: ignore[attr-defined]
        return self.step(dt_s, bool(s.clipped),  # type: ignore[attr-defined]
                         math.sqrt(bv) if bv >= 0.0 else None, s.phase,  # type: ignore[attr-defined]
                         s.error_norm, bool(s.heading_initialized),  # type: ignore[attr-defined]
                         s.yaw_error_rad if mag_used else 0.0,  # type: ignore[attr-defined]
                         mag_used, mag_age_s)

    def step(self, dt_s: float, clipped: bool, bias_sigma_rad_s: float | None, phase: float,
             error_norm_rad: float, heading_initialized: bool, yaw_error_rad: float,
             mag_used: bool, mag_age_s: float | None) -> tuple[float, ...]:
        """:meth:`update` from the state's figures (the bulk pipeline has them per row):
        ``bias_sigma_rad_s`` = √bias_var (None: no estimate yet, the prior is used),
        ``yaw_error_rad`` read only when ``mag_used``."""
        self._clip_s = self._clip_s + dt_s if clipped else 0.0
        sigma_b = bias_sigma_rad_s if bias_sigma_rad_s is not None else self.bias_prior
        settling = phase in (PHASE_STARTUP, PHASE_RECOVERING)
        e_t = error_norm_rad if settling else 0.0
        drift = sigma_b * self._clip_s
        tilt = min(self.tilt0 + e_t * e_t + drift * drift, max(_PI2, self.tilt0))
        if heading_initialized:
            if mag_used:
                self._yaw_err = abs(yaw_error_rad)
            yd = sigma_b * (mag_age_s or 0.0)
            yaw = min(self.yaw0 + self._yaw_err**2 + yd * yd,
                      max(_PI2, self.yaw_unref, self.yaw0))
        else:
            yaw = self.yaw_unref
        return (tilt, 0.0, 0.0, 0.0, tilt, 0.0, 0.0, 0.0, yaw)
