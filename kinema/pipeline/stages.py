"""Stages after generation that live beside the pipelines and are imported by name, on first use.

- ``ROBOT``: a human motion as a robot's joint angles (kinema.robot.stage); MuJoCo takes most of a
  second to import, and no other generation needs it.
- ``CHARACTER``: the user's humanoid character for a model with a skeleton of its own
  (kinema.retarget.stage): constraints read in the model's terms, motions retargeted, targets met.

Neither kinema.robot nor kinema.retarget imports kinema.pipeline, so naming them here adds no cycle
(docs/architecture.md).
"""

from __future__ import annotations

import importlib

ROBOT = "kinema.robot.stage:robot_motions"
ROBOT_DESCRIPTION = "kinema.robot.description:load_robot"  # read before sampling: a bad robot fails fast
CHARACTER = "kinema.retarget.stage:CharacterStage"


def load_stage(spec: str):
    """The object a ``"module:name"`` spec names (the module is imported on first use)."""
    module, name = spec.split(":")
    return getattr(importlib.import_module(module), name)
