"""Training the per-joint any-rig denoiser: multi-rig data (data), rig augmentation (augment),
constraint masks (masks) and the trainer (trainer)."""
