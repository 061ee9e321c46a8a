"""Glue between user constraints, the sampler's feature targets and post-processing targets.

``encode_user_constraints`` turns a constraints file / list / objects into feature targets for the
whole output (frames at the model fps). ``post_targets`` turns the same constraints into world-space
targets (joint positions and rotations, smoothed-root x/z, contacts) for kinema.postprocess.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from kinema.constraints import (
    Constraint,
    EndEffectorConstraint,
    FootContactConstraint,
    FullBodyConstraint,
    Root2DConstraint,
    constraint_to_json,
    load_constraints,
)
from kinema.constraints.types import resolve_joint
from kinema.errors import KinemaError
from kinema.geometry.rotations import axis_angle_to_quat
from kinema.kinematics import forward_kinematics
from kinema.motion.core import Motion
from kinema.postprocess import PostTargets, postprocess
from kinema.representation.flat import FlatRepresentation


@dataclass(frozen=True)
class UserTargets:
    """The user's constraints encoded for the whole output of ``T`` frames: unnormalised ``x_tgt`` /
    ``mask (T, D)`` and world joint x/z ``world_xz (T, J, 2)`` where ``world_mask (T, J)`` (None when
    no joint waits for the root)."""

    x_tgt: torch.Tensor
    mask: torch.Tensor
    world_xz: torch.Tensor | None = None
    world_mask: torch.Tensor | None = None


def encode_user_constraints(rep: FlatRepresentation, constraints, total_frames: int,
                            constraints_fps: float | None = None) -> tuple[list, UserTargets]:
    """(constraint objects, their `UserTargets`) at ``rep.fps``.

    ``constraints_fps``: the rate a file's ``frame_indices`` were written at (default: the file's own
    ``fps`` key, else the representation's)."""
    D = rep.dim
    if constraints is None or (isinstance(constraints, list) and not constraints):
        return [], UserTargets(torch.zeros(total_frames, D), torch.zeros(total_frames, D))
    if isinstance(constraints, (str, Path)):
        constraints = Path(constraints)
    elif isinstance(constraints, list):  # constraint objects go through the same checks as their JSON form
        constraints = [constraint_to_json(c) if isinstance(c, Constraint) else c for c in constraints]
    if constraints_fps is not None and not (isinstance(constraints_fps, (int, float)) and
                                            math.isfinite(constraints_fps) and constraints_fps > 0):
        raise KinemaError(f"constraints_fps must be a positive number, got {constraints_fps!r}")
    cons = load_constraints(constraints, rep.skeleton, rep.fps, total_frames, source_fps=constraints_fps)
    enc = rep.encode(cons, total_frames)
    wxz, wm = enc.world_xz, enc.world_mask
    if wm is not None and not bool(wm.any()):
        wxz = wm = None
    return cons, UserTargets(enc.x_tgt.float(), enc.mask.float(), wxz, wm)


def _append(store: dict, key, frames: torch.Tensor, values: torch.Tensor) -> None:
    if key in store:
        f0, v0 = store[key]
        frames, values = torch.cat([f0, frames]), torch.cat([v0, values])
    store[key] = (frames, values)


def _dense_root(c: Root2DConstraint, frames: list[int]) -> tuple[torch.Tensor, torch.Tensor]:
    pos = c.positions.double()
    if not c.dense or len(frames) < 2:
        return torch.tensor(frames), pos
    all_frames = torch.arange(frames[0], frames[-1] + 1)
    f = torch.tensor(frames, dtype=torch.float64)
    xs = [torch.from_numpy(np.interp(all_frames.numpy(), f.numpy(), pos[:, i].numpy())) for i in range(2)]
    return all_frames, torch.stack(xs, dim=-1)


def post_targets(constraints, skeleton, fps: float, num_frames: int) -> PostTargets:
    """World-space post-processing targets from validated constraint objects."""
    targets = PostTargets()
    roots: dict = {}
    contacts: dict = {}
    for c in constraints:
        frames = c.frames(fps, num_frames)
        fr = torch.tensor(frames)
        if isinstance(c, FullBodyConstraint):
            q = axis_angle_to_quat(c.local_rotations.double())
            G, P = forward_kinematics(q, c.root_positions.double(), skeleton.offsets, skeleton.parents)
            for j in range(skeleton.num_joints):
                _append(targets.joint_positions, j, fr, P[:, j])
                _append(targets.joint_rotations, j, fr, G[:, j])
            if c.smooth_root_2d is not None:
                _append(roots, 0, fr, c.smooth_root_2d.double())
        elif isinstance(c, EndEffectorConstraint):
            j = resolve_joint(skeleton, c.joint)
            if c.positions is not None:
                _append(targets.joint_positions, j, fr, c.positions.double())
            if c.rotations is not None:
                _append(targets.joint_rotations, j, fr, axis_angle_to_quat(c.rotations.double()))
            if c.smooth_root_2d is not None:
                _append(roots, 0, fr, c.smooth_root_2d.double())
        elif isinstance(c, Root2DConstraint):
            _append(roots, 0, *_dense_root(c, frames))
        elif isinstance(c, FootContactConstraint):
            _append(contacts, 0, fr, c.contacts.double())
    if roots:
        targets.root_xz = roots[0]
    if contacts:
        targets.contacts = contacts[0]
    return targets


def run_postprocess(motion: Motion, constraints, rep: FlatRepresentation) -> tuple[Motion, dict]:
    """Foot locking + IK + exact constraint hitting on ``rep``'s rig; returns the motion and a compact
    residual report."""
    targets = post_targets(constraints, rep.skeleton, rep.fps, motion.num_frames) if constraints else None
    motion, report = postprocess(motion, targets, rig=rep.rig)
    return motion, report
