"""One-axis reference form of the compensation scheme (Ryzhkov & Karpenko; thesis error path).

Block diagram, per sample (this is the form that reproduces the seeds' numbers)::

    gyro ω ──►(+)──► ∫ ──► γ̂ ─────────────┬──► output
               ▲(−)                        │
               │                     e = γ̂ − γ_acc     (error signal: sensor errors only)
               │                           ▼
               └── W1(s) ◄── 1/(T s+1) ◄── sat(±L)

    W1(s) = k1 + k2/s + k3/s²  (Ryzhkov & Karpenko: k3 = 0; Ryzhkov, drift: k3, second channel)

An optional second measured angle (the magnetometer, Ryzhkov, drift) enters through its own error
e_m = γ̂ − γ_mag and regulator W2(s) = r1 + r2/s, so that the error obeys
δ = s²/A·δ1 + (k1 s² + k2 s + k3)/A·δ2 + (r1 s + r2) s/A·δ3 with
A(s) = s³ + (k1+r1)s² + (k2+r2)s + k3.

Discretisation (variable dt, from the sample stamps), the same as the 3-D step: predict with
the gyro corrected by the integral states, γ⁻ = γ̂ + (ω − z)·dt; form the error from the
prediction; saturate; aperiodic unit by backward Euler f ← f + dt/(T+dt)·(sat(e) − f); integral
states by backward Euler (z ← z + k2·dt·f, used from the next sample on); correct
γ̂ = γ⁻ − g·f with g = k1·dt/(1 + k1·dt), the backward-Euler gain of the proportional path.
With k2 = k3 = 0, no saturation and T = 0 this is exactly Komplementär-Filter notes's
γ̂ₙ = α(γ̂ₙ₋₁ + dt·ω) + (1 − α)·γ_acc with α = 1/(1 + k1·dt); for small dt all paths converge to
the continuous transfer functions above.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


def proportional_step_gain(k: float, dt: float) -> float:
    """Backward-Euler gain of a proportional correction k [1/s] over dt [s]: k·dt/(1 + k·dt)."""
    return k * dt / (1.0 + k * dt)


def aperiodic_step_weight(time_constant_s: float, dt: float) -> float:
    """Backward-Euler weight of 1/(T·s + 1) over dt: dt/(T + dt) (1 when T = 0: unit off)."""
    return dt / (time_constant_s + dt) if time_constant_s > 0.0 else 1.0


@dataclass
class AxisParams:
    """Gains of the 1-axis loop (units: k1, r1 in 1/s; k2, r2 in 1/s²; k3 in 1/s³).

    ``saturation_limit_rad`` = None disables the saturation unit; ``aperiodic_time_constant_s``
    = 0 disables the aperiodic unit.
    """

    k1: float = 0.03
    k2: float = 0.001
    k3: float = 0.0
    r1: float = 0.0
    r2: float = 0.0
    saturation_limit_rad: float | None = None
    aperiodic_time_constant_s: float = 0.0


@dataclass
class AxisFilter:
    """1-axis compensation-scheme filter; all angles in rad, rates in rad/s, times in s.

    ``angle_rad`` is γ̂; ``initial_angle_rad`` is the integrator's initial condition (the
    seed's −γ0 enters here). The internal signals of the last step are kept for inspection.
    """

    params: AxisParams
    angle_rad: float = 0.0
    lag_state: float = 0.0
    integral_1: float = 0.0  # rate correction from the integral paths of W1 [rad/s]
    integral_2: float = 0.0  # state of the k3 path [rad/s²]
    mag_integral: float = 0.0  # rate correction from r2 [rad/s]
    error_rad: float = 0.0
    clipped: bool = False

    def update(
        self,
        gyro_rad_s: float,
        accel_angle_rad: float,
        dt_s: float,
        mag_angle_rad: float | None = None,
    ) -> float:
        """One sample: gyro rate [rad/s], accelerometer angle [rad], dt [s]; returns γ̂ [rad]."""
        p = self.params
        predicted = self.angle_rad + (gyro_rad_s - self.integral_1 - self.mag_integral) * dt_s
        error = predicted - accel_angle_rad
        self.error_rad = error
        clipped_error = error
        self.clipped = False
        if p.saturation_limit_rad is not None and abs(error) > p.saturation_limit_rad:
            clipped_error = math.copysign(p.saturation_limit_rad, error)
            self.clipped = True
        self.lag_state += aperiodic_step_weight(p.aperiodic_time_constant_s, dt_s) * (
            clipped_error - self.lag_state
        )
        f = self.lag_state
        # W1 = k1 + (k2 + k3/s)/s: integral_2' = k3·f, integral_1' = k2·f + integral_2 [rad/s]
        self.integral_2 += p.k3 * dt_s * f
        self.integral_1 += dt_s * (p.k2 * f + self.integral_2)
        correction = proportional_step_gain(p.k1, dt_s) * f
        if mag_angle_rad is not None and (p.r1 or p.r2):
            mag_error = predicted - mag_angle_rad
            self.mag_integral += p.r2 * dt_s * mag_error
            correction += proportional_step_gain(p.r1, dt_s) * mag_error
        self.angle_rad = predicted - correction
        return self.angle_rad

    def run(
        self,
        gyro_rad_s: list[float] | tuple[float, ...],
        accel_angle_rad: list[float] | tuple[float, ...],
        dt_s: float,
        mag_angle_rad: list[float] | tuple[float, ...] | None = None,
    ) -> list[float]:
        """Run a whole record at a fixed dt; returns γ̂ per sample [rad]."""
        out = []
        for i, (w, a) in enumerate(zip(gyro_rad_s, accel_angle_rad, strict=True)):
            m = None if mag_angle_rad is None else mag_angle_rad[i]
            out.append(self.update(w, a, dt_s, m))
        return out
