"""Heading offset between the filter's world frame and a velocity's world frame, from accelerations.

A 6-D filter (no magnetometer, or one ruled out) has an arbitrary heading: its world frame is
the velocity's frame turned by an unknown angle δ about the vertical. Whenever the vehicle
accelerates horizontally, the same acceleration is seen twice: by the IMU (mean specific force
rotated into the filter's world frame: a_f = F̄_w − g, horizontal part) and by the velocity
(its difference over the same stamps, a_v, in the velocity's frame)::

    a_f,xy ≈ Rz(δ)·a_v,xy + c      (as complex numbers: z_f = e^{iδ}·z_v + c + noise)

c: the filter's own tilt error seen as a horizontal specific force (g·ε), about constant over
the memory. With centred sums (means removed, which fits c), the least-squares angle is
δ̂ = arg Σ w·(z_f − z̄_f)·conj(z_v − z̄_v); its variance ≈ σ_n² / (2 Σ w·|z_v − z̄_v|²) with
σ_n² the scatter left (velocity noise, a varying tilt error, vibration). Sums fade with a
memory τ [s] because the 6-D filter's heading drifts. Weights are
the share of new information of each overlapping window (interval / window length), so that
σ counts independent windows. Known once σ < the required accuracy, at least
:data:`MIN_WINDOWS` independent windows have been seen and the velocity's acceleration stands
out of its own noise (:data:`MIN_SIGNAL_TO_NOISE`).
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass

#: Independent windows needed before the scatter (and so σ) is trusted.
MIN_WINDOWS = 3.0
#: The velocity's horizontal acceleration (its centred mean square) must exceed its own
#: differentiation noise this many times: without real acceleration the fit sees only noise,
#: and a small σ of noise against noise means nothing.
MIN_SIGNAL_TO_NOISE = 1.5


@dataclass(frozen=True)
class HeadingOffset:
    """The estimate: δ [rad] (filter world = Rz(δ)·velocity world, about world z), its standard
    deviation [rad] (inf before any horizontal acceleration), and whether it is known."""

    offset_rad: float
    sigma_rad: float
    known: bool


class HeadingOffsetEstimator:
    """Recursive, fading least-squares estimate of δ (see the module docstring)."""

    def __init__(self, required_sigma_rad: float, memory_s: float,
                 noise2_m2_s4: float = 0.0) -> None:
        """``noise2_m2_s4``: variance [m²/s⁴] (both axes) of the velocity side's acceleration
        noise (differentiation of a noisy velocity); see MIN_SIGNAL_TO_NOISE."""
        self.required_sigma_rad = float(required_sigma_rad)
        self.memory_s = float(memory_s)
        self.noise2_m2_s4 = float(noise2_m2_s4)
        self.reset()

    def reset(self) -> None:
        """Forget every acceleration seen."""
        self._c = 0j  # Σ w·z_f·conj(z_v)
        self._svv = 0.0  # Σ w·|z_v|²
        self._sff = 0.0  # Σ w·|z_f|²
        self._sf = 0j  # Σ w·z_f
        self._sv = 0j  # Σ w·z_v
        self._n = 0.0  # Σ w
        self._t: float | None = None

    def update(self, t_s: float, filter_xy: tuple[float, float], velocity_xy: tuple[float, float],
               weight: float) -> HeadingOffset:
        """Add one window: horizontal accelerations [m/s²] in the filter's world frame and in the
        velocity's frame, at time t_s [s]; ``weight`` = share of new information (0..1)."""
        if self._t is not None and t_s > self._t:
            fade = math.exp(-(t_s - self._t) / self.memory_s)
            self._c *= fade
            self._svv *= fade
            self._sff *= fade
            self._sf *= fade
            self._sv *= fade
            self._n *= fade
        self._t = t_s
        zf = complex(filter_xy[0], filter_xy[1])
        zv = complex(velocity_xy[0], velocity_xy[1])
        w = min(max(float(weight), 0.0), 1.0)
        self._c += w * zf * zv.conjugate()
        self._svv += w * (zv.real * zv.real + zv.imag * zv.imag)
        self._sff += w * (zf.real * zf.real + zf.imag * zf.imag)
        self._sf += w * zf
        self._sv += w * zv
        self._n += w
        return self.estimate()

    def rotate(self, angle_rad: float) -> None:
        """The filter's world frame was turned by ``angle_rad`` about the vertical (z_f →
        e^{i·angle}·z_f): the sums follow, so the windows seen so far stay consistent."""
        turn = cmath.exp(1j * angle_rad)
        self._c *= turn
        self._sf *= turn

    def estimate(self) -> HeadingOffset:
        """The current δ, σ and known flag."""
        n = self._n
        if n <= 0.0:
            return HeadingOffset(0.0, math.inf, False)
        # centred sums: a constant horizontal offset of z_f (a tilt error g·ε of the filter,
        # steady over the memory) is fitted, not taken for scatter or for heading
        c = self._c - self._sf * self._sv.conjugate() / n
        svv = self._svv - abs(self._sv) ** 2 / n
        sff = self._sff - abs(self._sf) ** 2 / n
        if svv <= 0.0 or c == 0j:
            return HeadingOffset(0.0, math.inf, False)
        offset = cmath.phase(c)
        residual = max(sff + svv - 2.0 * abs(c), 0.0)
        noise2 = residual / max(n - 1.0, 1e-12)
        sigma = math.sqrt(noise2 / (2.0 * svv))
        known = (self._n >= MIN_WINDOWS and sigma < self.required_sigma_rad
                 and svv > MIN_SIGNAL_TO_NOISE * self.noise2_m2_s4 * n)
        return HeadingOffset(offset, sigma, known)
