"""The filter core: no ROS, no I/O. Seeds' compensation scheme in 1-axis and 3-D form."""

from cf_estimator.core.axis import AxisFilter, AxisParams
from cf_estimator.core.batch import EstimateResult, estimate, estimate_many
from cf_estimator.core.batched import BatchedFilter
from cf_estimator.core.filter import ComplementaryFilter, FilterStatus
from cf_estimator.core.params import FilterParams

__all__ = [
    "AxisFilter",
    "AxisParams",
    "BatchedFilter",
    "ComplementaryFilter",
    "EstimateResult",
    "FilterParams",
    "FilterStatus",
    "estimate",
    "estimate_many",
]
