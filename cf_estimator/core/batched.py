"""Many parameter sets at once over the same data (for tuning): state arrays of shape (P,).

Runs exactly the equations of :mod:`cf_estimator.core.step` with NumPy arrays in place of
floats, both bias hypotheses of :class:`~cf_estimator.core.filter.ComplementaryFilter` side by
side, so its output equals P single filter runs (tested to 1e-12).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from types import SimpleNamespace

import numpy as np

from cf_estimator.core import quaternion as quat
from cf_estimator.core.filter import (
    EVIDENCE_RATIO,
    heading_from_mag,
    orientation_from_vectors,
    step_params,
    valid_vector,
)
from cf_estimator.core.ops import ArrayOps
from cf_estimator.core.params import FilterParams
from cf_estimator.core.step import PHASE_STARTUP, StepState, step


class BatchedFilter:
    """P filters with different parameters, advanced together sample by sample."""

    def __init__(self, params: Sequence[FilterParams]):
        if not params:
            raise ValueError("BatchedFilter needs at least one parameter set")
        frames = {p.world_frame for p in params}
        if len(frames) != 1:
            raise ValueError("all parameter sets of a batch must share world_frame")
        self.params = tuple(params)
        self.world_frame = frames.pop()
        self._view = _stacked([step_params(p) for p in params])
        self._null_view = _stacked([step_params(replace(p, bias_learning_k2=0.0))
                                    for p in params])
        self.size = len(params)
        self.reset()

    def reset(self) -> None:
        """Forget all state; the next valid accelerometer sample initialises every filter."""
        self._state = StepState(np.zeros(self.size), np.zeros(self.size, dtype=bool))
        self._null = StepState(np.zeros(self.size), np.zeros(self.size, dtype=bool))
        self.initialized = False

    def initialize_from(
        self, accel_m_s2: Sequence[float], mag: Sequence[float] | None = None
    ) -> bool:
        """Initialise all filters from one sample (as the single filter does); False if invalid."""
        if not valid_vector(accel_m_s2):
            return False
        use_mag = self._view.use_mag & heading_from_mag(accel_m_s2, mag)
        q_mag = orientation_from_vectors(accel_m_s2, mag) if valid_vector(mag) else None
        q_acc = orientation_from_vectors(accel_m_s2, None)
        for s in (self._state, self._null):
            for i, c in enumerate(("qw", "qx", "qy", "qz")):
                with_mag = q_acc[i] if q_mag is None else q_mag[i]
                setattr(s, c, np.where(use_mag, with_mag, q_acc[i]))
            s.heading_initialized = use_mag.copy()
            s.phase = np.full(self.size, PHASE_STARTUP)
        self.initialized = True
        return True

    def update(
        self,
        gyro_rad_s: Sequence[float],
        accel_m_s2: Sequence[float] | None,
        dt_s: float,
        mag: Sequence[float] | None = None,
    ) -> np.ndarray | None:
        """One sample for all P filters; returns (P, 4) q_world_from_sensor, None before init."""
        if not self.initialized:
            if accel_m_s2 is None or not self.initialize_from(accel_m_s2, mag):
                return None
            return self.orientation
        acc = tuple(float(c) for c in accel_m_s2) if valid_vector(accel_m_s2) else None
        mg = tuple(float(c) for c in mag) if valid_vector(mag) else None  # type: ignore[union-attr]
        gyro = tuple(float(c) for c in gyro_rad_s)
        step(self._state, self._view, gyro, acc, mg, float(dt_s), ArrayOps)  # type: ignore[arg-type]
        step(self._null, self._null_view, gyro, acc, mg, float(dt_s), ArrayOps)  # type: ignore[arg-type]
        return self.orientation

    def _published(self) -> np.ndarray:
        """(P,) bool: the hypothesis without in-flight learning is published
        (ComplementaryFilter._choose; with bias_learning_k2 0 the two are the same)."""
        return EVIDENCE_RATIO * self._null.pv_var < self._state.pv_var

    @property
    def orientation(self) -> np.ndarray:
        """(P, 4) q_world_from_sensor in the batch's world frame."""
        a, b = self._state, self._null
        null = self._published()[:, None]
        q = np.where(null, np.stack([b.qw, b.qx, b.qy, b.qz], axis=-1),
                     np.stack([a.qw, a.qx, a.qy, a.qz], axis=-1))
        return quat.enu_to_ned(q) if self.world_frame == "ned" else q

    @property
    def gyro_bias_rad_s(self) -> np.ndarray:
        """(P, 3) gyro-bias estimates [rad/s], sensor frame."""
        a, b = self._state, self._null
        return np.where(self._published()[:, None], np.stack([b.bx, b.by, b.bz], axis=-1),
                        np.stack([a.bx, a.by, a.bz], axis=-1))

    @property
    def state(self) -> StepState:
        """The live state arrays of the learning hypothesis (read them, do not modify)."""
        return self._state


def _stacked(views: list[SimpleNamespace]) -> SimpleNamespace:
    """One view of P parameter views: each field an array of shape (P,)."""
    return SimpleNamespace(**{k: np.array([getattr(v, k) for v in views]) for k in vars(views[0])})
