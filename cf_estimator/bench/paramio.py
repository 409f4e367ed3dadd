"""Parameter files for the bench and the tuner: the project's ROS 2 YAML loader and renderer
(:mod:`cf_estimator.params_file`), filter parameters only.

A file written by :func:`render_filter_params` is a parameter file that the node
(``--params-file``) and ``replay --params`` load unchanged: complete (filter parameters as given,
pipeline parameters as given or at their defaults), or only the parameters named by ``only``.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

from cf_estimator.core.params import FilterParams
from cf_estimator.params_file import load_params_file, render_params_yaml
from cf_estimator.pipeline.params import PipelineParams


def load_filter_params(path: str | os.PathLike) -> tuple[FilterParams, list[str]]:
    """(FilterParams, warnings) from a ROS 2 parameter YAML; ParameterError on failure."""
    filter_params, _pipeline_params, warnings = load_params_file(path)
    return filter_params, list(warnings)


def render_filter_params(params: FilterParams, header: str = "", *,
                         pipeline_params: PipelineParams | None = None,
                         only: Sequence[str] | None = None,
                         notes: Mapping[str, str] | None = None) -> str:
    """A ROS 2 parameter YAML (``/**:`` wildcard) holding ``params``, preceded by ``header``.

    ``only``: just these parameters (the tuner's searched ones), ``notes`` a comment line per
    name; ``pipeline_params``: the pipeline values written with the full file (defaults).
    """
    return header + render_params_yaml(params, pipeline_params, only=only, notes=notes)
