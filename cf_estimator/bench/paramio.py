"""Parameter files for the bench and the tuner: the project's ROS 2 YAML loader and renderer
(:mod:`cf_estimator.params_file`), filter parameters only.

A file written by :func:`render_filter_params` is a complete parameter file (filter parameters
as given, pipeline parameters at their defaults) that the node (``--params-file``) and
``replay --params`` load unchanged.
"""

from __future__ import annotations

import os

from cf_estimator.core.params import FilterParams
from cf_estimator.params_file import load_params_file, render_params_yaml


def load_filter_params(path: str | os.PathLike) -> tuple[FilterParams, list[str]]:
    """(FilterParams, warnings) from a ROS 2 parameter YAML; ParameterError on failure."""
    filter_params, _pipeline_params, warnings = load_params_file(path)
    return filter_params, list(warnings)


def render_filter_params(params: FilterParams, header: str = "") -> str:
    """A ROS 2 parameter YAML (``/**:`` wildcard) holding ``params``, preceded by ``header``."""
    return header + render_params_yaml(params)
