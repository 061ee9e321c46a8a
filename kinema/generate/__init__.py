"""The public face of generation: ``load_model`` -> a `MotionPipeline` (kinema.pipeline) whose
``generate(GenerationRequest)`` returns a `GenerationResult`.

The pipelines themselves live in kinema.human (the flat human model) and kinema.anyrig (the per-joint
model for any rig); this package only picks one by what the checkpoint says.
"""

from kinema.generate.loading import PIPELINES, load_model, resolve_model_path
from kinema.pipeline.request import GenerationRequest
from kinema.pipeline.result import GenerationReport, GenerationResult

__all__ = ["PIPELINES", "GenerationReport", "GenerationRequest", "GenerationResult", "load_model",
           "resolve_model_path"]
