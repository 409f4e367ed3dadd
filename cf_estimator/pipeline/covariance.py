"""Orientation covariance of the pipeline's output: the model of :mod:`cf_estimator.core.covariance`
(one model for the node, the bag replay and ``estimate()``; documented there and in
docs/ros_interface.md, "Covariance")."""

from __future__ import annotations

from cf_estimator.core.covariance import OrientationCovariance

__all__ = ["OrientationCovariance"]
