"""Feature representations: one object per layout owns every index computation on its tensors.

- kinema.representation.flat: `FlatRepresentation`, the Kimodo flat layout of the human model
  (layout.py channel groups, kimodo.py motion <-> features, stats.py normalisation, encode.py and
  masks.py constraints -> (target, mask), transform.py ground-plane augmentation);
- kinema.representation.joint: `JointRepresentation`, per-joint ``(T, J, 13)`` features for any rig,
  with batching.py padding clips of different rigs with frame / joint / channel masks.

See docs/rig.md.
"""
