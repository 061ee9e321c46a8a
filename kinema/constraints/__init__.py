"""Kinematic constraints for generation: typed objects and the JSON format.

- kinema.constraints.types: `FullBodyConstraint`, `EndEffectorConstraint`, `Root2DConstraint`,
  `FootContactConstraint`, `ConstraintError`;
- kinema.constraints.io: `load_constraints` / `save_constraints` (docs/constraints.md);
- kinema.constraints.fps: the ``{"fps", "constraints"}`` file form and frame conversion;
- kinema.constraints.kimodo_examples: Kimodo's example folders (`read_kimodo_meta`) and whole-pose constraints;

Their encoding as model features lives with the representation (kinema.representation.encode), which
imports this package, never the reverse.
"""

from kinema.constraints.io import constraint_to_json, dumps_constraints, load_constraints, save_constraints
from kinema.constraints.kimodo_examples import KIMODO_FPS, KimodoMeta, find_kimodo_meta, read_kimodo_meta
from kinema.constraints.types import (
    CONTACT_NAMES,
    Constraint,
    ConstraintError,
    ConstraintWarning,
    EndEffectorConstraint,
    FootContactConstraint,
    FullBodyConstraint,
    Root2DConstraint,
)

__all__ = [
    "CONTACT_NAMES",
    "KIMODO_FPS",
    "Constraint",
    "ConstraintError",
    "ConstraintWarning",
    "EndEffectorConstraint",
    "FootContactConstraint",
    "FullBodyConstraint",
    "KimodoMeta",
    "Root2DConstraint",
    "constraint_to_json",
    "dumps_constraints",
    "find_kimodo_meta",
    "load_constraints",
    "read_kimodo_meta",
    "save_constraints",
]
