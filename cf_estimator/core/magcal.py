"""The magnetometer calibration applied before the filter: ``m = S · (m_raw − h)``.

The parameters are the pipeline's (``mag_hard_iron_t``, ``mag_soft_iron``); their physical checks
(:func:`check_calibration`) live here, with the arithmetic, so that ``estimate`` (core) and the
pipeline's parameter schema refuse the same values with the same words.

``h`` = ``mag_hard_iron_t`` [T], ``S`` = ``mag_soft_iron`` (3x3 row-major, dimensionless), both
in the magnetometer message's own axes (the sensor frame, before ``body_frame`` turns it), as
``cf-estimator calibrate-mag`` fits them. The pipeline (node and replay:
:meth:`MagCorrection.apply_rows`) and ``estimate`` (:func:`correct_mag`) use the same
arithmetic, so they agree bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from cf_estimator.schema import ParameterError, ParamSpec

IDENTITY9 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
#: Largest hard-iron component [T]: 1 mT, twenty times the Earth's field (a value in Gauss or
#: µT given as Tesla is far beyond it).
HARD_IRON_MAX_T = 1e-3
#: Smallest soft-iron determinant [1]: invertible, and the axes' handedness kept.
SOFT_IRON_MIN_DET = 1e-6
_HARD = ParamSpec("mag_hard_iron_t", "float_list", (0.0, 0.0, 0.0), "T", "", length=3)
_SOFT = ParamSpec("mag_soft_iron", "float_list", IDENTITY9, "", "", length=9)


def check_calibration(hard_iron_t: Sequence[float] = (0.0, 0.0, 0.0),
                      soft_iron: Sequence[float] = IDENTITY9
                      ) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """``(h, S)`` as tuples of floats, or :class:`ParameterError` naming the parameter: not 3
    (9) finite numbers, a soft iron that is singular or flips the axes (det ≤
    SOFT_IRON_MIN_DET), a hard iron beyond HARD_IRON_MAX_T (not Tesla)."""
    h, s = _HARD.check(hard_iron_t), _SOFT.check(soft_iron)
    det = (s[0] * (s[4] * s[8] - s[5] * s[7]) - s[1] * (s[3] * s[8] - s[5] * s[6])
           + s[2] * (s[3] * s[7] - s[4] * s[6]))
    if not det > SOFT_IRON_MIN_DET:
        raise ParameterError(
            f"mag_soft_iron: determinant {det:.3g}: a calibration matrix must be invertible "
            "and keep the axes' handedness (det > 0); identity = no soft iron")
    if max(abs(v) for v in h) > HARD_IRON_MAX_T:
        raise ParameterError(
            f"mag_hard_iron_t: {h!r} T is not a hard iron (over 1 mT, "
            "twenty times the Earth's field): Tesla expected (1 G = 1e-4 T)")
    return h, s


class MagCorrection:
    """Hard and soft iron of one magnetometer (``identity``: nothing to do, skipped)."""

    __slots__ = ("h", "identity", "s")

    def __init__(self, hard_iron_t: Sequence[float] = (0.0, 0.0, 0.0),
                 soft_iron: Sequence[float] = IDENTITY9) -> None:
        self.h = tuple(float(v) for v in hard_iron_t)
        self.s = tuple(float(v) for v in soft_iron)
        self.identity = self.h == (0.0, 0.0, 0.0) and self.s == IDENTITY9

    def apply_rows(self, rows: Any) -> Any:
        """(N, 3) NumPy raw samples [T] → corrected [T] (a new array)."""
        import numpy as np

        h, s = self.h, self.s
        dx, dy, dz = rows[:, 0] - h[0], rows[:, 1] - h[1], rows[:, 2] - h[2]
        return np.column_stack([s[0] * dx + s[1] * dy + s[2] * dz,
                                s[3] * dx + s[4] * dy + s[5] * dz,
                                s[6] * dx + s[7] * dy + s[8] * dz])


def correct_mag(mag: Any, hard_iron_t: Sequence[float] = (0.0, 0.0, 0.0),
                soft_iron: Sequence[float] = IDENTITY9) -> Any:
    """(N, 3) magnetometer rows [T] corrected for ``estimate`` (NaN rows stay NaN); None: None."""
    if mag is None:
        return None
    import numpy as np

    corr = MagCorrection(hard_iron_t, soft_iron)
    rows = np.asarray(mag, dtype=float)
    return rows.copy() if corr.identity else corr.apply_rows(rows)
