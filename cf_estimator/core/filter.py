"""The 3-D complementary filter for one stream of samples (plain floats: fast per sample).

Usage::

    f = ComplementaryFilter(FilterParams())
    q = f.update(gyro_rad_s, accel_m_s2, dt_s, mag)   # (w, x, y, z), q_world_from_sensor

The first valid accelerometer sample initialises roll/pitch (and yaw from the magnetometer when
one is given; otherwise yaw starts at 0 and is fixed by the first usable magnetometer sample).
The equations live in :mod:`cf_estimator.core.step`; every decision they take is readable
through :meth:`ComplementaryFilter.status`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from types import SimpleNamespace
from typing import Any

import numpy as np

from cf_estimator.core import quaternion as quat
from cf_estimator.core.bias import BIAS_LEARNING_MAX_ERROR_RAD, drift_rate
from cf_estimator.core.kernel import compiled_kernel, resolve_backend
from cf_estimator.core.ops import FloatOps
from cf_estimator.core.params import FilterParams
from cf_estimator.core.state import LAGGED_ROTATION
from cf_estimator.core.step import (
    BIAS_CONVERGED_SIGMA_RAD_S,
    MAG_STATUS_NAMES,
    PHASE_NAMES,
    PHASE_STARTUP,
    StepState,
    step,
    turn_heading,
    up_direction,
)
from cf_estimator.schema import as_dict

Vector = Sequence[float]
_SQRT_HALF = math.sqrt(0.5)


def step_params(params: FilterParams) -> SimpleNamespace:
    """The parameter view the step reads: FilterParams fields plus derived flags."""
    if params.world_frame not in ("enu", "ned"):
        raise ValueError(
            f"world_frame {params.world_frame!r}: the core filters estimate in enu or ned; "
            "the pipeline publishes nwu (cf_estimator.pipeline.frames.core_params)"
        )
    view = SimpleNamespace(**as_dict(params))
    view.prefilter = params.aperiodic_prefilter
    return view


#: Largest gyro component [rad/s] the filter accepts (far beyond any sensor; keeps every
#: intermediate of the step finite).
GYRO_LIMIT_RAD_S = 1e9
#: Evidence ratio [1] between the two bias hypotheses (:class:`ComplementaryFilter`): the one
#: that learns no bias in flight is published while the velocity swing it implies has a mean
#: square at most 1/EVIDENCE_RATIO of the learning one's. A wrong attitude makes the implied
#: velocity grow (g·tilt error, integrated) while a manoeuvre's stays bounded; with about 4
#: degrees of freedom per window, a ratio of 2 is where chance stops explaining the difference
#: for one window in four. Measured: ``bench ablate`` (docs/decisions/0010).
EVIDENCE_RATIO = 2.0


def valid_vector(v: Vector | None) -> bool:
    """True when v is three finite components with a non-zero, finite squared norm."""
    if v is None or len(v) != 3:
        return False
    x, y, z = float(v[0]), float(v[1]), float(v[2])
    n2 = x * x + y * y + z * z
    return math.isfinite(x + y + z) and 0.0 < n2 < math.inf


def _east(up: np.ndarray, mag: Vector) -> np.ndarray | None:
    """Unit magnetic east (mag × up) in the sensor frame, None when the field is parallel to the
    unit vertical ``up`` (no horizontal component: no heading)."""
    east = np.cross(np.asarray(mag, dtype=float), up)
    norm = np.linalg.norm(east)
    return east / norm if norm > 1e-9 * np.linalg.norm(mag) else None


def heading_from_mag(accel: Vector, mag: Vector | None) -> bool:
    """True when ``mag`` (valid) has a horizontal component to take a heading from: not parallel
    to the gravity direction given by ``accel`` (then :func:`orientation_from_vectors` uses it)."""
    if not valid_vector(mag):
        return False
    up = np.asarray(accel, dtype=float)
    return _east(up / np.linalg.norm(up), mag) is not None  # type: ignore[arg-type]


def orientation_from_vectors(accel: Vector, mag: Vector | None = None) -> np.ndarray:
    """q_enu_from_sensor that explains a static accelerometer (and magnetometer) reading.

    Roll/pitch from the gravity direction; yaw from the horizontal magnetic field (magnetic
    north = ENU +y) when ``mag`` is given and not parallel to gravity, else yaw = 0.
    """
    up = np.asarray(accel, dtype=float)
    up = up / np.linalg.norm(up)
    east = _east(up, mag) if mag is not None else None
    if east is not None:
        return quat.from_matrix(np.vstack([east, np.cross(up, east), up]))
    roll = math.atan2(up[1], up[2])
    pitch = math.atan2(-up[0], math.hypot(up[1], up[2]))
    return quat.from_euler(roll, pitch, 0.0)


@dataclass(frozen=True)
class FilterStatus:
    """What the filter decided at the last sample (for diagnostics; frames and units given)."""

    phase: str  #: uninitialized | startup | running | recovering
    time_since_init_s: float
    error_rad: tuple[float, float, float]  #: raw error e = (a/‖g‖) × ĝ, sensor frame
    error_norm_rad: float  #: |e| ≈ tilt error plus linear acceleration / g
    clipped: bool  #: the saturation unit was active
    processed_error_rad: tuple[float, float, float]  #: after saturation and aperiodic unit
    gyro_bias_rad_s: tuple[float, float, float]  #: bias estimate, sensor frame
    gyro_bias_sigma_rad_s: float  #: σ of the bias estimate's error [rad/s] (bias.error_sigma)
    gyro_bias_converged: bool  #: sigma below BIAS_CONVERGED_SIGMA_RAD_S
    at_rest: bool  #: still (block statistics) for two blocks: the bias is learned from the gyro
    accel_used: bool
    mag_status: str  #: none | used | rejected | disabled
    heading_initialized: bool
    yaw_error_rad: float  #: heading error the last sample implies (used; rejected, not on body)
    recovery_count: int
    mag_yaw_rate_correction_rad_s: float  #: integral of the heading channel, world vertical
    #: the bias was last measured in a still phase at power-on without a magnetometer: a steady
    #: turn then (up to REST_GATE_SIGMAS·bias_prior_sigma_rad_s per axis) cannot be told from
    #: rest, so the heading rate is not verified until a later still phase or a magnetometer
    heading_rate_unverified: bool = False
    heading_recovering: bool = False  #: the heading channel is in its recovery (quick) mode
    #: the published bias hypothesis: 'in_flight' (a bias is learned in flight) or 'rest_only'
    #: (the evidence says the gyro has none to learn beyond rest and the nominal k2: a
    #: firmware-de-biased gyro; :class:`ComplementaryFilter`)
    bias_hypothesis: str = "in_flight"
    #: what the heading rests on: 'magnetometer' (the last sample was used), 'gyro' (the field
    #: is disturbed: off the reference, turned when the body did not, or not yet settled back;
    #: the heading integrates the gyro alone), 'none' (no heading reference: 6-D or no sample)
    heading_source: str = "none"
    #: the disturbed field moves with the sensor as it turns (a magnet or a current on the
    #: vehicle): it does not contradict the heading (state ``mag_on_body``)
    mag_on_body: bool = False


#: Columns of :meth:`ComplementaryFilter.run_rows`'s ``extra_out``: raw error e (3, rad, sensor),
#: bias b (3, rad/s, sensor), clipped, phase, at_rest, mag_status, the bias estimate's error σ
#: [rad/s] (bias.error_sigma: what the diagnostics report and the covariance model's drift
#: terms take), and the aperiodic unit's world-frame state l_x, l_y [rad] (ENU inside: the
#: horizontal error the accelerometer channel corrects the tilt by; the covariance model
#: averages it), the heading channel's last error [rad] (0 when the step used no magnetometer
#: sample) and the stillness blocks' accelerometer noise noise_a2 [(m/s²)²]: what
#: core/covariance.py reads; then the gyro-bias estimate (3, rad/s, sensor:
#: :attr:`ComplementaryFilter.gyro_bias_rad_s`, b minus the heading channel's rate on the
#: sensor axes): what the replay samples; the loop's running gain loop_k1 [1/s]; and the
#: velocity swing pv_var [rad²·s²], the evidence the bias hypotheses are weighed by.
EXTRA_COLUMNS = 20


#: Velocity aiding that begins (or comes back after a dropout) lets the filter take hold for
#: this long [s]: start-up gain, no clip, no bias learning (the tilt error it reveals is real).
AIDING_TAKE_HOLD_S = 2.0


@dataclass(slots=True)
class AidingInput:
    """What velocity aiding gives the filter at one IMU sample (``update(..., aiding=)``), as
    x-io Fusion's update takes an external heading: built by
    :meth:`cf_estimator.core.velocity.VelocityAiding.step_input`.

    ``accel_m_s2``: the specific force the step takes [m/s², sensor frame]: the vehicle's
    acceleration taken out while ``active``, else the accelerometer sample itself.
    ``moving``: the velocity has said the vehicle moves (start-up averages the accelerometer);
    ``moving_now``: it moves now (not at rest). ``started``: aiding began (or came back) at this
    sample, ``first_start``: for the first time (the bias learned unaided is reopened).
    ``realign``: the in-motion alignment's (tilt rotation vector [rad], output world frame;
    gyro bias [rad/s], sensor frame), once, or None. ``active``: this sample is aided;
    ``horizontal``: horizontally (the heading offset known). ``swing_var``: the vehicle's
    velocity swing over g, mean square [rad²·s²], from the velocity. ``window_error_rad``: the
    angle between the filter's vertical and the gravity the last velocity window measured.
    ``heading_turn_rad``: the heading correction due [rad] (6-D, about the output world z)."""

    accel_m_s2: Sequence[float]
    moving: bool
    moving_now: bool
    started: bool
    first_start: bool
    realign: tuple[Any, Any] | None
    active: bool
    horizontal: bool
    swing_var: float
    window_error_rad: float
    heading_turn_rad: float


class Extra:
    """Column indices of ``extra_out`` (the order above; ``c/cf_core.c`` writes the same)."""

    ERROR = slice(0, 3)  #: raw error e (3)
    BIAS = slice(3, 6)  #: integral state b (3)
    CLIPPED = 6
    PHASE = 7
    AT_REST = 8
    MAG_STATUS = 9
    BIAS_SIGMA = 10  #: the bias estimate's error σ (bias.error_sigma)
    LX = 11
    LY = 12
    YAW_ERROR = 13
    NOISE_A2 = 14
    GYRO_BIAS = slice(15, 18)  #: the gyro-bias estimate (3)
    LOOP_K1 = 18
    PV_VAR = 19  #: the velocity swing over g, mean square (bias.observe_velocity_swing)


def state_extras(s: Any) -> tuple:
    """One ``extra_out`` row (EXTRA_COLUMNS values) from a filter state (c/cf_core.c writes
    the same columns: ``cf_write_extra``, in ``State.run``)."""
    bx, by, bz = gyro_bias_of(s)
    return (s.ex, s.ey, s.ez, s.bx, s.by, s.bz, s.clipped, s.phase, s.at_rest, s.mag_status,
            bias_error_sigma(s), s.lx, s.ly, s.yaw_error_rad, s.noise_a2, bx, by, bz, s.loop_k1,
            s.pv_var)


def gyro_bias_of(s: Any) -> tuple[float, float, float]:
    """The gyro-bias estimate [rad/s, sensor] of a state: the integral b minus the heading
    channel's world-vertical rate z_m on the sensor axes (b − Rᵀ·ẑ·z_m)."""
    upx, upy, upz = up_direction(s)
    return (s.bx - s.z_m * upx, s.by - s.z_m * upy, s.bz - s.z_m * upz)


def bias_error_sigma(s: Any) -> float:
    """Standard deviation of the bias estimate's error [rad/s] (bias.error_sigma; NaN before the
    first step)."""
    return math.sqrt(s.bias_err_var) if s.bias_err_var >= 0.0 else math.nan


class ComplementaryFilter:
    """Compensation-scheme attitude filter (seeds 000/003/004); see module docstrings.

    Two hypotheses about the gyro run side by side, the same compensation scheme in both: it
    has a bias to learn in flight (``bias_learning_k2``), or it has none beyond what rest and
    the nominal k2 find (a gyro its firmware de-biased). Each implies a velocity: the
    accelerometer's disagreement integrated in the world frame (``pv_var``, the swing over g,
    bias.observe_velocity_swing). A real bias left unlearned makes that velocity grow without
    bound; a bias learned from a manoeuvre (a false one) does the same to the other. The
    output is the learning hypothesis unless the other explains the swing EVIDENCE_RATIO times
    better (:meth:`_choose`); every input, outside correction and parameter goes to both.
    With ``bias_learning_k2`` 0 they are the same and one runs.

    ``backend``: 'compiled' (the C twin of the step, default when built) or 'python' (the
    reference in :mod:`cf_estimator.core.step`); see :mod:`cf_estimator.core.kernel`.
    """

    def __init__(
        self,
        params: FilterParams | None = None,
        *,
        initial_orientation: Vector | None = None,
        backend: str | None = None,
    ):
        self.backend = resolve_backend(backend)
        self._kernel_params: Any = None
        self._null_kernel_params: Any = None
        self._null: Any = None
        self._learning: Any = self._new_state()
        self._state: Any = self._learning  # the published hypothesis
        self._initialized = False
        #: the compiled update of both hypotheses once initialised (_kernel.Pair), else None
        self._pair: Any = None
        #: the last update's aiding took hold on an attitude error (apply_aiding)
        self.aiding_attitude_error = False
        self.set_params(params if params is not None else FilterParams())
        if initial_orientation is not None:
            self.initialize(initial_orientation)

    # copy / deepcopy / pickle: the state travels as its field values (the compiled state and
    # parameter objects are rebuilt on arrival)
    def __getstate__(self) -> dict[str, Any]:
        d = {k: v for k, v in self.__dict__.items()
             if k not in ("_kernel_params", "_null_kernel_params", "_learning", "_null", "_state",
                          "_pair")}
        d["_saved"] = self.get_state()
        return d

    def __setstate__(self, d: dict[str, Any]) -> None:
        saved = d.pop("_saved")
        self.__dict__.update(d)
        self._kernel_params = self._null_kernel_params = self._null = None
        self._pair = None
        self._learning = self._state = self._new_state()
        self.set_params(self._params)
        self.set_state(saved)

    # -- parameters --------------------------------------------------------------------------
    @property
    def params(self) -> FilterParams:
        """The parameters in force."""
        return self._params

    def set_params(self, params: FilterParams) -> None:
        """Apply new (already validated) parameters; attitude, bias and phase are kept."""
        if not isinstance(params, FilterParams):
            raise TypeError("params must be a FilterParams")
        self._params = params
        self._view = step_params(params)
        if self.backend == "compiled":
            self._kernel_params = compiled_kernel.Params(self._view)  # type: ignore[union-attr]
        # the hypothesis without in-flight learning: the same filter with bias_learning_k2 0
        self._null_view = step_params(replace(params, bias_learning_k2=0.0))
        if self.backend == "compiled":
            self._null_kernel_params = compiled_kernel.Params(  # type: ignore[union-attr]
                self._null_view)
        if params.bias_learning_k2 <= 0.0:
            self._null = None
            self._state = self._learning
        elif self._null is None:  # from now on: it starts where the learning one is
            self._null = self._learning.copy()
        self._bind()

    def _bind(self) -> None:
        """The compiled update of the states and parameters now in force (after any change of
        them or of the initialisation): :attr:`_pair`."""
        pair = None
        if self._kernel_params is not None and self._initialized:
            pair = compiled_kernel.Pair(  # type: ignore[union-attr]
                self._learning, self._kernel_params, self._null,
                None if self._null is None else self._null_kernel_params)
        self._pair = pair

    def _new_state(self) -> Any:
        if self.backend == "compiled":
            return compiled_kernel.State()  # type: ignore[union-attr]
        return StepState(0.0, False)

    # -- state ---------------------------------------------------------------------------------
    @property
    def step_state(self) -> Any:
        """The step state (:class:`cf_estimator.core.state.StepState`, or the compiled twin's
        struct with the same fields): for reading — the pipeline, diagnostics, tests."""
        return self._state

    @property
    def initialized(self) -> bool:
        """True once an attitude exists (after the first valid accelerometer sample)."""
        return self._initialized

    def reset(self) -> None:
        """Forget everything: the next valid accelerometer sample initialises again."""
        self._learning = self._state = self._new_state()
        self._null = None if self._params.bias_learning_k2 <= 0.0 else self._new_state()
        self._initialized = False
        self._bind()

    def _hypotheses(self) -> tuple[Any, ...]:
        return (self._learning,) if self._null is None else (self._learning, self._null)

    def _choose(self) -> bool:
        """Publish the hypothesis the evidence favours (see the class docstring); True: the one
        without in-flight learning."""
        null = self._null is not None and (EVIDENCE_RATIO * self._null.pv_var
                                           < self._learning.pv_var)
        self._state = self._null if null else self._learning
        return null

    def initialize(self, q_world_from_sensor: Vector, *, heading_known: bool = True) -> None:
        """Start from a given attitude (in this filter's world frame); starts the start-up phase."""
        q = quat.normalize(np.asarray(q_world_from_sensor, dtype=float))
        if self._params.world_frame == "ned":
            q = quat.ned_to_enu(q)
        self.reset()
        for s in self._hypotheses():
            s.qw, s.qx, s.qy, s.qz = (float(c) for c in q)
            s.heading_initialized = heading_known
            s.phase = PHASE_STARTUP
        self._initialized = True
        self._bind()

    def correct_heading(self, turn_rad: float) -> None:
        """Turn the heading by ``turn_rad`` about the output world frame's z axis (ENU: up,
        NED: down; roll/pitch unchanged): an outside heading reference (velocity aiding's
        heading offset, 6-D)."""
        if turn_rad:
            up = -1.0 if self._params.world_frame == "ned" else 1.0  # the state is ENU inside
            for s in self._hypotheses():
                turn_heading(s, up * float(turn_rad), FloatOps)

    def realign(self, tilt_rad: Vector, bias_rad_s: Vector) -> None:
        """Take an outside estimate of tilt and gyro bias (velocity aiding's in-motion
        alignment, once it is known): q ← Exp(tilt_rad) ⊗ q, ``tilt_rad`` the rotation vector
        [rad] in the output world frame (ENU or NED) from the filter's tilt to the outside one;
        the bias estimate ← ``bias_rad_s`` [rad/s] (sensor frame). The aperiodic unit's memory
        of errors measured against the old tilt (and its low-passed R̄) is cleared. ValueError
        (state untouched) unless both are 3 finite values."""
        rot = np.asarray(tilt_rad, dtype=float)
        bias = np.asarray(bias_rad_s, dtype=float)
        if rot.shape != (3,) or bias.shape != (3,) or not (np.isfinite(rot).all()
                                                          and np.isfinite(bias).all()):
            raise ValueError(f"realign: tilt_rad and bias_rad_s must be 3 finite values, got "
                             f"{rot.tolist()!r} and {bias.tolist()!r}")
        if self._params.world_frame == "ned":  # the state is ENU inside
            rot = np.array([rot[1], rot[0], -rot[2]])
        for s in self._hypotheses():
            q = quat.normalize(quat.multiply(quat.exp(rot), [s.qw, s.qx, s.qy, s.qz]))
            s.qw, s.qx, s.qy, s.qz = (float(c) for c in q)
            s.bx, s.by, s.bz = (float(c) for c in bias)
            s.lx = s.ly = s.lz = 0.0
            for field in LAGGED_ROTATION:
                setattr(s, field.name, 0.0)  # the unit's R̄ starts again (learning_input)

    def set_aided(self, aided: bool) -> None:
        """Say whether the next update's accelerometer sample is velocity-aided (the vehicle's
        acceleration taken out): the aperiodic unit then only averages vibration
        (QUICK_LAG_TIME_CONSTANT_S instead of aperiodic_time_constant_s)."""
        for s in self._hypotheses():
            s.aided = bool(aided)

    def seed_swing(self, swing_var: float) -> None:
        """Another sensor (the velocity, when its aiding ends) measured the vehicle's velocity
        swing over g, mean square [rad²·s²]: the loop's swing memory (``pv_var``, which sets
        the loop gain, bias.loop_gain) takes it if larger. Non-finite or negative: ignored."""
        v = float(swing_var)
        for s in self._hypotheses():
            if math.isfinite(v) and v > s.pv_var:
                s.pv_var = v

    def mark_moving(self) -> None:
        """Another sensor (velocity aiding) says the vehicle moves: it is not at rest, so the
        start-up averages the accelerometer (gain 1/t) as after a stillness block that was not
        still, without waiting for the blocks' verdict."""
        for s in self._hypotheses():
            s.moved = True

    def interrupt_rest(self) -> None:
        """Another sensor (velocity aiding) says the vehicle moves now: whatever the stillness
        blocks say, it is not at rest — its gyro mean is no bias measurement (a multirotor
        slowing down in the air turns smoothly enough to pass the blocks' tests, and its
        accelerometer reads the thrust axis however it tilts). The run of still blocks starts
        again (two still blocks after the vehicle stops)."""
        for s in self._hypotheses():
            s.rest_timer_s = 0.0

    def take_hold(self, duration_s: float, reopen_bias: bool = False) -> None:
        """Run the loop as in start-up (gain startup_k1, no clip, no bias learning) for the next
        ``duration_s`` [s]: a correction that has just become trustworthy (velocity aiding that
        began) reveals a tilt error that is real, not a disturbance to reject."""
        for s in self._hypotheses():
            s.quick_until_s = max(float(s.quick_until_s), float(s.time_s) + float(duration_s))
            if reopen_bias:
                # what the bias estimator learned from the untrustworthy error is suspect:
                # uncertain again (the prior), so it is learned afresh from the trustworthy one
                prior = self._params.bias_prior_sigma_rad_s ** 2
                s.bias_var = max(float(s.bias_var), prior)
                s.bias_err_var = max(float(s.bias_err_var), prior)

    def apply_aiding(self, aiding: AidingInput) -> bool:
        """What velocity aiding tells the filter before a step, in this order: the vehicle moves
        (the start-up averages), take hold when aiding began (and again when, aided, the
        disagreement is an attitude error), the alignment's tilt and bias once known, the swing
        measured while aided when aiding ends, whether the sample is aided, the heading
        correction due. True when it took hold on an attitude error (the aiding counts it).
        :meth:`update` with ``aiding=`` calls it."""
        if aiding.moving:
            self.mark_moving()
        if aiding.moving_now:
            self.interrupt_rest()
        if aiding.started:
            self.take_hold(AIDING_TAKE_HOLD_S, reopen_bias=aiding.first_start)
        if aiding.realign is not None:
            self.realign(*aiding.realign)
        if self._state.aided and not aiding.active:
            # aiding ends (a dropout): what the filter measured of the swing while aided is what
            # the aiding left; the unaided loop takes the vehicle's swing from the velocity
            self.seed_swing(aiding.swing_var)
        self.set_aided(aiding.active)
        s = self._state
        attitude_error = (aiding.active and aiding.horizontal and s.time_s > s.quick_until_s
                          and aiding.window_error_rad > BIAS_LEARNING_MAX_ERROR_RAD)
        if attitude_error:
            # aided, the window's gravity is off the filter's vertical by the tilt error itself
            # (what the aiding leaves is hundredths of a rad): one beyond what a bias explains
            # is an attitude error (a gyro fault): take hold, learning nothing from it
            self.take_hold(AIDING_TAKE_HOLD_S)
        self.correct_heading(aiding.heading_turn_rad)
        return attitude_error

    def aiding_estimates(self) -> tuple[float, float, float, float, float, float]:
        """What velocity aiding reads of the filter, cheaply: the regulator's integral (bias)
        state b [rad/s] (sensor frame), its variance per axis [(rad/s)²] (< 0: none yet), the
        σ [rad] of the tilt error the gyro's drift leaves in the aided loop: d/k1, d the drift
        rate (:func:`~cf_estimator.core.bias.drift_rate`), k1 the configured gain (the aided
        loop's); unbounded (inf) with k1 = 0, a loop that never corrects its tilt; and 1.0 while
        the magnetometer references the heading (taken, the field not disturbed, no heading
        recovery under way), else 0.0."""
        s = self._state
        k1 = self._params.k1
        sigma_t = drift_rate(s, FloatOps) / k1 if k1 > 0.0 else math.inf
        compass = bool(s.heading_initialized) and not s.mag_disturbed and not s.mag_recovering
        return (s.bx, s.by, s.bz, s.bias_var, sigma_t, 1.0 if compass else 0.0)

    def initialize_from(self, accel_m_s2: Vector, mag: Vector | None = None) -> bool:
        """Initialise from one accelerometer (and magnetometer) sample; False if not valid."""
        if not valid_vector(accel_m_s2):
            return False
        use_mag = self._params.use_mag and heading_from_mag(accel_m_s2, mag)
        q = orientation_from_vectors(accel_m_s2, mag if use_mag else None)
        self.initialize(self._to_output(q), heading_known=use_mag)
        return True

    def update(
        self, gyro_rad_s: Vector, accel_m_s2: Vector | None, dt_s: float, mag: Vector | None = None,
        aiding: AidingInput | None = None,
    ) -> tuple[float, float, float, float] | None:
        """Process one sample; returns q_world_from_sensor (w, x, y, z) or None before init.

        gyro [rad/s] must be finite and within ±GYRO_LIMIT_RAD_S, dt [s] > 0 (ValueError
        otherwise); an invalid (non-finite, zero or overflowing norm) or
        missing accelerometer/magnetometer sample is skipped for this step (gyro-only).
        Magnetometer units are free (only the direction and relative norm are used).
        ``aiding`` (an initialised filter): velocity aiding's input at this sample
        (:meth:`apply_aiding` first; the step then takes ``aiding.accel_m_s2``, the aided
        specific force, in place of the ``accel_m_s2`` argument); :attr:`aiding_attitude_error`
        says whether it took hold on an attitude error.
        """
        if aiding is not None and self._initialized:
            self.aiding_attitude_error = self.apply_aiding(aiding)
            accel_m_s2 = aiding.accel_m_s2
        return self._update(gyro_rad_s, accel_m_s2, dt_s, mag)

    def _update(self, gyro_rad_s: Vector, accel_m_s2: Vector | None, dt_s: float,
                mag: Vector | None) -> tuple[float, float, float, float] | None:
        """The step itself (:meth:`update` after the aiding's input): both hypotheses."""
        if self._pair is not None:  # the compiled twin (initialised), same checks
            q, self._state = self._pair(gyro_rad_s, accel_m_s2, dt_s, mag)
            return q
        if not self._initialized:
            self.initialize_from(accel_m_s2, mag) if accel_m_s2 is not None else None
            return self.orientation_tuple() if self._initialized else None
        gx, gy, gz = (float(c) for c in gyro_rad_s)
        if not math.isfinite(gx + gy + gz):
            raise ValueError(f"gyro sample is not finite: {tuple(gyro_rad_s)!r}")
        if max(abs(gx), abs(gy), abs(gz)) > GYRO_LIMIT_RAD_S:
            raise ValueError(f"gyro sample beyond {GYRO_LIMIT_RAD_S:g} rad/s: "
                             f"{tuple(gyro_rad_s)!r}")
        if not (dt_s > 0.0 and math.isfinite(dt_s)):
            raise ValueError(f"dt must be a positive finite number of seconds, got {dt_s!r}")
        acc = tuple(float(c) for c in accel_m_s2) if valid_vector(accel_m_s2) else None
        mg = tuple(float(c) for c in mag) if valid_vector(mag) else None  # type: ignore[union-attr]
        step(self._learning, self._view, (gx, gy, gz), acc, mg, float(dt_s), FloatOps)  # type: ignore[arg-type]
        if self._null is not None:
            step(self._null, self._null_view, (gx, gy, gz), acc, mg, float(dt_s), FloatOps)  # type: ignore[arg-type]
            self._choose()
        return self.orientation_tuple()

    def run_rows(
        self,
        gyro_rad_s: np.ndarray,
        accel_m_s2: np.ndarray,
        mag: np.ndarray | None,
        dt_s: np.ndarray,
        start: int,
        q_out: np.ndarray,
        extra_out: np.ndarray | None = None,
    ) -> None:
        """:meth:`update` for rows ``start``..N−1 of whole recordings (initialised filter only).

        gyro/accel/mag: (N, 3) C-contiguous float64 (invalid accel/mag rows are skipped as in
        update); dt_s: (N,) [s]; writes q_out (N, 4) and, if given, extra_out (N, EXTRA_COLUMNS)
        for those rows. ValueError at the first non-finite gyro row or bad dt.
        """
        if not self._initialized:
            raise RuntimeError("run_rows needs an initialised filter")
        if self._kernel_params is not None:
            if self._null is None:
                self._learning.run(self._kernel_params, gyro_rad_s, accel_m_s2, mag, dt_s, start,
                                   q_out, extra_out)
                return
            try:
                self._learning.run(self._kernel_params, gyro_rad_s, accel_m_s2, mag, dt_s, start,
                                   q_out, extra_out, self._null, self._null_kernel_params)
            finally:
                self._choose()  # the published one after the last row run
            return
        g_rows, a_rows = gyro_rad_s.tolist(), accel_m_s2.tolist()
        m_rows = mag.tolist() if mag is not None else None
        dts = dt_s.tolist()
        for i in range(start, len(dts)):
            q_out[i] = self.update(g_rows[i], a_rows[i], dts[i], m_rows[i] if m_rows else None)
            if extra_out is not None:
                extra_out[i] = state_extras(self._state)

    # -- outputs -----------------------------------------------------------------------------
    def _to_output(self, q_enu: Any) -> np.ndarray:
        q = np.asarray(q_enu, dtype=float)
        return quat.enu_to_ned(q) if self._params.world_frame == "ned" else q

    def orientation_tuple(self) -> tuple[float, float, float, float]:
        """q_world_from_sensor (w, x, y, z) in the configured world frame, as floats."""
        s = self._state
        if self._params.world_frame == "ned":
            return (
                -_SQRT_HALF * (s.qx + s.qy),
                _SQRT_HALF * (s.qw + s.qz),
                _SQRT_HALF * (s.qw - s.qz),
                _SQRT_HALF * (s.qy - s.qx),
            )
        return (s.qw, s.qx, s.qy, s.qz)

    @property
    def orientation(self) -> np.ndarray:
        """q_world_from_sensor (w, x, y, z) as an array (NaN before initialisation)."""
        if not self._initialized:
            return np.full(4, np.nan)
        return np.array(self.orientation_tuple())

    @property
    def gyro_bias_rad_s(self) -> np.ndarray:
        """Gyro-bias estimate [rad/s], sensor frame.

        The regulator's integral state b plus the heading channel's world-vertical rate
        correction z_m seen on the sensor axes at the current attitude: b − Rᵀ·ẑ·z_m.
        """
        return np.array(gyro_bias_of(self._state))

    def status(self) -> FilterStatus:
        """The internal decisions of the last step (see :class:`FilterStatus`)."""
        s = self._state
        return FilterStatus(
            phase=PHASE_NAMES[int(s.phase)] if self._initialized else PHASE_NAMES[0],
            time_since_init_s=float(s.time_s),
            error_rad=(float(s.ex), float(s.ey), float(s.ez)),
            error_norm_rad=float(s.error_norm),
            clipped=bool(s.clipped),
            processed_error_rad=(float(s.fx), float(s.fy), float(s.fz)),
            gyro_bias_rad_s=tuple(float(c) for c in self.gyro_bias_rad_s),  # type: ignore[arg-type]
            gyro_bias_sigma_rad_s=bias_error_sigma(s),
            gyro_bias_converged=bias_error_sigma(s) < BIAS_CONVERGED_SIGMA_RAD_S,
            at_rest=bool(s.at_rest),
            accel_used=bool(s.accel_used),
            mag_status=MAG_STATUS_NAMES[int(s.mag_status)],
            heading_initialized=bool(s.heading_initialized),
            yaw_error_rad=float(s.yaw_error_rad),
            recovery_count=int(s.recovery_count),
            mag_yaw_rate_correction_rad_s=float(s.z_m),
            heading_rate_unverified=bool(s.bias_unverified),
            heading_recovering=bool(s.mag_recovering),
            bias_hypothesis="rest_only" if s is self._null else "in_flight",
            heading_source=("none" if not s.heading_initialized else
                            "gyro" if s.mag_disturbed else "magnetometer"),
            mag_on_body=bool(s.mag_on_body),
        )

    def get_state(self) -> dict[str, Any]:
        """Everything the filter has learned, as plain values (VQF's ``getState``):
        ``{"initialized": bool, "published": "in_flight" | "rest_only", "in_flight": {field:
        value}, "rest_only": {field: value} | None}``, the fields those of
        :class:`~cf_estimator.core.state.StepState` (units in core/state.py) for each bias
        hypothesis (``rest_only`` None when ``bias_learning_k2`` is 0). JSON-serialisable;
        :meth:`set_state` takes it back."""
        def fields(s: Any) -> dict[str, Any]:
            return {k: getattr(s, k) for k in StepState.FIELDS}

        return {"initialized": self._initialized,
                "published": "rest_only" if self._state is self._null else "in_flight",
                "in_flight": fields(self._learning),
                "rest_only": None if self._null is None else fields(self._null)}

    def set_state(self, state: dict[str, Any]) -> None:
        """Continue from a :meth:`get_state` (of a filter with the same parameters, or others:
        then they apply from the next sample). ValueError, the filter untouched, when a field
        is missing or unknown, or the hypotheses do not match ``bias_learning_k2``."""
        want = set(StepState.FIELDS)
        parts = [state.get("in_flight"), state.get("rest_only")]
        if not isinstance(parts[0], dict) or (parts[1] is None) != (self._null is None):
            raise ValueError("set_state: expected the 'in_flight' fields and, exactly when "
                             "bias_learning_k2 > 0, the 'rest_only' fields (get_state's form)")
        for part in (p for p in parts if p is not None):
            if not isinstance(part, dict) or set(part) != want:
                got = set(part) if isinstance(part, dict) else set()
                raise ValueError(f"set_state: missing fields {sorted(want - got)}, unknown "
                                 f"fields {sorted(got - want)}")
        if state.get("published") not in ("in_flight", "rest_only"):
            raise ValueError(f"set_state: 'published' must be 'in_flight' or 'rest_only', got "
                             f"{state.get('published')!r}")
        learning, null = self._new_state(), None if self._null is None else self._new_state()
        for target, part in ((learning, parts[0]), (null, parts[1])):
            if target is not None:
                for k, v in part.items():
                    setattr(target, k, v)
        self._learning, self._null = learning, null
        self._state = null if (null is not None and state["published"] == "rest_only") \
            else learning
        self._initialized = bool(state.get("initialized", True))
        self._bind()

    def state_snapshot(self) -> Any:
        """A copy of the full internal state (for tests and debugging)."""
        return self._state.copy()
