"""Requests generated as their mirror image, for a model whose action expert does one side worse.

Why (issue 38, docs/training.md "Stop 56"): every training clip of the human model is there twice, as
made and mirrored left to right with its caption's sides swapped, so in the data a right kick is exactly
the mirror image of a left kick. The action expert learned one side better all the same (stop 54's
expert O, probed on held-out phrasings at 4 s: left kicks 12 of 12, right 5 of 12; at 5 s left punches 6 of
12, right none). A model whose expert names a ``mirror_side`` (kinema.model.action_expert) therefore
makes a request whose expert prompt names that side alone as the mirror image of the request for the
other side: every prompt's side words swapped (kinema.model.sides.mirror_caption), the heading negated,
and the raw motions mirrored back (kinema.motion.mirror) before post-processing. Prompts that name no side
("A person walks forward.") stay as they are: the mirror of their training data is their training data.

A request is mirrored only when that maps it onto itself exactly: at least one prompt the expert mirrors,
no prompt naming the other side and no objectives (they are optimised in the user's frame). Its
constraints are sampled mirrored (:func:`mirror_constraints`: x -> -x, left and right joints and foot
contacts swapped, headings turned the other way, joint rotations mirrored as kinema.motion.mirror
does), and post-processing then hits the user's own constraints on the mirrored-back motion, so
residuals are measured in the frame the user gave. The report says which prompts were made as a mirror
image, and of what.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import torch

from kinema.constraints.types import (
    Constraint,
    EndEffectorConstraint,
    FootContactConstraint,
    FullBodyConstraint,
    Root2DConstraint,
    resolve_joint,
)
from kinema.geometry.rotations import axis_angle_to_quat, mirror_quat_x, quat_mul, quat_to_axis_angle
from kinema.model.action_expert import ActionExpert
from kinema.model.sides import mirror_caption, sides
from kinema.motion.core import Motion
from kinema.motion.mirror import CONTACT_MIRROR, mirror_corrections
from kinema.skeleton import Skeleton

#: x -> -x on (x, y, z) points and (x, z) ground points; a (cos psi, sin psi) heading turned to -psi
_X3, _X2, _HEADING = torch.tensor([-1.0, 1.0, 1.0]), torch.tensor([-1.0, 1.0]), torch.tensor([1.0, -1.0])


def mirrored_prompts(prompts: list[str], expert: ActionExpert | None, objectives: bool,
                     words: Callable[[str], str] = str) -> dict[str, str]:
    """``{prompt: the prompt it is made as}`` for a request of ``prompts`` (a timeline's, in order) to be
    generated as its mirror image, or ``{}`` when it is made as it is: no expert or no ``mirror_side``,
    ``objectives`` given, no prompt the expert mirrors, or a prompt naming the other side. ``words(p)``: the
    words prompt ``p`` is conditioned on (its grounding caption), which decide; default its own."""
    if expert is None or expert.mirror_side is None or objectives:
        return {}
    said = [words(p) for p in prompts]
    if not any(expert.mirrors(w) for w in said) or any(sides(w) - {expert.mirror_side} for w in said):
        return {}
    return {p: mirror_caption(p) for p in prompts}


def mirror_constraints(constraints: list[Constraint], skeleton: Skeleton) -> list[Constraint] | None:
    """The mirror images of loaded ``constraints`` (kinema.constraints.types) on ``skeleton``, exactly as
    kinema.motion.mirror mirrors a motion: what a mirrored request samples towards. None when one is of a
    kind this does not know."""
    out = []
    for c in constraints:
        if isinstance(c, Root2DConstraint):
            heading = None if c.heading is None else c.heading * _HEADING
            out.append(replace(c, positions=c.positions * _X2, heading=heading))
        elif isinstance(c, FootContactConstraint):
            out.append(replace(c, contacts=c.contacts[:, CONTACT_MIRROR]))
        elif isinstance(c, EndEffectorConstraint):
            out.append(_mirror_effector(c, skeleton))
        elif isinstance(c, FullBodyConstraint):
            out.append(_mirror_poses(c, skeleton))
        else:
            return None
    return out


def _mirror_2d(points: torch.Tensor | None) -> torch.Tensor | None:
    return None if points is None else points * _X2


def _mirror_effector(c: EndEffectorConstraint, skeleton: Skeleton) -> EndEffectorConstraint:
    """A joint target moved to the partner joint: positions reflected, a global rotation ``R`` of joint j
    becomes ``mirror(R) B_j`` (the partner's rest frame need not be the reflection of j's;
    kinema.motion.mirror.mirror_corrections)."""
    j = resolve_joint(skeleton, c.joint)
    rotations = c.rotations
    if rotations is not None:
        fix = mirror_corrections(skeleton)[j].to(rotations.dtype)
        rotations = quat_to_axis_angle(quat_mul(mirror_quat_x(axis_angle_to_quat(rotations)), fix))
    return replace(c, joint=skeleton.names[skeleton.mirror_map[j]], rotations=rotations,
                   positions=None if c.positions is None else c.positions * _X3,
                   smooth_root_2d=_mirror_2d(c.smooth_root_2d))


def _mirror_poses(c: FullBodyConstraint, skeleton: Skeleton) -> FullBodyConstraint:
    """A full-body constraint's keyframe poses mirrored as a motion is (kinema.motion.mirror)."""
    poses = Motion(skeleton, 1.0, c.root_positions.float(), axis_angle_to_quat(c.local_rotations.float()))
    mirrored = poses.mirror()
    return replace(c, local_rotations=quat_to_axis_angle(mirrored.local_rotations).to(c.local_rotations.dtype),
                   root_positions=mirrored.root_translation.to(c.root_positions.dtype),
                   smooth_root_2d=_mirror_2d(c.smooth_root_2d))
