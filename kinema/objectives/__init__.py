"""Objectives (implicit controls) met by optimising the diffusion noise: reach, joint-distance,
avoid, stay-within, time-agnostic paths and a realism prior (docs/objectives.md).

This package is the vocabulary (what an objective is, its JSON form, its value on a motion); the human
pipeline optimises the noise for them (kinema.human.noise_optimisation, kinema.human.objective_sampling),
so objectives never import a pipeline."""

from kinema.objectives.io import ObjectiveError, bind_objectives, load_objectives, parse_objective
from kinema.objectives.path import PathTimeAgnostic
from kinema.objectives.terms import Avoid, JointDistance, Objective, Reach, Realism, StayWithin

__all__ = [
    "Avoid",
    "JointDistance",
    "Objective",
    "ObjectiveError",
    "PathTimeAgnostic",
    "Reach",
    "Realism",
    "StayWithin",
    "bind_objectives",
    "load_objectives",
    "parse_objective",
]
