"""The 3-D compensation-scheme step: the filter's equations, written once for floats and arrays.

One sample, in the order the code runs (world frame ENU inside; q = q_world_from_sensor); each
stage is a function of its name here and a static function of the same name in core/c/cf_core.c::

    1. predict()  q⁻ = Exp_z(z_m·dt) ⊗ q ⊗ Exp((ω − b)·dt)
                  (gyro ω, bias estimate b; z_m: heading channel's world-vertical rate)
    .  classify_motion(): stillness blocks (rest → bias measurement), quick, linear acceleration
    2. tilt_error() e = (a/‖g‖) × ĝ,  ĝ = R⁻ᵀ·ẑ   (Ryzhkov & Karpenko: scaled by gravity, not |a|)
                  (≈ small-angle tilt error; linear in the linear acceleration)
    3. saturate() e_s = e·min(1, L/|e|)                     (by norm, keeps the direction)
                  L = saturation_limit_rad while a linear acceleration is present and the gyro
                  is still (impacts, vibration, manoeuvres); else no clip
    4. aperiodic() l ← l + dt/(T+dt)·(R⁻·e_s − l);  f = R⁻ᵀ·l  (1/(T s+1) in the world frame)
    5. regulate() b ← b − dt·k2'·f;  q ← q⁻ ⊗ Exp(g(k1')·f)
                  (W1 = k1 + k2/s; g(k) = k·dt/(1+k·dt), the backward-Euler gain;
                  b, the integral state, is the gyro-bias estimate; k2' = max(k2,
                  min(bias_learning_k2·σ_b²/σ_0², σ_b/σ_V)) while the bias is uncertain,
                  k1' = max(min(k1, √(d/σ_V)), 2√k2'); σ_V: the velocity swing, d: the
                  gyro's drift rate from the bias estimate's error, bias.py); then
                  l ← l − p·g(k1')·l with p = aperiodic_prefilter (0 while the tight clip
                  is on): the correction also turns the unit's memory (p = 1: a pre-filter of
                  the specific force in the world frame, as VQF's; p = 0: the thesis's unit on
                  the error)
    .  recover()  a clip unbroken for recovery_trigger_s: RECOVERING (as start-up)
    6. heading()  e_ψ = atan2(m_E, m_N) of the measured field in the world frame,
                  saturated; q ← Exp_z(g(r1)·e_ψ) ⊗ q; z_m ← z_m + r2·dt_m·e_ψ (heading only:
                  a rotation about the world vertical never changes roll/pitch); saturated
                  for recovery_trigger_s: heading recovery with startup_k1 (as the tilt's)

The parts (each its own module, each with its own tests; the state's fields are typed and grouped
by owner in :mod:`cf_estimator.core.state`): the rest/motion classifier
(:mod:`cf_estimator.core.stillness`), the bias estimator (:mod:`cf_estimator.core.bias`), and
here the compensation loop (steps 1-5) and the heading channel (step 6).

Stillness and bias (``stillness.classify``, ``bias.*``): on blocks of rest_window_s, a block
whose gyro and accelerometer means did not change from the previous block (beyond the thresholds
plus the noise measured from sample-to-sample differences: vibration-robust; a constant bias
cancels) is still; REST_STILL_BLOCKS still blocks in a row are rest. At rest each still block's
gyro mean is a bias measurement, fused by variance (scalar Kalman update; σ_b = √bias_var starts at
bias_prior_sigma_rad_s, grows by a random walk, shrinks with each measurement and, in motion,
with the integral's learning). Vibration widens the thresholds by at most REST_NOISE_CAP times
themselves; a turning magnetic field is motion; a steady block far from the bias estimate (on
any axis, REST_GATE_SIGMAS) is a constant-rate turn, not rest, however long it lasts.

Linear acceleration (the tight clip) is detected when the 50 ms low-passed | |a| − ‖g‖ | exceeds
acceleration_threshold_m_s2 plus ACCEL_DETECT_SIGMAS of the vibration left in the low-pass, or
at once for a spike (an impact).

Phases: STARTUP (after initialisation, for startup_duration_s: no clip, the unit bypassed, no
integral learning; gain startup_k1 while still, the running mean of the accelerometer since
initialisation, gain 1/t, once a stillness block was not still — started in the air, the
flight's accelerations average out) → RUNNING → RECOVERING (error clipped without a break for
recovery_trigger_s: a real attitude error, e.g. after gyro over-range; same as STARTUP until
|e| < L/2) → RUNNING. At rest the error path also runs as in STARTUP while the block's |a| is
within acceleration_threshold_m_s2 of ‖g‖ (nothing to reject: an error left by motion is removed
fast). While bypassed the unit follows the error with a 0.2 s lag, turned by each correction.
"""

from __future__ import annotations

import math
from typing import Any

from cf_estimator.core import bias
from cf_estimator.core.bias import (  # noqa: F401 - the constants of the whole step, here too
    BIAS_CONVERGED_SIGMA_RAD_S,
    BIAS_LEARNING_MAX_ERROR_RAD,
    BIAS_LEARNING_MIN_K1,
    BIAS_LEARNING_NOISE_SIGMAS,
    BIAS_RANDOM_WALK_RAD_S_SQRT_S,
    SWING_TIME_CONSTANT_S,
    SWING_VAR_TIME_CONSTANT_S,
)
from cf_estimator.core.ops import TINY, rotation_elements, sq
from cf_estimator.core.state import StepState
from cf_estimator.core.stillness import (  # noqa: F401
    BIAS_LIMIT_SIGMAS,
    GRAVITY_TIME_CONSTANT_S,
    REST_GATE_SIGMAS,
    REST_MAG_TOLERANCE_RAD,
    REST_NOISE_CAP,
    REST_NOISE_SIGMAS,
    REST_SAMPLE_SIGMAS,
    REST_STILL_BLOCKS,
    classify,
    rest_time_s,
)

PHASE_UNINITIALIZED = 0
PHASE_STARTUP = 1
PHASE_RUNNING = 2
PHASE_RECOVERING = 3
PHASE_NAMES = {0: "uninitialized", 1: "startup", 2: "running", 3: "recovering"}

MAG_NONE = 0  # no magnetometer sample at this step
MAG_USED = 1  # used for heading
MAG_REJECTED = 2  # disturbance (norm, dip or turn off the reference; settling): ignored
MAG_DISABLED = 3  # use_mag is off
MAG_STATUS_NAMES = {0: "none", 1: "used", 2: "rejected", 3: "disabled"}

#: Low-pass time constant of the rotation rate that selects the clip level [s].
RATE_LOWPASS_TIME_CONSTANT_S = 0.5
#: Low-pass time constant [s] of the rotation rate about the vertical (bias.turn_share): a turn
#: sustained over the loop's own time scale (1/k1, seconds) looks like a bias to it; a heading
#: change of a second, or a zig-zag's pitching seen through a tilted estimate, does not.
TURN_LOWPASS_TIME_CONSTANT_S = 2.0
#: Low-pass time constant [s] of the accelerometer for the linear-acceleration detector:
#: rotor vibration (50-200 Hz) averages out, a manoeuvre does not.
ACCEL_LOWPASS_TIME_CONSTANT_S = 0.05
#: A single accelerometer sample this many noise standard deviations (measured by the stillness
#: blocks) off ‖g‖ is an impact: the detector takes it at once, unfiltered.
ACCEL_SPIKE_SIGMAS = 4.0
#: The low-passed | |a| − ‖g‖ | must exceed acceleration_threshold_m_s2 by this many standard
#: deviations of what vibration leaves in the low-pass: rotor vibration is not a manoeuvre.
ACCEL_DETECT_SIGMAS = 3.0
#: Time constant [s] of the aperiodic unit when there is no manoeuvre for it to average out:
#: while the error bypasses it (start-up, rest, recovery) and while the specific force is
#: velocity-aided (the vehicle's acceleration taken out: what is left is vibration).
QUICK_LAG_TIME_CONSTANT_S = 0.2
#: The aperiodic unit sits inside the PI loop: its time constant is at most this over the loop's
#: k1 [1/s]. T·k1 = 3/4 puts the roots of T·s³ + s² + k1·s + k1²/4 (the critically damped loop
#: of a raised k2 = k1²/4, with the unit) at k1·(−1/2 ± j·√3/2) and −k1/3: a damping ratio of
#: 0.5. The 2 s unit in a loop raised to k1 = 1.8 /s (an in-flight start) rang at 0.07.
LOOP_LAG_FRACTION = 0.75
#: Magnetometer samples averaged for the field reference (norm, dip) after start-up.
MAG_REFERENCE_SAMPLES = 20
#: A rejected field that has stayed steady and turned as the gyro says for as long as the
#: current reference has been in use (at least MAG_SETTLE_S, at most this) [s] is taken as the
#: new normal and re-learned: a compass wrong at power-on is replaced within seconds, a long-held
#: reference only after this long; a magnet on the sensor, which turns with the body, never.
MAG_RELEARN_AFTER_S = 20.0
#: After a disturbance the field must agree with the reference this long without a break [s]
#: before it is used again (a rotating disturbed field passes the tests by chance for moments).
MAG_SETTLE_S = 3.0
#: Time constant [s] of the low-passed reference field direction (used samples), which the gyro
#: turns between samples: over this window a field must turn as the body turns.
MAG_TURN_TIME_CONSTANT_S = 1.0
#: Time constant [s] of the low-passed measured field direction (every sample, turned by the
#: gyro) that the checks compare: sensor noise averages out, a disturbance does not.
MAG_SMOOTH_TIME_CONSTANT_S = 0.25
#: Angle [rad] (chord) between a sample's direction and the gyro-predicted one beyond which the
#: field turned when the body did not: the noise floor ...
MAG_TURN_TOLERANCE_RAD = 0.05
#: ... plus this share of the angle the body turned over MAG_TURN_TIME_CONSTANT_S: a residual
#: hard iron of this share of the field (a calibration's leftover) still passes; a magnet of
#: 0.3-1x the Earth field on the sensor does not (BROAD's undisturbed trials are unchanged at
#: 0.05 and 0.1; 0.2 let a 0.3x magnet through).
MAG_TURN_FRACTION = 0.05
#: Standard deviations of the bias estimate allowed as gyro drift of the predicted direction per
#: second since the last used sample (a long disturbance: the field is recognised when it returns).
MAG_DRIFT_SIGMAS = 3.0
#: Relative norm change [1] of a rejected field, against the norm it had when the candidate
#: began, that resets the re-learning (a magnet on a turning body changes the norm).
MAG_CANDIDATE_NORM_TOLERANCE = 0.05
#: Longest time [s] one magnetometer sample's correction may stand for (sparse magnetometers).
MAG_MAX_DT_S = 1.0
#: Recovery ends once the error is below this share of the clip level [1] (tilt).
RECOVERY_EXIT_FRACTION = 0.5
#: Heading recovery ends once the heading error is below this share of
#: mag_saturation_limit_rad [1].
MAG_RECOVERY_EXIT_FRACTION = 0.1
#: Clip level of the heading error while the heading channel is quick (start-up, recovery) [rad]:
#: above π, i.e. no clip.
MAG_QUICK_LIMIT_RAD = 4.0
#: A unit field whose horizontal component in the world frame is below this gives no heading [1].
MAG_MIN_HORIZONTAL = 1e-3


def _mul(aw: Any, ax: Any, ay: Any, az: Any, bw: Any, bx: Any, by: Any, bz: Any) -> tuple:
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


def _exp(vx: Any, vy: Any, vz: Any, o: Any) -> tuple:
    angle = o.sqrt(vx * vx + vy * vy + vz * vz)
    k = o.sin_half_over(angle)
    return o.cos(0.5 * angle), k * vx, k * vy, k * vz


def _rotate(qw: Any, qx: Any, qy: Any, qz: Any, vx: Any, vy: Any, vz: Any) -> tuple:
    """v' = q ⊗ v ⊗ q* (sensor → world for q_world_from_sensor)."""
    tx = 2.0 * (qy * vz - qz * vy)
    ty = 2.0 * (qz * vx - qx * vz)
    tz = 2.0 * (qx * vy - qy * vx)
    return (
        vx + qw * tx + (qy * tz - qz * ty),
        vy + qw * ty + (qz * tx - qx * tz),
        vz + qw * tz + (qx * ty - qy * tx),
    )


def turn_heading(s: StepState, angle: Any, o: Any) -> None:
    """q ← Exp_z(angle) ⊗ q (a world-vertical rotation), and the world-frame horizontal states
    with it: the lag state l, the low-passed R̄ (rows x, y) and the pseudo-velocity pv
    (bias.observe_velocity_swing).

    Turning them too keeps the tilt path exactly independent of heading corrections: f = Rᵀ·l
    and the learning input R̄ᵀ·l are unchanged, and so is |pv| (the swing σ_V that sets the
    loop gain, bias.loop_gain), so the magnetometer can never move roll/pitch.
    """
    cw, cz = o.cos(0.5 * angle), o.sin(0.5 * angle)
    s.qw, s.qx, s.qy, s.qz = (
        cw * s.qw - cz * s.qz,
        cw * s.qx - cz * s.qy,
        cw * s.qy + cz * s.qx,
        cw * s.qz + cz * s.qw,
    )
    c, sn = cw * cw - cz * cz, 2.0 * cw * cz
    s.lx, s.ly = c * s.lx - sn * s.ly, sn * s.lx + c * s.ly
    s.pvx, s.pvy = c * s.pvx - sn * s.pvy, sn * s.pvx + c * s.pvy
    s.rxx, s.ryx = c * s.rxx - sn * s.ryx, sn * s.rxx + c * s.ryx
    s.rxy, s.ryy = c * s.rxy - sn * s.ryy, sn * s.rxy + c * s.ryy
    s.rxz, s.ryz = c * s.rxz - sn * s.ryz, sn * s.rxz + c * s.ryz


def _toward_unit(v: tuple, u: tuple, a: Any, o: Any) -> tuple:
    """A unit vector low-pass: v + a·(u − v), renormalised (weight ``a`` in [0, 1])."""
    x, y, z = v[0] + a * (u[0] - v[0]), v[1] + a * (u[1] - v[1]), v[2] + a * (u[2] - v[2])
    n = o.maximum(o.sqrt(x * x + y * y + z * z), TINY)
    return x / n, y / n, z / n


def up_direction(s: StepState) -> tuple:
    """The estimated up (gravity) direction in the sensor frame: the third row of R(q)."""
    return (2.0 * (s.qx * s.qz - s.qw * s.qy), 2.0 * (s.qy * s.qz + s.qw * s.qx),
            1.0 - 2.0 * (s.qx * s.qx + s.qy * s.qy))


def _normalize(s: StepState, o: Any) -> None:
    n = o.sqrt(s.qw * s.qw + s.qx * s.qx + s.qy * s.qy + s.qz * s.qz)
    s.qw, s.qx, s.qy, s.qz = s.qw / n, s.qx / n, s.qy / n, s.qz / n


def step(
    s: StepState,
    p: Any,
    gyro: tuple[float, float, float],
    accel: tuple[float, float, float] | None,
    mag: tuple[float, float, float] | None,
    dt: float,
    o: Any,
) -> None:
    """Advance the state one sample (see the module docstring), stage after stage.

    ``p`` has the FilterParams field names (floats, or arrays for a batch).
    ``accel``/``mag`` are None when absent or invalid at this sample (the caller checks
    finiteness and non-zero norm). ``dt`` > 0 [s]. The C twin's step() (core/c/cf_core.c, the
    body of cf_step) calls the same stages, of the same names, in the same order.
    """
    s.time_s = s.time_s + dt
    bias.add_process_noise(s, p, dt, o)
    startup = s.time_s <= p.startup_duration_s
    # trust the accelerometer fully, learn no bias: start-up, recovery, and a take-hold phase
    # (velocity aiding that just began: the tilt error it reveals is real)
    fast = startup | s.recovering | (s.time_s <= s.quick_until_s)
    learn = o.not_(fast)

    predict(s, gyro, dt, o)
    s.clipped = s.clipped & False
    s.accel_used = accel is not None
    if accel is not None:
        up = up_direction(s)  # q is the predicted one until regulate() corrects it
        quick, accelerating = classify_motion(s, p, gyro, accel, mag, up, fast, dt, o)
        u, v, en = tilt_error(s, accel, up, o)
        scale, limit, tight, clipped = saturate(s, p, en, quick, accelerating, o)
        f, g = aperiodic(s, p, scale, quick, tight, dt, o)
        regulate(s, p, f, g, en, u, v, quick, tight, learn, dt, o)
        recover(s, p, clipped, en, limit, learn, dt, o)
    bias.clamp(s, p, o)

    s.mag_status = o.where(p.use_mag, MAG_NONE, MAG_DISABLED)
    if mag is not None:
        heading(s, p, mag, fast, learn, o)
    _normalize(s, o)
    s.phase = o.where(
        s.recovering, PHASE_RECOVERING, o.where(startup, PHASE_STARTUP, PHASE_RUNNING)
    )


def predict(s: StepState, gyro: tuple, dt: Any, o: Any) -> None:
    """Stage 1: q ← Exp_z(z_m·dt) ⊗ q ⊗ Exp((ω − b)·dt) [gyro rad/s, dt s]; the field
    directions the heading channel checks samples against turn with the body."""
    gx, gy, gz = gyro
    dw, dx, dy, dz = _exp((gx - s.bx) * dt, (gy - s.by) * dt, (gz - s.bz) * dt, o)
    qw, qx, qy, qz = _mul(s.qw, s.qx, s.qy, s.qz, dw, dx, dy, dz)
    s.qw, s.qx, s.qy, s.qz = qw, qx, qy, qz
    turn_heading(s, s.z_m * dt, o)
    s.mvx, s.mvy, s.mvz = _rotate(dw, -dx, -dy, -dz, s.mvx, s.mvy, s.mvz)
    s.mcx, s.mcy, s.mcz = _rotate(dw, -dx, -dy, -dz, s.mcx, s.mcy, s.mcz)
    s.mmx, s.mmy, s.mmz = _rotate(dw, -dx, -dy, -dz, s.mmx, s.mmy, s.mmz)


def classify_motion(s: StepState, p: Any, gyro: tuple, accel: tuple, mag: tuple | None,
                    up: tuple, fast: Any, dt: Any, o: Any) -> tuple[Any, Any]:
    """Before the error: rest or motion, and is there a linear acceleration → (quick, accelerating).

    The stillness blocks (``stillness.classify``) and their bias measurement at rest; quick: the
    error bypasses the clip and the unit (``fast``, or at rest with |a| = ‖g‖ and no strong
    vibration); the linear-acceleration detector (peak hold of the 50 ms low-passed
    | |a| − ‖g‖ | [m/s²], or of a spike: an impact); the rotation-rate low-pass [rad/s] and
    the turn's, about ``up`` (:func:`up_direction` of the predicted q).
    """
    gx, gy, gz = gyro
    ax, ay, az = accel
    an = o.sqrt(ax * ax + ay * ay + az * az)
    s.g_ref = o.where(s.g_ref > 0.0, s.g_ref, p.gravity_m_s2)  # ‖g‖: prior, learned below
    deviation = o.maximum(an - s.g_ref, s.g_ref - an)  # | |a| - ‖g‖ |
    # an impact: a single sample far above the noise of the last block (see the detector)
    spike = deviation > p.acceleration_threshold_m_s2 + ACCEL_SPIKE_SIGMAS * o.sqrt(s.noise_a2)
    bias.fuse_rest(s, classify(s, p, gyro, accel, mag, dt, o), o)
    # at rest the block mean of the gyro is the bias, whatever the accelerometer says; but
    # the error path trusts the accelerometer only if |a| = ‖g‖: a steady linear
    # acceleration (constant accelerometer, still gyro: the 25 m/s manoeuvre) is not gravity
    steady_g = o.sqrt(s.pax * s.pax + s.pay * s.pay + s.paz * s.paz)  # last block's |a|
    # ... and only without strong vibration: at startup_k1 it would pass into the attitude
    quick = fast | (s.at_rest & (o.maximum(steady_g - s.g_ref, s.g_ref - steady_g)
                                 < p.acceleration_threshold_m_s2)
                    & (s.noise_a2 < sq(p.acceleration_threshold_m_s2)))
    # linear-acceleration detector, blind to vibration: | |a| - ‖g‖ | of the accelerometer
    # low-passed over ACCEL_LOWPASS_TIME_CONSTANT_S, or of this very sample when it is a
    # spike far above the noise measured by the stillness blocks (an impact)
    aw = o.where(s.last_n <= 1.0, 1.0, dt / (ACCEL_LOWPASS_TIME_CONSTANT_S + dt))
    s.acx, s.acy, s.acz = (s.acx + aw * (ax - s.acx), s.acy + aw * (ay - s.acy),
                           s.acz + aw * (az - s.acz))
    an_lp = o.sqrt(s.acx * s.acx + s.acy * s.acy + s.acz * s.acz)
    level = o.where(spike, deviation, o.maximum(an_lp - s.g_ref, s.g_ref - an_lp))
    hold = rest_time_s(p)  # quiet again when it could be at rest
    decayed = s.accel_hold * (hold / (hold + dt))
    s.accel_hold = o.maximum(level, decayed)
    # vibration left in the low-pass (white-noise approximation of the 1st-order low-pass,
    # per axis, from the stillness blocks' noise): not a manoeuvre
    lp_sigma = o.sqrt(s.noise_a2 / 3.0 * dt / (2.0 * ACCEL_LOWPASS_TIME_CONSTANT_S + dt))
    accelerating = s.accel_hold > p.acceleration_threshold_m_s2 + ACCEL_DETECT_SIGMAS * lp_sigma
    rate = o.sqrt(sq(gx - s.bx) + sq(gy - s.by) + sq(gz - s.bz))
    lw = dt / (RATE_LOWPASS_TIME_CONSTANT_S + dt)
    s.rate_lp = s.rate_lp + lw * (rate - s.rate_lp)
    vx, vy, vz = up  # the turn: the rate about the vertical (bias.turn_share)
    turn = (gx - s.bx) * vx + (gy - s.by) * vy + (gz - s.bz) * vz
    tw = dt / (TURN_LOWPASS_TIME_CONSTANT_S + dt)
    s.turn_rate_lp = s.turn_rate_lp + tw * (turn - s.turn_rate_lp)
    # its size held over the loop's memory 1/k1: the lean a turn left in the loop's error
    # outlasts a figure-8's reversal (bias.turn_share)
    memory = 1.0 / o.maximum(p.k1, BIAS_LEARNING_MIN_K1)
    s.turn_hold = o.maximum(o.maximum(s.turn_rate_lp, -s.turn_rate_lp),
                            s.turn_hold * (memory / (memory + dt)))
    return quick, accelerating


def tilt_error(s: StepState, accel: tuple, up: tuple, o: Any) -> tuple[tuple, tuple, Any]:
    """Stage 2: e = (a/‖g‖) × ĝ (into s.ex, s.ey, s.ez, s.error_norm) → (a/‖g‖, ĝ, |e|).

    Ryzhkov & Karpenko: scaled by gravity, not by |a|, so the error stays linear in the linear
    acceleration and the aperiodic unit averages zero-mean accelerations out. ĝ = ``up``: the
    predicted gravity (up) direction in the sensor frame, the third row of R.
    """
    ax, ay, az = accel
    ux, uy, uz = ax / s.g_ref, ay / s.g_ref, az / s.g_ref
    vx, vy, vz = up
    ex, ey, ez = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
    en = o.sqrt(ex * ex + ey * ey + ez * ez)
    s.ex, s.ey, s.ez, s.error_norm = ex, ey, ez, en
    return (ux, uy, uz), (vx, vy, vz), en


def saturate(s: StepState, p: Any, en: Any, quick: Any, accelerating: Any,
             o: Any) -> tuple[Any, Any, Any, Any]:
    """Stage 3: saturation by norm → (scale of e, clip level L [rad], tight, clipped).

    The clip (L = saturation_limit_rad) only for a linear acceleration on a still gyro
    (impacts, vibration, manoeuvres: the thesis's disturbances); never while quick, and never
    while rotating or unaccelerated (L = ∞): a real attitude error, e.g. what a gyro's scale
    error leaves after a fast turn, is then corrected at the loop's full rate."""
    tight = accelerating & (s.rate_lp < p.rotation_threshold_rad_s)
    limit = o.where(tight, p.saturation_limit_rad, math.inf)  # no clip: L = ∞
    clipped = p.use_saturation & o.not_(quick) & (en > limit)
    scale = o.where(clipped, limit / o.maximum(en, TINY), 1.0)
    return scale, limit, tight, clipped


def aperiodic(s: StepState, p: Any, scale: Any, quick: Any, tight: Any, dt: Any,
              o: Any) -> tuple:
    """Stage 4: the aperiodic unit 1/(T s+1) in the world frame on the saturated error →
    f = R⁻ᵀ·l in the sensor frame [rad] (quick: the error bypasses the unit); T at most
    LOOP_LAG_FRACTION / k1 of the loop (k1 as raised for learning), except under the tight
    clip: the loop is saturated then, and the unit's memory is what rejects the disturbance."""
    ex, ey, ez = s.ex * scale, s.ey * scale, s.ez * scale
    wx, wy, wz = _rotate(s.qw, s.qx, s.qy, s.qz, ex, ey, ez)
    # aided (velocity aiding took the vehicle's acceleration out): nothing slow to average
    lag = o.where(s.aided, QUICK_LAG_TIME_CONSTANT_S, p.aperiodic_time_constant_s)
    # never slower than the linear loop it sits in (LOOP_LAG_FRACTION; k1 as raised for
    # learning); under the tight clip the loop is saturated and the thesis's unit is kept
    k1, _ = bias.learning_gains(s, p, o)
    lag = o.where(tight, lag, o.minimum(lag, LOOP_LAG_FRACTION / o.maximum(k1, TINY)))
    weight = dt / (o.where(quick, QUICK_LAG_TIME_CONSTANT_S, lag) + dt)
    s.lx = s.lx + weight * (wx - s.lx)
    s.ly = s.ly + weight * (wy - s.ly)
    s.lz = s.lz + weight * (wz - s.lz)
    # quick (start-up, recovery, rest): the error bypasses the unit, which follows it with a
    # short lag and is turned by every quick correction (regulate), so that when the bypass
    # ends it holds the recent error as the current estimate sees it: not the last noisy
    # sample, nor a memory of errors the quick loop has already removed
    lx, ly, lz = o.where(quick, wx, s.lx), o.where(quick, wy, s.ly), o.where(quick, wz, s.lz)
    fx, fy, fz = _rotate(s.qw, -s.qx, -s.qy, -s.qz, lx, ly, lz)
    s.fx, s.fy, s.fz = fx, fy, fz
    return (fx, fy, fz), learning_input(s, (lx, ly, lz), weight, o)


def learning_input(s: StepState, lag: tuple, weight: Any, o: Any) -> tuple:
    """R̄ᵀ·l [rad, sensor frame]: what the integral (the bias estimate) learns from.

    The unit's state l is the world-frame error low-passed over its memory T. The proportional
    path corrects by f = Rᵀ·l, the current attitude's view of it; the integral learns from
    R̄ᵀ·l, R̄ the rotation R (sensor → world) low-passed as the unit low-passes (the same
    ``weight``): a lagged world vector mapped back by an equally lagged rotation. At rest or in
    a translation R̄ = R and the two agree. While the body turns about the vertical at ω, a
    sensor-fixed error e (what a gyro bias leaves, and what a multirotor's rotor drag and a
    steady turn's lean leave too) comes back along its own axis as e/(1 + (ωT)²): the turn
    averages it out of the world frame, and the learning fades as that evidence does. Through
    f = Rᵀ·l the same e came back turned by atan(ωT) about the vertical (72° at 1.5 rad/s over
    2 s), into other axes, one way in a left turn and the other in a right one: a tight
    figure-8 taught 1.15 °/s of bias to a de-biased gyro (now 0.25 °/s; docs/decisions/0005, "The
    tight turn"). R̄ starts as R (all zero: not set yet), is turned with heading corrections
    (:func:`turn_heading`) and cleared with the unit (ComplementaryFilter.realign)."""
    lx, ly, lz = lag
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_elements(s.qw, s.qx, s.qy, s.qz)
    w = o.where(s.rxx * s.rxx + s.ryy * s.ryy + s.rzz * s.rzz == 0.0, 1.0, weight)
    s.rxx = s.rxx + w * (r00 - s.rxx)
    s.rxy = s.rxy + w * (r01 - s.rxy)
    s.rxz = s.rxz + w * (r02 - s.rxz)
    s.ryx = s.ryx + w * (r10 - s.ryx)
    s.ryy = s.ryy + w * (r11 - s.ryy)
    s.ryz = s.ryz + w * (r12 - s.ryz)
    s.rzx = s.rzx + w * (r20 - s.rzx)
    s.rzy = s.rzy + w * (r21 - s.rzy)
    s.rzz = s.rzz + w * (r22 - s.rzz)
    return (s.rxx * lx + s.ryx * ly + s.rzx * lz, s.rxy * lx + s.ryy * ly + s.rzy * lz,
            s.rxz * lx + s.ryz * ly + s.rzz * lz)


def regulate(s: StepState, p: Any, f: tuple, g: tuple, en: Any, u: tuple, v: tuple,
             quick: Any, tight: Any, learn: Any, dt: Any, o: Any) -> None:
    """Stage 5: the PI regulator on f; its integral state is the bias estimate, learned
    from g = R̄ᵀ·l (:func:`learning_input`).

    While the bias is uncertain (no still phase yet) the loop runs faster: k2 up to
    bias_learning_k2 in proportion to the bias variance (at most σ_b/σ_V: the vehicle's
    velocity swing, the raw error integrated in the world frame, must not move the estimate by
    more than its uncertainty), k1 kept at least critically damping it; a large swing lowers
    k1 below the configured one (bias.loop_gain). The correction
    q ← q ⊗ Exp(g(k1)·f) also turns the unit's memory by the share aperiodic_prefilter (quick:
    fully; tight clip: not at all).
    """
    fx, fy, fz = f
    ux, uy, uz = u
    vx, vy, vz = v
    wx, wy, _ = _rotate(s.qw, s.qx, s.qy, s.qz, s.ex, s.ey, s.ez)
    bias.observe_velocity_swing(s, wx, wy, dt, o)
    loop = bias.loop_gain(s, p, o)
    k1, k2 = bias.learning_gains(s, p, o, loop)
    s.loop_k1 = o.maximum(loop, 2.0 * o.sqrt(p.k2))  # without the raise
    # an error beyond the learning limit (BIAS_LEARNING_MAX_ERROR_RAD, widened by the samples'
    # scatter) is an attitude error (a gyro over range, a glitch), not a bias: the integral
    # does not learn from it (anti-windup; beyond 90° the cross product shrinks again, hence
    # the sign of the dot product too)
    small = (en < bias.learning_limit_rad(s, o)) & (ux * vx + uy * vy + uz * vz > 0.0)
    bias.integrate(s, p, g, k1, k2, learn, small, dt, o)
    # start-up in motion (a block that was not still, or a velocity that says so: moved is
    # also set by ComplementaryFilter.mark_moving): the running mean of the accelerometer
    # since initialisation (gain 1/t, the least-squares tilt of the samples so far, turned by
    # the gyro): started in the air, a flight's accelerations average out instead of the last
    # 1/startup_k1 s of one leg being taken for the vertical (and its decay for bias, once the
    # learning begins). Still (or not yet known): startup_k1, as a long mean would lag by the
    # gyro's bias × t/2 on a sensor at rest.
    averaging = (s.time_s <= p.startup_duration_s) & s.moved
    k1 = o.where(averaging, 1.0 / o.maximum(s.time_s, dt),
                 o.where(quick, o.maximum(k1, p.startup_k1), k1))
    gain = k1 * dt / (1.0 + k1 * dt)
    dw, dx, dy, dz = _exp(gain * fx, gain * fy, gain * fz, o)
    s.qw, s.qx, s.qy, s.qz = _mul(s.qw, s.qx, s.qy, s.qz, dw, dx, dy, dz)
    # 1: a pre-filter of the specific force whose memory matches the current estimate, as
    # VQF's; 0: the thesis's unit on the error. Not while a linear acceleration is detected
    # (the tight clip): what the unit holds then is the disturbance, and the thesis's unit
    # rejects it best (impacts 18.9' -> 17.8')
    dec = gain * o.where(quick, 1.0, o.where(tight, 0.0, p.prefilter))
    s.lx, s.ly, s.lz = s.lx - dec * s.lx, s.ly - dec * s.ly, s.lz - dec * s.lz


def recover(s: StepState, p: Any, clipped: Any, en: Any, limit: Any, learn: Any, dt: Any,
            o: Any) -> None:
    """After the regulator: a clip unbroken for recovery_trigger_s [s] is a real attitude
    error, not a disturbance: recovery (as start-up) until |e| < RECOVERY_EXIT_FRACTION · L."""
    s.clip_timer_s = o.where(clipped, s.clip_timer_s + dt, 0.0)
    enter = (p.recovery_trigger_s > 0.0) & (s.clip_timer_s >= p.recovery_trigger_s) & learn
    leave = s.recovering & (en < RECOVERY_EXIT_FRACTION * limit)
    s.recovery_count = s.recovery_count + o.where(enter, 1, 0)
    s.recovering = o.where(s.recovering, o.not_(leave), enter)
    s.clip_timer_s = o.where(enter, 0.0, s.clip_timer_s)
    s.clipped = clipped


def heading(s: StepState, p: Any, mag: tuple, fast: Any, learn: Any, o: Any) -> None:
    """Stage 6: the heading channel: one magnetometer sample (any unit) checked against the
    field reference, then the heading correction about the world vertical."""
    mx, my, mz = mag
    mn = o.sqrt(mx * mx + my * my + mz * mz)
    ux, uy, uz = mx / mn, my / mn, mz / mn
    wx, wy, wz = _rotate(s.qw, s.qx, s.qy, s.qz, ux, uy, uz)
    horizontal = o.sqrt(wx * wx + wy * wy)
    dip = o.atan2(-wz, horizontal)
    # time since the last used sample: the drift allowed to the predicted direction, and
    # (capped) how long one correction stands for
    age = o.where(s.mag_last_time_s < 0.0, 0.0, s.time_s - s.mag_last_time_s)
    dt_m = o.minimum(age, MAG_MAX_DT_S)

    dt_s = o.minimum(
        o.where(s.mag_seen_time_s < 0.0, 0.0, s.time_s - s.mag_seen_time_s), MAG_MAX_DT_S
    )
    fresh = s.mag_seen_time_s < 0.0
    s.mag_seen_time_s = s.time_s

    # field reference (norm, dip, direction): learned at start, re-learned when a rejected field
    # has been steady and turned as the gyro says for as long as the reference was in use
    in_use = o.where(s.mag_last_time_s < 0.0, 0.0, s.mag_last_time_s - s.mag_ref_time_s)
    relearn = s.mag_cand_timer_s > o.minimum(o.maximum(in_use, MAG_SETTLE_S), MAG_RELEARN_AFTER_S)
    s.mag_ref_count = o.where(relearn, 0, s.mag_ref_count)
    s.mag_ref_time_s = o.where(relearn, s.time_s, s.mag_ref_time_s)
    s.mag_cand_timer_s = o.where(relearn, 0.0, s.mag_cand_timer_s)
    s.mvx, s.mvy, s.mvz = (o.where(relearn, s.mcx, s.mvx), o.where(relearn, s.mcy, s.mvy),
                           o.where(relearn, s.mcz, s.mvz))
    learning = p.use_mag & (s.mag_ref_count < MAG_REFERENCE_SAMPLES)
    n = s.mag_ref_count + 1
    s.mag_ref_norm = o.where(learning, s.mag_ref_norm + (mn - s.mag_ref_norm) / n, s.mag_ref_norm)
    s.mag_ref_dip = o.where(learning, s.mag_ref_dip + (dip - s.mag_ref_dip) / n, s.mag_ref_dip)
    s.mag_ref_count = o.where(learning, n, s.mag_ref_count)
    off_norm = o.maximum(
        mn / o.maximum(s.mag_ref_norm, TINY) - 1.0, 1.0 - mn / o.maximum(s.mag_ref_norm, TINY)
    )
    off_dip = o.maximum(dip - s.mag_ref_dip, s.mag_ref_dip - dip)
    # the measured direction, low-passed (every sample; turned by the gyro between samples)
    a = o.where(fresh, 1.0, dt_s / (MAG_SMOOTH_TIME_CONSTANT_S + dt_s))
    mmx, mmy, mmz = _toward_unit((s.mmx, s.mmy, s.mmz), (ux, uy, uz), a, o)
    s.mmx, s.mmy, s.mmz = mmx, mmy, mmz
    # a field that turned when the body did not: the measured direction against the one the
    # gyro predicts (tolerance: noise, a calibration's leftover times the angle turned, drift)
    tol = MAG_TURN_TOLERANCE_RAD + MAG_TURN_FRACTION * MAG_TURN_TIME_CONSTANT_S * s.rate_lp
    drift = MAG_DRIFT_SIGMAS * o.sqrt(o.maximum(s.bias_var, 0.0)) * age
    turned = o.sqrt(sq(mmx - s.mvx) + sq(mmy - s.mvy) + sq(mmz - s.mvz)) > tol + drift
    off = (off_norm > p.mag_field_tolerance) | (off_dip > p.mag_field_tolerance) | turned
    # latched: after the field turned, used again only once it agrees for MAG_SETTLE_S
    # unbroken (a single sample off in norm or dip is noise: rejected alone)
    s.mag_ok_timer_s = o.where(learning, MAG_SETTLE_S,
                               o.where(turned, 0.0, s.mag_ok_timer_s + dt_s))
    disturbed = (
        p.mag_rejection & o.not_(learning) & (off | (s.mag_ok_timer_s < MAG_SETTLE_S))
    )
    s.mag_disturbed = disturbed
    # the candidate: a rejected field that keeps the norm and the direction (turned by the gyro)
    # it had when the candidate began; over seconds a magnet on a turning body moves away from
    # both, a world-fixed field does not
    drift_c = MAG_DRIFT_SIGMAS * o.sqrt(o.maximum(s.bias_var, 0.0)) * s.mag_cand_timer_s
    cand_moved = (
        (o.sqrt(sq(mmx - s.mcx) + sq(mmy - s.mcy) + sq(mmz - s.mcz))
         > 2.0 * MAG_TURN_TOLERANCE_RAD + drift_c)
        | (o.maximum(mn - s.mag_cand_norm, s.mag_cand_norm - mn)
           > MAG_CANDIDATE_NORM_TOLERANCE * s.mag_cand_norm)
    )
    keep = disturbed & o.not_(cand_moved)
    # a candidate that moved after the body turned by more than its tolerance moved with the
    # body: the field is on the sensor (a magnet), it does not say the heading is wrong
    turned_away = s.rate_lp * s.mag_cand_timer_s > 2.0 * MAG_TURN_TOLERANCE_RAD
    s.mag_on_body = disturbed & (s.mag_on_body | (cand_moved & turned_away))
    s.mag_cand_timer_s = o.where(keep, s.mag_cand_timer_s + dt_s, 0.0)
    s.mcx, s.mcy, s.mcz = (o.where(keep, s.mcx, mmx), o.where(keep, s.mcy, mmy),
                           o.where(keep, s.mcz, mmz))
    s.mag_cand_norm = o.where(keep, s.mag_cand_norm, mn)
    a = o.where(fresh, 1.0, dt_s / (MAG_TURN_TIME_CONSTANT_S + dt_s))
    s.mvx, s.mvy, s.mvz = _toward_unit((s.mvx, s.mvy, s.mvz), (ux, uy, uz),
                                       o.where(disturbed, 0.0, a), o)

    usable = p.use_mag & o.not_(disturbed) & (horizontal > MAG_MIN_HORIZONTAL)
    s.mag_status = o.where(p.use_mag, o.where(disturbed, MAG_REJECTED, MAG_USED), MAG_DISABLED)
    s.mag_last_time_s = o.where(usable, s.time_s, s.mag_last_time_s)
    first = usable & o.not_(s.heading_initialized)
    s.heading_initialized = s.heading_initialized | usable

    # heading recovery (as the tilt's): a heading error saturated without a break for
    # recovery_trigger_s of used samples is a real heading error (a compass that was wrong at
    # start, a magnetometer that came back): corrected with startup_k1 until below 0.1 × the limit
    yaw_error = o.atan2(wx, wy)
    big = o.maximum(yaw_error, -yaw_error) > p.mag_saturation_limit_rad
    s.mag_clip_timer_s = o.where(usable, o.where(big & learn & o.not_(first),
                                                 s.mag_clip_timer_s + dt_m, 0.0),
                                 o.where(disturbed, 0.0, s.mag_clip_timer_s))
    enter = (p.recovery_trigger_s > 0.0) & (s.mag_clip_timer_s >= p.recovery_trigger_s)
    leave = usable & (o.maximum(yaw_error, -yaw_error)
                      < MAG_RECOVERY_EXIT_FRACTION * p.mag_saturation_limit_rad)
    s.mag_recovering = o.where(s.mag_recovering, o.not_(leave), enter)
    s.mag_clip_timer_s = o.where(enter, 0.0, s.mag_clip_timer_s)
    quick = fast | s.mag_recovering
    r1 = o.where(quick, o.maximum(p.r1, p.startup_k1), p.r1)
    gain = o.where(usable, r1 * dt_m / (1.0 + r1 * dt_m), 0.0)
    ldt = o.where(usable & learn, dt_m, 0.0)
    limit = o.where(quick, MAG_QUICK_LIMIT_RAD, p.mag_saturation_limit_rad)

    # rotate about the world vertical by the heading error the sample implies (the first fix:
    # all of it): used, or rejected but not seen to move with the body (a field that may be the
    # truth and the heading wrong: covariance.py reports it)
    s.yaw_error_rad = o.where(usable | (disturbed & o.not_(s.mag_on_body)), yaw_error, 0.0)
    yaw_c = o.minimum(o.maximum(yaw_error, -limit), limit)
    angle = o.where(first, yaw_error, gain * yaw_c)
    s.z_m = s.z_m + o.where(first, 0.0, p.r2 * ldt * yaw_c)
    turn_heading(s, angle, o)
