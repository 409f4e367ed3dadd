"""Analysis of the compensation scheme, beside the estimator: the papers' one-axis filter
(:mod:`~cf_estimator.analysis.axis`), the transfer-function formulas
(:mod:`~cf_estimator.analysis.design`, ``cf-estimator design``) and the thesis's requirement
check (:mod:`~cf_estimator.analysis.thesis`). The estimator itself is :mod:`cf_estimator.core`."""

from cf_estimator.analysis.axis import AxisFilter, AxisParams

__all__ = ["AxisFilter", "AxisParams"]
