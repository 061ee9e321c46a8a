"""The human model without Python: ONNX graphs, one runtime JSON, and the reference sampler that follows
the written loop (docs/onnx_runtime.md). ``export`` writes the folder; ``sampler`` runs it with onnxruntime
and numpy only; ``web/`` is the JavaScript runtime of the same loop."""
