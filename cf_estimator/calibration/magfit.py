"""Hard-iron and soft-iron fit of magnetometer samples (NumPy only, no ROS, no I/O).

Model (sensor frame, any unit; the result keeps the samples' unit): a raw sample is
``m_raw = A · b + h`` with ``b`` the undisturbed field (constant norm, any direction), ``h`` the
hard iron (a constant offset) and ``A`` the soft iron (a symmetric distortion). The correction
applied before the filter is ``m = S · (m_raw − h)`` with ``S = A⁻¹`` symmetric, normalised to
``det S = 1`` (the correction keeps the volume of the ellipsoid: the field's magnitude is the
ellipsoid's mean radius, a distortion is not also a unit change).

Steps (:func:`fit`):

1. Sphere fit (linear least squares of ``|m|² = 2 c·m + k``): the hard iron ``c`` alone. Refused
   when the samples do not constrain the centre (rotations about one axis only: a circle).
2. Coverage: the share of the sphere the centred directions ``(m − c)/|m − c|`` visit, counted
   on :data:`COVERAGE_CELLS` equal-area cells (a Fibonacci lattice; a sample counts for its
   nearest cell).
3. Ellipsoid fit (linear least squares of the general quadric, ``x ᵀ M x + 2 uᵀx = 1``) when the
   coverage reaches :data:`ELLIPSOID_MIN_COVERAGE`; refused when the quadric is not an ellipsoid
   (M not positive definite) or is too eccentric to be a magnetometer's distortion.
4. Residual: the RMS of ``|S (m − h)| / R − 1`` over the samples (R the fitted field), in % of the
   field: the samples that do not lie on the fitted surface (noise, disturbances, a field that
   changed during the recording).

A fit the data cannot support raises :class:`CalibrationError` with one line saying why and
what to record instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Equal-area cells on the unit sphere the coverage counts.
COVERAGE_CELLS = 100
#: Coverage a soft-iron (ellipsoid) fit needs: below it the ellipsoid's axes are guessed, not
#: measured (docs/decisions/0001-magnetometer-calibration.md).
ELLIPSOID_MIN_COVERAGE = 0.60
#: Coverage a hard-iron-only (sphere) fit needs.
SPHERE_MIN_COVERAGE = 0.30
#: Fewest samples of a fit (9 unknowns of the ellipsoid, with room for noise).
MIN_SAMPLES = 30
#: A residual above this share of the field: the samples are not one field seen from many
#: directions (a disturbance moved with the sensor, the field changed): refused.
MAX_RESIDUAL = 0.05
#: Largest RMS departure from the fitted sphere [share of its radius] before the coverage is
#: even looked at: beyond it the "sphere" is fitted to noise on a small patch (a level flight),
#: not to a field seen from many directions (a soft iron that the ellipsoid corrects stays far
#: below: 10 % between axes gives about 4 %).
MAX_SPHERE_RESIDUAL = 0.15
#: Smallest spread of the samples (RMS distance from their mean) as a share of their median norm:
#: below it the sensor hardly turned (allows a hard iron up to about ten times the field).
MIN_SPREAD = 0.10
#: Ratio of the longest to the shortest axis of a plausible soft-iron distortion.
MAX_AXIS_RATIO = 3.0


class CalibrationError(ValueError):
    """The samples cannot support the asked fit (one line: why, and what to do)."""


@dataclass(frozen=True)
class MagCalibration:
    """A fitted calibration: ``m = soft_iron · (m_raw − hard_iron)``, sensor frame.

    ``hard_iron`` (3,) and ``field`` in the samples' unit (Tesla for ROS and ulog input);
    ``soft_iron`` (3, 3) symmetric, det 1 (identity for a sphere fit). ``coverage``: share of
    the sphere visited [0..1]; ``residual``: RMS of the corrected norms about ``field``, as a
    share of it; ``model``: ``"ellipsoid"`` or ``"sphere"``; ``n_samples``: samples fitted.
    """

    hard_iron: np.ndarray
    soft_iron: np.ndarray
    field: float
    coverage: float
    residual: float
    model: str
    n_samples: int
    sphere_residual: float

    def apply(self, raw: np.ndarray) -> np.ndarray:
        """(N, 3) raw samples → corrected, same unit."""
        return (np.asarray(raw, dtype=float) - self.hard_iron) @ self.soft_iron.T


def fibonacci_sphere(n: int = COVERAGE_CELLS) -> np.ndarray:
    """(n, 3) unit vectors spread evenly over the sphere (centres of near-equal-area cells)."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    phi = i * math.pi * (3.0 - math.sqrt(5.0))
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), z])


_CELLS = fibonacci_sphere()


def coverage(directions: np.ndarray) -> float:
    """Share of the :data:`COVERAGE_CELLS` cells that hold at least one of the unit vectors
    ``directions`` (N, 3)."""
    d = np.asarray(directions, dtype=float)
    if d.shape[0] == 0:
        return 0.0
    hit = np.zeros(_CELLS.shape[0], dtype=bool)
    for a in range(0, d.shape[0], 4096):
        hit[np.argmax(d[a:a + 4096] @ _CELLS.T, axis=1)] = True
    return float(np.count_nonzero(hit)) / _CELLS.shape[0]


def clean_samples(raw: np.ndarray) -> np.ndarray:
    """The finite, non-zero rows of (N, 3) ``raw`` (magnetometers send NaN for "not read")."""
    m = np.asarray(raw, dtype=float).reshape(-1, 3)
    ok = np.all(np.isfinite(m), axis=1) & np.any(m != 0.0, axis=1)
    return m[ok]


def fit_sphere(m: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares sphere through (N, 3) samples → ``(centre (3,), radius)``.

    Raises :class:`CalibrationError` when the samples leave the centre undetermined (all on one
    circle: the sensor turned about one axis only)."""
    scale = float(np.median(np.linalg.norm(m, axis=1))) or 1.0
    x = m / scale  # well-conditioned whatever the unit (T, G, counts)
    design = np.column_stack([2.0 * x, np.ones(x.shape[0])])
    s = np.linalg.svd(design, compute_uv=False)
    if s[-1] < 1e-6 * s[0] * math.sqrt(x.shape[0]):
        raise CalibrationError(
            "the samples lie on one circle (the sensor turned about a single axis): the offset "
            "along that axis is undetermined; record rotations about every axis")
    sol, *_ = np.linalg.lstsq(design, np.sum(x * x, axis=1), rcond=None)
    c = sol[:3]
    r2 = sol[3] + c @ c
    if not r2 > 0.0:
        raise CalibrationError("the samples do not lie on a sphere (no real radius fits them)")
    return c * scale, math.sqrt(r2) * scale


def fit_ellipsoid(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-squares ellipsoid through (N, 3) samples → ``(centre, S, field)``: ``S`` symmetric,
    det 1, maps the ellipsoid onto a sphere of radius ``field`` about the centre.

    Raises :class:`CalibrationError` when the best quadric is not an ellipsoid or is too
    eccentric (:data:`MAX_AXIS_RATIO`) to be a magnetometer's distortion."""
    scale = float(np.median(np.linalg.norm(m, axis=1))) or 1.0
    x, y, z = (m / scale).T
    # the general quadric x'Qx + 2u'x + k = 0: the unit coefficient vector nearest the null
    # space (no term fixed to 1: a hard iron as large as the field puts the origin on the
    # ellipsoid, where the usual "= 1" form degenerates)
    design = np.column_stack([x * x, y * y, z * z, 2 * x * y, 2 * x * z, 2 * y * z,
                              2 * x, 2 * y, 2 * z, np.ones(x.shape[0])])
    p = np.linalg.svd(design, full_matrices=False)[2][-1]
    q = np.array([[p[0], p[3], p[4]], [p[3], p[1], p[5]], [p[4], p[5], p[2]]])
    u = p[6:9]
    try:
        c = -np.linalg.solve(q, u)
    except np.linalg.LinAlgError:
        raise CalibrationError("the samples fit no ellipsoid (a degenerate quadric)") from None
    # (x - c)' Q (x - c) = c'Qc - k
    gain = c @ q @ c - p[9]
    mat = q / gain if gain != 0.0 else q * np.nan
    if not np.all(np.isfinite(mat)):
        raise CalibrationError("the samples fit no ellipsoid (a degenerate quadric)")
    w, v = np.linalg.eigh(mat)
    if not np.all(w > 0.0):
        raise CalibrationError("the samples fit no ellipsoid (the best quadric is open): a "
                               "disturbance or too little rotation")
    axes = 1.0 / np.sqrt(w)  # semi-axes
    ratio = float(axes.max() / axes.min())
    if ratio > MAX_AXIS_RATIO:
        raise CalibrationError(
            f"the fitted ellipsoid's axes differ by {ratio:.1f}x (over {MAX_AXIS_RATIO:g}x): not "
            "a magnetometer's soft iron; record more rotations away from magnetic objects")
    field = float(np.prod(axes) ** (1.0 / 3.0))  # the sphere of the same volume
    soft = v @ np.diag(np.sqrt(w) * field) @ v.T  # symmetric, det 1
    return c * scale, soft, field * scale


def _residual(m: np.ndarray, h: np.ndarray, s: np.ndarray, field: float) -> float:
    corrected = (m - h) @ s.T
    return float(np.sqrt(np.mean((np.linalg.norm(corrected, axis=1) / field - 1.0) ** 2)))


def fit(raw: np.ndarray, *, hard_iron_only: bool = False,
        min_coverage: float = ELLIPSOID_MIN_COVERAGE) -> MagCalibration:
    """Calibration of (N, 3) raw magnetometer samples (sensor frame, any unit; NaN rows
    skipped): a sphere, then an ellipsoid (see the module docstring).

    ``hard_iron_only``: the sphere's centre only (soft iron identity), accepted from
    :data:`SPHERE_MIN_COVERAGE`; else the ellipsoid, which needs ``min_coverage``.
    Raises :class:`CalibrationError` (one line) when the samples cannot support it.
    """
    m = clean_samples(raw)
    if m.shape[0] < MIN_SAMPLES:
        raise CalibrationError(f"{m.shape[0]} usable magnetometer samples; a calibration needs "
                               f"at least {MIN_SAMPLES}")
    norms0 = np.linalg.norm(m, axis=1)
    if float(np.std(norms0)) <= 1e-6 * float(np.mean(norms0)):
        raise CalibrationError("every sample has the same norm: the driver normalises the field "
                               "(a direction only), so its offset cannot be seen; calibrate the "
                               "raw magnetometer")
    spread = float(np.sqrt(np.mean(np.sum((m - m.mean(axis=0)) ** 2, axis=1))))
    median = float(np.median(norms0))
    if spread < MIN_SPREAD * median:
        raise CalibrationError(
            f"the samples spread over {spread / median:.1%} of the field only: the sensor hardly "
            "turned (e.g. a level flight); record the sensor turned through every orientation")
    centre, radius = fit_sphere(m)
    sphere_res = _residual(m, centre, np.eye(3), radius)
    if sphere_res > MAX_SPHERE_RESIDUAL:
        raise CalibrationError(
            f"the samples leave the best sphere by {sphere_res:.0%} of its radius: too little "
            "rotation or a disturbance moving with the sensor; record the sensor turned through "
            "every orientation away from steel and motors")
    d = m - centre
    norms = np.linalg.norm(d, axis=1)
    cov = coverage(d / np.where(norms > 0, norms, 1.0)[:, None])
    eye = np.eye(3)
    need = SPHERE_MIN_COVERAGE if hard_iron_only else min_coverage
    if cov < need:
        what = "a hard-iron (sphere) fit" if hard_iron_only else "a hard- and soft-iron fit"
        alt = ("" if hard_iron_only or cov < SPHERE_MIN_COVERAGE else
               "; or --hard-iron-only for the offset alone")
        raise CalibrationError(
            f"the recording turns the sensor through {cov:.0%} of the sphere, {what} needs "
            f"{need:.0%}: record the sensor turned through every orientation (a slow tumble "
            f"about each axis){alt}")
    if hard_iron_only:
        h, s, field, model, res = centre, eye, radius, "sphere", sphere_res
    else:
        h, s, field = fit_ellipsoid(m)
        model, res = "ellipsoid", _residual(m, h, s, field)
    if res > MAX_RESIDUAL:
        raise CalibrationError(
            f"the samples leave the fitted {model} by {res:.1%} of the field RMS (over "
            f"{MAX_RESIDUAL:.0%}): the field changed during the recording or a magnet moved "
            "with the sensor; record again away from steel and motors")
    return MagCalibration(np.asarray(h, dtype=float), np.asarray(s, dtype=float), float(field),
                          cov, res, model, int(m.shape[0]), sphere_res)
