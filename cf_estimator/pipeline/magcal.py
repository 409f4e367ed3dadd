"""The magnetometer calibration applied before the filter: ``m = S · (m_raw − h)``.

``h`` = ``mag_hard_iron_t`` [T], ``S`` = ``mag_soft_iron`` (3x3 row-major, dimensionless), both
in the magnetometer message's own axes (the sensor frame, before ``body_frame`` turns it), as
``cf-estimator calibrate-mag`` fits them. The node and the replay (``on_mag``, message by
message), the replay's bulk path (:meth:`MagCorrection.apply_rows`) and ``estimate``
(:func:`correct_mag`) use the same arithmetic, so they agree bit for bit.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

IDENTITY9 = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


class MagCorrection:
    """Hard and soft iron of one magnetometer (``identity``: nothing to do, skipped)."""

    __slots__ = ("h", "identity", "s")

    def __init__(self, hard_iron_t: Sequence[float] = (0.0, 0.0, 0.0),
                 soft_iron: Sequence[float] = IDENTITY9) -> None:
        self.h = tuple(float(v) for v in hard_iron_t)
        self.s = tuple(float(v) for v in soft_iron)
        self.identity = self.h == (0.0, 0.0, 0.0) and self.s == IDENTITY9

    def apply(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        """One raw sample [T] → corrected [T]."""
        h, s = self.h, self.s
        dx, dy, dz = x - h[0], y - h[1], z - h[2]
        return (s[0] * dx + s[1] * dy + s[2] * dz,
                s[3] * dx + s[4] * dy + s[5] * dz,
                s[6] * dx + s[7] * dy + s[8] * dz)

    def apply_rows(self, rows: Any) -> Any:
        """(N, 3) NumPy raw samples → corrected (a new array; :meth:`apply`'s arithmetic)."""
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
