"""The filter core: no ROS, no I/O. The seeds' compensation scheme in 3-D (the 1-axis form and
the design formulas: :mod:`cf_estimator.analysis`)."""

from cf_estimator.core.batch import EstimateResult, estimate, estimate_many
from cf_estimator.core.batched import BatchedFilter
from cf_estimator.core.filter import ComplementaryFilter, FilterStatus
from cf_estimator.core.params import FilterParams

__all__ = [
    "BatchedFilter",
    "ComplementaryFilter",
    "EstimateResult",
    "FilterParams",
    "FilterStatus",
    "estimate",
    "estimate_many",
]
