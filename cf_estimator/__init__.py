"""cf_estimator: complementary-filter attitude (roll, pitch, yaw) from IMU and magnetometer.

The public Python API is the filter core; the ROS node, the bag replay and the CLI are adapters.
"""

from cf_estimator.analysis import AxisFilter, AxisParams
from cf_estimator.core import (
    BatchedFilter,
    ComplementaryFilter,
    EstimateResult,
    FilterParams,
    FilterStatus,
    estimate,
    estimate_many,
)
from cf_estimator.schema import ParameterError

__version__ = "0.1.0"

__all__ = [
    "AxisFilter",
    "AxisParams",
    "BatchedFilter",
    "ComplementaryFilter",
    "EstimateResult",
    "FilterParams",
    "FilterStatus",
    "ParameterError",
    "__version__",
    "estimate",
    "estimate_many",
]
