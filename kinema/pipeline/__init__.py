"""What every generation pipeline shares: the request, the result and report, the interface.

`GenerationRequest` (request) is everything a user can ask; `MotionPipeline` (base) is the interface
both models implement; `GenerationResult` / `GenerationReport` (result) is what a call returns.
Timelines (timeline) and progress callbacks (progress) are shared by both implementations.
"""
