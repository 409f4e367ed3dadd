"""Processing pipeline: message-like objects in → validated filter calls → output contents.

No ROS imports: the node and the bag replay both drive :class:`ImuPipeline`.
"""

from cf_estimator.pipeline.diagnostics import DiagnosticsReport
from cf_estimator.pipeline.params import PipelineParams
from cf_estimator.pipeline.pipeline import ImuPipeline, PipelineOutput

__all__ = ["DiagnosticsReport", "ImuPipeline", "PipelineOutput", "PipelineParams"]
