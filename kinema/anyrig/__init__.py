"""The any-rig pipeline: the per-joint denoiser for any skeleton ("How to Move Your Dragon" / AnyTop).

`AnyRigPipeline` (kinema.anyrig.pipeline) implements kinema.pipeline's `MotionPipeline` on a rig the
user gives: windows (windows, sampling), world-frame constraints (constraints, world), grounding,
foot locking and the exact pass (ground, feet, post).
"""
