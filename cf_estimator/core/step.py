"""The 3-D compensation-scheme step: the filter's equations, written once for floats and arrays.

One sample, in the order the code runs (world frame ENU inside; q = q_world_from_sensor)::

    1. predict    q⁻ = Exp_z(z_m·dt) ⊗ q ⊗ Exp((ω − b)·dt)
                  (gyro ω, bias estimate b; z_m: heading channel's world-vertical rate)
    2. error      e = (a/‖g‖) × ĝ,  ĝ = R⁻ᵀ·ẑ   (Ryzhkov & Karpenko: scaled by gravity, not |a|)
                  (≈ small-angle tilt error; linear in the linear acceleration)
    3. saturate   e_s = e·min(1, L/|e|)                     (by norm, keeps the direction)
                  L = saturation_limit_rad while a linear acceleration is present and the gyro
                  is still (impacts, vibration, manoeuvres), else wide_saturation_limit_rad
    4. aperiodic  l ← l + dt/(T+dt)·(R⁻·e_s − l);  f = R⁻ᵀ·l  (1/(T s+1) in the world frame)
    5. regulator  c ← c + k3·dt·f;  b ← b − dt·(k2'·f + c);  q ← q⁻ ⊗ Exp(g(k1')·f)
                  (W1 = k1 + k2/s + k3/s²; g(k) = k·dt/(1+k·dt), the backward-Euler gain;
                  b, the integral state, is the gyro-bias estimate; k2' = max(k2,
                  bias_learning_k2·σ_b²/σ_0²) and k1' = max(k1, 2√k2') while the bias is
                  uncertain); then l ← l − p·g(k1')·l with p = aperiodic_prefilter (0 while
                  the tight clip is on): the correction also turns the unit's memory (p = 1: a
                  pre-filter of the specific force in the world frame, as VQF's; p = 0: the
                  thesis's unit on the error)
    6. magnetom.  'yaw':  e_ψ = atan2(m_E, m_N) of the measured field in the world frame,
                  saturated; q ← Exp_z(g(r1)·e_ψ) ⊗ q; z_m ← z_m + r2·dt_m·e_ψ (heading only:
                  a rotation about the world vertical never changes roll/pitch); saturated
                  for recovery_trigger_s: heading recovery with startup_k1 (as the tilt's)
                  'full': e_m = m̂ × (R⁻ᵀ·m_ref) through W2 = r1 + r2/s on all axes (Ryzhkov, drift)

Stillness and bias (``_stillness``): on blocks of rest_window_s, a block whose gyro and
accelerometer means did not change from the previous block (beyond the thresholds plus the
noise measured from sample-to-sample differences: vibration-robust; a constant bias cancels) is
still; rest_time_s of still blocks is rest. At rest each still block's gyro mean is a bias
measurement, fused by variance (scalar Kalman update; σ_b = √bias_var starts at
bias_prior_sigma_rad_s, grows by a random walk, shrinks with each measurement and, in motion,
with the integral's learning). Vibration widens the thresholds by at most REST_NOISE_CAP times
themselves; a turning magnetic field is motion; a steady block far from the bias estimate (on
any axis, REST_GATE_SIGMAS) is a constant-rate turn, not rest, however long it lasts.

Linear acceleration (the tight clip) is detected when the 50 ms low-passed | |a| − ‖g‖ | exceeds
acceleration_threshold_m_s2 plus ACCEL_DETECT_SIGMAS of the vibration left in the low-pass, or
at once for a spike (an impact).

Phases: STARTUP (after initialisation, for startup_duration_s: gain startup_k1, no clip, the
unit bypassed, no integral learning) → RUNNING → RECOVERING (error clipped without a break for
recovery_trigger_s: a real attitude error, e.g. after gyro over-range; same as STARTUP until
|e| < L/2) → RUNNING. At rest the error path also runs as in STARTUP while the block's |a| is
within acceleration_threshold_m_s2 of ‖g‖ (nothing to reject: an error left by motion is removed
fast). While bypassed the unit follows the error with a 0.2 s lag, turned by each correction.
"""

from __future__ import annotations

from typing import Any

PHASE_UNINITIALIZED = 0
PHASE_STARTUP = 1
PHASE_RUNNING = 2
PHASE_RECOVERING = 3
PHASE_NAMES = {0: "uninitialized", 1: "startup", 2: "running", 3: "recovering"}

MAG_NONE = 0  # no magnetometer sample at this step
MAG_USED = 1  # used for heading
MAG_REJECTED = 2  # norm or dip off the learned reference: disturbance, ignored
MAG_DISABLED = 3  # use_mag is off
MAG_STATUS_NAMES = {0: "none", 1: "used", 2: "rejected", 3: "disabled"}

#: Low-pass time constant of the rotation rate that selects the clip level [s].
RATE_LOWPASS_TIME_CONSTANT_S = 0.5
#: Low-pass time constant [s] of the accelerometer for the linear-acceleration detector:
#: rotor vibration (50-200 Hz) averages out, a manoeuvre does not.
ACCEL_LOWPASS_TIME_CONSTANT_S = 0.05
#: A single accelerometer sample this many noise standard deviations (measured by the stillness
#: blocks) off ‖g‖ is an impact: the detector takes it at once, unfiltered.
ACCEL_SPIKE_SIGMAS = 4.0
#: The low-passed | |a| − ‖g‖ | must exceed acceleration_threshold_m_s2 by this many standard
#: deviations of what vibration leaves in the low-pass: rotor vibration is not a manoeuvre.
ACCEL_DETECT_SIGMAS = 3.0
#: Time constant [s] of the aperiodic unit while the error bypasses it (start-up, rest, recovery).
QUICK_LAG_TIME_CONSTANT_S = 0.2
#: Stillness: a change of the block means within this many standard deviations of the observed
#: noise floor is no change (the floor includes rotor vibration, so vibration is not motion) ...
REST_NOISE_SIGMAS = 2.0
#: ... but the noise may widen each threshold by at most this multiple of the threshold itself:
#: rotor vibration never widens "still" until flight fits inside it (phantom4, 3-6 m/s² of
#: vibration: uncapped, 17 of 40 airborne recordings were taken for rest).
REST_NOISE_CAP = 1.0
#: Stillness with a magnetometer: the block-mean field direction (unit vector, sensor frame) may
#: turn by at most this plus rest_gyro_threshold_rad_s × the block length [rad]; more is a turn
#: (a steady turn looks still to the gyro and accelerometer, never to the magnetometer).
REST_MAG_TOLERANCE_RAD = 0.01
#: A single sample this many noise standard deviations (plus the thresholds) away from the last
#: block mean ends a still phase at once, without waiting for the block to end.
REST_SAMPLE_SIGMAS = 8.0
#: A steady block whose gyro mean is, on any axis, this many standard deviations (of the bias
#: estimate and of the block mean) from the bias estimate is a steady turn, not rest — however
#: long it lasts: biases drift (BIAS_RANDOM_WALK_RAD_S_SQRT_S), they do not jump. At power-on
#: the prior bias_prior_sigma_rad_s bounds what a still phase may take as bias.
REST_GATE_SIGMAS = 3.0
#: The integral (bias) learns only while the raw error is below this [rad]: a bias within the
#: prior leaves an error of at most a few REST_GATE_SIGMAS·bias_prior_sigma_rad_s / k1 (< 0.2
#: rad at the defaults); more is an attitude error, which must not wind the bias up.
BIAS_LEARNING_MAX_ERROR_RAD = 0.35
#: Bias random walk [rad/s/sqrt(s)]: how fast the confidence in a learned bias fades.
BIAS_RANDOM_WALK_RAD_S_SQRT_S = 2e-4
#: The bias estimate counts as converged below this standard deviation [rad/s].
BIAS_CONVERGED_SIGMA_RAD_S = 0.005
#: Time constant [s] with which ‖g‖ follows |a| while the sensor is steady: slow enough that a
#: steady linear acceleration of a few seconds (the thesis's 25 m/s in 5 s) is not absorbed.
GRAVITY_TIME_CONSTANT_S = 10.0
#: Magnetometer samples averaged for the field reference (norm, dip) after start-up.
MAG_REFERENCE_SAMPLES = 20
#: A magnetic field rejected this long [s] is taken as the new normal and re-learned.
MAG_RELEARN_AFTER_S = 20.0
#: Longest time [s] one magnetometer sample's correction may stand for (sparse magnetometers).
MAG_MAX_DT_S = 1.0


class StepState:
    """Filter state; each attribute is a float/bool (one filter) or an array (P parameter sets).

    Frames and units: q* = q_world(ENU)_from_sensor; b* gyro-bias estimate [rad/s, sensor];
    c* k3-path state [rad/s², sensor]; l* aperiodic-unit state [rad, world]; z_m yaw-rate
    correction [rad/s, world z]; e* last raw error [rad, sensor]; f* last processed error.
    Stillness: blk_* sums of the current block (gyro [rad/s], accel [m/s²], *2 sums of squared
    differences), p* means of the previous block, l* the last sample, noise_*2 the last block's
    noise variance (sum over axes), blk_m* / pm* the current / previous block's sum / mean of
    unit magnetometer vectors (pm_n: how many samples the previous block had),
    bias_var variance of the bias estimate [(rad/s)²] (per axis); moved: a non-still block was
    seen since initialisation; bias_unverified: the last rest bias measurement came from a still
    phase at power-on without a magnetometer (a steady turn then cannot be told from rest);
    mag_clip_timer_s / mag_recovering: the heading channel's recovery (as the tilt's).
    """

    FIELDS = [
        "qw",
        "qx",
        "qy",
        "qz",
        "bx",
        "by",
        "bz",
        "cx",
        "cy",
        "cz",
        "lx",
        "ly",
        "lz",
        "z_m",
        "time_s",
        "clip_timer_s",
        "recovering",
        "rest_timer_s",
        "blk_n",
        "blk_t",
        "blk_gx",
        "blk_gy",
        "blk_gz",
        "blk_ax",
        "blk_ay",
        "blk_az",
        "blk_g2",
        "blk_a2",
        "prev_n",
        "pgx",
        "pgy",
        "pgz",
        "pax",
        "pay",
        "paz",
        "blk_d",
        "last_n",
        "lgx",
        "lgy",
        "lgz",
        "lax",
        "lay",
        "laz",
        "noise_g2",
        "noise_a2",
        "bias_var",
        "blk_mx",
        "blk_my",
        "blk_mz",
        "blk_mn",
        "pmx",
        "pmy",
        "pmz",
        "pm_n",
        "moved",
        "bias_unverified",
        "mag_clip_timer_s",
        "mag_recovering",
        "at_rest",
        "mag_ref_norm",
        "mag_ref_dip",
        "mag_ref_count",
        "mag_disturbed",
        "mag_reject_timer_s",
        "mag_last_time_s",
        "heading_initialized",
        "g_ref",
        "accel_hold",
        "acx",
        "acy",
        "acz",
        "rate_lp",
        "ex",
        "ey",
        "ez",
        "error_norm",
        "fx",
        "fy",
        "fz",
        "clipped",
        "accel_used",
        "mag_status",
        "yaw_error_rad",
        "phase",
        "recovery_count",
    ]

    BOOL_FIELDS = (
        "recovering",
        "at_rest",
        "mag_disturbed",
        "heading_initialized",
        "clipped",
        "accel_used",
        "moved",
        "bias_unverified",
        "mag_recovering",
    )

    def __init__(self, zero: Any, false: Any) -> None:
        """``zero``/``false``: 0.0/False for one filter, or zero/False arrays of shape (P,)."""
        for name in self.FIELDS:
            setattr(self, name, zero * 1.0)
        for name in self.BOOL_FIELDS:
            setattr(self, name, false & True)
        self.qw = zero + 1.0
        self.mag_last_time_s = zero - 1.0
        self.bias_var = zero - 1.0  # < 0: not yet set from the parameters (first step sets it)

    def copy(self) -> StepState:
        """A copy (arrays copied too)."""
        new = StepState.__new__(StepState)
        for name in self.FIELDS:
            value = getattr(self, name)
            setattr(new, name, value.copy() if hasattr(value, "copy") else value)
        return new


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


def _turn_heading(s: StepState, angle: Any, o: Any) -> None:
    """q ← Exp_z(angle) ⊗ q (a world-vertical rotation), and the world-frame lag state with it.

    Turning the lag state too keeps the tilt path exactly independent of heading corrections:
    f = Rᵀ·l is unchanged, so the magnetometer can never move roll/pitch.
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


def _normalize(s: StepState, o: Any) -> None:
    n = o.sqrt(s.qw * s.qw + s.qx * s.qx + s.qy * s.qy + s.qz * s.qz)
    s.qw, s.qx, s.qy, s.qz = s.qw / n, s.qx / n, s.qy / n, s.qz / n


def _stillness(s: StepState, p: Any, gyro: tuple, accel: tuple, mag: tuple | None, dt: Any,
               o: Any) -> None:
    """Stillness detection and bias learning at rest, on blocks of ``rest_window_s``.

    Still = the gyro and accelerometer block means did not change from the previous block by
    more than the thresholds plus REST_NOISE_SIGMAS standard deviations of a block-mean
    difference. The noise (sensor noise and rotor vibration) is measured in each block from
    sample-to-sample differences, which slow motion hardly changes: vibration averages out in a
    block mean and widens the tolerance by what it adds to it; a constant gyro bias cancels in
    the difference. After ``rest_time_s`` of still blocks the sensor is at rest: each further
    still block is a measurement of the bias (its gyro mean, variance from its noise), fused
    with the estimate by its variance (a scalar Kalman update), and ‖g‖ follows |a| slowly.
    The noise widens the thresholds by at most REST_NOISE_CAP times themselves; with a
    magnetometer a turning field direction is motion (REST_MAG_TOLERANCE_RAD).
    """
    gx, gy, gz = gyro
    ax, ay, az = accel
    s.blk_n = s.blk_n + 1.0
    s.blk_t = s.blk_t + dt
    s.blk_gx, s.blk_gy, s.blk_gz = s.blk_gx + gx, s.blk_gy + gy, s.blk_gz + gz
    s.blk_ax, s.blk_ay, s.blk_az = s.blk_ax + ax, s.blk_ay + ay, s.blk_az + az
    # squared sample-to-sample differences (noise); the first sample has none
    seen = o.where(s.last_n > 0.0, 1.0, 0.0)
    s.blk_g2 = s.blk_g2 + seen * ((gx - s.lgx) ** 2 + (gy - s.lgy) ** 2 + (gz - s.lgz) ** 2)
    s.blk_a2 = s.blk_a2 + seen * ((ax - s.lax) ** 2 + (ay - s.lay) ** 2 + (az - s.laz) ** 2)
    s.blk_d = s.blk_d + seen
    s.lgx, s.lgy, s.lgz, s.lax, s.lay, s.laz = gx, gy, gz, ax, ay, az
    s.last_n = s.last_n + 1.0
    if mag is not None:  # unit field direction, sensor frame (any unit in)
        mx, my, mz = mag
        mn = o.sqrt(mx * mx + my * my + mz * mz)
        use = o.where(p.use_mag, 1.0, 0.0)
        s.blk_mx = s.blk_mx + use * mx / mn
        s.blk_my = s.blk_my + use * my / mn
        s.blk_mz = s.blk_mz + use * mz / mn
        s.blk_mn = s.blk_mn + use
    has_prev = s.prev_n > 0.0
    # a sample far outside the noise around the last block's mean ends rest at once
    jump_g = o.sqrt((gx - s.pgx) ** 2 + (gy - s.pgy) ** 2 + (gz - s.pgz) ** 2) > (
        p.rest_gyro_threshold_rad_s + REST_SAMPLE_SIGMAS * o.sqrt(s.noise_g2))
    jump_a = o.sqrt((ax - s.pax) ** 2 + (ay - s.pay) ** 2 + (az - s.paz) ** 2) > (
        p.rest_accel_threshold_m_s2 + REST_SAMPLE_SIGMAS * o.sqrt(s.noise_a2))
    s.rest_timer_s = o.where(has_prev & (jump_g | jump_a), 0.0, s.rest_timer_s)

    done = s.blk_t >= p.rest_window_s
    n = s.blk_n
    mgx, mgy, mgz = s.blk_gx / n, s.blk_gy / n, s.blk_gz / n
    max_, may, maz = s.blk_ax / n, s.blk_ay / n, s.blk_az / n
    # white-noise variance (sum over axes) from differences: E|x_k - x_k-1|^2 = 2 var
    nd = 2.0 * o.maximum(s.blk_d, 1.0)
    noise_g2, noise_a2 = s.blk_g2 / nd, s.blk_a2 / nd
    spread = 1.0 / n + 1.0 / o.maximum(s.prev_n, 1.0)
    dg = o.sqrt((mgx - s.pgx) ** 2 + (mgy - s.pgy) ** 2 + (mgz - s.pgz) ** 2)
    da = o.sqrt((max_ - s.pax) ** 2 + (may - s.pay) ** 2 + (maz - s.paz) ** 2)
    tol_g = p.rest_gyro_threshold_rad_s + REST_NOISE_SIGMAS * o.minimum(
        o.sqrt(noise_g2 * spread), REST_NOISE_CAP * p.rest_gyro_threshold_rad_s)
    tol_a = p.rest_accel_threshold_m_s2 + REST_NOISE_SIGMAS * o.minimum(
        o.sqrt(noise_a2 * spread), REST_NOISE_CAP * p.rest_accel_threshold_m_s2)
    # the field direction of this block against the previous one (both with samples)
    mag_seen = (s.blk_mn > 0.0) & (s.pm_n > 0.0)
    bm = o.maximum(o.sqrt(s.blk_mx * s.blk_mx + s.blk_my * s.blk_my + s.blk_mz * s.blk_mz),
                   1e-300)
    umx, umy, umz = s.blk_mx / bm, s.blk_my / bm, s.blk_mz / bm
    dm = o.sqrt((umx - s.pmx) ** 2 + (umy - s.pmy) ** 2 + (umz - s.pmz) ** 2)
    turned = mag_seen & (dm > REST_MAG_TOLERANCE_RAD + p.rest_gyro_threshold_rad_s * s.blk_t)
    steady = (
        has_prev
        & (dg < tol_g)
        & (da < tol_a)
        & o.not_(turned)
        & (o.sqrt(mgx * mgx + mgy * mgy + mgz * mgz) < p.bias_limit_rad_s * 1.7320508075688772)
    )
    # a steady turn at a constant rate looks still; a block whose gyro mean is far from the bias
    # estimate on any axis (beyond REST_GATE_SIGMAS of the estimate's and the block's spread) is
    # motion however long it lasts
    r = o.maximum(noise_g2 / (3.0 * n), 1e-12)
    gate = p.rest_gyro_threshold_rad_s + REST_GATE_SIGMAS * o.sqrt(s.bias_var + r)
    consistent = ((o.maximum(mgx - s.bx, s.bx - mgx) < gate)
                  & (o.maximum(mgy - s.by, s.by - mgy) < gate)
                  & (o.maximum(mgz - s.bz, s.bz - mgz) < gate))
    still = steady & consistent
    s.moved = s.moved | (done & has_prev & o.not_(still))
    s.rest_timer_s = o.where(done, o.where(still, s.rest_timer_s + s.blk_t, 0.0), s.rest_timer_s)
    s.at_rest = p.rest_bias_learning & (s.rest_timer_s >= p.rest_time_s)
    # a still block at rest measures the bias: scalar Kalman update per axis
    measure = done & s.at_rest
    s.bias_unverified = o.where(measure, o.not_(s.moved) & o.not_(mag_seen), s.bias_unverified)
    k = o.where(measure, s.bias_var / (s.bias_var + r), 0.0)
    s.bx, s.by, s.bz = s.bx + k * (mgx - s.bx), s.by + k * (mgy - s.by), s.bz + k * (mgz - s.bz)
    s.bias_var = s.bias_var - k * s.bias_var
    gw = o.where(done & still, s.blk_t / (GRAVITY_TIME_CONSTANT_S + s.blk_t), 0.0)
    s.g_ref = s.g_ref + gw * (o.sqrt(max_ * max_ + may * may + maz * maz) - s.g_ref)
    # next block
    s.noise_g2 = o.where(done, noise_g2, s.noise_g2)
    s.noise_a2 = o.where(done, noise_a2, s.noise_a2)
    s.pgx, s.pgy, s.pgz = (o.where(done, mgx, s.pgx), o.where(done, mgy, s.pgy),
                           o.where(done, mgz, s.pgz))
    s.pax, s.pay, s.paz = (o.where(done, max_, s.pax), o.where(done, may, s.pay),
                           o.where(done, maz, s.paz))
    s.prev_n = o.where(done, n, s.prev_n)
    has_mag = done & (s.blk_mn > 0.0)
    s.pmx, s.pmy, s.pmz = (o.where(has_mag, umx, s.pmx), o.where(has_mag, umy, s.pmy),
                           o.where(has_mag, umz, s.pmz))
    s.pm_n = o.where(done, s.blk_mn, s.pm_n)
    keep = o.where(done, 0.0, 1.0)
    s.blk_n, s.blk_t, s.blk_d = s.blk_n * keep, s.blk_t * keep, s.blk_d * keep
    s.blk_gx, s.blk_gy, s.blk_gz = s.blk_gx * keep, s.blk_gy * keep, s.blk_gz * keep
    s.blk_ax, s.blk_ay, s.blk_az = s.blk_ax * keep, s.blk_ay * keep, s.blk_az * keep
    s.blk_g2, s.blk_a2 = s.blk_g2 * keep, s.blk_a2 * keep
    s.blk_mx, s.blk_my, s.blk_mz = s.blk_mx * keep, s.blk_my * keep, s.blk_mz * keep
    s.blk_mn = s.blk_mn * keep


def step(
    s: StepState,
    p: Any,
    gyro: tuple[float, float, float],
    accel: tuple[float, float, float] | None,
    mag: tuple[float, float, float] | None,
    dt: float,
    o: Any,
) -> None:
    """Advance the state one sample (see the module docstring).

    ``p`` has the FilterParams field names (floats, or arrays for a batch) plus ``mag_full``.
    ``accel``/``mag`` are None when absent or invalid at this sample (the caller checks
    finiteness and non-zero norm). ``dt`` > 0 [s].
    """
    gx, gy, gz = gyro
    s.time_s = s.time_s + dt
    s.bias_var = o.where(s.bias_var < 0.0, p.bias_prior_sigma_rad_s ** 2, s.bias_var) + (
        BIAS_RANDOM_WALK_RAD_S_SQRT_S ** 2 * dt)
    startup = s.time_s <= p.startup_duration_s
    fast = startup | s.recovering  # trust the accelerometer fully, learn no bias
    learn = o.not_(fast)

    # 1. predict with the bias-corrected gyro, then the magnetometer's yaw-rate correction
    dw, dx, dy, dz = _exp((gx - s.bx) * dt, (gy - s.by) * dt, (gz - s.bz) * dt, o)
    qw, qx, qy, qz = _mul(s.qw, s.qx, s.qy, s.qz, dw, dx, dy, dz)
    s.qw, s.qx, s.qy, s.qz = qw, qx, qy, qz
    _turn_heading(s, s.z_m * dt, o)

    s.clipped = s.clipped & False
    s.accel_used = accel is not None
    if accel is not None:
        ax, ay, az = accel
        an = o.sqrt(ax * ax + ay * ay + az * az)
        s.g_ref = o.where(s.g_ref > 0.0, s.g_ref, p.gravity_m_s2)  # ‖g‖: prior, learned below
        deviation = o.maximum(an - s.g_ref, s.g_ref - an)  # | |a| - ‖g‖ |
        # an impact: a single sample far above the noise of the last block (see the detector)
        spike = deviation > p.acceleration_threshold_m_s2 + ACCEL_SPIKE_SIGMAS * o.sqrt(
            s.noise_a2)
        _stillness(s, p, gyro, accel, mag, dt, o)
        # at rest the block mean of the gyro is the bias, whatever the accelerometer says; but
        # the error path trusts the accelerometer only if |a| = ‖g‖: a steady linear
        # acceleration (constant accelerometer, still gyro: the 25 m/s manoeuvre) is not gravity
        steady_g = o.sqrt(s.pax * s.pax + s.pay * s.pay + s.paz * s.paz)  # last block's |a|
        # ... and only without strong vibration: at startup_k1 it would pass into the attitude
        quick = fast | (s.at_rest & (o.maximum(steady_g - s.g_ref, s.g_ref - steady_g)
                                     < p.acceleration_threshold_m_s2)
                        & (s.noise_a2 < p.acceleration_threshold_m_s2 ** 2))
        # linear-acceleration detector: peak hold of | |a| - ‖g‖ |
        # linear-acceleration detector, blind to vibration: | |a| - ‖g‖ | of the accelerometer
        # low-passed over ACCEL_LOWPASS_TIME_CONSTANT_S, or of this very sample when it is a
        # spike far above the noise measured by the stillness blocks (an impact)
        aw = o.where(s.last_n <= 1.0, 1.0, dt / (ACCEL_LOWPASS_TIME_CONSTANT_S + dt))
        s.acx, s.acy, s.acz = (s.acx + aw * (ax - s.acx), s.acy + aw * (ay - s.acy),
                               s.acz + aw * (az - s.acz))
        an_lp = o.sqrt(s.acx * s.acx + s.acy * s.acy + s.acz * s.acz)
        level = o.where(spike, deviation, o.maximum(an_lp - s.g_ref, s.g_ref - an_lp))
        decayed = s.accel_hold * (p.acceleration_hold_s / (p.acceleration_hold_s + dt))
        s.accel_hold = o.maximum(level, decayed)
        # vibration left in the low-pass (white-noise approximation of the 1st-order low-pass,
        # per axis, from the stillness blocks' noise): not a manoeuvre
        lp_sigma = o.sqrt(s.noise_a2 / 3.0 * dt / (2.0 * ACCEL_LOWPASS_TIME_CONSTANT_S + dt))
        accelerating = s.accel_hold > p.acceleration_threshold_m_s2 + ACCEL_DETECT_SIGMAS * lp_sigma
        rate = o.sqrt((gx - s.bx) ** 2 + (gy - s.by) ** 2 + (gz - s.bz) ** 2)
        lw = dt / (RATE_LOWPASS_TIME_CONSTANT_S + dt)
        s.rate_lp = s.rate_lp + lw * (rate - s.rate_lp)
        # Ryzhkov & Karpenko: e = (a/‖g‖) × ĝ — scaled by gravity, not by |a|, so the error stays
        # linear in the linear acceleration and the aperiodic unit averages zero-mean
        # accelerations out
        ux, uy, uz = ax / s.g_ref, ay / s.g_ref, az / s.g_ref
        # 2. predicted gravity (up) direction in the sensor frame: third row of R
        vx = 2.0 * (s.qx * s.qz - s.qw * s.qy)
        vy = 2.0 * (s.qy * s.qz + s.qw * s.qx)
        vz = 1.0 - 2.0 * (s.qx * s.qx + s.qy * s.qy)
        ex, ey, ez = uy * vz - uz * vy, uz * vx - ux * vz, ux * vy - uy * vx
        en = o.sqrt(ex * ex + ey * ey + ez * ez)
        s.ex, s.ey, s.ez, s.error_norm = ex, ey, ez, en
        # 3. saturation by norm
        # tight clip only for linear acceleration on a still gyro (impacts, vibration, manoeuvres)
        tight = accelerating & (s.rate_lp < p.rotation_threshold_rad_s)
        limit = o.where(tight, p.saturation_limit_rad, p.wide_saturation_limit_rad)
        clipped = p.use_saturation & o.not_(quick) & (en > limit)
        scale = o.where(clipped, limit / o.maximum(en, 1e-300), 1.0)
        # 4. aperiodic unit in the world frame (weight 1 = unit bypassed)
        wx, wy, wz = _rotate(s.qw, s.qx, s.qy, s.qz, ex * scale, ey * scale, ez * scale)
        weight = dt / (o.where(quick, QUICK_LAG_TIME_CONSTANT_S, p.aperiodic_time_constant_s) + dt)
        s.lx = s.lx + weight * (wx - s.lx)
        s.ly = s.ly + weight * (wy - s.ly)
        s.lz = s.lz + weight * (wz - s.lz)
        # quick (start-up, recovery, rest): the error bypasses the unit, which follows it with a
        # short lag and is turned by every quick correction (below), so that when the bypass
        # ends it holds the recent error as the current estimate sees it: not the last noisy
        # sample, nor a memory of errors the quick loop has already removed
        lx, ly, lz = o.where(quick, wx, s.lx), o.where(quick, wy, s.ly), o.where(quick, wz, s.lz)
        fx, fy, fz = _rotate(s.qw, -s.qx, -s.qy, -s.qz, lx, ly, lz)
        s.fx, s.fy, s.fz = fx, fy, fz
        # 5. PI(+k3) regulator: integral states are the bias estimate. While the bias is
        # uncertain (no still phase yet) the loop runs faster: k2 up to bias_learning_k2 in
        # proportion to the bias variance, k1 kept at least critically damping it
        share = o.minimum(s.bias_var / (p.bias_prior_sigma_rad_s ** 2), 1.0)
        k2 = o.maximum(p.k2, p.bias_learning_k2 * share)
        k1 = o.maximum(p.k1, 2.0 * o.sqrt(k2))
        k3dt = o.where(learn, p.k3 * dt, 0.0)
        s.cx, s.cy, s.cz = s.cx + k3dt * fx, s.cy + k3dt * fy, s.cz + k3dt * fz
        # an error beyond BIAS_LEARNING_MAX_ERROR_RAD is an attitude error (a gyro over range, a
        # glitch), not a bias: the integral does not learn from it (anti-windup; beyond 90° the
        # cross product shrinks again, hence the sign of the dot product too)
        small = (en < BIAS_LEARNING_MAX_ERROR_RAD) & (ux * vx + uy * vy + uz * vz > 0.0)
        ldt = o.where(learn & small, dt, 0.0)
        s.bx = s.bx - ldt * (k2 * fx + s.cx)
        s.by = s.by - ldt * (k2 * fy + s.cy)
        s.bz = s.bz - ldt * (k2 * fz + s.cz)
        # the integral learns the bias with time constant ~k1/k2: its variance shrinks so
        s.bias_var = s.bias_var / (1.0 + ldt * k2 / o.maximum(k1, 1e-3))
        k1 = o.where(quick, o.maximum(k1, p.startup_k1), k1)
        gain = k1 * dt / (1.0 + k1 * dt)
        dw, dx, dy, dz = _exp(gain * fx, gain * fy, gain * fz, o)
        s.qw, s.qx, s.qy, s.qz = _mul(s.qw, s.qx, s.qy, s.qz, dw, dx, dy, dz)
        # the correction also turns, by the share aperiodic_prefilter (quick: fully), the
        # filtered error the unit holds (1: a pre-filter of the specific force whose memory
        # matches the current estimate, as VQF's; 0: the thesis's unit on the error). Not while
        # a linear acceleration is detected (the tight clip): what the unit holds then is the
        # disturbance, and the thesis's unit rejects it best (impacts 18.9' -> 17.8')
        dec = gain * o.where(quick, 1.0, o.where(tight, 0.0, p.prefilter))
        s.lx, s.ly, s.lz = s.lx - dec * s.lx, s.ly - dec * s.ly, s.lz - dec * s.lz
        # recovery: a long unbroken clip is a real attitude error, not a disturbance
        s.clip_timer_s = o.where(clipped, s.clip_timer_s + dt, 0.0)
        enter = (p.recovery_trigger_s > 0.0) & (s.clip_timer_s >= p.recovery_trigger_s) & learn
        leave = s.recovering & (en < 0.5 * limit)
        s.recovery_count = s.recovery_count + o.where(enter, 1, 0)
        s.recovering = o.where(s.recovering, o.not_(leave), enter)
        s.clip_timer_s = o.where(enter, 0.0, s.clip_timer_s)
        s.clipped = clipped

    lim = p.bias_limit_rad_s
    s.bx = o.minimum(o.maximum(s.bx, -lim), lim)
    s.by = o.minimum(o.maximum(s.by, -lim), lim)
    s.bz = o.minimum(o.maximum(s.bz, -lim), lim)

    s.mag_reject_timer_s = o.where(s.mag_disturbed, s.mag_reject_timer_s + dt, 0.0)
    s.mag_status = o.where(p.use_mag, MAG_NONE, MAG_DISABLED)
    if mag is not None:
        _magnetometer(s, p, mag, fast, learn, o)
    _normalize(s, o)
    s.phase = o.where(
        s.recovering, PHASE_RECOVERING, o.where(startup, PHASE_STARTUP, PHASE_RUNNING)
    )


def _magnetometer(s: StepState, p: Any, mag: tuple, fast: Any, learn: Any, o: Any) -> None:
    """Step 6: heading correction from one magnetometer sample (any unit)."""
    mx, my, mz = mag
    mn = o.sqrt(mx * mx + my * my + mz * mz)
    ux, uy, uz = mx / mn, my / mn, mz / mn
    wx, wy, wz = _rotate(s.qw, s.qx, s.qy, s.qz, ux, uy, uz)
    horizontal = o.sqrt(wx * wx + wy * wy)
    dip = o.atan2(-wz, horizontal)
    dt_m = o.minimum(
        o.where(s.mag_last_time_s < 0.0, 0.0, s.time_s - s.mag_last_time_s), MAG_MAX_DT_S
    )

    # field reference (norm, dip): learned at start and after a long rejection
    learning = p.use_mag & (s.mag_ref_count < MAG_REFERENCE_SAMPLES)
    relearn = s.mag_reject_timer_s > MAG_RELEARN_AFTER_S
    s.mag_ref_count = o.where(relearn, 0, s.mag_ref_count)
    s.mag_reject_timer_s = o.where(relearn, 0.0, s.mag_reject_timer_s)
    n = s.mag_ref_count + 1
    s.mag_ref_norm = o.where(learning, s.mag_ref_norm + (mn - s.mag_ref_norm) / n, s.mag_ref_norm)
    s.mag_ref_dip = o.where(learning, s.mag_ref_dip + (dip - s.mag_ref_dip) / n, s.mag_ref_dip)
    s.mag_ref_count = o.where(learning, n, s.mag_ref_count)
    off_norm = o.maximum(
        mn / o.maximum(s.mag_ref_norm, 1e-300) - 1.0, 1.0 - mn / o.maximum(s.mag_ref_norm, 1e-300)
    )
    off_dip = o.maximum(dip - s.mag_ref_dip, s.mag_ref_dip - dip)
    disturbed = (
        p.mag_rejection
        & o.not_(learning)
        & ((off_norm > p.mag_norm_tolerance) | (off_dip > p.mag_dip_tolerance_rad))
    )
    s.mag_disturbed = disturbed
    usable = p.use_mag & o.not_(disturbed) & (horizontal > 1e-3)
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
                                 s.mag_clip_timer_s)
    enter = (p.recovery_trigger_s > 0.0) & (s.mag_clip_timer_s >= p.recovery_trigger_s)
    leave = usable & (o.maximum(yaw_error, -yaw_error) < 0.1 * p.mag_saturation_limit_rad)
    s.mag_recovering = o.where(s.mag_recovering, o.not_(leave), enter)
    s.mag_clip_timer_s = o.where(enter, 0.0, s.mag_clip_timer_s)
    quick = fast | s.mag_recovering
    r1 = o.where(quick, o.maximum(p.r1, p.startup_k1), p.r1)
    gain = o.where(usable, r1 * dt_m / (1.0 + r1 * dt_m), 0.0)
    ldt = o.where(usable & learn, dt_m, 0.0)
    limit = o.where(quick, 4.0, p.mag_saturation_limit_rad)

    # 'yaw' mode (and the first heading fix of either mode): rotate about the world vertical
    s.yaw_error_rad = o.where(usable, yaw_error, 0.0)
    yaw_c = o.minimum(o.maximum(yaw_error, -limit), limit)
    yaw_mode = o.not_(p.mag_full) | first
    angle = o.where(first, yaw_error, o.where(yaw_mode, gain * yaw_c, 0.0))
    s.z_m = s.z_m + o.where(yaw_mode & o.not_(first), p.r2 * ldt * yaw_c, 0.0)
    _turn_heading(s, angle, o)

    # 'full' mode (Ryzhkov, drift): vector error against the reference field, all axes
    full = p.mag_full & o.not_(first) & usable
    rx, ry, rz = 0.0 * s.mag_ref_dip, o.cos(s.mag_ref_dip), -o.sin(s.mag_ref_dip)
    px, py, pz = _rotate(s.qw, -s.qx, -s.qy, -s.qz, rx, ry, rz)
    ex, ey, ez = uy * pz - uz * py, uz * px - ux * pz, ux * py - uy * px
    en = o.sqrt(ex * ex + ey * ey + ez * ez)
    scale = o.where(full, o.minimum(1.0, limit / o.maximum(en, 1e-300)), 0.0)
    ex, ey, ez = ex * scale, ey * scale, ez * scale
    s.bx, s.by, s.bz = s.bx - p.r2 * ldt * ex, s.by - p.r2 * ldt * ey, s.bz - p.r2 * ldt * ez
    dw, dx, dy, dz = _exp(gain * ex, gain * ey, gain * ez, o)
    s.qw, s.qx, s.qy, s.qz = _mul(s.qw, s.qx, s.qy, s.qz, dw, dx, dy, dz)
