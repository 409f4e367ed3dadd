"""Filter parameters: one frozen dataclass, validated on construction, that is also the schema.

Gains follow the papers' names (docs/references.md): the accelerometer channel's regulator is
W1(s) = k1 + k2/s (Ryzhkov & Karpenko), the magnetometer channel's W2(s) = r1 + r2/s on the
heading alone (Ryzhkov, drift; its full-vector variant with k3 is not offered:
docs/decisions/0011-full-vector-variant-removed.md).
The saturation unit and the aperiodic unit 1/(T·s + 1) act on the error signal before W1 (the
thesis, Habliuk 2023). Defaults are chosen by measurement on recorded and simulated data (see
docs/decisions/0004-defaults-history.md).
"""

from __future__ import annotations

from dataclasses import dataclass

from cf_estimator.schema import ParameterError, param, validate_fields

#: ``world_frame`` choices. The core estimates in ENU or NED; NWU is published by the pipeline
#: (:mod:`cf_estimator.pipeline.frames`, a fixed rotation of the ENU estimate).
WORLD_FRAMES = ("enu", "ned", "nwu")
VELOCITY_HEADINGS = ("auto", "filter")


@dataclass(frozen=True)
class FilterParams:
    """Parameters of the complementary filter (units in every field's description)."""

    k1: float = param(
        0.35,
        "1/s",
        "Proportional gain of the accelerometer channel (W1 = k1 + k2/s, Ryzhkov & Karpenko).",
        minimum=0.0,
        maximum=100.0,
        group="gains",
    )
    k2: float = param(
        0.005,
        "1/s^2",
        "Integral gain of the accelerometer channel; its state is the gyro-bias "
        "estimate (0 disables bias learning from the accelerometer).",
        minimum=0.0,
        maximum=100.0,
        group="gains",
    )
    use_saturation: bool = param(
        True,
        "",
        "Clip the error vector by norm before the aperiodic unit and the regulator, while a "
        "linear acceleration is present and the gyro is still (impacts, vibration, manoeuvres); "
        "never while rotating faster than rotation_threshold_rad_s or unaccelerated: a real "
        "attitude error (a gyro's scale error after a fast turn) is then corrected in full.",
        group="error path",
    )
    saturation_limit_rad: float = param(
        0.01,
        "rad",
        "Saturation level of the accelerometer error |e| (e ~ small-angle tilt "
        "error). Keep it above about 2*gyro_bias*17.7 s for Ryzhkov & Karpenko's example gains "
        "or bias is not tracked.",
        minimum=0.0,
        maximum=2.0,
        minimum_exclusive=True,
        group="error path",
    )
    rotation_threshold_rad_s: float = param(
        0.2,
        "rad/s",
        "Above this low-passed rotation rate the error is not clipped.",
        minimum=0.0,
        maximum=100.0,
        group="error path",
    )
    acceleration_threshold_m_s2: float = param(
        0.5,
        "m/s^2",
        "Linear acceleration is present while | |a| - g_ref | exceeds this (g_ref: |a| learned "
        "during start-up and rest); then the clip is saturation_limit_rad. At rest the error "
        "path is quick only while the block mean's |a| is within this of g_ref.",
        minimum=0.0,
        maximum=100.0,
        minimum_exclusive=True,
        group="error path",
    )
    aperiodic_time_constant_s: float = param(
        2.0,
        "s",
        "Time constant T of the aperiodic unit 1/(T*s+1) on the clipped error, applied "
        "in the world frame (0 = off). Must satisfy T < k1/k2 for stability. While the "
        "bias is learned in flight (k1 raised) at most 0.75/k1, outside the tight clip.",
        minimum=0.0,
        maximum=1000.0,
        group="error path",
    )
    aperiodic_prefilter: float = param(
        0.5,
        "1",
        "Share of each correction that also turns what the aperiodic unit holds. 1: the unit is "
        "a pre-filter of the measured specific force in the world frame (its memory always "
        "matches the current estimate, as in VQF); 0: the thesis's unit on the clipped error, "
        "whose memory of already-corrected error keeps acting (slower, smoother loop); 0 too "
        "while a linear acceleration is detected (tight clip). Chosen "
        "by measurement on BROAD, EuRoC and the thesis scenarios (docs/decisions/0004).",
        minimum=0.0,
        maximum=1.0,
        group="error path",
    )
    startup_duration_s: float = param(
        2.0,
        "s",
        "Start-up phase after initialisation: no clip, no aperiodic unit, no bias "
        "learning; gain startup_k1 while still, the running mean of the accelerometer "
        "since initialisation (gain 1/t) once a block was not still or a velocity says the "
        "vehicle moves (0 = none). The error path also runs so (startup_k1) while at rest.",
        minimum=0.0,
        maximum=60.0,
        group="phases",
    )
    startup_k1: float = param(
        5.0,
        "1/s",
        "Proportional gain of both channels during recovery and rest, and of the start-up "
        "until a block was not still (the heading's for the whole start-up).",
        minimum=0.0,
        maximum=100.0,
        group="phases",
    )
    recovery_trigger_s: float = param(
        10.0,
        "s",
        "If the error stays clipped without a break this long, it is a real attitude error, "
        "not a disturbance: recover with startup_k1, no clip, no lag until |e| < L/2 (0 = never).",
        minimum=0.0,
        maximum=3600.0,
        group="phases",
    )
    use_mag: bool = param(
        True,
        "",
        "Use the magnetometer for heading (False: 6-D, yaw drifts with the gyro).",
        group="magnetometer",
    )
    r1: float = param(
        0.07,
        "1/s",
        "Proportional gain of the magnetometer channel (W2 = r1 + r2/s, Ryzhkov, drift).",
        minimum=0.0,
        maximum=100.0,
        group="magnetometer",
    )
    r2: float = param(
        0.0,
        "1/s^2",
        "Integral gain of the magnetometer channel (yaw-rate bias in 'yaw' mode).",
        minimum=0.0,
        maximum=100.0,
        group="magnetometer",
    )
    mag_saturation_limit_rad: float = param(
        0.2,
        "rad",
        "Saturation level of the magnetometer (heading) error.",
        minimum=0.0,
        maximum=4.0,
        minimum_exclusive=True,
        group="magnetometer",
    )
    mag_rejection: bool = param(
        True,
        "",
        "Ignore magnetometer samples whose norm or dip angle departs from the reference "
        "learned at start-up (magnetic disturbances).",
        group="magnetometer",
    )
    mag_field_tolerance: float = param(
        0.17,
        "1",
        "Share of the reference field a disturbance may add before a magnetometer sample is "
        "rejected: its norm may depart by this fraction, its dip angle by this many rad (a "
        "disturbance of relative size d moves either by at most about d).",
        minimum=0.0,
        maximum=3.2,
        minimum_exclusive=True,
        group="magnetometer",
    )
    rest_bias_learning: bool = param(
        True,
        "",
        "Detect stillness: then learn the gyro bias from the gyro's block means, and run the "
        "error path as in start-up (no clip, no lag, gain startup_k1) while |a| = ‖g‖.",
        group="bias",
    )
    rest_window_s: float = param(
        0.5,
        "s",
        "Stillness detection: block length. Each block's gyro and accelerometer means are "
        "compared with the previous block's; two still blocks in a row are rest (each further "
        "one measures the bias), and a linear acceleration counts as present for two blocks "
        "after it was last seen.",
        minimum=0.0,
        maximum=60.0,
        minimum_exclusive=True,
        group="bias",
    )
    rest_gyro_threshold_rad_s: float = param(
        0.01,
        "rad/s",
        "Stillness detection: the gyro block mean may change by this much from one block to "
        "the next, plus 2 standard deviations of the noise measured in the block (sensor noise "
        "and vibration, from sample-to-sample differences).",
        minimum=0.0,
        maximum=10.0,
        minimum_exclusive=True,
        group="bias",
    )
    rest_accel_threshold_m_s2: float = param(
        0.2,
        "m/s^2",
        "Stillness detection: the accelerometer block mean may change by this much, plus 2 "
        "standard deviations of the noise measured in the block.",
        minimum=0.0,
        maximum=100.0,
        minimum_exclusive=True,
        group="bias",
    )
    bias_prior_sigma_rad_s: float = param(
        0.1,
        "rad/s",
        "Prior standard deviation of the gyro bias (uncalibrated MEMS gyros: several deg/s). "
        "It weighs the first still blocks against the initial estimate 0; the estimate is "
        "bounded at 5 times it on each axis (anti-windup).",
        minimum=0.0,
        maximum=10.0,
        minimum_exclusive=True,
        group="bias",
    )
    bias_learning_k2: float = param(
        0.8,
        "1/s^2",
        "Integral gain while the bias is uncertain (no still phase yet): the loop's k2 is "
        "raised towards this in proportion to the bias variance, and k1 to at least 2*sqrt(k2), "
        "so a large bias is learned in flight within about 20 s, from any start (0 = off).",
        minimum=0.0,
        maximum=10.0,
        group="bias",
    )
    world_frame: str = param(
        "enu",
        "",
        "World frame of the output orientation: 'enu' (REP-103, z up, yaw from east), "
        "'ned' (z down, yaw from north, clockwise) or 'nwu' (z up, yaw from north, "
        "counter-clockwise; published by the node and the replay, the core filters take enu "
        "or ned).",
        choices=WORLD_FRAMES,
        read_only=True,
        group="frames",
    )
    gravity_m_s2: float = param(
        9.80665,
        "m/s^2",
        "Local gravity magnitude: the prior of the filter's ‖g‖ (which then follows |a| slowly "
        "while the sensor is steady, so a mis-scaled accelerometer is learned) and the input "
        "unit checks.",
        minimum=1.0,
        maximum=30.0,
        group="frames",
    )

    velocity_window_s: float = param(
        1.0,
        "s",
        "Velocity aiding: the world-frame acceleration is the velocity difference over the "
        "newest accepted velocity samples spanning at least this long (noise: about "
        "sqrt(2)*velocity_noise/window), matched by the mean specific force over the same "
        "stamps. A longer window averages the noise but delays the in-motion alignment (a few "
        "windows) and with it the take-hold: Phantom 4 horizontal aided 0.86 / 1.03 / 4.2 deg "
        "at 1 / 2 / 3 s (docs/decisions/0006).",
        minimum=0.0,
        maximum=30.0,
        minimum_exclusive=True,
        group="velocity aiding",
    )
    velocity_timeout_s: float = param(
        1.5,
        "s",
        "Velocity aiding: a velocity sample older than this (by header stamp, against the IMU "
        "stamp) is stale; without a fresh one the filter runs IMU-only, exactly as unaided.",
        minimum=0.0,
        maximum=30.0,
        minimum_exclusive=True,
        group="velocity aiding",
    )
    velocity_jump_threshold_m_s: float = param(
        1.0,
        "m/s",
        "Velocity aiding: a velocity sample whose change from the last accepted one departs "
        "from the IMU's own prediction by more than this (plus 2 m/s^2 times the interval) is "
        "a jump (GNSS glitch) and rejected.",
        minimum=0.0,
        maximum=100.0,
        minimum_exclusive=True,
        group="velocity aiding",
    )
    velocity_noise_m_s: float = param(
        0.1,
        "m/s",
        "Velocity aiding: noise (standard deviation per axis) of the velocity input. A "
        "horizontal acceleration within its differentiation noise is taken out only in part "
        "(none below it), so a noisy velocity adds no tilt noise in steady flight "
        "(0 = always take it out in full). The in-motion alignment weighs its windows by "
        "their scatter, never by less than this noise: a cleaner velocity is not trusted "
        "further.",
        minimum=0.0,
        maximum=10.0,
        group="velocity aiding",
    )
    velocity_heading: str = param(
        "auto",
        "",
        "Velocity aiding: how the filter's heading is tied to the velocity's world frame. "
        "'auto': estimate the heading offset from the accelerations (observable while the "
        "vehicle accelerates horizontally) and aid once it is known to "
        "velocity_heading_sigma_rad; 'filter': the filter's heading already is the velocity's "
        "frame (magnetometer heading with negligible declination, or a simulator).",
        choices=VELOCITY_HEADINGS,
        group="velocity aiding",
    )
    velocity_heading_sigma_rad: float = param(
        0.3,
        "rad",
        "Velocity aiding ('auto'): aid only while the heading offset's standard deviation is "
        "below this (0.3 rad = 17 deg: the tilt error left by it is about sigma*|a_h|/g, "
        "against |a_h|/g unaided: aiding that early already removes most of the error).",
        minimum=0.0,
        maximum=3.2,
        minimum_exclusive=True,
        group="velocity aiding",
    )
    velocity_heading_memory_s: float = param(
        60.0,
        "s",
        "Velocity aiding ('auto'): memory (forgetting time constant) of the heading-offset "
        "estimator; the 6-D filter's heading drifts, so old accelerations count less.",
        minimum=0.0,
        maximum=3600.0,
        minimum_exclusive=True,
        group="velocity aiding",
    )

    velocity_compass_sigma_rad: float = param(
        0.1,
        "rad",
        "Velocity aiding ('auto') with a magnetometer: standard deviation of the offset "
        "between the compass's heading and the velocity's frame (the compass's error, and any "
        "declination magnetic_declination_rad does not hold). While the magnetometer "
        "references the heading, the offset starts at 0 with this uncertainty (aiding "
        "horizontally from the first velocity window when it is below "
        "velocity_heading_sigma_rad) and the accelerations refine it; 0 = the accelerations "
        "alone, as without a compass.",
        minimum=0.0,
        maximum=3.2,
        group="velocity aiding",
    )

    def __post_init__(self) -> None:
        validate_fields(self)
        if self.k2 > 0.0 and self.aperiodic_time_constant_s * self.k2 >= self.k1:
            raise ParameterError(
                "aperiodic_time_constant_s: the loop T*s^3 + s^2 + k1*s + k2 is unstable "
                f"unless T < k1/k2 = {self.k1 / self.k2:.4g} s "
                f"(got T = {self.aperiodic_time_constant_s:g} s)"
            )
