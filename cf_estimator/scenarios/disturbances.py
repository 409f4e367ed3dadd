"""The thesis's accelerometer disturbances (Habliuk 2023, 2.6 and 3.x).

* :func:`impacts` — repeated shocks: 60 impacts, 80 per minute, 15 g, 10–15 ms.
* :func:`vibration` — sinusoidal vibration of 6 g amplitude, 20–120 Hz.
* :func:`acceleration_manoeuvre` — "25 m/s reached in 5 s": 5 m/s² forward for 5 s.

Impacts and vibration are vibration of the base seen by the accelerometer only: the functions
return an (N, 3) specific-force disturbance [m/s²] in the sensor (= body) frame to add to the
accelerometer (:meth:`~cf_estimator.scenarios.sensors.ImuData.with_accel_disturbance`); the gyro
sees nothing. The acceleration manoeuvre is a real motion: it is added to the truth's world
acceleration and velocity, and the accelerometer then sees it through the sensor model.

Valid sample rates: impacts need at least 5 samples across the shortest pulse (≥ 500 Hz for
10 ms; 1 kHz recommended); vibration needs at least 4 samples per cycle of the highest frequency
(≥ 480 Hz for 120 Hz, i.e. no aliasing and a recognisable waveform; 1 kHz recommended, where the
sampled peaks reach ≥ 93 % of the amplitude in every cycle). Lower rates raise ``ValueError``:
200 Hz would alias 120 Hz vibration to 80 Hz.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from cf_estimator.core.quaternion import to_matrix as quat_to_matrix
from cf_estimator.scenarios.integration import FloatArray
from cf_estimator.scenarios.motion import GRAVITY_M_S2, Truth

G = GRAVITY_M_S2

IMPACT_SHAPES = ("rectangular", "half_sine")
VIBRATION_MODES = ("sweep", "stepped")


def _rate_hz(t: FloatArray) -> float:
    if t.shape[0] < 2:
        raise ValueError("need at least 2 samples")
    return float(1.0 / np.median(np.diff(t)))


def _unit(direction: ArrayLike) -> FloatArray:
    d = np.asarray(direction, dtype=float).reshape(3)
    norm = np.linalg.norm(d)
    if not norm > 0:
        raise ValueError("direction must be a non-zero 3-vector")
    return d / norm


def impact_times(start_s: float, count: int = 60, per_minute: float = 80.0) -> FloatArray:
    """Onset times [s] of the impacts: ``start_s + i·60/per_minute``, i = 0 … count−1."""
    return start_s + np.arange(count) * (60.0 / per_minute)


def impacts(
    t_s: ArrayLike,
    start_s: float,
    *,
    count: int = 60,
    per_minute: float = 80.0,
    amplitude_m_s2: float = 15.0 * G,
    duration_s: float | tuple[float, float] = (0.010, 0.015),
    shape: str = "rectangular",
    direction_body: ArrayLike = (1.0, 0.0, 0.0),
    rng: np.random.Generator | None = None,
) -> FloatArray:
    """Repeated unipolar impacts as a sensor-frame specific-force disturbance (N, 3) [m/s²].

    Impact i starts at ``start_s + i·60/per_minute`` [s] (80/min → every 0.75 s; 60 impacts span
    44.25 s + one pulse) and lasts ``d_i``: a fixed ``duration_s`` [s], or for a (lo, hi) range
    drawn uniformly per impact from ``rng`` (with ``rng=None``: spread evenly over the range,
    deterministic). ``shape``: ``"rectangular"`` (default; the thesis builds them in Simulink from
    pulse-generator blocks: value ``amplitude_m_s2`` for ``t_i ≤ t < t_i + d_i``) or
    ``"half_sine"`` (``A·sin(π(t − t_i)/d_i)``, the classical shock-test pulse). Unipolar, along
    the unit vector ``direction_body`` (body = sensor frame; default +x = forward: horizontal in
    level flight, so it tilts the measured gravity direction, whereas a vertical disturbance would
    only change |f|). Default amplitude 15 g.
    """
    t = np.asarray(t_s, dtype=float)
    if shape not in IMPACT_SHAPES:
        raise ValueError(f"unknown impact shape {shape!r}; valid: {', '.join(IMPACT_SHAPES)}")
    if count < 0 or per_minute <= 0:
        raise ValueError("count must be >= 0 and per_minute > 0")
    if isinstance(duration_s, tuple | list):
        lo, hi = (float(x) for x in duration_s)
        if not 0 < lo <= hi:
            raise ValueError(f"invalid impact duration range {duration_s}")
        if rng is None:
            durations = np.linspace(lo, hi, count) if count > 1 else np.full(count, lo)
        else:
            durations = rng.uniform(lo, hi, count)
    else:
        lo = float(duration_s)
        if not lo > 0:
            raise ValueError("impact duration must be > 0")
        durations = np.full(count, lo)
    rate = _rate_hz(t)
    if lo * rate < 5:
        raise ValueError(
            f"impacts of {lo * 1e3:.1f} ms need a sample rate >= {5 / lo:.0f} Hz "
            f"(5 samples per pulse); got {rate:.0f} Hz"
        )
    mag = np.zeros(t.shape[0])
    onsets = impact_times(start_s, count, per_minute)
    for t_i, d_i in zip(onsets, durations, strict=True):
        i0, i1 = np.searchsorted(t, (t_i, t_i + d_i), side="left")
        if shape == "rectangular":
            mag[i0:i1] = amplitude_m_s2
        else:
            mag[i0:i1] = amplitude_m_s2 * np.sin(np.pi * (t[i0:i1] - t_i) / d_i)
    return mag[:, None] * _unit(direction_body)[None, :]


def vibration(
    t_s: ArrayLike,
    start_s: float,
    duration_s: float,
    *,
    amplitude_m_s2: float = 6.0 * G,
    f_lo_hz: float = 20.0,
    f_hi_hz: float = 120.0,
    direction_body: ArrayLike = (1.0, 0.0, 0.0),
    mode: str = "sweep",
    steps: int = 6,
    taper_s: float = 0.05,
) -> FloatArray:
    """Sinusoidal vibration as a sensor-frame specific-force disturbance (N, 3) [m/s²].

    One sinusoid of amplitude ``amplitude_m_s2`` (default 6 g) at any instant, along
    ``direction_body`` (default +x), on ``[start_s, start_s + duration_s)``:

    * ``mode="sweep"`` (default): linear sweep, instantaneous frequency
      ``f(τ) = f_lo + (f_hi − f_lo)·τ/duration`` (20 → 120 Hz), phase 0 at the start;
    * ``mode="stepped"``: ``steps`` equal dwells at frequencies evenly spaced from f_lo to f_hi
      (20, 40, …, 120 Hz by default), phase-continuous.

    The envelope rises and falls with raised-cosine tapers of ``taper_s`` [s] at both ends (no
    step at the edges); in between the amplitude is exactly ``amplitude_m_s2``. Requires a sample
    rate ≥ 4·f_hi (see the module docstring).
    """
    t = np.asarray(t_s, dtype=float)
    if mode not in VIBRATION_MODES:
        raise ValueError(f"unknown vibration mode {mode!r}; valid: {', '.join(VIBRATION_MODES)}")
    if not (0 < f_lo_hz <= f_hi_hz) or duration_s <= 0:
        raise ValueError("need 0 < f_lo_hz <= f_hi_hz and duration_s > 0")
    rate = _rate_hz(t)
    if rate < 4 * f_hi_hz:
        raise ValueError(
            f"vibration up to {f_hi_hz:g} Hz needs a sample rate >= {4 * f_hi_hz:g} Hz "
            f"(1000 Hz recommended); got {rate:.0f} Hz, which would misrepresent or alias it"
        )
    i0, i1 = np.searchsorted(t, (start_s, start_s + duration_s), side="left")
    tau = t[i0:i1] - start_s
    if mode == "sweep":
        phase = 2 * np.pi * (f_lo_hz * tau + 0.5 * (f_hi_hz - f_lo_hz) * tau**2 / duration_s)
    else:
        freqs = np.linspace(f_lo_hz, f_hi_hz, steps) if steps > 1 else np.array([f_lo_hz])
        dwell = duration_s / len(freqs)
        idx = np.minimum((tau // dwell).astype(int), len(freqs) - 1)
        phase_at_step = np.concatenate(([0.0], np.cumsum(2 * np.pi * freqs[:-1] * dwell)))
        phase = phase_at_step[idx] + 2 * np.pi * freqs[idx] * (tau - idx * dwell)
    env = np.ones_like(tau)
    if taper_s > 0:
        ramp = min(taper_s, 0.5 * duration_s)
        env = np.minimum(env, 0.5 - 0.5 * np.cos(np.pi * np.clip(tau / ramp, 0, 1)))
        env = np.minimum(env, 0.5 - 0.5 * np.cos(np.pi * np.clip((duration_s - tau) / ramp, 0, 1)))
    mag = np.zeros(t.shape[0])
    mag[i0:i1] = amplitude_m_s2 * env * np.sin(phase)
    return mag[:, None] * _unit(direction_body)[None, :]


def _edge(x: FloatArray, ramp_s: float) -> tuple[FloatArray, FloatArray]:
    """Step at x = 0 smoothed by a raised cosine over [−ramp/2, ramp/2], and its integral.

    The smoothing is symmetric about 0, so the integral equals max(x, 0) once past the ramp.
    """
    if ramp_s <= 0:
        return (x >= 0).astype(float), np.maximum(x, 0.0)
    u = np.clip((x + 0.5 * ramp_s) / ramp_s, 0.0, 1.0)
    val = 0.5 - 0.5 * np.cos(np.pi * u)
    integ = np.where(
        x >= 0.5 * ramp_s, x, 0.5 * ramp_s * (u - np.sin(np.pi * u) / np.pi)
    )
    return val, integ


def acceleration_profile(
    t_s: ArrayLike, start_s: float, duration_s: float = 5.0, accel_m_s2: float = 5.0,
    ramp_s: float = 0.0,
) -> tuple[FloatArray, FloatArray]:
    """Forward acceleration a(t) [m/s²] of the manoeuvre and the speed it adds Δv(t) [m/s].

    ``ramp_s = 0``: a rectangular pulse ``accel_m_s2`` on ``[start_s, start_s + duration_s)``
    (the thesis's pulse generator). ``ramp_s > 0``: raised-cosine edges centred on the nominal
    edges, so the area — the final speed change ``accel_m_s2·duration_s`` — is unchanged.
    """
    t = np.asarray(t_s, dtype=float)
    r0, i0 = _edge(t - start_s, ramp_s)
    r1, i1 = _edge(t - (start_s + duration_s), ramp_s)
    return accel_m_s2 * (r0 - r1), accel_m_s2 * (i0 - i1)


def acceleration_manoeuvre(
    truth: Truth,
    start_s: float,
    *,
    duration_s: float = 5.0,
    accel_m_s2: float = 5.0,
    ramp_s: float = 0.0,
    heading_rad: float | None = None,
) -> Truth:
    """Return ``truth`` with a forward horizontal acceleration added (thesis: 25 m/s in 5 s).

    Adds ``a(t)·(cos h, sin h, 0)`` to ``accel_world_m_s2`` and its integral to
    ``velocity_world_m_s`` (if present), where ``h`` is ``heading_rad`` (ENU, from east,
    counter-clockwise) or, by default, the body's heading at ``start_s`` (the horizontal projection
    of body x), kept fixed over the manoeuvre so the velocity change is exactly
    ``accel_m_s2·duration_s`` along one direction. The orientation and body rates are unchanged
    (the thesis treats the manoeuvre as an accelerometer disturbance of a level vehicle). The
    vehicle keeps the gained velocity afterwards.
    """
    t = truth.t_s
    if not (t[0] <= start_s and start_s + duration_s <= t[-1]):
        raise ValueError(
            f"manoeuvre [{start_s}, {start_s + duration_s}] s is outside the trajectory "
            f"[{t[0]}, {t[-1]}] s"
        )
    if heading_rad is None:
        k = min(int(np.searchsorted(t, start_s)), t.shape[0] - 1)
        fwd = quat_to_matrix(truth.q_world_from_body[k])[:, 0]
        if np.hypot(fwd[0], fwd[1]) < 1e-6:
            raise ValueError("body x axis is vertical at the manoeuvre start: give heading_rad")
        heading_rad = float(np.arctan2(fwd[1], fwd[0]))
    direction = np.array([np.cos(heading_rad), np.sin(heading_rad), 0.0])
    a, dv = acceleration_profile(t, start_s, duration_s, accel_m_s2, ramp_s)
    vel = truth.velocity_world_m_s
    return dataclasses.replace(
        truth,
        accel_world_m_s2=truth.accel_world_m_s2 + a[:, None] * direction,
        velocity_world_m_s=None if vel is None else vel + dv[:, None] * direction,
    )


def windows_overlap(windows: Sequence[tuple[float, float, str]]) -> bool:
    """True if any two (start_s, end_s, label) windows overlap."""
    spans = sorted((w[0], w[1]) for w in windows)
    return any(b0 < a1 for (_, a1), (b0, _) in zip(spans, spans[1:], strict=False))


#: Rotor speed at hover [rev/s] of the simulated multirotor (≈ 4500 rpm; blade pass 2× that).
ROTOR_HOVER_HZ = 75.0


def rotor_vibration(
    t_s: ArrayLike,
    rotor_speed: ArrayLike,
    rng: np.random.Generator,
    *,
    accel_rms_m_s2: float = 3.0,
    gyro_rms_rad_s: float = 0.03,
    hover_hz: float = ROTOR_HOVER_HZ,
    n_rotors: int = 6,
    speed_spread: float = 0.04,
) -> tuple[FloatArray, FloatArray]:
    """Rotor vibration seen by the accelerometer and the gyro: sensor-frame disturbances
    (accel (N, 3) [m/s²], gyro (N, 3) [rad/s]), both zero-mean.

    Each of ``n_rotors`` rotors spins at ``hover_hz``·``rotor_speed``(t)·(1 + δᵢ), δᵢ drawn
    uniformly in ±``speed_spread`` (the vehicle's differential thrust), and shakes the sensor at
    its rotation frequency (imbalance) and twice it (blade pass of a two-blade rotor): 2·n_rotors
    sinusoids, phase-continuous, each along a fixed random direction (the frame's response),
    amplitude ∝ ``rotor_speed``² (imbalance force ∝ speed²). Scaled so that at
    ``rotor_speed`` = 1 the RMS of the vibration vector's norm is ``accel_rms_m_s2`` (resp.
    ``gyro_rms_rad_s``). With rotor speeds 0.7–1.1 (idle on the ground to climbing) and
    75 Hz at hover, the content lies in 50–180 Hz. Sampled as it is, without an anti-alias
    filter: at 200 Hz the components above 100 Hz alias to 20–100 Hz, as on an IMU read
    at a low rate.
    """
    t = np.asarray(t_s, dtype=float)
    r = np.asarray(rotor_speed, dtype=float)
    if r.shape != t.shape:
        raise ValueError(f"rotor_speed must have shape {t.shape}, got {r.shape}")
    n = t.shape[0]
    delta = rng.uniform(-speed_spread, speed_spread, n_rotors)
    harmonics = np.array([1.0, 2.0])
    # rotor phase [rev] = ∫ hover_hz·r dt (trapezoid; r is smooth)
    rev = np.concatenate(([0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(t)))) * hover_hz
    out = []
    for rms in (accel_rms_m_s2, gyro_rms_rad_s):
        weights = rng.uniform(0.5, 1.0, (n_rotors, harmonics.size))
        amps = rms * weights / np.sqrt(0.5 * np.sum(weights**2))
        dirs = rng.normal(size=(n_rotors, harmonics.size, 3))
        dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
        phase0 = rng.uniform(0.0, 2 * np.pi, (n_rotors, harmonics.size))
        vib = np.zeros((n, 3))
        for i in range(n_rotors):
            for j, h in enumerate(harmonics):
                s = np.sin(2 * np.pi * h * (1 + delta[i]) * rev + phase0[i, j])
                vib += (amps[i, j] * r**2 * s)[:, None] * dirs[i, j][None, :]
        out.append(vib)
    return out[0], out[1]
