"""The human pipeline: the flat root/body denoiser on the one human skeleton it was trained on (Kimodo).

`HumanPipeline` (kinema.human.pipeline) implements kinema.pipeline's `MotionPipeline`: text and
constraints -> DDIM with separated guidance, timelines with regenerated joins (segments), optional
keyjoint planning (SFControl, keyjoint_planning), post-processing.
"""
