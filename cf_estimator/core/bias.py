"""Gyro-bias estimator: the regulator's integral, measured at rest, learned in motion.

The estimate b (sensor frame, rad/s) is the PI regulator's integral state; its variance
``bias_var`` (per axis; the learning's schedule) and the variance of its error
``bias_err_var`` (:func:`error_sigma`) are tracked beside it:

- :func:`add_process_noise` — every sample: the prior at the first one, then a random walk
  (biases drift, BIAS_RANDOM_WALK_RAD_S_SQRT_S);
- :func:`fuse_rest` — a still block at rest (from :mod:`cf_estimator.core.stillness`) is a
  measurement of b: scalar Kalman update per axis;
- :func:`learning_gains` — in motion, while b is uncertain, k2 is raised towards
  ``bias_learning_k2`` in proportion to the variance and k1 to at least 2√k2 (critically damped):
  learned within about 20 s of any start, in the air too; but never beyond σ_b/σ_V, the gain at
  which the vehicle's own velocity swing would move the estimate by more than its uncertainty
  (:func:`observe_velocity_swing`), and not while the vehicle turns (:func:`turn_share`); k1
  itself is lowered below the configured one when the velocity swing is large
  (:func:`loop_gain`: √(d/σ_V), the gyro's drift rate d — from the estimate's error,
  :func:`error_sigma`, not the schedule's σ_b — against the swing);
- :func:`integrate` — the integral itself (k2 on the learning input R̄ᵀ·l,
  step.learning_input: the bias direction the aperiodic unit's state shows), except
  from an error too large to be a bias (:func:`learning_limit_rad`, anti-windup, no narrower
  than the samples' own scatter); the variance shrinks as it learns (time constant k1/k2);
- :func:`clamp` — bounded by BIAS_LIMIT_SIGMAS × ``bias_prior_sigma_rad_s``.

Owns the ``BIAS`` fields of :mod:`cf_estimator.core.state`. Written
once for floats and arrays; ``c/cf_core.c`` repeats it inline in ``step``/``stillness``.
"""

from __future__ import annotations

from typing import Any

from cf_estimator.core.ops import TINY, sq
from cf_estimator.core.state import StepState
from cf_estimator.core.stillness import RestMeasurement, bias_limit_rad_s

#: The integral (bias) learns only while the raw error is below this [rad]: a bias within the
#: prior leaves an error of at most a few REST_GATE_SIGMAS·bias_prior_sigma_rad_s / k1 (< 0.2
#: rad at the defaults); more is an attitude error, which must not wind the bias up.
BIAS_LEARNING_MAX_ERROR_RAD = 0.35
#: ... unaided, widened by this many standard deviations of one accelerometer sample's scatter
#: (the stillness blocks' noise over ‖g‖ [rad]): a per-sample gate narrower than the samples'
#: own scatter selects them by their noise, and while the error's mean swings with a manoeuvre,
#: learning from that selection rectifies the swing into a wrong bias (the Phantom's DOTs: rotor
#: vibration of 3-5 m/s² per sample, two thirds of the samples beyond 0.35 rad).
BIAS_LEARNING_NOISE_SIGMAS = 3.0
#: Bias random walk [rad/s/sqrt(s)]: how fast the confidence in a learned bias fades.
BIAS_RANDOM_WALK_RAD_S_SQRT_S = 2e-4
#: The bias estimate counts as converged below this standard deviation [rad/s].
BIAS_CONVERGED_SIGMA_RAD_S = 0.005
#: Smallest k1 [1/s] in the integral's learning time constant k1/k2 (k1 = 0 learns at once).
BIAS_LEARNING_MIN_K1 = 1e-3
#: High-pass time constant [s] of the pseudo-velocity (the disagreement integrated in the world
#: frame): longer than a manoeuvre's legs and its returns (a zig-zag's out-and-back: 10-20 s), so
#: it holds the vehicle's velocity changes over g.
SWING_TIME_CONSTANT_S = 30.0
#: Time constant [s] of the pseudo-velocity's mean square (a growing window until then).
SWING_VAR_TIME_CONSTANT_S = 10.0
#: The gyro's scale-factor and cross-axis error [1] (a MEMS datasheet's ±1 %, after factory
#: trim): rotating at ω, the integrated attitude drifts by about this × ω [rad/s] on top of the
#: bias's σ_b (:func:`loop_gain`).
GYRO_SCALE_UNCERTAINTY = 0.01


def add_process_noise(s: StepState, p: Any, dt: Any, o: Any) -> None:
    """The prior (``bias_prior_sigma_rad_s``²) at the first step, then + random walk × dt (both
    variances)."""
    walk = sq(BIAS_RANDOM_WALK_RAD_S_SQRT_S) * dt
    prior = sq(p.bias_prior_sigma_rad_s)
    s.bias_var = o.where(s.bias_var < 0.0, prior, s.bias_var) + walk
    s.bias_err_var = o.where(s.bias_err_var < 0.0, prior, s.bias_err_var) + walk


def fuse_rest(s: StepState, m: RestMeasurement, o: Any) -> None:
    """A still block at rest measures b: scalar Kalman update per axis (gain var/(var + r)).
    Marks the bias unverified when the still phase began at power-on without a magnetometer."""
    s.bias_unverified = o.where(m.measure, o.not_(s.moved) & o.not_(m.mag_seen),
                                s.bias_unverified)
    k = o.where(m.measure, s.bias_var / (s.bias_var + m.variance), 0.0)
    s.bx = s.bx + k * (m.mean_x - s.bx)
    s.by = s.by + k * (m.mean_y - s.by)
    s.bz = s.bz + k * (m.mean_z - s.bz)
    s.bias_var = s.bias_var - k * s.bias_var
    # the error after an update of gain k, whatever k was: (1 − k)²·before + k²·measurement's
    s.bias_err_var = o.where(m.measure, sq(1.0 - k) * s.bias_err_var + k * k * m.variance,
                             s.bias_err_var)


def observe_velocity_swing(s: StepState, wx: Any, wy: Any, dt: Any, o: Any) -> None:
    """The accelerometer's disagreement (wx, wy) [rad, world frame, horizontal] integrated into
    the pseudo-velocity over g ``pv`` [rad·s] (high-passed over SWING_TIME_CONSTANT_S) and its
    mean square ``pv_var``. The integral state learns k2·∫f: a vehicle whose velocity swings by
    Δv moves it by about k2·Δv/g, however well the attitude is known."""
    leak = dt / (SWING_TIME_CONSTANT_S + dt)
    s.pvx = s.pvx + wx * dt - leak * s.pvx
    s.pvy = s.pvy + wy * dt - leak * s.pvy
    w = dt / (o.minimum(SWING_VAR_TIME_CONSTANT_S, o.maximum(s.time_s, dt)) + dt)
    s.pv_var = s.pv_var + w * (s.pvx * s.pvx + s.pvy * s.pvy - s.pv_var)


def learning_limit_rad(s: StepState, o: Any) -> Any:
    """The raw error [rad] up to which a sample may teach the integral (anti-windup):
    BIAS_LEARNING_MAX_ERROR_RAD, unaided widened by BIAS_LEARNING_NOISE_SIGMAS × one sample's
    scatter (√noise_a2 / ‖g‖). Aided, the error's mean no longer swings with the manoeuvre, so
    the narrow gate selects without rectifying, and its slower learning averages what the aiding
    leaves (latency, the heading offset's error)."""
    widen = BIAS_LEARNING_NOISE_SIGMAS * o.sqrt(s.noise_a2) / s.g_ref
    return BIAS_LEARNING_MAX_ERROR_RAD + o.where(s.aided, 0.0, widen)


def turn_share(s: StepState, p: Any, o: Any) -> Any:
    """The share [0, 1] of the learning raise left while the vehicle turns about the vertical
    at ω = ``turn_hold`` [rad/s]: (k1²/(k1² + ω²))², k1 the configured loop gain
    (FilterParams.k1, not the raised one). Turning, a horizontal bias b rotates in the world
    frame and tilts the estimate by only b/|k1 + jω| (its evidence power falls as 1/ω²), while
    the accelerometer's disagreement is the turn's centripetal acceleration ω × v over g (its
    power grows as ω²): the evidence ratio falls as ω⁻⁴ above the loop's bandwidth. A
    constant-rate turn looks the same in the body frame as a bias (a steady error), so raising
    the loop there learns the turn: on a figure-8 the raised loop took up to 6 °/s of a
    de-biased gyro for bias. ω is the rate low-passed over TURN_LOWPASS_TIME_CONSTANT_S
    (step.py: a turn long enough to pass for a bias), its size held while the loop still holds
    the turn's lean — decaying over the loop's memory 1/k1: a figure-8's reversal passes the
    signed low-pass through zero in a second, and with it the full raise came back and learned
    the lean the loop's error still held (tight figure-8s, 1 m/s at 1.5 rad/s: 1.79 → 1.15 °/s
    learned, 2.12° → 1.55°; with the integral learning through the unit's own lag,
    step.learning_input, 0.25 °/s and 0.75°; docs/decisions/0005, "The tight turn"). Without the
    share, the raise at full power in a turn learns what the turn leaves: tight 4.85°. A gyro
    bias about the vertical as large as the prior (0.1 rad/s) counts as a turn too, and takes
    15 % of the raise."""
    k1_2 = sq(o.maximum(p.k1, BIAS_LEARNING_MIN_K1))
    w = s.turn_hold
    share = k1_2 / (k1_2 + w * w)
    return share * share


def learning_gains(s: StepState, p: Any, o: Any, loop: Any = None) -> tuple[Any, Any]:
    """(k1 [1/s], k2 [1/s²]) of the regulator at this step (``loop``: :func:`loop_gain` of
    this state, when the caller has it already).

    k2: raised while b is uncertain, the raise at most σ_b/σ_V [rad/s over rad·s] (the velocity
    swing moves the estimate by no more than its uncertainty σ_b = √bias_var; σ_V = √pv_var)
    and scaled by :func:`turn_share`. k1: the gain the disturbance allows (:func:`loop_gain`),
    at least 2√k2 (the PI loop critically damped)."""
    sigma_b = o.sqrt(o.maximum(s.bias_var, 0.0))
    sigma_v = o.maximum(o.sqrt(s.pv_var), TINY)
    share = o.minimum(s.bias_var / sq(p.bias_prior_sigma_rad_s), 1.0)
    k2 = o.maximum(p.k2, o.minimum(p.bias_learning_k2 * share, sigma_b / sigma_v)
                   * turn_share(s, p, o))
    k1 = o.maximum(loop_gain(s, p, o) if loop is None else loop, 2.0 * o.sqrt(k2))
    return k1, k2


def error_sigma(s: StepState, o: Any) -> Any:
    """σ [rad/s] of the bias estimate's error, per axis: √``bias_err_var``.

    ``bias_var`` shrinks while the integral learns at k2/k1 (:func:`integrate`): the slow mode
    of the PI loop for k2 ≪ k1², and the learning raise's schedule (the raise lasts while
    bias_var/prior² is large). The error it leaves decays with that mode, e^(−∫k2/k1·dt)
    (faster still where the raise makes the loop critically damped), so its variance falls at
    least twice as fast: ``bias_err_var`` starts at the same prior, takes the same random walk
    and the same still-block measurements (with the gain bias_var chose, :func:`fuse_rest`),
    and shrinks at 2·k2/k1 while learning. ``bias_var`` is the schedule and a bound; this is the
    error. Measured (shipped defaults, the reference's own rates for the true bias, per-axis
    RMS of the horizontal components at 10 / 20 / 30 s; docs/decisions/0005, "the loop's drift from
    the bias estimate's error"): phantom4 vertical error 0.39 / 0.17 / 0.18 °/s, σ_b 2.28 /
    1.26 / 0.91, this 0.93 / 0.28 / 0.15."""
    return o.sqrt(o.maximum(s.bias_err_var, 0.0))


def loop_gain(s: StepState, p: Any, o: Any) -> Any:
    """The loop's k1 [1/s] for the disturbance measured: √(d/σ_V), at most FilterParams.k1.

    The tilt error the loop leaves is about d/k1 from the gyro (its integration drifts at
    d = σ_e + GYRO_SCALE_UNCERTAINTY·|ω| [rad/s], σ_e the bias estimate's error
    (:func:`error_sigma`), ω the low-passed rotation rate) and about
    k1·σ_V from the accelerations it is told are gravity (σ_V [rad·s]: the velocity swing over
    g, :func:`observe_velocity_swing`); their sum of squares is least at k1 = √(d/σ_V). A
    handheld sensor or a hover swings little and keeps the configured k1; a multirotor's
    sustained manoeuvres (velocity swings of metres per second) lower it. Velocity-aided, the
    accelerations are taken out of the measurement (σ_V still holds the swing from before):
    the configured k1."""
    sigma_v = o.maximum(o.sqrt(s.pv_var), TINY)
    return o.where(s.aided, p.k1, o.minimum(p.k1, o.sqrt(drift_rate(s, o) / sigma_v)))


def drift_rate(s: StepState, o: Any) -> Any:
    """d [rad/s]: the rate the gyro's integration drifts at — the bias estimate's error
    (:func:`error_sigma`) plus GYRO_SCALE_UNCERTAINTY × the low-passed rotation rate."""
    return error_sigma(s, o) + GYRO_SCALE_UNCERTAINTY * s.rate_lp


def integrate(s: StepState, p: Any, f: tuple, k1: Any, k2: Any, learn: Any, small: Any,
              dt: Any, o: Any) -> None:
    """The integral states on the learning input ``f`` [rad, sensor] (R̄ᵀ·l,
    step.learning_input): the bias estimate b
    (``learn``: not in start-up/recovery; ``small``: the raw error is small enough to be a
    bias's, see :func:`learning_limit_rad`); the variance shrinks as the integral learns."""
    fx, fy, fz = f
    ldt = o.where(learn & small, dt, 0.0)
    s.bx = s.bx - ldt * (k2 * fx)
    s.by = s.by - ldt * (k2 * fy)
    s.bz = s.bz - ldt * (k2 * fz)
    # the integral learns the bias with time constant ~k1/k2: its variance shrinks so, the
    # variance of the error it leaves twice as fast (error_sigma)
    k1m = o.maximum(k1, BIAS_LEARNING_MIN_K1)
    s.bias_var = s.bias_var / (1.0 + ldt * k2 / k1m)
    s.bias_err_var = s.bias_err_var / (1.0 + 2.0 * ldt * k2 / k1m)


def clamp(s: StepState, p: Any, o: Any) -> None:
    """Each component within ±:func:`~cf_estimator.core.stillness.bias_limit_rad_s`
    (anti-windup)."""
    lim = bias_limit_rad_s(p)
    s.bx = o.minimum(o.maximum(s.bx, -lim), lim)
    s.by = o.minimum(o.maximum(s.by, -lim), lim)
    s.bz = o.minimum(o.maximum(s.bz, -lim), lim)
