"""Rest/motion classifier: is the sensor at rest (and so the gyro mean a bias measurement)?

Block statistics of ``rest_window_s`` blocks against the noise the blocks measure (sample-to-
sample differences: sensor noise and rotor vibration), capped so that vibration never widens
"still" until flight fits inside it; a turning magnetic field and a gyro mean far from the bias
estimate are motion. Owns the ``CLASSIFIER`` fields of :mod:`cf_estimator.core.state`; reads the
bias estimate (``b*``, ``bias_var``) for the gate. Written once for floats and arrays
(:mod:`cf_estimator.core.ops`); ``c/cf_core.c`` repeats it (``stillness()``).
"""

from __future__ import annotations

from typing import Any, NamedTuple

from cf_estimator.core.ops import TINY, sq
from cf_estimator.core.state import StepState

#: Stillness: a change of the block means within this many standard deviations of the observed
#: noise floor is no change (the floor includes rotor vibration, so vibration is not motion) ...
REST_NOISE_SIGMAS = 2.0
#: ... but the noise may widen each threshold by at most this multiple of the threshold itself:
#: rotor vibration never widens "still" until flight fits inside it (phantom4, 3-6 m/s² of
#: vibration: uncapped, 17 of 40 airborne recordings were taken for rest).
REST_NOISE_CAP = 1.0
#: Stillness with a magnetometer: the block-mean field direction (unit vector, sensor frame) may
#: turn by at most this plus rest_gyro_threshold_rad_s × the block length [rad], plus
#: REST_NOISE_SIGMAS of the two means' measured noise (capped at REST_NOISE_CAP × this: a 2 Hz
#: compass's single sample a block); more is a turn (a steady turn looks still to the gyro and
#: accelerometer, never to the magnetometer).
REST_MAG_TOLERANCE_RAD = 0.01
#: A single sample this many noise standard deviations (plus the thresholds) away from the last
#: block mean ends a still phase at once, without waiting for the block to end.
REST_SAMPLE_SIGMAS = 8.0
#: A steady block whose gyro mean is, on any axis, this many standard deviations (of the bias
#: estimate and of the block mean) from the bias estimate is a steady turn, not rest — however
#: long it lasts: biases drift (BIAS_RANDOM_WALK_RAD_S_SQRT_S), they do not jump. At power-on
#: the prior bias_prior_sigma_rad_s bounds what a still phase may take as bias.
REST_GATE_SIGMAS = 3.0
#: Still blocks in a row that make rest (rest_window_s each): one still block can be a pause in
#: a swing, two in a row are rest. The acceleration detector holds a linear acceleration as
#: present for as long (classify_motion): a sensor is quiet again when it could be at rest.
REST_STILL_BLOCKS = 2.0
#: A gyro bias beyond this many standard deviations of its prior (bias_prior_sigma_rad_s) on any
#: axis is not a bias (the prior's tail, p < 1e-6): the estimate is bounded there (anti-windup,
#: bias.clamp) and a block whose mean is beyond it on every axis is a turn, not rest.
BIAS_LIMIT_SIGMAS = 5.0
#: Time constant [s] with which ‖g‖ follows |a| while the sensor is steady: slow enough that a
#: steady linear acceleration of a few seconds (the thesis's 25 m/s in 5 s) is not absorbed.
GRAVITY_TIME_CONSTANT_S = 10.0
#: Smallest variance [(rad/s)²] of a block's gyro mean as a bias measurement (a noiseless gyro).
REST_MIN_VARIANCE = 1e-12
#: √3: the norm of a gyro mean with every component at the bias limit (a block whose mean is
#: beyond it cannot be a bias).
SQRT3 = 1.7320508075688772


def rest_time_s(p: Any) -> Any:
    """How long still blocks must follow each other before the sensor is at rest [s]:
    REST_STILL_BLOCKS blocks of ``rest_window_s``."""
    return REST_STILL_BLOCKS * p.rest_window_s


def bias_limit_rad_s(p: Any) -> Any:
    """The bound of each component of the gyro-bias estimate [rad/s]: BIAS_LIMIT_SIGMAS
    standard deviations of its prior ``bias_prior_sigma_rad_s``."""
    return BIAS_LIMIT_SIGMAS * p.bias_prior_sigma_rad_s


class RestMeasurement(NamedTuple):
    """What a block end gives the bias estimator: ``measure`` (a still block at rest), the
    block's gyro mean (sensor frame) [rad/s], its variance per axis [(rad/s)²], and whether
    the block had magnetometer samples to rule out a turn."""

    measure: Any
    mean_x: Any
    mean_y: Any
    mean_z: Any
    variance: Any
    mag_seen: Any


def classify(s: StepState, p: Any, gyro: tuple, accel: tuple, mag: tuple | None, dt: Any,
             o: Any) -> RestMeasurement:
    """One sample into the block statistics; at a block's end, still or not, rest or not.

    Still = the gyro and accelerometer block means did not change from the previous block by
    more than the thresholds plus REST_NOISE_SIGMAS standard deviations of a block-mean
    difference. The noise (sensor noise and rotor vibration) is measured in each block from
    sample-to-sample differences, which slow motion hardly changes: vibration averages out in a
    block mean and widens the tolerance by what it adds to it; a constant gyro bias cancels in
    the difference. After REST_STILL_BLOCKS still blocks in a row the sensor is at rest: each
    further still block is a measurement of the bias (returned: its gyro mean, variance from its
    noise, for :func:`cf_estimator.core.bias.fuse_rest`), and ‖g‖ follows |a| slowly.
    The noise widens the thresholds by at most REST_NOISE_CAP times themselves; with a
    magnetometer a turning field direction is motion (REST_MAG_TOLERANCE_RAD); a block far
    from the bias estimate (REST_GATE_SIGMAS, per axis) is a steady turn, never rest. ``gyro``
    [rad/s], ``accel`` [m/s²], ``mag`` (any unit, or None) in the sensor frame; ``dt`` [s].
    """
    gx, gy, gz = gyro
    ax, ay, az = accel
    s.blk_n = s.blk_n + 1.0
    s.blk_t = s.blk_t + dt
    s.blk_gx, s.blk_gy, s.blk_gz = s.blk_gx + gx, s.blk_gy + gy, s.blk_gz + gz
    s.blk_ax, s.blk_ay, s.blk_az = s.blk_ax + ax, s.blk_ay + ay, s.blk_az + az
    # squared sample-to-sample differences (noise); the first sample has none
    seen = o.where(s.last_n > 0.0, 1.0, 0.0)
    s.blk_g2 = s.blk_g2 + seen * (sq(gx - s.lgx) + sq(gy - s.lgy) + sq(gz - s.lgz))
    s.blk_a2 = s.blk_a2 + seen * (sq(ax - s.lax) + sq(ay - s.lay) + sq(az - s.laz))
    s.blk_d = s.blk_d + seen
    s.lgx, s.lgy, s.lgz, s.lax, s.lay, s.laz = gx, gy, gz, ax, ay, az
    s.last_n = s.last_n + 1.0
    if mag is not None:  # unit field direction, sensor frame (any unit in)
        mx, my, mz = mag
        mn = o.sqrt(mx * mx + my * my + mz * mz)
        use = o.where(p.use_mag, 1.0, 0.0)
        ux, uy, uz = mx / mn, my / mn, mz / mn
        s.blk_mx = s.blk_mx + use * ux
        s.blk_my = s.blk_my + use * uy
        s.blk_mz = s.blk_mz + use * uz
        s.blk_mn = s.blk_mn + use
        # its noise as the gyro's: sample-to-sample differences (the previous sample may lie
        # in an earlier block: a sparse magnetometer has one sample a block, or none)
        seen_m = use * o.where(s.lmx * s.lmx + s.lmy * s.lmy + s.lmz * s.lmz > 0.0, 1.0, 0.0)
        s.blk_m2 = s.blk_m2 + seen_m * (sq(ux - s.lmx) + sq(uy - s.lmy) + sq(uz - s.lmz))
        s.blk_md = s.blk_md + seen_m
        s.lmx, s.lmy, s.lmz = (s.lmx + use * (ux - s.lmx), s.lmy + use * (uy - s.lmy),
                               s.lmz + use * (uz - s.lmz))
    has_prev = s.prev_n > 0.0
    # a sample far outside the noise around the last block's mean ends rest at once
    jump_g = o.sqrt(sq(gx - s.pgx) + sq(gy - s.pgy) + sq(gz - s.pgz)) > (
        p.rest_gyro_threshold_rad_s + REST_SAMPLE_SIGMAS * o.sqrt(s.noise_g2))
    jump_a = o.sqrt(sq(ax - s.pax) + sq(ay - s.pay) + sq(az - s.paz)) > (
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
    dg = o.sqrt(sq(mgx - s.pgx) + sq(mgy - s.pgy) + sq(mgz - s.pgz))
    da = o.sqrt(sq(max_ - s.pax) + sq(may - s.pay) + sq(maz - s.paz))
    tol_g = p.rest_gyro_threshold_rad_s + REST_NOISE_SIGMAS * o.minimum(
        o.sqrt(noise_g2 * spread), REST_NOISE_CAP * p.rest_gyro_threshold_rad_s)
    tol_a = p.rest_accel_threshold_m_s2 + REST_NOISE_SIGMAS * o.minimum(
        o.sqrt(noise_a2 * spread), REST_NOISE_CAP * p.rest_accel_threshold_m_s2)
    # the field direction of this block against the previous one (both with samples)
    mag_seen = (s.blk_mn > 0.0) & (s.pm_n > 0.0)
    bm = o.maximum(o.sqrt(s.blk_mx * s.blk_mx + s.blk_my * s.blk_my + s.blk_mz * s.blk_mz),
                   TINY)
    umx, umy, umz = s.blk_mx / bm, s.blk_my / bm, s.blk_mz / bm
    dm = o.sqrt(sq(umx - s.pmx) + sq(umy - s.pmy) + sq(umz - s.pmz))
    # the two block means' noise, as for the gyro (one sample a block at 2 Hz: ~0.01 rad)
    noise_m2 = o.where(s.blk_md > 0.0, s.blk_m2 / (2.0 * o.maximum(s.blk_md, 1.0)), s.noise_m2)
    spread_m = 1.0 / o.maximum(s.blk_mn, 1.0) + 1.0 / o.maximum(s.pm_n, 1.0)
    tol_m = REST_MAG_TOLERANCE_RAD + p.rest_gyro_threshold_rad_s * s.blk_t + REST_NOISE_SIGMAS \
        * o.minimum(o.sqrt(noise_m2 * spread_m), REST_NOISE_CAP * REST_MAG_TOLERANCE_RAD)
    turned = mag_seen & (dm > tol_m)
    steady = (
        has_prev
        & (dg < tol_g)
        & (da < tol_a)
        & o.not_(turned)
        & (o.sqrt(mgx * mgx + mgy * mgy + mgz * mgz)
           < bias_limit_rad_s(p) * SQRT3)
    )
    # a steady turn at a constant rate looks still; a block whose gyro mean is far from the bias
    # estimate on any axis (beyond REST_GATE_SIGMAS of the estimate's and the block's spread) is
    # motion however long it lasts
    r = o.maximum(noise_g2 / (3.0 * n), REST_MIN_VARIANCE)
    gate = p.rest_gyro_threshold_rad_s + REST_GATE_SIGMAS * o.sqrt(s.bias_var + r)
    consistent = ((o.maximum(mgx - s.bx, s.bx - mgx) < gate)
                  & (o.maximum(mgy - s.by, s.by - mgy) < gate)
                  & (o.maximum(mgz - s.bz, s.bz - mgz) < gate))
    still = steady & consistent
    s.moved = s.moved | (done & has_prev & o.not_(still))
    s.rest_timer_s = o.where(done, o.where(still, s.rest_timer_s + s.blk_t, 0.0), s.rest_timer_s)
    s.at_rest = p.rest_bias_learning & (s.rest_timer_s >= rest_time_s(p))
    # a still block at rest measures the bias (the bias estimator fuses it, after this)
    measure = done & s.at_rest
    gw = o.where(done & still, s.blk_t / (GRAVITY_TIME_CONSTANT_S + s.blk_t), 0.0)
    s.g_ref = s.g_ref + gw * (o.sqrt(max_ * max_ + may * may + maz * maz) - s.g_ref)
    # next block
    s.noise_g2 = o.where(done, noise_g2, s.noise_g2)
    s.noise_a2 = o.where(done, noise_a2, s.noise_a2)
    s.noise_m2 = o.where(done, noise_m2, s.noise_m2)
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
    s.blk_mn, s.blk_m2, s.blk_md = s.blk_mn * keep, s.blk_m2 * keep, s.blk_md * keep
    return RestMeasurement(measure, mgx, mgy, mgz, r, mag_seen)
