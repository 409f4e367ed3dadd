"""Bags without ROS: read ROS 1/ROS 2 bags, replay them through the pipeline, simulate flights.

``io`` (rosbags reading/writing, Jazzy messages), ``replay`` (through
:class:`cf_estimator.pipeline.ImuPipeline`, the node's code path), ``simulate`` (scenario → bag),
``plots`` (PNG). Errors meant for users are :class:`BagError` / :class:`ReplayError`.
"""

from cf_estimator.bag.io import BagError, InputBag, OutputBag, open_bag
from cf_estimator.bag.metrics import error_statistics
from cf_estimator.bag.replay import (
    ReplayError,
    ReplayOptions,
    ReplayResult,
    ReplayVariant,
    replay_bag,
    replay_variants,
)
from cf_estimator.bag.simulate import SimulatedBag, write_scenario_bag

__all__ = [
    "BagError",
    "InputBag",
    "OutputBag",
    "ReplayError",
    "ReplayOptions",
    "ReplayResult",
    "ReplayVariant",
    "SimulatedBag",
    "error_statistics",
    "open_bag",
    "replay_bag",
    "replay_variants",
    "write_scenario_bag",
]
