"""Orientation covariance from what the filter knows (what a downstream EKF should weigh).

The filter does not propagate a covariance; this model turns the state it reports after each
step into variances [rad²] about the world x, y, z axes (diagonal of ``orientation_covariance``,
row-major 3×3). One model for the node and the bag replay (the pipeline) and
:func:`cf_estimator.core.batch.estimate` (``tilt_sigma_rad``, ``heading_sigma_rad``).
Documented in docs/ros_interface.md ("Covariance").

Tilt: the variance of the inclination error, ``S = cov[0] + cov[4]`` [rad²] (a 2-D error: the
expected e² of the angle between the estimated and the true "up"); reported as ``S/2`` on each of
the world x and y axes::

    S = 2·(v0 + e_t² + D(t_clip)) + M + L + V

- ``v0`` [rad²] = ``orientation_covariance_rad2``: what the filter cannot see (accelerometer
  bias, mounting), per axis.
- ``e_t`` [rad] = the raw error norm while the filter is in start-up or recovery (its tilt is
  still being pulled in: the error is the best evidence of how wrong it is), else 0.
- ``D(t_clip)``: ``t_clip`` [s] = how long the error has been clipped without a break (the
  accelerometer is distrusted: the tilt is gyro-integrated for that long); ``D(t)`` [rad²] =
  :func:`gyro_drift_var`, the variance of an angle the gyro integrates alone for t:
  ``(σ_b² − q·t)·t² + q·t³/3`` (the first term never below 0), ``σ_b`` [rad/s] the bias
  estimate's error now, √bias_err_var (:func:`cf_estimator.core.bias.error_sigma`: not
  bias_var, the learning's schedule; the prior ``bias_prior_sigma_rad_s`` before the first
  estimate), ``q`` [rad²/s³] the bias random walk's (BIAS_RANDOM_WALK_RAD_S_SQRT_S²): the error
  known when the gyro was left alone drifts the angle as t², the walk since — which σ_b² has
  taken on as q·t — as its integral, q·t³/3 (counting it as (σ_b·t)² took the walk's latest
  size for the whole time, three times its share).
- ``M`` [rad²] = the mean square, over the loop's own memory ``1/k1`` [s], of ``|c|``: the tilt
  correction the accelerometer channel has made over the last CORRECTION_WINDOW_S for the
  disagreement's *transient* part, ``c = k1·∫(l_h − l̄)·dt`` high-passed over that window [rad],
  k1 the loop's running gain (``loop_k1`` of the state: the configured k1, lowered where the
  vehicle's velocity swings, bias.loop_gain; not the bias-learning raise, whose corrections are
  the bias's error; ``l_h``: the aperiodic unit's state in the world frame, horizontal, the
  low-passed disagreement between the accelerometer and the estimate it corrects the tilt by;
  ``l̄``: its steady part, ``l_h`` low-passed over the loop's memory ``1/k1``). While the
  vehicle accelerates by ``a_h`` the accelerometer points off the vertical by ``|a_h|/g``; a
  loop that cannot tell that from a tilt follows it, and the tilt error it takes on is exactly
  the correction it made: ``k1·∫`` of the disagreement, which dies away as the loop catches up
  (a zig-zag: its legs cancel in ``c`` as they do in the tilt error — the disagreement itself,
  ``|l_h|``, is the swing the loop did *not* follow and over-counts it by ω/k1 at a zig-zag's
  ω; docs/decisions/0007). A leg held in one world direction for longer than ``1/k1``
  is counted short: its transient and steady parts are both ``A·k1·t·e^(−k1·t)`` for a lean
  ``A``, and ``M + L`` peaks at 1.3–1.4·(A/e)² while the tilt goes on to ``A`` (a vehicle whose
  velocity is bounded holds no leg long). Older corrections are taken as averaged out. When
  velocity aiding takes the vehicle's acceleration out, or at rest, the disagreement is the
  real (small) tilt error and the corrections remove it: ``M`` shrinks by itself.
- ``L`` [rad²] = ``|l̄|²``: a disagreement that outlasts the loop's memory is no acceleration
  the loop follows (an acceleration's disagreement dies away as the loop catches up, and a
  vehicle cannot accelerate one way for long) but a rate it compensates through its
  proportional path — the gyro bias's error not learned yet, typically after a start in the
  air. The tilt error that leaves is that disagreement itself (the accelerometer measuring
  gravity, the disagreement *is* the tilt error), not the correction it keeps making: counted
  in ``c``, it would grow to ``k1·|l̄|·CORRECTION_WINDOW_S`` (1.4–3.5× the lag at the loop's
  gains, and 7° after the Phantom's in-air starts whose tilt was 2–5° off).
- ``V`` [rad²] = ``σ_a²/g² · dt · k1`` with ``σ_a² = noise_a2/6`` [(m/s²)²] the accelerometer's
  white noise per axis (vibration; ``noise_a2`` = the stillness blocks' mean squared
  sample-to-sample difference summed over the axes) and ``dt`` [s] the sample interval: the
  variance white noise leaves in the tilt through the loop ``k1/(T s² + s + k1)`` (k1/2 per
  axis, for any aperiodic time constant T), both axes.

Yaw, heading referenced by the magnetometer: ``y0 + e_y² + D(t_mag)``. ``y0`` =
``yaw_covariance_rad2``; ``e_y`` [rad] = the last heading error the magnetometer channel measured
(the error it is still correcting: a 120° error reports ≈ 120°, falling as the heading comes
back). Once the channel rejects the field as disturbed, two explanations remain: the field is
wrong, and the heading error is what the channel had measured before — the mean of its
innovations over its own memory (``yaw_memory_s``: 1/r1, at most CORRECTION_WINDOW_S), in which
the few disturbed samples that passed its tests before it caught the change count by their
share only —, or the heading is wrong and the rejected field right (a compass wrong at
power-on, a still sensor whose field jumped: nothing tells them from a magnet): its own
innovation. ``e_y`` is the larger of the two until the rejected field is seen to move with the
body as it turns (``mag_on_body`` of the filter's state, which then reports no innovation for
it: a magnet on the sensor contradicts nothing), then the mean alone. (Held as it was, the
last used innovation — the magnet's field — was reported for as long as the magnet stayed:
41° on a BROAD trial whose heading was 2° off.) ``t_mag`` [s] = time since the last magnetometer
sample the filter used (a dropout, or a disturbed field — heading source 'gyro' — grows the
variance with the gyro drift D). Not referenced (``use_mag`` false, or no usable sample yet):
``unreferenced_yaw_covariance_rad2``.

Constants: ``v0`` and ``y0`` are the only fitted ones (maximum likelihood of the errors under the
model's Gaussian: tilt on EuRoC's samples at rest on the ground, 6-D — the floor is what is left
when nothing moves —; yaw on BROAD's undisturbed trials, 9-D; docs/decisions/0007);
``M``'s gain k1 (the loop's running gain), its window CORRECTION_WINDOW_S, its memory and
``l̄``'s, ``1/k1``, and ``V`` follow from the loop. Each variance is
capped at π² (an angle error is at most π), or at its floor (yaw: also the unreferenced
variance) if larger. :meth:`OrientationCovariance.step` is one row in plain floats
(``estimate``); :meth:`OrientationCovariance.rows` runs it over the pipeline's arrays, in the
compiled kernel when asked (``c/cf_core.c`` ``cf_covariance_rows``: the same
operations in the same order as :meth:`OrientationCovariance.steps`, the reference).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from cf_estimator.core.bias import BIAS_RANDOM_WALK_RAD_S_SQRT_S
from cf_estimator.core.kernel import compiled_kernel
from cf_estimator.core.step import PHASE_RECOVERING, PHASE_STARTUP

_PI2 = math.pi * math.pi
_SETTLING = (PHASE_STARTUP, PHASE_RECOVERING)

#: Default ``v0`` [rad²] per tilt axis (``orientation_covariance_rad2``): what is left when nothing
#: moves — fitted by maximum likelihood on EuRoC's samples at rest on the ground (its three
#: flights before take-off, 6-D), checked on every family in motion (docs/decisions/0007,
#: "Covariance"; 6.4e-5 before, fitted on the phantom4 vertical campaign in flight).
TILT_FLOOR_RAD2 = 1.0e-4
#: Window [s] of the correction term ``M``: corrections older than this are taken as averaged
#: out (a manoeuvre's legs; the swing observer's pseudo-velocity window when ``M`` was built).
CORRECTION_WINDOW_S = 10.0
#: Default ``y0`` [rad²] (``yaw_covariance_rad2``): fitted on BROAD's undisturbed trials, 9-D:
#: the likelihood is flat from 3e-4 to 5e-4 (maximum 3.8e-4), and within that range the
#: trials' mean(e²/σ²) is 0.54 at 3e-4, 0.46 at 4e-4 (docs/decisions/0007).
YAW_FLOOR_RAD2 = 3e-4
#: Default yaw variance [rad²] while no magnetometer references the heading.
UNREFERENCED_YAW_RAD2 = 10.0


def gyro_drift_var(sigma_b: float, t: float) -> float:
    """Variance [rad²] of the angle a gyro integrates alone for ``t`` [s], whose bias error
    has the σ ``sigma_b`` [rad/s] now: the error's part known at the start of ``t`` (σ_b² less
    the random walk's ``q·t`` since, never below 0) drifts as t², the walk's as ``q·t³/3`` (the
    integral of a random walk: a bias that wandered off late has turned the angle less)."""
    q = BIAS_RANDOM_WALK_RAD_S_SQRT_S * BIAS_RANDOM_WALK_RAD_S_SQRT_S
    known = sigma_b * sigma_b - q * t
    return (known if known > 0.0 else 0.0) * t * t + q * t * t * t / 3.0


class OrientationCovariance:
    """Per-message covariance model (see the module docstring); ``reset`` with the filter.

    ``k1`` [1/s]: the accelerometer channel's gain (FilterParams.k1); ``gravity_m_s2``: ‖g‖;
    ``r1`` [1/s]: the magnetometer channel's gain (FilterParams.r1), whose memory the heading
    error's running mean takes (:attr:`yaw_memory_s`).
    """

    __slots__ = ("_clip_s", "_yaw_err", "_ms", "_cx", "_cy", "_sx", "_sy", "_yaw_lp", "_yaw_gap",
                 "tilt0", "yaw0", "yaw_unref", "bias_prior", "k1", "r1", "_inv_6g2")

    def __init__(self, tilt0_rad2: float, yaw0_rad2: float, yaw_unreferenced_rad2: float,
                 bias_prior_sigma_rad_s: float, k1: float = 0.35,
                 gravity_m_s2: float = 9.80665, r1: float = 0.07) -> None:
        self.tilt0 = tilt0_rad2
        self.yaw0 = yaw0_rad2
        self.yaw_unref = yaw_unreferenced_rad2
        self.bias_prior = bias_prior_sigma_rad_s
        self.k1 = k1
        self.r1 = r1
        self._inv_6g2 = 1.0 / (6.0 * gravity_m_s2 * gravity_m_s2)
        self.reset()

    @property
    def yaw_memory_s(self) -> float:
        """Memory [s] of the heading error's running mean: the magnetometer channel's own,
        1/r1, at most CORRECTION_WINDOW_S."""
        return 1.0 / self.r1 if self.r1 * CORRECTION_WINDOW_S > 1.0 else CORRECTION_WINDOW_S

    def set_gravity(self, gravity_m_s2: float) -> None:
        """‖g‖ [m/s²] the vibration term divides by."""
        self._inv_6g2 = 1.0 / (6.0 * gravity_m_s2 * gravity_m_s2)

    def reset(self) -> None:
        """Forget the clip duration, the disagreement's steady part, the correction and its mean
        square, and the heading error (last and running mean; a filter reset)."""
        self._clip_s = 0.0
        self._yaw_err = 0.0
        self._ms = 0.0
        self._cx = 0.0
        self._cy = 0.0
        self._sx = 0.0
        self._sy = 0.0
        self._yaw_lp = 0.0
        self._yaw_gap = 0.0

    def step(self, dt_s: float, clipped: bool, bias_sigma_rad_s: float | None, phase: float,
             error_norm_rad: float, lx_rad: float, ly_rad: float, noise_a2: float,
             heading_initialized: bool, yaw_error_rad: float, mag_used: bool,
             mag_age_s: float | None, loop_k1: float = 0.0, mag_rejected: bool = False
             ) -> tuple[float, ...]:
        """Covariance after one filter step (``estimate``'s model, row by row), from the state's
        figures: ``bias_sigma_rad_s`` = √bias_err_var, the bias estimate's error (None: no
        estimate yet, the prior is used),
        ``lx_rad``, ``ly_rad`` the aperiodic unit's world-frame state, ``noise_a2``
        [(m/s²)²] the accelerometer noise of the stillness blocks, ``yaw_error_rad`` read only
        when ``mag_used`` or ``mag_rejected``, ``loop_k1`` [1/s] the loop's running gain (≤ 0:
        none yet, the configured k1), ``mag_rejected`` the step rejected a magnetometer sample
        (disturbed)."""
        self._clip_s = self._clip_s + dt_s if clipped else 0.0
        sigma_b = bias_sigma_rad_s if bias_sigma_rad_s is not None else self.bias_prior
        k1 = loop_k1 if loop_k1 > 0.0 else self.k1
        kdt = k1 * dt_s
        mem = kdt / (1.0 + kdt)  # a low-pass over the loop's memory 1/k1
        leak = dt_s / (CORRECTION_WINDOW_S + dt_s)
        sx = self._sx + mem * (lx_rad - self._sx)  # the disagreement's steady part [rad]
        sy = self._sy + mem * (ly_rad - self._sy)
        cx = self._cx + kdt * (lx_rad - sx) - leak * self._cx  # the correction made [rad]
        cy = self._cy + kdt * (ly_rad - sy) - leak * self._cy
        ms = self._ms
        ms += mem * (cx * cx + cy * cy - ms)
        self._cx, self._cy, self._sx, self._sy, self._ms = cx, cy, sx, sy, ms
        e_t = error_norm_rad if phase in _SETTLING else 0.0
        drift = gyro_drift_var(sigma_b, self._clip_s) if self._clip_s > 0.0 else 0.0
        noise = noise_a2 * self._inv_6g2 * dt_s  # σ_a²/g²·dt [rad²·s]
        tilt = min(self.tilt0 + e_t * e_t + drift + 0.5 * (ms + sx * sx + sy * sy + noise * k1),
                   max(_PI2, self.tilt0))
        self._yaw_gap += dt_s
        if heading_initialized:
            if mag_used:
                gap = self._yaw_gap
                self._yaw_lp += gap / (self.yaw_memory_s + gap) * (yaw_error_rad - self._yaw_lp)
                self._yaw_gap = 0.0
                self._yaw_err = abs(yaw_error_rad)
            elif mag_rejected:
                self._yaw_err = max(abs(self._yaw_lp), abs(yaw_error_rad))
            yd = gyro_drift_var(sigma_b, mag_age_s) if mag_age_s else 0.0
            yaw = min(self.yaw0 + self._yaw_err**2 + yd,
                      max(_PI2, self.yaw_unref, self.yaw0))
        else:
            yaw = self.yaw_unref
        return (tilt, 0.0, 0.0, 0.0, tilt, 0.0, 0.0, 0.0, yaw)

    def steps(self, dt_s: Sequence[float], clipped: Sequence[bool],
              bias_sigma_rad_s: Sequence[float], phase: Sequence[float],
              error_norm_rad: Sequence[float], lx_rad: Sequence[float], ly_rad: Sequence[float],
              noise_a2: Sequence[float], heading_initialized: bool,
              yaw_error_rad: Sequence[float], mag_used: Sequence[bool],
              mag_age_s: Sequence[float | None], loop_k1: Sequence[float],
              mag_rejected: Sequence[bool]) -> tuple[list[float], list[float]]:
        """:meth:`step` over rows, the same operations in the same order, as
        (tilt, yaw) variances per row [rad²] (the pipeline: one call per run instead of one
        per row). ``bias_sigma_rad_s`` NaN: no estimate yet (the prior is used)."""
        clip_s, ms, yaw_err, cx, cy = self._clip_s, self._ms, self._yaw_err, self._cx, self._cy
        sx, sy = self._sx, self._sy
        yaw_lp, yaw_gap, yaw_memory = self._yaw_lp, self._yaw_gap, self.yaw_memory_s
        k1_cfg, prior, inv_6g2 = self.k1, self.bias_prior, self._inv_6g2
        tilt0, yaw0, yaw_unref = self.tilt0, self.yaw0, self.yaw_unref
        tilt_cap, yaw_cap = max(_PI2, tilt0), max(_PI2, yaw_unref, yaw0)
        settling = _SETTLING
        tilts: list[float] = []
        yaws: list[float] = []
        for dt, clip, sb, ph, en, lx, ly, na2, ye, used, age, kr, rejected in zip(
                dt_s, clipped, bias_sigma_rad_s, phase, error_norm_rad, lx_rad, ly_rad,
                noise_a2, yaw_error_rad, mag_used, mag_age_s, loop_k1, mag_rejected,
                strict=True):
            clip_s = clip_s + dt if clip else 0.0
            sigma_b = sb if sb == sb else prior
            k1 = kr if kr > 0.0 else k1_cfg
            kdt = k1 * dt
            mem = kdt / (1.0 + kdt)
            leak = dt / (CORRECTION_WINDOW_S + dt)
            sx, sy = sx + mem * (lx - sx), sy + mem * (ly - sy)
            cx, cy = cx + kdt * (lx - sx) - leak * cx, cy + kdt * (ly - sy) - leak * cy
            ms += mem * (cx * cx + cy * cy - ms)
            e_t = en if ph in settling else 0.0
            drift = gyro_drift_var(sigma_b, clip_s)
            noise = na2 * inv_6g2 * dt
            tilts.append(min(tilt0 + e_t * e_t + drift
                             + 0.5 * (ms + sx * sx + sy * sy + noise * k1), tilt_cap))
            yaw_gap += dt
            if heading_initialized:
                if used:
                    yaw_lp += yaw_gap / (yaw_memory + yaw_gap) * (ye - yaw_lp)
                    yaw_gap = 0.0
                    yaw_err = abs(ye)
                elif rejected:
                    yaw_err = max(abs(yaw_lp), abs(ye))
                yd = gyro_drift_var(sigma_b, age or 0.0)
                yaws.append(min(yaw0 + yaw_err**2 + yd, yaw_cap))
            else:
                yaws.append(yaw_unref)
        self._clip_s, self._ms, self._yaw_err, self._cx, self._cy = clip_s, ms, yaw_err, cx, cy
        self._sx, self._sy, self._yaw_lp, self._yaw_gap = sx, sy, yaw_lp, yaw_gap
        return tilts, yaws

    def rows(self, dt_s: np.ndarray, clipped: np.ndarray, bias_sigma_rad_s: np.ndarray,
             phase: np.ndarray, error_norm_rad: np.ndarray, lx_rad: np.ndarray,
             ly_rad: np.ndarray, noise_a2: np.ndarray, heading_initialized: bool,
             yaw_error_rad: np.ndarray, mag_used: np.ndarray, mag_age_s: np.ndarray | None,
             loop_k1: np.ndarray, mag_rejected: np.ndarray, backend: str = "python"
             ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`steps` over 1-D float64 arrays (columns of a row-major array will do):
        ``clipped``, ``mag_used``, ``mag_rejected`` non-zero = true, ``mag_age_s`` None =
        never. ``backend`` 'compiled': the C twin of :meth:`steps` (same bits; the bulk
        pipeline's path), else :meth:`steps` itself. Returns the (tilt, yaw) variances per row
        [rad²]."""
        n = int(dt_s.shape[0])
        if backend == "compiled" and compiled_kernel is not None:
            tilt, yaw = np.empty(n), np.empty(n)
            consts = (self.k1, self.bias_prior, self._inv_6g2, self.tilt0, self.yaw0,
                      self.yaw_unref, max(_PI2, self.tilt0),
                      max(_PI2, self.yaw_unref, self.yaw0), self.yaw_memory_s)
            state = (self._clip_s, self._ms, self._yaw_err, self._cx, self._cy, self._sx,
                     self._sy, self._yaw_lp, self._yaw_gap)
            (self._clip_s, self._ms, self._yaw_err, self._cx, self._cy, self._sx, self._sy,
             self._yaw_lp, self._yaw_gap) = compiled_kernel.covariance_rows(
                consts, state, bool(heading_initialized), dt_s, clipped, bias_sigma_rad_s,
                phase, error_norm_rad, lx_rad, ly_rad, noise_a2, yaw_error_rad, mag_used,
                mag_age_s, loop_k1, mag_rejected, tilt, yaw)
            return tilt, yaw
        tilts, yaws = self.steps(
            dt_s.tolist(), (clipped != 0.0).tolist(), bias_sigma_rad_s.tolist(),
            phase.tolist(), error_norm_rad.tolist(), lx_rad.tolist(), ly_rad.tolist(),
            noise_a2.tolist(), heading_initialized, yaw_error_rad.tolist(),
            (mag_used != 0).tolist(), [None] * n if mag_age_s is None else mag_age_s.tolist(),
            loop_k1.tolist(), (mag_rejected != 0).tolist())
        return np.asarray(tilts, dtype=np.float64), np.asarray(yaws, dtype=np.float64)
