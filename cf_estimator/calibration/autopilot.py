"""The autopilot's own magnetometer calibration, read from a log's parameters.

PX4 (``CAL_MAGn_*``, v1.12 and later; older logs lack the off-diagonal terms): the driver's raw
field is corrected as ``m = R · S · (raw − off)`` [Gauss], with ``off = (XOFF, YOFF, ZOFF)``,
``S`` the scale matrix (diagonal ``XSCALE, YSCALE, ZSCALE``, off-diagonal ``XODIAG`` (xy),
``YODIAG`` (xz), ``ZODIAG`` (yz)) and ``R`` the mounting rotation (``ROT``). PX4 logs record
``vehicle_magnetometer`` already corrected so: a fit of those samples finds what the autopilot's
calibration left (a hard iron close to zero when it still holds).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from cf_estimator.pipeline.px4 import GAUSS_TO_TESLA


@dataclass(frozen=True)
class AutopilotCalibration:
    """One magnetometer's calibration as the autopilot stored it, in our terms.

    ``hard_iron_t`` (3,) [T, the raw sensor axes]; ``soft_iron`` (3, 3) the autopilot's scale
    matrix as stored (not normalised); ``source``: e.g. ``"PX4 CAL_MAG1 (device 592905, prime)"``.
    """

    hard_iron_t: np.ndarray
    soft_iron: np.ndarray
    source: str

    @property
    def soft_iron_det1(self) -> np.ndarray:
        """The scale matrix normalised to det 1 (how :mod:`.magfit` states a soft iron)."""
        return self.soft_iron / np.cbrt(np.linalg.det(self.soft_iron))


def px4_calibration(parameters: Mapping[str, Any]) -> AutopilotCalibration | None:
    """The calibration of the magnetometer PX4 uses (``CAL_MAG_PRIME``; else the first
    ``CAL_MAGn`` with a device id), or None when the log has no ``CAL_MAGn_XOFF``."""
    def get(key: str, default: float = 0.0) -> float:
        return float(parameters.get(key, default))

    indices = [n for n in range(4) if f"CAL_MAG{n}_XOFF" in parameters]
    if not indices:
        return None
    prime = int(get("CAL_MAG_PRIME", 0))
    chosen = next((n for n in indices if prime and int(get(f"CAL_MAG{n}_ID")) == prime), None)
    how = "prime"
    if chosen is None:
        chosen = next((n for n in indices if int(get(f"CAL_MAG{n}_ID")) != 0), indices[0])
        how = "CAL_MAG_PRIME not set: the first calibrated device"
    p = f"CAL_MAG{chosen}_"
    off = np.array([get(p + "XOFF"), get(p + "YOFF"), get(p + "ZOFF")]) * GAUSS_TO_TESLA
    xy, xz, yz = get(p + "XODIAG"), get(p + "YODIAG"), get(p + "ZODIAG")
    scale = np.array([[get(p + "XSCALE", 1.0), xy, xz],
                      [xy, get(p + "YSCALE", 1.0), yz],
                      [xz, yz, get(p + "ZSCALE", 1.0)]])
    return AutopilotCalibration(
        off, scale, f"PX4 CAL_MAG{chosen} (device {int(get(p + 'ID'))}, {how})")
