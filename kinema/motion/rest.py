"""Re-express a motion on the same joints with a different (clean) rest pose.

BVH rigs often have odd rest poses (Bandai Namco's lies along +X). For export, kinema re-bases motions
so that the all-identity pose is a natural standing pose facing +Z, Y up: with ``G0`` the global
rotations of the chosen rest pose, new offsets are ``o'_j = G0_parent(j) o_j`` (world-space bone vectors
of the rest pose) and new global rotations ``G'_j = G_j G0_j^-1``. Joint positions are unchanged.
"""

from __future__ import annotations

import math

import torch

from kinema.geometry.rotations import axis_angle_to_quat, quat_inverse, quat_mul, quat_rotate
from kinema.kinematics import forward_kinematics
from kinema.motion.core import Motion
from kinema.motion.heading import heading_from_positions
from kinema.skeleton import Skeleton


def rest_globals(skeleton: Skeleton, rest_local: torch.Tensor) -> torch.Tensor:
    """(J, 4) global rotations of the pose given by local rotations ``rest_local (J, 4)``."""
    G, _ = forward_kinematics(rest_local.double()[None], torch.zeros(1, 3, dtype=torch.float64),
                              skeleton.offsets, skeleton.parents)
    return G[0]


def clean_skeleton(skeleton: Skeleton, rest_local: torch.Tensor) -> Skeleton:
    """The skeleton whose identity pose is the pose ``rest_local``; it keeps no rest rotations."""
    G0 = rest_globals(skeleton, rest_local)
    parents = [max(p, 0) for p in skeleton.parents]
    offsets = quat_rotate(G0[parents], skeleton.offsets)
    offsets[0] = skeleton.offsets[0]
    ends = {}
    for j, v in skeleton.end_sites.items():
        ends[j] = tuple(quat_rotate(G0[j], torch.tensor(v, dtype=torch.float64)).tolist())
    return Skeleton(skeleton.names, skeleton.parents, offsets, None, ends, skeleton.role_overrides, skeleton.name)


def rebase_rest_pose(motion: Motion, rest_local: torch.Tensor | None = None) -> Motion:
    """The same motion on :func:`clean_skeleton`; ``rest_local`` defaults to the skeleton's rest rotations."""
    skel = motion.skeleton
    rest_local = skel.rest_rotations if rest_local is None else rest_local
    if rest_local is None:
        return motion
    G0 = rest_globals(skel, rest_local).to(motion.dtype)
    G, _ = motion.global_transforms()
    G_new = quat_mul(G, quat_inverse(G0)[None])
    positions = None if motion.local_translations is None else motion.positions
    return Motion.from_global(clean_skeleton(skel, rest_local), motion.fps, motion.root_translation, G_new,
                              motion.foot_contacts, positions)


def standing_rest_pose(motion: Motion, frame: int = 0) -> torch.Tensor:
    """Local rotations (J, 4) of ``motion``'s pose at ``frame``, turned to face +Z (heading 0)."""
    L = motion.local_rotations[frame].double().clone()
    h = heading_from_positions(motion.positions[frame : frame + 1].double(), motion.skeleton)[0]
    psi = math.atan2(float(h[1]), float(h[0]))
    turn = axis_angle_to_quat(torch.tensor([0.0, -psi, 0.0], dtype=torch.float64))
    L[0] = quat_mul(turn, L[0])
    return L
