"""Evaluation metrics (Kimodo Sec. 6.1): per-motion quality and constraint errors, set-level distribution metrics.

- :mod:`kinema.evaluate.metrics`: foot skate, contact accuracy, constraint errors (full-body, end-effector
  position/rotation, 2D smoothed root, pelvis deviation p95), jerk and jitter, computed the same way on
  ground-truth and generated motions.
- :mod:`kinema.evaluate.distribution`: FID, diversity, multimodality, R-precision and coverage/novelty
  AUC over plain embedding (or feature) tensors produced by any retrieval model.
"""
