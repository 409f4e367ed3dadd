"""Design formulas of the compensation scheme (Ryzhkov & Karpenko).

Pure functions, no ROS. Units: gains k1 [1/s], k2 [1/s²]; angles [rad]; rates [rad/s];
times [s]; frequencies [rad/s] unless the name says ``_hz``; accelerations as ``a_over_g``
(dimensionless; the seeds' small-angle convention: a/g of 0.2 is an accelerometer angle error of
0.2 rad = 11.46°).

The 1-axis loop with the PI regulator W(s) = k1 + k2/s has the error (Ryzhkov & Karpenko, eq. (5))::

    δ = s/D·δ1 + (k1 s + k2)/D·δ2 − s²/D·γ0,      D(s) = s² + k1 s + k2

with δ1 the gyro error, δ2 the accelerometer angle error and γ0 the initial angle. The seed writes
D = s² + ξ n s + n² with n = √k2 and ξ = k1/n (so the seed's ξ is *twice* the classical damping
ratio ζ = k1/(2n); the seed's "ξ = 1" is ζ = 0.5, an oscillating loop, as the seed notes).

With the thesis's aperiodic unit 1/(T s + 1) on the error path (before W) the loop becomes::

    δ = s(T s + 1)/P·δ1 + (k1 s + k2)/P·δ2,      P(s) = T s³ + s² + k1 s + k2

which is stable iff T < k1/k2 (Routh). Functions that accept ``aperiodic_time_constant_s`` use
P; with T = 0 they use D. The saturation unit is nonlinear: its effect is given by the guidance
formulas below and by simulation of :class:`cf_estimator.analysis.axis.AxisFilter` in the thesis
check (:mod:`cf_estimator.analysis.thesis`).

"Exact" below means computed from the continuous-time transfer function without the seed's
approximations: closed-form where available (drift peak, vibration), otherwise by propagating
the state-space model with the exact matrix exponential on a fine grid and refining the peak
locally (relative accuracy ≈ 1e-9, far below any quantity reported).

Where the seed's printed numbers are off (see docs and ``test/test_design.py``): n = √0.001 =
0.0316 1/s (printed 0.0312); the drift peak for k1 = 0.03, k2 = 0.001, ω = 5e-4 rad/s is
0.507° (printed 0.85°; its rough ω/n gives 0.906°); a 0.2 rad, 5 s accelerometer pulse gives
1.73° (printed 1.9°, from ω_e/n with n rounded to 0.03).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Standard gravity [m/s²].
STANDARD_GRAVITY_M_S2 = 9.80665
#: Arc minutes per radian.
ARCMIN_PER_RAD = 180.0 * 60.0 / math.pi
#: 1 °/h in rad/s.
RAD_S_PER_DEG_H = math.pi / 180.0 / 3600.0


_REFINE_STEPS = 400
_GRID_STEPS = 20000


def rad_to_deg(angle_rad: float) -> float:
    """Radians to degrees."""
    return math.degrees(angle_rad)


def rad_to_arcmin(angle_rad: float) -> float:
    """Radians to arc minutes."""
    return angle_rad * ARCMIN_PER_RAD


def _check_gains(k1: float, k2: float) -> None:
    if not (math.isfinite(k1) and math.isfinite(k2)):
        raise ValueError(f"gains must be finite numbers (k1 = {k1}, k2 = {k2})")
    if k1 < 0.0 or k2 < 0.0:
        raise ValueError(f"gains must be >= 0 (k1 = {k1} 1/s, k2 = {k2} 1/s^2)")


def check_decaying(k1: float, k2: float, aperiodic_time_constant_s: float = 0.0) -> None:
    _check_gains(k1, k2)
    if k1 <= 0.0:
        raise ValueError("k1 must be > 0: with k1 = 0 the loop is undamped and never settles")
    t = aperiodic_time_constant_s
    if not math.isfinite(t) or t < 0.0:
        raise ValueError(f"aperiodic time constant must be >= 0 s (got {t})")
    if t > 0.0 and k2 > 0.0 and t >= k1 / k2:
        raise ValueError(
            f"aperiodic time constant T = {t} s makes the loop unstable: need T < k1/k2 = "
            f"{k1 / k2:.6g} s"
        )


# --------------------------------------------------------------------------- loop parameters


def natural_frequency(k2: float) -> float:
    """Natural frequency n = √k2 [rad/s] of D(s) = s² + k1 s + k2 (k2 in 1/s²)."""
    if not math.isfinite(k2) or k2 < 0.0:
        raise ValueError(f"k2 must be a finite number >= 0 (got {k2})")
    return math.sqrt(k2)


def _require_n(k2: float) -> float:
    n = natural_frequency(k2)
    if n == 0.0:
        raise ValueError(
            "k2 = 0: the natural frequency n = sqrt(k2) is 0, so xi = k1/n, the period 2*pi/n and "
            "the seed's rough omega/n are undefined (k2 = 0 is the first-order filter)"
        )
    return n


def seed_damping(k1: float, k2: float) -> float:
    """The seed's relative damping ξ = k1/n (dimensionless; ξ = 2ζ). Raises if k2 = 0."""
    _check_gains(k1, k2)
    return k1 / _require_n(k2)


def classical_damping(k1: float, k2: float) -> float:
    """Classical damping ratio ζ = k1/(2n) of s² + 2ζ n s + n² (ζ < 1: oscillating)."""
    return 0.5 * seed_damping(k1, k2)


def natural_period_s(k2: float) -> float:
    """Period 2π/n [s] of the *undamped* natural frequency (the seed's 198.7 s for k2 = 0.001)."""
    return 2.0 * math.pi / _require_n(k2)


def natural_frequency_from_period(period_s: float) -> float:
    """n = 2π/T [rad/s] from a period T [s] (inverse of :func:`natural_period_s`)."""
    if not math.isfinite(period_s) or period_s <= 0.0:
        raise ValueError(f"period must be > 0 s (got {period_s})")
    return 2.0 * math.pi / period_s


def gains_from_natural_frequency(n: float, xi: float = 1.0) -> tuple[float, float]:
    """Gains (k1 [1/s], k2 [1/s²]) = (ξ n, n²) from n [rad/s] and the *seed's* ξ = k1/n.

    ``xi`` = 1 is the seed's choice (classical ζ = 0.5); ``xi`` = 2 is critical damping.
    """
    if not math.isfinite(n) or n <= 0.0:
        raise ValueError(f"natural frequency n must be > 0 rad/s (got {n})")
    if not math.isfinite(xi) or xi <= 0.0:
        raise ValueError(f"damping xi must be > 0 (got {xi})")
    return xi * n, n * n


def gains_from_period(period_s: float, xi: float = 1.0) -> tuple[float, float]:
    """Gains (k1, k2) from the natural period 2π/n [s] and the seed's ξ."""
    return gains_from_natural_frequency(natural_frequency_from_period(period_s), xi)


# ----------------------------------------------------------------- closed-form responses, T = 0


def _decomposition(k1: float, k2: float) -> tuple[float, float, int]:
    """(a, β, kind) with D = (s + a)² ∓ β²: kind −1 underdamped, 0 critical, +1 overdamped."""
    a = 0.5 * k1
    disc = a * a - k2
    if disc < 0.0:
        return a, math.sqrt(-disc), -1
    if disc == 0.0:
        return a, 0.0, 0
    return a, math.sqrt(disc), 1


def impulse_response_d(k1: float, k2: float, t_s: np.ndarray | float) -> np.ndarray:
    """h(t) [s] = impulse response of 1/D(s) = 1/(s² + k1 s + k2) at times t [s] ≥ 0.

    This is also the response of s/D (the gyro-error path) to a unit rate step 1/s, so a drift
    step ω [rad/s] gives the error ω·h(t) [rad].
    """
    _check_gains(k1, k2)
    t = np.asarray(t_s, dtype=float)
    a, b, kind = _decomposition(k1, k2)
    if kind < 0:
        return np.exp(-a * t) * np.sin(b * t) / b
    if kind == 0:
        return t * np.exp(-a * t)
    return np.exp(-(a - b) * t) * (-np.expm1(-2.0 * b * t)) / (2.0 * b)


def initial_error_response(k1: float, k2: float, t_s: np.ndarray | float) -> np.ndarray:
    """h'(t) (dimensionless): the error per unit initial angle error, s/D impulse response.

    Starts at 1 and decays to 0 (Ryzhkov & Karpenko, eq. (5), third term, up to sign). Also
    1 − the step response of the accelerometer path (k1 s + k2)/D.
    """
    _check_gains(k1, k2)
    t = np.asarray(t_s, dtype=float)
    a, b, kind = _decomposition(k1, k2)
    if kind < 0:
        return np.exp(-a * t) * (np.cos(b * t) - a * np.sin(b * t) / b)
    if kind == 0:
        return (1.0 - a * t) * np.exp(-a * t)
    e2 = np.exp(-2.0 * b * t)
    sinh_term = -np.expm1(-2.0 * b * t) / (2.0 * b)
    return np.exp(-(a - b) * t) * (0.5 * (1.0 + e2) - a * sinh_term)


def impulse_response_peak(k1: float, k2: float) -> tuple[float, float]:
    """(max_t |h(t)| [s], time of the maximum [s]) for h = impulse response of 1/D.

    Closed form. For k2 = 0, h rises to 1/k1 without reaching it: returns (1/k1, inf). For the
    seed's k1 = 0.03, k2 = 0.001: 17.70 s at t = 38.7 s.
    """
    _check_gains(k1, k2)
    a, b, kind = _decomposition(k1, k2)
    if k2 == 0.0:
        if k1 == 0.0:
            return math.inf, math.inf
        return 1.0 / k1, math.inf
    n = math.sqrt(k2)
    if kind < 0:
        t_peak = math.atan2(b, a) / b
        return math.exp(-a * t_peak) / n, t_peak
    if kind == 0:
        return 1.0 / (a * math.e), 1.0 / a
    r1, r2 = a - b, a + b
    t_peak = math.log(r2 / r1) / (r2 - r1)
    return float(impulse_response_d(k1, k2, t_peak)), t_peak


def settling_time_s(k1: float, k2: float, tolerance: float = 0.02) -> float:
    """Exact 2 % settling time [s] of the initial-error response h'(t) (see above).

    The last time |h'(t)| ≥ ``tolerance`` (h'(0) = 1), found on a grid and refined by bisection:
    the time after which the error from an initial angle stays within ±2 % of it. Compare
    :func:`envelope_settling_time_s`.
    """
    check_decaying(k1, k2)
    if not 0.0 < tolerance < 1.0:
        raise ValueError(f"tolerance must be in (0, 1) (got {tolerance})")
    horizon = 3.0 * envelope_settling_time_s(k1, k2, tolerance)
    for _ in range(60):
        t = np.linspace(0.0, horizon, _GRID_STEPS + 1)
        outside = np.nonzero(np.abs(initial_error_response(k1, k2, t)) >= tolerance)[0]
        last = int(outside[-1])
        if last < _GRID_STEPS:
            break
        horizon *= 2.0
    lo, hi = float(t[last]), float(t[last + 1])
    for _ in range(80):  # |h'| ≥ tol at lo, < tol at hi
        mid = 0.5 * (lo + hi)
        if abs(float(initial_error_response(k1, k2, mid))) >= tolerance:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def envelope_settling_time_s(k1: float, k2: float, tolerance: float = 0.02) -> float:
    """Envelope settling time ln(1/tol)/σ [s], σ the slowest decay rate of D.

    For ζ < 1, σ = ζ n = k1/2, so this is the textbook ≈ 4/(ζ n) = 8/k1 (ln 50 = 3.91); it
    ignores the envelope's amplitude and the oscillation's phase, hence it differs from the
    exact :func:`settling_time_s`.
    """
    check_decaying(k1, k2)
    a, b, kind = _decomposition(k1, k2)
    sigma = a - b if kind > 0 else a
    return math.log(1.0 / tolerance) / sigma


# ----------------------------------------------------------------- state-space engine (any T)


def _polynomials(k1: float, k2: float, t_ap: float) -> tuple[list[float], list[float], list[float]]:
    """(gyro-path numerator, accelerometer-path numerator, denominator), highest power first.

    With the aperiodic unit: s(Ts+1)/P and (k1 s + k2)/P, P = T s³ + s² + k1 s + k2.
    """
    if t_ap > 0.0:
        return [t_ap, 1.0, 0.0], [k1, k2], [t_ap, 1.0, k1, k2]
    return [1.0, 0.0], [k1, k2], [1.0, k1, k2]


@dataclass(frozen=True)
class _StateSpace:
    """x' = A x + B u, y = C x + D u, with the input held constant (augmented as a state)."""

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: float
    slowest_rate: float  # smallest −Re(pole) [1/s]
    fastest_oscillation: float  # largest |Im(pole)| [rad/s]

    def step_matrix(self, dt: float) -> np.ndarray:
        """Exact transition of z = [x; u] over dt for a constant input: expm([[A, B], [0, 0]]dt)."""
        m = self.a.shape[0]
        big = np.zeros((m + 1, m + 1))
        big[:m, :m] = self.a * dt
        big[:m, m] = self.b * dt
        from scipy.linalg import expm  # local: the CLI builds every parser at start-up

        return expm(big)

    def output(self, z: np.ndarray) -> np.ndarray:
        """y = C x + D u for states z = [x; u] (last axis)."""
        return z[..., :-1] @ self.c + self.d * z[..., -1]


def _state_space(num: list[float], den: list[float]) -> _StateSpace:
    """Controllable canonical form of num/den (degree of num ≤ degree of den)."""
    den_a = np.asarray(den, dtype=float)
    num_a = np.asarray(num, dtype=float) / den_a[0]
    den_a = den_a / den_a[0]
    m = len(den_a) - 1
    num_a = np.concatenate([np.zeros(m + 1 - len(num_a)), num_a])
    d = float(num_a[0])
    num_a = num_a - d * den_a  # strictly proper remainder
    a = np.zeros((m, m))
    a[0, :] = -den_a[1:]
    a[1:, :-1] = np.eye(m - 1)
    b = np.zeros(m)
    b[0] = 1.0
    c = num_a[1:].copy()
    poles = np.roots(den_a)
    rates = -poles.real
    if np.any(rates <= 0.0):
        raise ValueError("the loop is not asymptotically stable")
    return _StateSpace(a, b, c, d, float(rates.min()), float(np.abs(poles.imag).max()))


def _horizon(ss: _StateSpace) -> float:
    """Time after which a free response has decayed by e^-25, but at least 2 periods."""
    h = 25.0 / ss.slowest_rate
    if ss.fastest_oscillation > 0.0:
        h = max(h, 4.0 * math.pi / ss.fastest_oscillation)
    return h


def _propagate(ss: _StateSpace, z0: np.ndarray, dt: float, steps: int) -> np.ndarray:
    """States z_k = Φ^k z0, k = 0..steps (Φ the exact transition over dt), in blocks."""
    phi = ss.step_matrix(dt)
    zs = np.empty((steps + 1, z0.size))
    zs[0] = z0
    block = min(steps + 1, 1024)
    for i in range(1, block):
        zs[i] = phi @ zs[i - 1]
    phi_block = np.linalg.matrix_power(phi, block)
    power = phi_block.copy()
    start = block
    while start <= steps:
        stop = min(start + block, steps + 1)
        zs[start:stop] = zs[: stop - start] @ power.T
        power = phi_block @ power
        start = stop
    return zs


@dataclass(frozen=True)
class Peak:
    """A peak of |response|: ``value`` (signed, in the response's unit) at ``time_s`` [s]."""

    value: float
    time_s: float

    @property
    def magnitude(self) -> float:
        """|value|."""
        return abs(self.value)


def _scan(ss: _StateSpace, z0: np.ndarray, t0: float, duration: float) -> tuple[Peak, np.ndarray]:
    """Propagate z = [x; u] from z0 over ``duration``; return the peak of |y| (grid of ≥ 40
    points per fastest oscillation period, then refined 400× around the best point) and the
    final state."""
    steps = _GRID_STEPS
    if ss.fastest_oscillation > 0.0:
        per_period = duration * ss.fastest_oscillation / (2.0 * math.pi)
        steps = max(steps, min(int(40 * per_period), 400_000))
    dt = duration / steps
    zs = _propagate(ss, z0, dt, steps)
    y = ss.output(zs)
    i = int(np.argmax(np.abs(y)))
    best = Peak(float(y[i]), t0 + i * dt)
    lo, hi = max(i - 1, 0), min(i + 1, steps)
    fine = _propagate(ss, zs[lo], (hi - lo) * dt / _REFINE_STEPS, _REFINE_STEPS)
    yf = ss.output(fine)
    k = int(np.argmax(np.abs(yf)))
    if abs(yf[k]) > best.magnitude:
        best = Peak(float(yf[k]), t0 + lo * dt + k * (hi - lo) * dt / _REFINE_STEPS)
    return best, zs[-1]


def _pulse_peak(num: list[float], den: list[float], height: float, duration_s: float) -> Peak:
    """Exact peak of num/den driven by a rectangular pulse of ``height`` for ``duration_s``."""
    ss = _state_space(num, den)
    z0 = np.zeros(ss.a.shape[0] + 1)
    z0[-1] = height
    during, z_end = _scan(ss, z0, 0.0, duration_s)
    z_end = z_end.copy()
    z_end[-1] = 0.0
    after, _ = _scan(ss, z_end, duration_s, _horizon(ss))
    return during if during.magnitude >= after.magnitude else after


def _impulse_peak(num: list[float], den: list[float]) -> Peak:
    """Exact peak of the impulse response of a strictly proper num/den (free response from B)."""
    ss = _state_space(num, den)
    z0 = np.append(ss.b, 0.0)
    peak, _ = _scan(ss, z0, 0.0, _horizon(ss))
    return peak


# ----------------------------------------------------------------------------- peak errors


def drift_peak(
    k1: float, k2: float, drift_rad_s: float, aperiodic_time_constant_s: float = 0.0
) -> Peak:
    """Peak error [rad] and its time [s] after a gyro drift step ω [rad/s] (fixed base).

    Error = s/D·(ω/s) = ω·h(t): the peak is ω·max|h| (closed form for T = 0; with the
    aperiodic unit, the impulse response of (Ts+1)/P). With k2 = 0 there is no integral: the
    error rises to the static ω/k1 (returned with time = inf unless a lag makes it overshoot).
    """
    t_ap = aperiodic_time_constant_s
    if t_ap == 0.0:
        hmax, t_peak = impulse_response_peak(k1, k2)
        return Peak(drift_rad_s * hmax, t_peak)
    check_decaying(k1, k2, t_ap)
    if k2 == 0.0:  # step response of (Ts+1)/(Ts² + s + k1): may overshoot its final 1/k1
        ss = _state_space([t_ap, 1.0], [t_ap, 1.0, k1])
        z0 = np.zeros(ss.a.shape[0] + 1)
        z0[-1] = 1.0
        p, _ = _scan(ss, z0, 0.0, _horizon(ss))
        if p.magnitude <= 1.0 / k1:
            return Peak(drift_rad_s / k1, math.inf)
        return Peak(drift_rad_s * p.value, p.time_s)
    p = _impulse_peak([t_ap, 1.0], _polynomials(k1, k2, t_ap)[2])
    return Peak(drift_rad_s * p.value, p.time_s)


def drift_peak_error_rad(
    k1: float, k2: float, drift_rad_s: float, aperiodic_time_constant_s: float = 0.0
) -> float:
    """|peak error| [rad] from a gyro drift step ω [rad/s]: ω·max|h(t)|, h the impulse
    response of 1/(s² + k1 s + k2). Seed gains, ω = 5e-4: 8.85e-3 rad = 0.507°."""
    return drift_peak(k1, k2, drift_rad_s, aperiodic_time_constant_s).magnitude


def rough_peak_error_rad(k2: float, rate_rad_s: float) -> float:
    """The seed's rough peak of s/D·(ω/s): ω/n [rad] (Ryzhkov & Karpenko; overestimates, since it
    ignores the damping: 0.906° against the exact 0.507° for the seed's numbers)."""
    return abs(rate_rad_s) / _require_n(k2)


def seed_equivalent_rate_rad_s(k2: float, a_over_g: float, duration_s: float) -> float:
    """The seed's equivalent drift of a short accelerometer event: ω_e = k2·(a/g)·τ [rad/s].

    The seed's rough accel peak is then ω_e/n = n·(a/g)·τ (:func:`rough_peak_error_rad`).
    """
    return k2 * a_over_g * duration_s


def accel_event_peak(
    k1: float,
    k2: float,
    a_over_g: float,
    duration_s: float,
    aperiodic_time_constant_s: float = 0.0,
) -> Peak:
    """Exact peak error [rad] (and time [s]) of (k1 s + k2)/D driven by a rectangular
    accelerometer-angle pulse of height a/g [rad] lasting ``duration_s`` [s]."""
    check_decaying(k1, k2, aperiodic_time_constant_s)
    if not math.isfinite(duration_s) or duration_s <= 0.0:
        raise ValueError(f"event duration must be > 0 s (got {duration_s})")
    _, num, den = _polynomials(k1, k2, aperiodic_time_constant_s)
    if k2 == 0.0 and aperiodic_time_constant_s == 0.0:
        num, den = [k1], [1.0, k1]  # cancel the common pole at 0
    elif k2 == 0.0:
        num, den = [k1], [aperiodic_time_constant_s, 1.0, k1]
    return _pulse_peak(num, den, a_over_g, duration_s)


def accel_event_peak_error_rad(
    k1: float,
    k2: float,
    a_over_g: float,
    duration_s: float,
    aperiodic_time_constant_s: float = 0.0,
) -> float:
    """|peak error| [rad] from a linear-acceleration event a/g for τ s (exact; seed gains,
    0.2 for 5 s: 0.0302 rad = 1.73°; without a filter the error is the pulse, 11.46°)."""
    return accel_event_peak(k1, k2, a_over_g, duration_s, aperiodic_time_constant_s).magnitude


def accel_event_short_approx_rad(k1: float, a_over_g: float, duration_s: float) -> float:
    """Short-event approximation k1·(a/g)·τ [rad] (τ ≪ 1/k1: the proportional path dominates).

    The seed's own rough form is :func:`rough_peak_error_rad` of
    :func:`seed_equivalent_rate_rad_s`, i.e. n·(a/g)·τ.
    """
    return abs(k1 * a_over_g * duration_s)


def vibration_gain(
    k1: float, k2: float, frequency_hz: float, aperiodic_time_constant_s: float = 0.0
) -> float:
    """|H(j 2π f)| of the accelerometer path H = (k1 s + k2)/D (or /P with the aperiodic unit)."""
    _check_gains(k1, k2)
    if not math.isfinite(frequency_hz) or frequency_hz <= 0.0:
        raise ValueError(f"vibration frequency must be > 0 Hz (got {frequency_hz})")
    _, num, den = _polynomials(k1, k2, aperiodic_time_constant_s)
    s = 2j * math.pi * frequency_hz
    return float(abs(np.polyval(num, s) / np.polyval(den, s)))


def vibration_peak_error_rad(
    k1: float,
    k2: float,
    amplitude_rad: float,
    frequency_hz: float,
    aperiodic_time_constant_s: float = 0.0,
) -> float:
    """Steady-state error amplitude [rad] = |H(j2πf)|·A for an accelerometer-angle sinusoid of
    amplitude A [rad] at f [Hz] (exact; ≈ A·k1/(2πf) for f ≫ n). A sinusoid switched on at
    a zero crossing adds a slowly decaying offset of the same order (≤ 2× in the first cycles).
    """
    return vibration_gain(k1, k2, frequency_hz, aperiodic_time_constant_s) * abs(amplitude_rad)


def vibration_approx_rad(k1: float, amplitude_rad: float, frequency_hz: float) -> float:
    """High-frequency approximation A·k1/(2πf) [rad] of :func:`vibration_peak_error_rad`."""
    return abs(amplitude_rad) * k1 / (2.0 * math.pi * frequency_hz)


# ----------------------------------------------------------------------- saturation guidance


def min_saturation_limit_rad(
    k1: float, k2: float, bias_rad_s: float, margin: float = 2.0
) -> float:
    """Lowest sensible clip level L_min = margin·ω_bias·max|h| [rad].

    On a fixed base the error signal after a bias step ω is ω·h(t), peaking at ω·max|h|
    (seed gains: ω·17.7 s). A clip below that slows bias tracking (the integral then grows only
    at k2·L) and an initial error is removed at the clipped rate; the factor 2 is the margin
    DESIGN.md asks for, so other disturbances on top of the bias do not keep the clip engaged.
    """
    return margin * drift_peak_error_rad(k1, k2, abs(bias_rad_s))


def clipped_accel_error_rad(
    k1: float, k2: float, limit_rad: float, a_over_g: float, duration_s: float
) -> float:
    """Worst-case error [rad] of the clipped loop under a sustained accelerometer error a/g
    [rad] for τ [s]: the error signal is held at e = min(|a/g|, L), so the estimate moves at
    k1·e plus the integral's k2·e·t, giving k1·e·τ + k2·e·τ²/2 (the second term is the k2
    contribution; an aperiodic unit after the clip only lowers this). Seed gains, L = 0.02,
    0.51 g for 5 s: 3.25e-3 rad = 11.2′.
    """
    _check_gains(k1, k2)
    e = min(abs(a_over_g), limit_rad)
    return k1 * e * duration_s + 0.5 * k2 * e * duration_s**2


def clipped_recovery_time_s(
    k1: float, limit_rad: float, initial_error_rad: float, k2: float = 0.0
) -> float:
    """Time [s] to remove an initial error γ0 [rad] while the error is clipped at L [rad].

    k2 = 0 (proportional path only): γ0/(k1·L). With k2 > 0 the integral adds k2·L·t to the
    rate, so k1·L·t + k2·L·t²/2 = γ0 is solved instead (shorter, but the integral's state —
    the bias estimate — is then off by k2·L·t and overshoots while it unwinds).
    """
    if limit_rad <= 0.0:
        raise ValueError(f"saturation limit must be > 0 rad (got {limit_rad})")
    g0 = abs(initial_error_rad)
    if k2 <= 0.0:
        if k1 <= 0.0:
            return math.inf
        return g0 / (k1 * limit_rad)
    a, b = 0.5 * k2 * limit_rad, k1 * limit_rad
    return (-b + math.sqrt(b * b + 4.0 * a * g0)) / (2.0 * a)


# ------------------------------------------------------- thesis first-order filter (Habliuk 2023)


def first_order_accel_error_approx_rad(
    a_over_g: float, duration_s: float, time_constant_s: float
) -> float:
    """Thesis's u_acc ≈ (a/g)·τ/T [rad] for W(s) = s/(Ts+1) (a/g ≈ 1, τ = 5, T = 100: 2.87°)."""
    return abs(a_over_g) * duration_s / time_constant_s


def first_order_accel_error_exact_rad(
    a_over_g: float, duration_s: float, time_constant_s: float
) -> float:
    """Exact peak of 1/(Ts+1) driven by a pulse a/g for τ: (a/g)(1 − e^{−τ/T}) [rad] (2.79°)."""
    return abs(a_over_g) * -math.expm1(-duration_s / time_constant_s)


def first_order_static_drift_error_rad(time_constant_s: float, drift_rad_s: float) -> float:
    """Thesis's static error of the first-order filter from gyro drift: u_st = T·ω_dr [rad]
    (exact: the limit of the drift-step response; T = 100 s, 5e-5 rad/s: 0.29°)."""
    return time_constant_s * abs(drift_rad_s)


def first_order_static_drift_error_approx_rad(time_constant_s: float, drift_rad_s: float) -> float:
    """Same as :func:`first_order_static_drift_error_rad`: the thesis formula is already exact."""
    return first_order_static_drift_error_rad(time_constant_s, drift_rad_s)


def transient_horizon_s(k1: float, k2: float, t_ap: float) -> float:
    """How long [s] the loop's slow transient takes to pass its peak and first overshoot
    (gains k1 [1/s], k2 [1/s²], aperiodic time constant t_ap [s]): the time a simulation of
    an event must run on after it."""
    _, _, den = _polynomials(k1, k2, t_ap)
    ss = _state_space([1.0], den) if k2 > 0.0 else None
    if ss is None:
        return 10.0 / k1
    return min(_horizon(ss) / 5.0, 1000.0)
