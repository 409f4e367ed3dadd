"""Velocity aiding: take the vehicle's own acceleration out of the specific force (GNSS, odometry).

The accelerometer measures f = Rᵀ·(a − g_w). An IMU-only filter takes f for gravity; in a
sustained manoeuvre it tilts towards the thrust. With a world-frame velocity v(t) the kinematic
acceleration a is known (late, noisy, at a low rate), and f − Rᵀ·a is gravity alone. This
module builds that aided specific force for the unchanged filter step, outside it
(``accel_aided = accel − R̂ᵀ·a_world``), aligned on stamps:

- **Differentiation matched to the input.** For the newest accepted velocity sample k and the
  latest earlier one j with t_k − t_j ≥ ``velocity_window_s``: a_v = (v_k − v_j)/(t_k − t_j),
  the exact mean acceleration over [t_j, t_k]. The IMU's specific force is averaged over the
  very same interval (by stamps, from a cumulative sum), so both sides see the same motion
  whatever the velocity's rate, latency (50–200 ms for GNSS) or jitter.
- **Delay without loop delay.** The mean specific force is accumulated in a frame P carried by
  the gyro alone (P ← P ⊗ Exp((ω − b̂)·dt), b̂ the filter's bias estimate): m_P = F̄_P − a_v(in
  P) is then a gravity measurement that stays valid in P while time passes (only gyro
  integration over the delay, not the filter's own corrections, lies between it and now), and
  the step gets ``Pᵀ·(m_P + f_P − lowpass(f_P))``: gravity from the velocity window, plus
  the specific force's content faster than :data:`HIGHPASS_TIME_CONSTANT_S` (vibration,
  impacts: what the step's detectors and saturation expect to see).
- **Horizontal once the heading is known, vertical before.** With the heading offset known,
  a_v's horizontal part is taken out: a vertical acceleration is along gravity and tilts
  nothing, and left in, it keeps the step's stillness and linear-acceleration detectors seeing
  the vehicle's vertical motion (taking it out as well was measured: phantom4 offline aided
  1.00° vs 0.70°). Before the heading is known (hover, vertical zig-zags, the first seconds of
  any flight) the vertical part alone is taken out, which needs no heading: the aiding then
  begins with the first velocity window, with its take-hold (start-up gain, the bias learned
  unaided reopened) and its short lag. Measured against waiting for the heading
  (``bench euroc --velocity``, shipped defaults): phantom4 vertical 1.28° → 1.16°, horizontal
  1.87° → 1.51°, EuRoC from the ground 0.95° → 0.96°, mid-air late windows 2.0/1.8/1.6° →
  1.7/1.5/1.3°; most of the gain is the earlier take-hold and window, not the vertical
  acceleration itself (the same mode without it: 1.17°, 1.52°). A second take-hold when the
  horizontal aiding begins was measured and dropped (1.26°/1.93°: the offset is still up to
  velocity_heading_sigma_rad off then); the alignment below replaced it.
- **Noise.** A horizontal acceleration within the differentiation noise (from
  ``velocity_noise_m_s``) is shrunk towards 0 (factor 1 − noise²/|a_h|², never below 0): in
  steady flight a noisy velocity adds no tilt noise, in a manoeuvre it is taken out in full.
- **Heading and alignment.** a_v is in the velocity's frame; the filter's world frame may be
  turned about the vertical by δ (6-D: arbitrary heading). Every velocity window also feeds the
  in-motion alignment (:mod:`cf_estimator.core.alignment`): the rotation from P to the
  velocity's world frame and the gyro bias, fitted from the windows alone (open loop: the
  filter's corrections do not enter it). ``velocity_heading='auto'`` takes δ from it and aids
  the horizontal only once it is known; ``'filter'`` takes δ = 0. With a magnetometer that
  references the heading, 'auto' starts from the compass: δ = 0 ± velocity_compass_sigma_rad,
  the fit weighed in by inverse variance once it is known (:func:`with_compass`), so the
  horizontal aiding begins with the first window. Measured (9-D, the simulated 10 Hz GNSS
  velocity; tilt peak, seeds 0–2, 0.1 rad against the fit alone): the `uav` flight after
  10 s 34.2 / 37.7 / 33.0′ against 40.6 / 43.7 / 32.7′ (RMS 12.3′ both), the thesis manoeuvre
  (its window + 15 s) 37.4 / 35.1 / 18.5′ against 42.9 / 35.5 / 18.8′; BROAD aided by its
  optical positions (`bench broad --velocity`, 9-D) 1.978° total against 1.977° — a hand's
  quick accelerations show the offset at once anyway. When the fit first becomes
  known, the filter takes its tilt and gyro bias at once
  (:meth:`~cf_estimator.core.filter.ComplementaryFilter.realign`): the take-hold of a flight
  started in the air, seconds instead of the loop's slow pull-in (``bench cross`` aided rows,
  before → after: phantom4 horizontal 1.41° → 0.84°, phantom4 vertical 1.24° → 0.69°, EuRoC
  mid-air 12 s–end 1.68/1.56/1.24° → 1.13/1.26/0.86°).
- **An uncertain heading, across the acceleration.** The error δ's uncertainty σ_δ leaves in the
  acceleration taken out, σ_δ·|a_h|, lies across a_h; across a_h the aided measurement is weighed
  against the filter's own tilt (σ_t: the drift its gyro leaves, ``aiding_estimates()`` of
  the filter) as a Kalman gain would, along a_h it is kept whole
  (:meth:`VelocityAiding._across_heading_error`).
  The thesis manoeuvre, whose fit is known 0.5 s into a 5 m/s² acceleration with σ_δ near
  0.3 rad: aided peak 51.7′ → 42.8′ (heading known from the start: 32.5′); the Phantom 4
  flights, started in the air with σ_t of 10–15°, unchanged.
- **Not at rest while moving.** A velocity beyond :data:`MOVING_SPEED_SIGMAS` of its noise
  says the vehicle moves: the filter is not at rest then, whatever its stillness blocks say
  (:meth:`~cf_estimator.core.filter.ComplementaryFilter.interrupt_rest`), so no gyro mean is
  taken for bias. A multirotor slowing down in the air turns smoothly enough to pass the
  blocks' tests and its accelerometer reads the thrust axis however it tilts: on EuRoC
  MH_05 (started 20 and 40 s in) a still run at 1 m/s took 0.6 °/s of turn for bias with
  σ 0.2 °/s and the aided tilt error grew to 2.7°; with the velocity's word, ``bench cross``'s
  aided EuRoC mid-air rows (12 s–end, starts 20 / 40 / 60 s) went 1.13 / 1.27 / 0.86° →
  0.89 / 0.87 / 0.86°.
- **An attitude error revealed while aided is taken hold of.** Aided horizontally, the
  gravity a velocity window measures is off the filter's vertical by the tilt error, less
  what the aiding leaves (the velocity's noise and latency: hundredths of a radian); beyond
  ``BIAS_LEARNING_MAX_ERROR_RAD`` (0.35 rad, the error no bias explains) — a gyro fault, an
  over-range — it is an attitude error: the filter takes hold again, as when aiding began,
  instead of learning part of it as gyro bias. A 34° step (``bench euroc --velocity
  --gyro-fault 15 --settle 20``), aided: phantom4 3.56° → 1.30°; horizontal zig-zags
  (``--gyro-fault 10 --settle 15``) 4.00° → 1.22°. Without the fault nothing changes
  (``bench cross``: the same JSON). The window's means, not the aperiodic unit's per-sample
  state: a hand shaking the sensor at 8 g passed that state for an attitude error, and each
  take-hold trusted the shake (BROAD's fast translation aided by its optical positions: up
  to 178° off; BENCHMARKS.md "After a gyro fault", docs/decisions/0006). A window whose
  gravity is not g's size (beyond the same share of g) judges nothing: an attitude error turns
  it, a window whose velocity and IMU disagree (a shake against the velocity's own bandwidth,
  in 0.5 s windows: false take-holds and 166° off) does not.
- **Fallback.** Without a fresh window (no velocity, a stamp older than ``velocity_timeout_s``,
  a dropout) the raw accelerometer sample is returned untouched: the filter's
  outputs are then bit-identical to the unaided filter's.

Velocity samples are queued by stamp and used once the IMU stamps pass them. Rejected (and
counted): non-finite values, zero/negative stamps, stamps not after the previous one, samples
older than the IMU buffer, and jumps (the change from the last accepted sample departs from
the IMU's own prediction by more than ``velocity_jump_threshold_m_s`` +
:data:`IMU_PREDICTION_M_S2`·interval). :data:`REANCHOR_REJECTIONS` jumps in a row: the stream
moved for good (re-anchored, the window starts again) — unless each of them changed by as much
as the IMU says, only in another direction (|Δv − g·dt| = |∫f dt| within the same tolerance,
which no attitude enters): then the filter's attitude is what is off (a gyro fault in hard
motion, where a tilt error turns a large ∫f dt far from the velocity's change); the sample is
taken and the window goes on, and the attitude-error check ("An attitude error revealed while
aided", above) finds the error in its gravity. (Keeping every such sample out made a gyro
fault in BROAD's hard shake, aided, stay 22–41° off for 13 s, the aiding off for most of it;
now aided throughout and below 5° after 8 s, unaided 10 s.)
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from cf_estimator.core.alignment import HeadingOffset, InMotionAlignment
from cf_estimator.core.bias import (
    BIAS_LEARNING_MAX_ERROR_RAD,
    SWING_TIME_CONSTANT_S,
    SWING_VAR_TIME_CONSTANT_S,
)
from cf_estimator.core.filter import AidingInput
from cf_estimator.core.ops import rotation_elements
from cf_estimator.core.params import FilterParams
from cf_estimator.core.quaternion import to_matrix

#: Without a heading reference of its own (6-D), the filter is steered onto the velocity's
#: frame once the heading offset δ is known: the first fix turns its heading at once, then it
#: turns by this gain × δ per second, so the offset stays near 0 instead of drifting with the
#: gyro. (An integral on the heading channel's rate correction z_m as well, 0.01/s², followed
#: the estimator's lag — it averages 60 s of accelerations — and let the heading drift 7° in
#: 40 s of a simulated flight: dropped.)
HEADING_STEER_GAIN_1_S = 0.2
#: Longest interval [s] between heading-offset updates that one steering step may stand for.
HEADING_STEER_MAX_DT_S = 1.0
#: Time constant [s] of the low-pass whose complement (the specific force's fast content:
#: vibration, impacts) is passed through while aided: slower content is replaced by the
#: velocity-aided gravity measurement.
HIGHPASS_TIME_CONSTANT_S = 0.05
#: Allowed IMU prediction error of the velocity change [m/s per s of interval] in the jump gate
#: (a tilt error of about 0.2 rad times g).
IMU_PREDICTION_M_S2 = 2.0
#: Consecutive jumps after which the stream is re-anchored on the newest sample.
REANCHOR_REJECTIONS = 5
#: IMU history kept beyond velocity_timeout_s + velocity_window_s [s].
BUFFER_MARGIN_S = 0.5
#: Velocity samples awaiting the IMU stamps to pass them (older ones are dropped, counted).
MAX_PENDING = 1000
#: A velocity sample whose norm exceeds this many σ of its noise (velocity_noise_m_s, per axis)
#: says the vehicle moves: it is not at rest, and the filter's start-up averages the
#: accelerometer as after a stillness block that was not still (ComplementaryFilter.mark_moving;
#: a three-axis noise norm passes 5 σ once in about 10⁵ samples).
MOVING_SPEED_SIGMAS = 5.0

REJECT_REASONS = ("nonfinite", "stamp", "backwards", "too_old", "jump", "frame", "malformed")


@dataclass(frozen=True)
class VelocityStatus:
    """What the aiding did (diagnostics; counts since construction or the last reset)."""

    active: bool  #: the last IMU sample was aided
    mode: str  #: 'off' | 'vertical' (heading offset unknown: a_z only) | 'aided'
    received: int  #: velocity samples offered
    used: int  #: accepted into the velocity window
    stale_samples: int  #: IMU samples that found the velocity older than velocity_timeout_s
    aided_samples: int  #: IMU samples aided (vertically or horizontally)
    horizontal_samples: int  #: IMU samples aided horizontally (heading offset known)
    rejected: dict[str, int]  #: velocity samples rejected, by reason (REJECT_REASONS)
    reanchors: int  #: times the stream was re-anchored after repeated jumps
    heading_offset_rad: float  #: δ: filter world = Rz(δ)·velocity world
    heading_sigma_rad: float  #: standard deviation of δ (inf: not observed yet)
    heading_known: bool
    age_s: float  #: IMU stamp − stamp of the newest velocity window end (inf: none)
    axes: str  #: world axes whose acceleration the last IMU sample had taken out: 'none' |
    #: 'z' (heading offset unknown) | 'xy' (heading known; the vertical is left in)
    aided_for_s: float  #: IMU stamp − stamp of the first sample of the current aided stretch
    #: (0 when not aided)
    first_velocity_t_s: float  #: stamp of the first velocity sample accepted (nan: none yet)
    first_aided_t_s: float  #: IMU stamp of the first aided sample (nan: not aided yet)
    aligned_t_s: float  #: IMU stamp at which the in-motion alignment became known and the
    #: filter took its tilt and gyro bias (nan: not yet)
    moving_now: bool = False  #: the velocity says the vehicle moves: the filter is not at rest
    #: (VelocityAiding.moving_now)
    attitude_errors: int = 0  #: times an attitude error revealed while aided horizontally (a
    #: gyro fault) made the filter take hold again (ComplementaryFilter.apply_aiding)


def _rot(qw: float, qx: float, qy: float, qz: float, x: float, y: float, z: float
         ) -> tuple[float, float, float]:
    """q ⊗ v ⊗ q* for a unit quaternion (w, x, y, z)."""
    tx = 2.0 * (qy * z - qz * y)
    ty = 2.0 * (qz * x - qx * z)
    tz = 2.0 * (qx * y - qy * x)
    return (x + qw * tx + qy * tz - qz * ty, y + qw * ty + qz * tx - qx * tz,
            z + qw * tz + qx * ty - qy * tx)


def _mul(aw: float, ax: float, ay: float, az: float, bw: float, bx: float, by: float,
         bz: float) -> tuple[float, float, float, float]:
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


class VelocityAiding:
    """Turns IMU samples into aided specific force given world-frame velocity samples.

    Per IMU sample, the aiding is an input of the filter's update (:meth:`update_filter`)::

        inp = aiding.step_input(t_s, gyro, accel, dt_s, filter.orientation_tuple(),
                                filter.aiding_estimates())
        filter.update(gyro, accel, dt_s, mag, aiding=inp)
        if filter.aiding_attitude_error:
            aiding.note_attitude_error()

    ``q_filter``: the filter's q_world_from_sensor before the update (its world frame, ENU or
    NED); ``aiding_estimates()``: its gyro-bias estimate [rad/s] (sensor frame), the estimate's
    variance, and its tilt's σ from the gyro's drift.
    Velocity samples [m/s] in the velocity's world frame (same axes convention as the filter's
    world: ENU or NED) arrive through :meth:`add_velocity` with their header stamps [s].
    """

    def __init__(self, params: FilterParams | None = None) -> None:
        self.set_params(params if params is not None else FilterParams())
        self.reset()

    def set_params(self, params: FilterParams) -> None:
        """Apply new parameters (the window and counters are kept)."""
        self._params = params
        self._window = params.velocity_window_s
        self._timeout = params.velocity_timeout_s
        self._jump = params.velocity_jump_threshold_m_s
        self._auto = params.velocity_heading == "auto"
        # the compass's prior on the heading offset (with_compass): 'auto' with a magnetometer
        self._compass = params.velocity_compass_sigma_rad if (
            self._auto and params.use_mag) else 0.0
        # steer a filter without its own heading reference onto the velocity's frame
        self._steer = self._auto and not params.use_mag
        self._span = params.velocity_timeout_s + params.velocity_window_s + BUFFER_MARGIN_S
        # a speed² [m²/s²] beyond which a velocity sample says the vehicle moves
        limit = MOVING_SPEED_SIGMAS * params.velocity_noise_m_s
        self._moving_speed2 = limit * limit
        # differentiation noise of the velocity over one window, both horizontal axes [m²/s⁴]
        noise2 = 4.0 * (params.velocity_noise_m_s / params.velocity_window_s) ** 2
        if hasattr(self, "_heading"):
            self._heading.required_sigma_rad = params.velocity_heading_sigma_rad
            self._heading.memory_s = params.velocity_heading_memory_s
            self._heading.noise2_m2_s4 = noise2
            self._heading.bias_prior_sigma_rad_s = params.bias_prior_sigma_rad_s
        else:
            self._heading = InMotionAlignment(params.velocity_heading_sigma_rad,
                                              params.velocity_heading_memory_s, noise2,
                                              params.bias_prior_sigma_rad_s)

    def reset(self) -> None:
        """Forget the IMU history, the velocity window and the heading offset (counters kept
        unless :meth:`reset_counters`)."""
        self._p: tuple[float, float, float, float] | None = None
        self._bt: list[float] = []  # IMU stamps [s]
        self._bs: list[tuple[float, ...]] = []  # self._sum at that stamp
        self._b0 = 0  # first live index of the buffer lists
        # Σ f_P·dt [m/s] (3), ∫P·dt [s] (3×3, rows) and ∫P·b̂·dt [rad] (3): the alignment's
        self._sum: tuple[float, ...] = (0.0,) * 15
        self._lp = (0.0, 0.0, 0.0)  # low-pass of f_P (HIGHPASS_TIME_CONSTANT_S)
        self._pending: list[tuple[float, tuple[float, float, float]]] = []
        self._hist: list[tuple[float, tuple[float, float, float], tuple[float, float, float]]
                         ] = []  # accepted (t, v, Σ f_P at t)
        self._last_stamp = -math.inf
        self._jumps = 0
        self._turned = 0  # of those, jumps whose size matched the IMU's (only turned)
        self._m: tuple[float, float, float] | None = None  # gravity measurement in P [m/s²]
        self._m_t = -math.inf
        self._m_axes = "none"  # world axes whose acceleration _m has taken out: 'z' | 'xy'
        self._window_error = 0.0  # angle [rad] of the last 'xy' _m from the filter's vertical
        self._heading.reset()
        self._hd = HeadingOffset(0.0, math.inf, False)
        self._active = self._started = self._first = self._ever = False
        self._moving = False  # a velocity sample beyond MOVING_SPEED_SIGMAS was queued
        self._fast_t = -math.inf  # stamp of the newest accepted sample beyond it
        # the horizontal velocity low-passed over SWING_TIME_CONSTANT_S (its stamp) and the
        # mean square of what is left, over g² (_observe_swing)
        self._vlp: tuple[float, float] | None = None
        self._vlp_t = 0.0
        self._swing_var = 0.0
        self._realigned_t = math.nan  # IMU stamp at which the alignment became known
        # for the filter, once: (tilt correction [rad] in its world frame, gyro bias [rad/s])
        self._realign: tuple[Any, Any] | None = None
        self._since = math.nan  # IMU stamp of the first sample of the current aided stretch
        self._first_v_t = math.nan  # stamp of the first accepted velocity sample
        self._first_aided_t = math.nan  # IMU stamp of the first aided sample
        self._steer_t: float | None = None
        self._turn = 0.0
        if not hasattr(self, "_received"):
            self.reset_counters()

    def reset_counters(self) -> None:
        """Zero every counter."""
        self._received = 0
        self._used = 0
        self._stale = 0
        self._aided = 0
        self._aided_xy = 0
        self._reanchors = 0
        self._attitude_errors = 0
        self.rejected = dict.fromkeys(REJECT_REASONS, 0)

    # -- velocity input ------------------------------------------------------------------------
    def reject(self, reason: str) -> None:
        """Count a velocity sample rejected before it got here (e.g. 'frame' by the pipeline)."""
        self._received += 1
        self.rejected[reason] += 1

    def add_velocity(self, t_s: float, v_m_s: Sequence[float]) -> str | None:
        """Queue one velocity sample (stamp [s], world-frame velocity [m/s]); returns None when
        queued, else the rejection reason (counted)."""
        self._received += 1
        try:
            vx, vy, vz = (float(c) for c in v_m_s)
            t = float(t_s)
        except (TypeError, ValueError):
            self.rejected["nonfinite"] += 1
            return "nonfinite"
        if not math.isfinite(vx + vy + vz + t):
            reason = "nonfinite"
        elif t <= self._last_stamp:
            reason = "backwards"
        elif self._bt and t < self._bt[self._b0]:
            reason = "too_old"
        else:
            self._last_stamp = t
            self._moving = self._moving or vx * vx + vy * vy + vz * vz > self._moving_speed2
            self._pending.append((t, (vx, vy, vz)))
            if len(self._pending) > MAX_PENDING:
                self._pending.pop(0)
                self.rejected["too_old"] += 1
            return None
        self.rejected[reason] += 1
        return reason

    # -- per IMU sample ------------------------------------------------------------------------
    def step_input(self, t_s: float, gyro_rad_s: Sequence[float], accel_m_s2: Sequence[float],
                   dt_s: float, q_filter: Sequence[float], filter_state: Sequence[float]
                   ) -> AidingInput:
        """The filter's input at IMU stamp t_s [s] (``filter.update(..., aiding=)``):
        :meth:`aided_accel` and what the aiding says with it; the realignment and heading
        correction due are handed over once."""
        accel = self.aided_accel(t_s, gyro_rad_s, accel_m_s2, dt_s, q_filter, filter_state)
        return AidingInput(accel, self._moving, self.moving_now, self.started, self.first_start,
                           self.take_realignment(), self._active, self.axes == "xy",
                           self._swing_var, self.window_error_rad,
                           self.take_heading_correction())

    def aided_accel(self, t_s: float, gyro_rad_s: Sequence[float], accel_m_s2: Sequence[float],
                    dt_s: float, q_filter: Sequence[float], filter_state: Sequence[float]
                    ) -> Sequence[float]:
        """The accelerometer sample to give the filter at IMU stamp t_s [s]: aided when a fresh
        velocity window is known (horizontally once the heading offset is known, vertically
        before), else ``accel_m_s2`` itself (same object). ``filter_state``: the filter's gyro
        bias estimate [rad/s] (sensor frame), optionally its variance [(rad/s)²] per axis
        (< 0: none yet) and the σ [rad] of its tilt from the gyro's drift, as
        :meth:`~cf_estimator.core.filter.ComplementaryFilter.aiding_estimates` gives them."""
        # queued samples the buffer covers, with P and q_filter both at the last IMU stamp
        bt = self._bt
        if self._pending and bt and self._pending[0][0] <= bt[-1]:
            self._take_pending(bt[-1], q_filter, filter_state)
        ax, ay, az = float(accel_m_s2[0]), float(accel_m_s2[1]), float(accel_m_s2[2])
        if self._p is None:
            pw, px, py, pz = (float(c) for c in q_filter)
        else:
            aw, bx, by, bz = self._p
            hx = 0.5 * (gyro_rad_s[0] - filter_state[0]) * dt_s
            hy = 0.5 * (gyro_rad_s[1] - filter_state[1]) * dt_s
            hz = 0.5 * (gyro_rad_s[2] - filter_state[2]) * dt_s
            n = math.sqrt(hx * hx + hy * hy + hz * hz)
            c = math.cos(n)
            sn = math.sin(n) / n if n > 1e-12 else 1.0
            hx, hy, hz = hx * sn, hy * sn, hz * sn
            pw = aw * c - bx * hx - by * hy - bz * hz
            px = aw * hx + bx * c + by * hz - bz * hy
            py = aw * hy - bx * hz + by * c + bz * hx
            pz = aw * hz + bx * hy - by * hx + bz * c
            inv = 1.0 / math.sqrt(pw * pw + px * px + py * py + pz * pz)
            pw, px, py, pz = pw * inv, px * inv, py * inv, pz * inv
        self._p = (pw, px, py, pz)
        # f_P = P ⊗ f ⊗ P*
        tx, ty, tz = 2.0 * (py * az - pz * ay), 2.0 * (pz * ax - px * az), 2.0 * (px * ay - py * ax)
        fx = ax + pw * tx + py * tz - pz * ty
        fy = ay + pw * ty + pz * tx - px * tz
        fz = az + pw * tz + px * ty - py * tx
        if bt:
            d = t_s - bt[-1]
            if d <= 0.0:  # not after the last stamp: nothing to add
                self._active = self._started = self._first = False
                return accel_m_s2
            # P as a matrix: ∫P·dt and ∫P·b̂·dt for the alignment's drift model
            r00, r01, r02, r10, r11, r12, r20, r21, r22 = rotation_elements(pw, px, py, pz)
            b0, b1, b2 = filter_state[0], filter_state[1], filter_state[2]
            s_ = self._sum
            self._sum = (s_[0] + fx * d, s_[1] + fy * d, s_[2] + fz * d,
                         s_[3] + r00 * d, s_[4] + r01 * d, s_[5] + r02 * d,
                         s_[6] + r10 * d, s_[7] + r11 * d, s_[8] + r12 * d,
                         s_[9] + r20 * d, s_[10] + r21 * d, s_[11] + r22 * d,
                         s_[12] + (r00 * b0 + r01 * b1 + r02 * b2) * d,
                         s_[13] + (r10 * b0 + r11 * b1 + r12 * b2) * d,
                         s_[14] + (r20 * b0 + r21 * b1 + r22 * b2) * d)
            k = d / (HIGHPASS_TIME_CONSTANT_S + d)
            lx, ly, lz = self._lp
            self._lp = lp = (lx + k * (fx - lx), ly + k * (fy - ly), lz + k * (fz - lz))
        else:
            self._lp = lp = (fx, fy, fz)
        bt.append(t_s)
        self._bs.append(self._sum)
        if not len(bt) & 127:  # drop history older than the span now and then
            start = t_s - self._span
            if bt[self._b0] < start:
                self._b0 = bisect.bisect_left(bt, start, self._b0)
                if self._b0 > 4096:
                    del bt[:self._b0]
                    del self._bs[:self._b0]
                    self._b0 = 0
        m = self._m
        if m is None or t_s - self._m_t > self._timeout:
            self._active = self._started = self._first = False
            if m is not None:
                self._stale += 1
            return accel_m_s2
        self._started = not self._active
        self._first = self._started and not self._ever
        if self._started:
            self._since = t_s
            if self._first:
                self._first_aided_t = t_s
        self._active = self._ever = True
        self._aided += 1
        if self._m_axes == "xy":
            self._aided_xy += 1
        # Pᵀ·(m_P + f_P − lowpass(f_P)): gravity from the velocity window, fast content kept
        gx, gy, gz = m[0] + fx - lp[0], m[1] + fy - lp[1], m[2] + fz - lp[2]
        tx, ty, tz = 2.0 * (pz * gy - py * gz), 2.0 * (px * gz - pz * gx), 2.0 * (py * gx - px * gy)
        return (gx + pw * tx - py * tz + pz * ty, gy + pw * ty - pz * tx + px * tz,
                gz + pw * tz - px * ty + py * tx)

    def _at(self, t: float) -> tuple[float, ...]:
        """The running sums (self._sum) at stamp t (linear between IMU stamps; clamped to the
        buffer)."""
        bt, bs = self._bt, self._bs
        if t <= bt[self._b0]:
            return bs[self._b0]
        k = bisect.bisect_left(bt, t, self._b0)
        if k >= len(bt):
            return bs[-1]
        if bt[k] == t:
            return bs[k]
        a = (t - bt[k - 1]) / (bt[k] - bt[k - 1])
        return tuple(u + a * (w - u) for u, w in zip(bs[k - 1], bs[k], strict=True))

    def _observe_swing(self, t: float, v: Sequence[float]) -> None:
        """The vehicle's horizontal velocity swing over g from the velocity itself: v_h
        high-passed over SWING_TIME_CONSTANT_S and its mean square over SWING_VAR_TIME_CONSTANT_S
        [rad²·s²] — what the filter's pseudo-velocity measures unaided from the accelerometer
        (bias.observe_velocity_swing), where aided it sees only what the aiding leaves."""
        if self._vlp is None:
            self._vlp, self._vlp_t = (v[0], v[1]), t
            return
        dt = t - self._vlp_t
        self._vlp_t = t
        a = dt / (SWING_TIME_CONSTANT_S + dt)
        lx = self._vlp[0] + a * (v[0] - self._vlp[0])
        ly = self._vlp[1] + a * (v[1] - self._vlp[1])
        self._vlp = (lx, ly)
        g = self._params.gravity_m_s2
        hx, hy = (v[0] - lx) / g, (v[1] - ly) / g
        self._swing_var += dt / (SWING_VAR_TIME_CONSTANT_S + dt) * (
            hx * hx + hy * hy - self._swing_var)

    @property
    def swing_var(self) -> float:
        """The vehicle's velocity swing over g, mean square [rad²·s²], from the velocity samples
        (0 before two were accepted)."""
        return self._swing_var

    def _take_pending(self, t_s: float, q_filter: Sequence[float],
                      filter_state: Sequence[float]) -> None:
        """Accept the queued velocity samples whose stamps the IMU has passed."""
        qw, qx, qy, qz = q_filter
        pw, px, py, pz = self._p  # type: ignore[misc]
        # W = q_filter ⊗ P*: from the gyro frame P to the filter's world frame
        ww, wx, wy, wz = _mul(qw, qx, qy, qz, pw, -px, -py, -pz)
        while self._pending and self._pending[0][0] <= t_s:
            t, v = self._pending.pop(0)
            if t < self._bt[self._b0]:
                self.rejected["too_old"] += 1
                continue
            s = self._at(t)
            hist = self._hist
            if hist and t - hist[-1][0] > self._timeout:
                hist.clear()  # a dropout: the window starts again
            if hist:
                t1, v1, s1 = hist[-1]
                dt = t - t1
                # the IMU's prediction of the velocity change, in the velocity's frame
                dwx, dwy, dwz = _rot(ww, wx, wy, wz, s[0] - s1[0], s[1] - s1[1], s[2] - s1[2])
                g = self._params.gravity_m_s2 * dt
                dwz -= g if self._params.world_frame == "enu" else -g
                dvx, dvy, dvz = v[0] - v1[0], v[1] - v1[1], v[2] - v1[2]
                if self._hd.known or not self._auto:
                    c, sn = math.cos(self._hd.offset_rad), math.sin(self._hd.offset_rad)
                    ex, ey = c * dvx - sn * dvy - dwx, sn * dvx + c * dvy - dwy
                    err = math.sqrt(ex * ex + ey * ey + (dvz - dwz) ** 2)
                else:
                    err = math.hypot(math.hypot(dvx, dvy) - math.hypot(dwx, dwy), dvz - dwz)
                tol = self._jump + IMU_PREDICTION_M_S2 * dt
                if err > tol:
                    self._jumps += 1
                    self.rejected["jump"] += 1
                    # the change as large as the IMU's (|Δv − g·dt| = |∫f dt|, whatever the
                    # attitude), only turned: the filter's attitude may be what is off
                    gz = dvz + (g if self._params.world_frame == "enu" else -g)
                    size = math.sqrt(dvx * dvx + dvy * dvy + gz * gz)
                    imu = math.sqrt(sum((a - b) ** 2 for a, b in zip(s[:3], s1[:3],
                                                                      strict=True)))
                    self._turned += abs(size - imu) <= tol
                    if self._jumps < REANCHOR_REJECTIONS:
                        continue
                    self._reanchors += 1
                    if self._turned < self._jumps:
                        hist.clear()  # the stream moved for good: the window starts again
                    # else every one had the IMU's size: a turned attitude (a gyro fault),
                    # not a moved stream; the window goes on, and its gravity shows the error
            self._jumps = self._turned = 0
            self._used += 1
            if self._used == 1:
                self._first_v_t = t
            hist.append((t, v, s))
            if v[0] * v[0] + v[1] * v[1] + v[2] * v[2] > self._moving_speed2:
                self._fast_t = t
            self._observe_swing(t, v)
            # the window: the latest earlier sample at least velocity_window_s before t
            k = len(hist) - 1
            j = k - 1
            while j > 0 and t - hist[j][0] < self._window:
                j -= 1
            if j < 0 or t - hist[j][0] < self._window * 0.999:
                continue
            del hist[:j]  # older samples are no longer needed
            t0, v0, s0 = hist[0]
            span = t - t0
            mx, my, mz = ((s[0] - s0[0]) / span, (s[1] - s0[1]) / span, (s[2] - s0[2]) / span)
            ax, ay = (v[0] - v0[0]) / span, (v[1] - v0[1]) / span
            # mean specific force in the filter's world frame: its horizontal part is the
            # acceleration as the filter sees it (heading offset δ from the velocity's)
            fwx, fwy, fwz = _rot(ww, wx, wy, wz, mx, my, mz)
            if self._heading.offer((t - hist[-2][0]) / span if len(hist) > 1 else 1.0):
                self._align(t, t_s, span, (mx, my, mz), v, v0, s, s0,
                            (ww, wx, wy, wz), filter_state)
            if not self._hd.known:
                # heading unknown: the vertical acceleration alone, which needs no heading
                self._m = _rot(ww, -wx, -wy, -wz, fwx, fwy, fwz - (v[2] - v0[2]) / span)
                self._m_t = t
                self._m_axes = "z"
                continue
            c, sn = math.cos(self._hd.offset_rad), math.sin(self._hd.offset_rad)
            # shrinkage: an acceleration within the differentiation noise (2 axes of variance
            # 2·σ_v²/span²) is mostly noise and taken out only in part (none when below it)
            h2 = ax * ax + ay * ay
            noise2 = 4.0 * (self._params.velocity_noise_m_s / span) ** 2
            keep = max(0.0, 1.0 - noise2 / h2) if h2 > 0.0 else 0.0
            awx, awy = keep * (c * ax - sn * ay), keep * (sn * ax + c * ay)
            gx, gy = self._across_heading_error(fwx - awx, fwy - awy, awx, awy, filter_state)
            # its angle from the filter's vertical (the attitude-error check, apply_aiding);
            # none while the alignment's realignment is pending: it takes the tilt at once,
            # and the next window is measured against the realigned filter
            # and none from a window whose gravity is not g's size: a turned attitude keeps
            # the size, a window whose velocity and IMU disagree (a hard shake seen by a
            # velocity of its own bandwidth) does not, and judges nothing
            up = fwz if self._params.world_frame == "enu" else -fwz
            size = math.sqrt(gx * gx + gy * gy + fwz * fwz)
            g_ref = self._params.gravity_m_s2
            self._window_error = (
                0.0 if (self._realign is not None
                        or abs(size - g_ref) > BIAS_LEARNING_MAX_ERROR_RAD * g_ref)
                else math.atan2(math.hypot(gx, gy), up))
            # gravity measurement (specific force minus acceleration), world → P
            self._m = _rot(ww, -wx, -wy, -wz, gx, gy, fwz)
            self._m_t = t
            self._m_axes = "xy"
            if self._steer:
                self._steer_heading(t)

    def _across_heading_error(self, gx: float, gy: float, awx: float, awy: float,
                              filter_state: Sequence[float]) -> tuple[float, float]:
        """The horizontal part (gx, gy) [m/s², filter's world] of the aided gravity measurement,
        weighed across the acceleration taken out (awx, awy) against the filter's own tilt.

        The heading offset's uncertainty σ_δ turns that acceleration: the error it leaves,
        σ_δ·|a_h|, lies across a_h (along it, δ enters to second order only). Across a_h the
        measurement is weighed against the filter's tilt (σ_t·g, σ_t the tilt error its gyro's
        drift leaves: ``ComplementaryFilter.aiding_estimates``) as a Kalman gain would:
        w = σ_t²/(σ_t² + (σ_δ·|a_h|/g)²) of it is kept, the rest taken as the filter's (a level
        horizontal part: no correction). A known heading ('filter', σ_δ = 0), or none taken
        out, keeps it whole."""
        a_h = math.hypot(awx, awy)
        sigma_t = filter_state[4] if len(filter_state) > 4 else math.inf
        if a_h == 0.0 or self._hd.sigma_rad == 0.0 or not sigma_t < math.inf:
            return gx, gy
        ratio = self._hd.sigma_rad * a_h / (max(sigma_t, 1e-12) * self._params.gravity_m_s2)
        lose = 1.0 - 1.0 / (1.0 + ratio * ratio)
        nx, ny = -awy / a_h, awx / a_h
        across = lose * (gx * nx + gy * ny)
        return gx - across * nx, gy - across * ny

    def _align(self, t: float, now_s: float, span: float, force_p: tuple[float, float, float],
               v: Sequence[float], v0: Sequence[float], s: Sequence[float],
               s0: Sequence[float], w_quat: tuple[float, float, float, float],
               filter_state: Sequence[float]) -> None:
        """Feed the window [t − span, t] to the in-motion alignment (a kept window: see
        InMotionAlignment.offer), then take δ from it ('auto') and, the first time it is known,
        schedule the filter's realignment. ``now_s``: the last IMU stamp; ``s``, ``s0``: the
        running sums at the window's ends; ``w_quat``: P → the filter's world."""
        w_mat = to_matrix(w_quat)
        g = self._params.gravity_m_s2
        accel = ((v[0] - v0[0]) / span, (v[1] - v0[1]) / span,
                 (v[2] - v0[2]) / span + (g if self._params.world_frame == "enu" else -g))
        self._heading.update(t, force_p, accel,
                             [0.5 * (u + w) for u, w in zip(s0[3:], s[3:], strict=True)],
                             self._bs[-1][3:], filter_state, w_mat, to_matrix(self._p))
        fit = self._heading.estimate(w_mat)
        if not self._auto:
            self._hd = HeadingOffset(0.0, 0.0, True)
        elif self._compass > 0.0 and len(filter_state) > 5 and filter_state[5] > 0.0:
            self._hd = with_compass(fit, self._compass,
                                    self._params.velocity_heading_sigma_rad)
        else:
            self._hd = fit
        if fit.known and math.isnan(self._realigned_t):  # first known: realign
            self._realigned_t = now_s
            self._realign = (self._heading.tilt_correction(w_mat), self._heading.bias_rad_s)
            self._heading.freeze_prior()

    def _steer_heading(self, t: float) -> None:
        """Schedule the turn of the filter's heading towards the velocity's frame (see
        HEADING_STEER_GAIN_1_S); δ follows the turn at once (the alignment, fitted in P, is
        not touched by it)."""
        first = self._steer_t is None
        dt = 0.0 if first else min(t - self._steer_t, HEADING_STEER_MAX_DT_S)
        self._steer_t = t
        d = self._hd.offset_rad
        # the first fix turns the heading at once (as the magnetometer's first sample does)
        turn = d if first else HEADING_STEER_GAIN_1_S * dt * d
        self._turn -= turn
        self._hd = HeadingOffset(d - turn, self._hd.sigma_rad, self._hd.known)

    def take_heading_correction(self) -> float:
        """The turn [rad] of the filter's heading (about the world vertical) due since the last
        call (:meth:`~cf_estimator.core.filter.ComplementaryFilter.correct_heading`): 6-D with
        ``velocity_heading='auto'`` only, zero otherwise."""
        out = self._turn
        self._turn = 0.0
        return out

    def take_realignment(self) -> tuple[Any, Any] | None:
        """Once, when the in-motion alignment has become known: (tilt correction [rad], a
        rotation vector in the filter's world frame about a horizontal axis; gyro bias [rad/s],
        sensor frame) for :meth:`~cf_estimator.core.filter.ComplementaryFilter.realign`; None
        otherwise."""
        out, self._realign = self._realign, None
        return out

    # -- status --------------------------------------------------------------------------------
    @property
    def moving(self) -> bool:
        """True once a queued velocity sample said the vehicle moves (MOVING_SPEED_SIGMAS)."""
        return self._moving

    @property
    def moving_now(self) -> bool:
        """True while the velocity says the vehicle moves: an accepted sample beyond
        MOVING_SPEED_SIGMAS within velocity_timeout_s of the last IMU stamp (not at rest,
        :meth:`~cf_estimator.core.filter.ComplementaryFilter.interrupt_rest`)."""
        return bool(self._bt) and self._bt[-1] - self._fast_t <= self._timeout

    @property
    def active(self) -> bool:
        """True when the last IMU sample was aided (vertically or fully)."""
        return self._active

    @property
    def started(self) -> bool:
        """True when the last IMU sample was the first aided one after unaided ones (aiding
        began, or came back after a dropout): the caller lets the filter take hold
        (:meth:`~cf_estimator.core.filter.ComplementaryFilter.take_hold`)."""
        return self._started

    @property
    def first_start(self) -> bool:
        """True when :attr:`started` is the first start since the last reset: the bias learned
        before it came from the unaided (untrustworthy) error and is learned afresh; after a
        dropout it was learned while aided and is kept."""
        return self._first

    @property
    def axes(self) -> str:
        """World axes whose acceleration the last IMU sample had taken out: 'xy' (heading offset
        known: the horizontal acceleration; the vertical one tilts nothing and stays), 'z'
        (heading offset not known yet: the vertical acceleration, which needs no heading) or
        'none' (not aided)."""
        return self._m_axes if self._active else "none"

    @property
    def mode(self) -> str:
        """Aiding of the last IMU sample: 'off', 'vertical' (heading offset not known yet: the
        vertical acceleration alone) or 'aided' (the horizontal acceleration)."""
        if not self._active:
            return "off"
        return "vertical" if self._m_axes == "z" else "aided"

    def status(self, t_s: float | None = None) -> VelocityStatus:
        """Counters and state (``t_s``: IMU stamp for the age; default the last one)."""
        now = t_s if t_s is not None else (self._bt[-1] if self._bt else math.nan)
        return VelocityStatus(
            active=self._active, mode=self.mode, received=self._received, used=self._used,
            stale_samples=self._stale, aided_samples=self._aided,
            horizontal_samples=self._aided_xy, rejected=dict(self.rejected),
            reanchors=self._reanchors, heading_offset_rad=self._hd.offset_rad,
            heading_sigma_rad=self._hd.sigma_rad,
            heading_known=self._hd.known or not self._auto,
            age_s=now - self._m_t if self._m is not None else math.inf,
            axes=self.axes, aided_for_s=now - self._since if self._active else 0.0,
            first_velocity_t_s=self._first_v_t, first_aided_t_s=self._first_aided_t,
            aligned_t_s=self._realigned_t, moving_now=self.moving_now,
            attitude_errors=self._attitude_errors)

    @property
    def window_error_rad(self) -> float:
        """Angle [rad] between the filter's vertical and the gravity the last velocity window
        measured, horizontally aided (its specific force and acceleration are means over the
        window: what the filter is told, without the sample-to-sample content); 0 before."""
        return self._window_error

    def update_filter(self, f: Any, t_s: float, gyro_rad_s: Sequence[float],
                      accel_m_s2: Sequence[float], dt_s: float, mag: Sequence[float] | None
                      ) -> tuple[Any, Sequence[float]]:
        """One update of the initialised ComplementaryFilter ``f`` with this aiding's input at
        IMU stamp t_s [s] (the class docstring's four lines) → (its q, the specific force the
        step took [m/s², sensor frame])."""
        inp = self.step_input(t_s, gyro_rad_s, accel_m_s2, dt_s, f.orientation_tuple(),
                              f.aiding_estimates())
        q = f.update(gyro_rad_s, accel_m_s2, dt_s, mag, aiding=inp)
        if f.aiding_attitude_error:
            self.note_attitude_error()
        return q, inp.accel_m_s2

    def note_attitude_error(self) -> None:
        """Count one take-hold on an attitude error revealed while aided
        (:meth:`~cf_estimator.core.filter.ComplementaryFilter.apply_aiding` returned True)."""
        self._attitude_errors += 1

    @property
    def attitude_errors(self) -> int:
        """Take-holds on an attitude error revealed while aided so far (cumulative)."""
        return self._attitude_errors


def with_compass(fit: HeadingOffset, sigma_rad: float, required_rad: float) -> HeadingOffset:
    """The heading offset δ from the in-motion alignment's ``fit`` and the compass's prior,
    0 ± ``sigma_rad`` [rad] (the filter's heading is the magnetometer's: the velocity's frame
    but for the compass's error and any declination not set): weighed by their inverse
    variances once the fit is known (before, its σ is the scatter of too few windows, or of
    noise against noise), the prior alone before; known while σ is below ``required_rad``
    (velocity_heading_sigma_rad)."""
    if fit.known and math.isfinite(fit.sigma_rad):
        p2, f2 = sigma_rad * sigma_rad, fit.sigma_rad * fit.sigma_rad
        return HeadingOffset(fit.offset_rad * p2 / (p2 + f2), math.sqrt(p2 * f2 / (p2 + f2)),
                             True)
    return HeadingOffset(0.0, sigma_rad, sigma_rad < required_rad)
