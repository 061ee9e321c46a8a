"""Kinematic constraints for generation: typed objects, the JSON format and the feature encoding.

- kinema.constraints.types: `FullBodyConstraint`, `EndEffectorConstraint`, `Root2DConstraint`,
  `FootContactConstraint`, `ConstraintError`;
- kinema.constraints.io: `load_constraints` / `save_constraints` (docs/constraints.md);
- kinema.constraints.encode: `encode_constraints` -> `ConstraintTargets` (x_tgt, mask, world x/z).
"""

from kinema.constraints.encode import ConstraintTargets, encode_constraints, world_to_relative
from kinema.constraints.io import constraint_to_json, dumps_constraints, load_constraints, save_constraints
from kinema.constraints.types import (
    CONTACT_NAMES,
    Constraint,
    ConstraintError,
    EndEffectorConstraint,
    FootContactConstraint,
    FullBodyConstraint,
    Root2DConstraint,
)

__all__ = [
    "CONTACT_NAMES",
    "Constraint",
    "ConstraintError",
    "ConstraintTargets",
    "EndEffectorConstraint",
    "FootContactConstraint",
    "FullBodyConstraint",
    "Root2DConstraint",
    "constraint_to_json",
    "dumps_constraints",
    "encode_constraints",
    "load_constraints",
    "save_constraints",
    "world_to_relative",
]
