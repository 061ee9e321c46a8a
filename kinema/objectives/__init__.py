"""Objectives (implicit controls) met by optimising the diffusion noise: reach, joint-distance,
avoid, stay-within, time-agnostic paths and a realism prior (docs/objectives.md)."""

from kinema.objectives.io import ObjectiveError, bind_objectives, load_objectives, parse_objective
from kinema.objectives.optimize import NoiseOptSettings, optimise_noise
from kinema.objectives.path import PathTimeAgnostic
from kinema.objectives.terms import Avoid, JointDistance, Objective, Reach, Realism, StayWithin

__all__ = [
    "Avoid",
    "JointDistance",
    "NoiseOptSettings",
    "Objective",
    "ObjectiveError",
    "PathTimeAgnostic",
    "Reach",
    "Realism",
    "StayWithin",
    "bind_objectives",
    "load_objectives",
    "optimise_noise",
    "parse_objective",
]
