"""Velocity sensor model (GNSS or odometry) from a :class:`Truth`: rate, noise, latency, faults.

Per output sample j at stamp t_j = t_0 + j/rate (the measurement time, as a GNSS receiver stamps
its fix): ``v_j = v_world(t_j) + n_j`` (white, std ``noise_m_s`` per axis, world frame ENU),
delivered at ``arrival_j = t_j + latency_s`` (transport delay: the filter aligns on stamps, not
arrival). Faults: ``dropouts`` (start_s, end_s) deliver nothing; ``glitches`` (start_s, end_s,
(dx, dy, dz)) add a velocity step [m/s] while they last (a GNSS multipath jump).
The true velocity is the Truth's ``velocity_world_m_s`` or, when absent, its
``accel_world_m_s2`` integrated (trapezoid, starting at rest).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cf_estimator.scenarios.integration import FloatArray
from cf_estimator.scenarios.motion import Truth


@dataclass(frozen=True)
class VelocityModel:
    """A velocity sensor: ``rate_hz`` [Hz], ``noise_m_s`` [m/s] std per axis, ``latency_s`` [s],
    ``dropouts`` [(start_s, end_s)], ``glitches`` [(start_s, end_s, (dx, dy, dz) m/s)]."""

    rate_hz: float = 10.0
    noise_m_s: float = 0.1
    latency_s: float = 0.1
    dropouts: tuple[tuple[float, float], ...] = ()
    glitches: tuple[tuple[float, float, tuple[float, float, float]], ...] = ()

    def __post_init__(self) -> None:
        if not (np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise ValueError(f"velocity rate_hz must be > 0, got {self.rate_hz!r}")
        if not (np.isfinite(self.noise_m_s) and self.noise_m_s >= 0):
            raise ValueError(f"velocity noise_m_s must be >= 0, got {self.noise_m_s!r}")
        if not (np.isfinite(self.latency_s) and self.latency_s >= 0):
            raise ValueError(f"velocity latency_s must be >= 0, got {self.latency_s!r}")


@dataclass(frozen=True)
class VelocityData:
    """Simulated velocity samples: stamps (M,) [s], velocity (M, 3) [m/s] world frame (ENU),
    arrival times (M,) [s] (stamp + latency)."""

    t_s: FloatArray
    v_world_m_s: FloatArray
    arrival_s: FloatArray


def true_velocity(truth: Truth) -> FloatArray:
    """(N, 3) world-frame velocity [m/s] of a Truth (given, or its acceleration integrated)."""
    if truth.velocity_world_m_s is not None:
        return np.asarray(truth.velocity_world_m_s, dtype=float)
    a = np.asarray(truth.accel_world_m_s2, dtype=float)
    dt = np.diff(truth.t_s)[:, None]
    return np.concatenate([np.zeros((1, 3)), np.cumsum(0.5 * (a[1:] + a[:-1]) * dt, axis=0)])


def measure_velocity(truth: Truth, model: VelocityModel, rng: np.random.Generator
                     ) -> VelocityData:
    """Velocity samples of ``truth`` as ``model`` measures them (see the module docstring)."""
    t = truth.t_s
    stamps = np.arange(t[0], t[-1], 1.0 / model.rate_hz)
    v_true = true_velocity(truth)
    v = np.stack([np.interp(stamps, t, v_true[:, i]) for i in range(3)], axis=1)
    v = v + rng.normal(0.0, model.noise_m_s, v.shape) if model.noise_m_s > 0 else v
    for start, end, step in model.glitches:
        inside = (stamps >= start) & (stamps < end)
        v[inside] += np.asarray(step, dtype=float)
    keep = np.ones(stamps.shape[0], dtype=bool)
    for start, end in model.dropouts:
        keep &= ~((stamps >= start) & (stamps < end))
    stamps, v = stamps[keep], v[keep]
    return VelocityData(stamps, v, stamps + model.latency_s)


def with_faults(model: VelocityModel, dropouts: Sequence[tuple[float, float]] = (),
                glitches: Sequence[tuple[float, float, tuple[float, float, float]]] = ()
                ) -> VelocityModel:
    """``model`` with more dropouts and glitches."""
    return VelocityModel(model.rate_hz, model.noise_m_s, model.latency_s,
                         model.dropouts + tuple(dropouts), model.glitches + tuple(glitches))
