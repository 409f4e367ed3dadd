"""In-motion alignment from velocity: attitude, heading offset and gyro bias from accelerations.

With a world-frame velocity, the same motion is seen twice: by the IMU and by the velocity. Per
velocity window (span Δt)::

    β = Δv/Δt − g_w  (velocity's world frame)  =  X(t)·α,   α = mean specific force over it (P)

P is the frame carried by the gyro alone (:mod:`cf_estimator.core.velocity`, with the filter's
bias estimate b̂) and X(t) rotates it into the velocity's world frame. X would be constant with
a perfect gyro; with the true bias b, P misses ∫P·(b − b̂)·dt, so a window at time t_k is seen
now as ``X_now·Exp(ΔJ_k·b − ΔL_k)·α_k`` with ΔJ_k = ∫P·dt and ΔL_k = ∫P·b̂·dt from t_k to now
(both known). The fit is a weighted least squares over the windows of the last
:data:`REMEMBER_MEMORIES` memories (weights fading with the memory [s]) for X_now (3 angles)
and b (3), Gauss–Newton from the last estimate per kept window (iterated while a step exceeds
:data:`CONVERGED_RAD`: the first horizontal accelerations can reveal a heading tens of degrees
off), b's prior the filter's own bias estimate and variance until the filter takes the fit's
(:meth:`InMotionAlignment.freeze_prior`), about the vertical at most
:data:`VERTICAL_BIAS_PRIOR_SIGMA_RAD_S`: the classic in-motion alignment of an inertial
navigator. Gravity fixes X's tilt at once; horizontal accelerations fix its heading and b about
the vertical; each world axis is weighed by its own residual scatter (vertical velocities are
often the noisier: a barometer, a quantised height).

**Open loop.** Nothing here depends on the filter's corrections: a heading offset fitted in the
filter's own world frame was self-consistent at any error (the tilt the aiding makes with a
wrong δ turns the filter's view of the accelerations by that very δ; measured on the Phantom 4
horizontal flights, it stayed 5–7° off for 40 s).

What the filter gets from it: the heading offset δ (the rotation about the vertical of W·X̂ᵀ, W
the filter's P → world), its σ from the fit's covariance, and — once known — the tilt and bias
the fit found (:meth:`InMotionAlignment.tilt_correction`, :attr:`InMotionAlignment.bias_rad_s`).
Known once σ(δ) < the required accuracy, at least :data:`MIN_WINDOWS` independent windows have
been seen and the velocity's horizontal acceleration stands out of its own noise
(:data:`MIN_SIGNAL_TO_NOISE`). Window weights are the share of new information of each
overlapping window (interval / window length), so that the fit counts independent windows.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from cf_estimator.core import quaternion as quat

#: Independent windows needed before the scatter (and so σ) is trusted: the scatter has n − 2
#: degrees of freedom (the heading and the bias about the vertical take two), σ grows as they
#: shrink, and at least half of one is asked for. With 1 s windows the fit can be known 3.6 s
#: after the first velocity sample (bench cross aided rows, 3 → 2.5: phantom4 horizontal
#: median time to < 2° 5.1 → 4.3 s, mean 0.84 → 0.86° (its noise 0.04°); phantom4 4.5 → 4.3 s;
#: EuRoC and the thesis manoeuvre unchanged; 2: 4.2 s, 0.87°).
MIN_WINDOWS = 2.5
#: The velocity's horizontal acceleration (its centred mean square) must exceed its own
#: differentiation noise this many times: without real acceleration the fit sees only noise,
#: and a small σ of noise against noise means nothing.
MIN_SIGNAL_TO_NOISE = 1.5
#: Prior standard deviation [rad] of X's correction about each axis (the fit's regulariser: the
#: rotation about the vertical is not observed without horizontal accelerations).
ROTATION_PRIOR_SIGMA_RAD = math.pi
#: Floor of the fitted noise variances [m²/s⁴] (a perfect simulated velocity), under the one
#: the configured velocity noise sets (:meth:`InMotionAlignment._scatter`).
MIN_NOISE2_M2_S4 = 1e-6
#: Prior standard deviation [rad/s] of the gyro's bias about the vertical, at most: a MEMS
#: gyro's typical bias (about 1 °/s). Gravity observes the other two axes within seconds; this
#: one only through the heading's drift, slowly, and a looser prior lets the fit trade the
#: heading now against it (measured: the aided rows of bench cross with 0.05 rad/s: phantom4
#: 0.72°, EuRoC mid-air 60 s 1.21°; with 0.02 rad/s: 0.70°, 0.89°; with the filter's own
#: 0.1 rad/s prior: 0.86°, 1.19°; thesis aided peak 25.0', 27.3', 38.9').
VERTICAL_BIAS_PRIOR_SIGMA_RAD_S = 0.02
#: Gauss–Newton iterations per kept window at most, while the rotation step exceeds
#: CONVERGED_RAD [rad]: a heading revealed tens of degrees off converges within the window;
#: smaller steps go on with the next windows (each iteration costs as much as the first).
MAX_ITERATIONS = 5
CONVERGED_RAD = 1e-2
#: Floor of the bias prior's variance [(rad/s)²] (1e-4 °/s: a filter that has rested long).
MIN_BIAS_VAR = 3e-12
#: Windows older than this many memories are dropped (weight below e⁻²).
REMEMBER_MEMORIES = 2.0
#: At most this many windows kept per window length (new information 1/this each): overlapping
#: windows share most of their data, and the fit's cost (a solve per kept window over the 600
#: windows of 2 memories of 60 s) must not grow with the velocity's rate (phantom4 aided,
#: horizontal / vertical: 10 per window 0.826 / 0.698°, 5: 0.838 / 0.695°, 2: 0.848 / 0.714°;
#: the node load with 10 per window and 3 memories missed its p99 target, docs/decisions/0009).
ROWS_PER_WINDOW = 5.0

# columns of a stored window
_T, _W, _A, _B, _J, _L = 0, 1, slice(2, 5), slice(5, 8), slice(8, 17), slice(17, 20)


@dataclass(frozen=True)
class HeadingOffset:
    """The estimate: δ [rad] (filter world = Rz(δ)·velocity world, about world z), its standard
    deviation [rad] (inf before any horizontal acceleration), and whether it is known."""

    offset_rad: float
    sigma_rad: float
    known: bool


def _skew(v: np.ndarray) -> np.ndarray:
    """[v×] of each row of v (N, 3) → (N, 3, 3)."""
    s = np.zeros((len(v), 3, 3))
    s[:, 0, 1], s[:, 0, 2] = -v[:, 2], v[:, 1]
    s[:, 1, 0], s[:, 1, 2] = v[:, 2], -v[:, 0]
    s[:, 2, 0], s[:, 2, 1] = -v[:, 1], v[:, 0]
    return s


class InMotionAlignment:
    """Fading least-squares fit of X_now (P → velocity world) and the gyro bias b (see the
    module docstring)."""

    def __init__(self, required_sigma_rad: float, memory_s: float,
                 noise2_m2_s4: float = 0.0, bias_prior_sigma_rad_s: float = 0.1) -> None:
        """``required_sigma_rad``: σ(δ) [rad] below which the fit is known; ``memory_s`` [s]:
        fading time constant of the windows' weights; ``noise2_m2_s4``: variance [m²/s⁴] (both
        horizontal axes) of the velocity's acceleration noise (see MIN_SIGNAL_TO_NOISE; half of
        it per axis is the floor of the residuals' scatter, :meth:`_scatter`);
        ``bias_prior_sigma_rad_s``: prior σ [rad/s] of b about the filter's b̂ at the start
        when the filter has no variance of its own yet."""
        self.required_sigma_rad = float(required_sigma_rad)
        self.memory_s = float(memory_s)
        self.noise2_m2_s4 = float(noise2_m2_s4)
        self.bias_prior_sigma_rad_s = float(bias_prior_sigma_rad_s)
        self.reset()

    def reset(self) -> None:
        """Forget every window seen."""
        self._x: np.ndarray | None = None  # X̂_now: P → velocity world (3×3)
        self._p_now = np.eye(3)  # P now: sensor → P
        self._bias = np.zeros(3)  # b [rad/s], sensor frame
        self._bias0 = np.zeros(3)  # its prior mean (the filter's b̂)
        self._bias_prior_var = self.bias_prior_sigma_rad_s ** 2  # and variance [(rad/s)²]
        self._frozen = False  # the prior no longer follows the filter
        self._now = np.zeros(12)  # ∫P·dt (9, rows) and ∫P·b̂·dt (3) at now
        self._rows = np.zeros((0, 20))  # per window: t, w, α (3), β (3), ∫P (9), ∫P·b̂ (3)
        self._share = 0.0  # new information not stored yet (thinning)
        self._weights = np.zeros(0)  # the rows' faded weights at the last fit
        self._cov = np.full((6, 6), np.inf)  # of (θ, b) [rad², (rad/s)²]
        self._var = (1.0, 1.0)  # residual variances, horizontal and vertical [m²/s⁴]

    @property
    def bias_rad_s(self) -> np.ndarray:
        """The fitted gyro bias b [rad/s] (sensor frame)."""
        return self._bias.copy()

    def offer(self, share: float) -> bool:
        """A new window with this ``share`` of new information (0..1, its interval over its
        length): True if it is to be kept (:meth:`update` it), False if its information is
        carried over to the next one (ROWS_PER_WINDOW; the first window is always kept)."""
        self._share += min(max(float(share), 0.0), 1.0)
        return self._share >= 1.0 / ROWS_PER_WINDOW or not len(self._rows)

    def update(self, t_s: float, force_p: Sequence[float], accel_world: Sequence[float],
               drift_mid: Sequence[float], drift_now: Sequence[float],
               filter_bias: Sequence[float], w_filter_from_p: np.ndarray,
               p_now: np.ndarray) -> None:
        """Keep one window ending at t_s [s] (after :meth:`offer` said so; its weight is the
        information offered since the last kept one) and fit: the mean specific force [m/s²]
        over it in P (α); the velocity's acceleration minus gravity [m/s²] in its world frame
        (β); ``drift_mid``/``drift_now``: ∫P·dt [s] (9, rows) and ∫P·b̂·dt
        [rad] (3) at the window's middle and now; ``filter_bias``: b̂ [rad/s] and optionally its
        variance [(rad/s)²] per axis (< 0: none yet: bias_prior_sigma_rad_s), the filter's: the
        fit's prior for b until :meth:`freeze_prior` (the filter still learns: at rest, say);
        ``w_filter_from_p``: P → the filter's world (3×3), X's start (heading as the
        filter's); ``p_now``: P now (3×3, sensor → P)."""
        now = np.asarray(drift_now, dtype=float)
        self._p_now = p_now
        if not self._frozen:
            self._bias0 = np.array(filter_bias[:3], dtype=float)
            var = float(filter_bias[3]) if len(filter_bias) > 3 else -1.0
            self._bias_prior_var = var if var >= 0.0 else self.bias_prior_sigma_rad_s ** 2
        if self._x is None:
            self._x = np.array(w_filter_from_p, dtype=float)
            self._bias = self._bias0.copy()
        else:  # X̂ carried to now by the fitted bias (what P missed since the last window)
            self._x = self._x @ _rotation(self._missed(self._now, now[None, :])[0])
        self._now = now
        row = np.concatenate([[t_s, self._share], force_p, accel_world, drift_mid])
        self._share = 0.0
        rows = np.vstack([self._rows, row])
        self._rows = rows[t_s - rows[:, _T] < REMEMBER_MEMORIES * self.memory_s]
        self._weights = (np.exp(-(t_s - self._rows[:, _T]) / self.memory_s) * self._rows[:, _W])
        # Gauss–Newton, the axes' weights held, iterated while a step exceeds CONVERGED_RAD:
        # one step is enough once X̂ is near, not when the first horizontal accelerations reveal
        # a heading tens of degrees off
        res = self._residuals() if float(self._weights.sum()) >= MIN_WINDOWS else None
        self._var = self._scatter(res)
        for _ in range(MAX_ITERATIONS):
            if self._step(res) < CONVERGED_RAD:
                break
            res = None  # X̂ and b moved: the next step computes them again

    def freeze_prior(self) -> None:
        """Keep the bias prior as it is: the filter has taken the fit's bias (realigned), and a
        prior that followed it would count the fit's own estimate as evidence."""
        self._frozen = True

    def _missed(self, now: np.ndarray, then: np.ndarray) -> np.ndarray:
        """Rotation [rad] (in P) that P missed from each of ``then`` (N, 12) to ``now``:
        ∫P·(b − b̂)·dt = ΔJ·b − ΔL, with the fitted b."""
        dj = (now[:9] - then[:, :9]).reshape(-1, 3, 3)
        return dj @ self._bias - (now[9:] - then[:, 9:])

    def _residuals(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """In the velocity's world frame: r = β − X̂·Exp(φ)·α (N, 3), X̂·Exp(φ)·α (N, 3), and
        ΔJ (N, 3, 3) from each window to now."""
        assert self._x is not None
        a, b, mid = self._rows[:, _A], self._rows[:, _B], self._rows[:, 8:20]
        c = quat.rotate(quat.exp(self._missed(self._now, mid)), a) @ self._x.T
        return b - c, c, (self._now[:9] - mid[:, :9]).reshape(-1, 3, 3)

    def _scatter(self, res: tuple[np.ndarray, np.ndarray, np.ndarray] | None
                 ) -> tuple[float, float]:
        """Residual variances [m²/s⁴] at X̂: horizontal (per axis) and vertical (1 before the
        fit has MIN_WINDOWS: nothing to judge yet), never below the per-axis differentiation
        noise of the configured velocity noise (``noise2_m2_s4``/2; at least MIN_NOISE2_M2_S4).

        The floor: a velocity cleaner than configured (a noiseless simulation, motion capture)
        leaves a scatter of what the model leaves out alone, and a fit weighed by it trusts its
        first few windows far beyond what they hold. With the heading known, the thesis
        manoeuvre aided by a noiseless velocity took −0.56 °/s about the vertical (true 0.005)
        when the fit became known half a second into the acceleration, and the heading then
        drifted across the 5 m/s²: peak 64.2′ against 32.5′ at 0.1 m/s; with the floor 18.0′
        (docs/decisions/0006, "Thesis manoeuvre aided"). A velocity as noisy as configured scatters
        about as much as the floor, which then changes little."""
        w = self._weights
        n = float(w.sum())
        if n < MIN_WINDOWS or res is None:
            return 1.0, 1.0
        r = res[0]
        dof = n - 2.0
        floor = max(0.5 * self.noise2_m2_s4, MIN_NOISE2_M2_S4)
        return (max(float(w @ (r[:, 0] ** 2 + r[:, 1] ** 2)) / (2.0 * dof), floor),
                max(float(w @ r[:, 2] ** 2) / dof, floor))

    def _step(self, res: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None) -> float:
        """One Gauss–Newton step on (θ, ε): X̂ ← X̂·Exp(θ), b ← b + ε; returns |θ| [rad].
        ``res``: :meth:`_residuals` at the current X̂ and b, when already computed."""
        x, w = self._x, self._weights
        assert x is not None
        # the residual's Jacobian in (θ, ε): X̂·[α'×]·(I, ΔJ) = [(X̂α')×]·X̂·(I, ΔJ),
        # α' = Exp(φ)·α; each world axis weighed by its scatter (horizontal, vertical)
        r, c, dj = res if res is not None else self._residuals()
        j_theta = _skew(c) @ x
        jac = np.concatenate([j_theta, j_theta @ dj], axis=2)  # (N, 3, 6)
        var_h, var_v = self._var
        scale = np.sqrt(w)[:, None] / np.sqrt([var_h, var_h, var_v])[None, :]  # (N, 3)
        jw = (jac * scale[:, :, None]).reshape(-1, 6)
        normal = jw.T @ jw
        rhs = -(jw.T @ (r * scale).ravel())
        # the bias prior: the filter's variance, and about the vertical at most
        # VERTICAL_BIAS_PRIOR_SIGMA_RAD_S (u: the vertical in the sensor frame)
        var = max(self._bias_prior_var, MIN_BIAS_VAR)
        u = self._p_now.T @ x[2]
        tighter = max(0.0, VERTICAL_BIAS_PRIOR_SIGMA_RAD_S ** -2.0 - 1.0 / var)
        bprior = np.eye(3) / var + tighter * np.outer(u, u)
        prior = np.zeros((6, 6))
        prior[:3, :3] = np.eye(3) * ROTATION_PRIOR_SIGMA_RAD ** -2.0
        prior[3:, 3:] = bprior
        rhs[3:] -= bprior @ (self._bias - self._bias0)
        try:
            cov = np.linalg.inv(normal + prior)
        except np.linalg.LinAlgError:
            return 0.0
        step = cov @ rhs
        self._x = x @ _rotation(step[:3])
        self._bias = self._bias + step[3:]
        self._cov = cov
        return float(np.linalg.norm(step[:3]))

    def estimate(self, w_filter_from_p: np.ndarray) -> HeadingOffset:
        """δ, σ and known flag given W (3×3: P → the filter's world frame, now)."""
        if self._x is None or not len(self._rows):
            return HeadingOffset(0.0, math.inf, False)
        d = w_filter_from_p @ self._x.T  # velocity world → filter world
        offset = math.atan2(d[1, 0] - d[0, 1], d[0, 0] + d[1, 1])
        up = self._x[2]  # the velocity world's vertical, in P
        sigma = math.sqrt(max(float(up @ self._cov[:3, :3] @ up), 0.0))
        w = self._weights
        n = float(w.sum())
        bh = self._rows[:, 5:7]
        svv = float(w @ np.sum((bh - (w @ bh) / n) ** 2, axis=1))
        known = (n >= MIN_WINDOWS and sigma < self.required_sigma_rad
                 and svv > MIN_SIGNAL_TO_NOISE * self.noise2_m2_s4 * n)
        return HeadingOffset(offset, sigma, known)

    def tilt_correction(self, w_filter_from_p: np.ndarray) -> np.ndarray:
        """Rotation vector [rad] in the filter's world frame that turns the filter's vertical
        onto the fit's (about a horizontal axis: heading unchanged), given W (3×3: P → the
        filter's world frame, now)."""
        if self._x is None:
            return np.zeros(3)
        up_filter, up_fit = w_filter_from_p[2], self._x[2]  # both verticals, in P
        axis = np.cross(up_fit, up_filter)
        sin = float(np.linalg.norm(axis))
        if sin < 1e-12:
            return np.zeros(3)
        return w_filter_from_p @ (axis / sin * math.atan2(sin, float(up_filter @ up_fit)))


def _rotation(rotvec: np.ndarray) -> np.ndarray:
    """3×3 rotation matrix of a rotation vector [rad]."""
    return quat.to_matrix(quat.exp(rotvec))
