"""What the any-rig denoiser knows about a skeleton: per-joint codes computed once per rig.

- ``tree (J, tree_depth * tree_branch + 1)``: TreePE input (Shiv & Quirk 2019, as in "How to Move Your
  Dragon" Sec. 3): the joint's path from the skeleton's top as a stack of one-hot child slots, nearest
  step first (slot = rank among its parent's children, clamped to ``tree_branch - 1``), truncated to
  ``tree_depth`` steps, plus the depth / 16;
- ``rest (J, 6 (2F + 1) + 6)``: RestPE input: the rest offset from the parent and the rest position
  relative to the rig's root (rig units: rest pose about 1 across), each coordinate with ``F``
  sinusoids (NeRF style), and the joint's global rest rotation as 6D (the rotation features are
  global rotations, whose meaning depends on the bone's rest frame);
- ``hops (J, J)``: edges between every pair of joints (AnyTop-style spatial attention bias);
- ``flags (J, 2)``: [is the rig's root, is a contact joint].

``batch_codes`` pads several rigs to ``J`` joints with a joint mask (padding: zeros, hop bucket
``max_hops``). Shapes are per rig ``(J, ...)`` and per batch ``(B, J, ...)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from kinema.geometry.rotations import quat_to_sixd
from kinema.kinematics import forward_kinematics
from kinema.model.anyrig.config import AnyRigConfig
from kinema.rig import Rig


@dataclass(frozen=True)
class SkeletonCodes:
    """Static per-joint inputs of one rig (see the module docstring); float32 except ``hops``."""

    tree: torch.Tensor
    rest: torch.Tensor
    hops: torch.Tensor
    flags: torch.Tensor

    @property
    def num_joints(self) -> int:
        return self.tree.shape[0]


@dataclass(frozen=True)
class CodeBatch:
    """Padded codes of a batch of rigs: ``tree (B, J, Dt)``, ``rest (B, J, Dr)``, ``hops (B, J, J)``,
    ``flags (B, J, 2)``, ``joint_mask (B, J)`` (True = real joint)."""

    tree: torch.Tensor
    rest: torch.Tensor
    hops: torch.Tensor
    flags: torch.Tensor
    joint_mask: torch.Tensor

    def repeat(self, k: int) -> CodeBatch:
        """The batch repeated ``k`` times along B (guidance branches)."""
        return CodeBatch(
            *(
                x.repeat(k, *([1] * (x.dim() - 1)))
                for x in (self.tree, self.rest, self.hops, self.flags, self.joint_mask)
            )
        )


def tree_dim(config: AnyRigConfig) -> int:
    return config.tree_depth * config.tree_branch + 1


def rest_dim(config: AnyRigConfig) -> int:
    return 6 * (2 * config.rest_freqs + 1) + 6


def _tree_code(rig: Rig, depth: int, branch: int) -> torch.Tensor:
    parents = rig.skeleton.parents
    children = rig.skeleton.children
    slot = [0] * len(parents)
    for kids in children:
        for rank, c in enumerate(kids):
            slot[c] = min(rank, branch - 1)
    code = torch.zeros(len(parents), depth * branch + 1)
    for j in range(len(parents)):
        step, k = j, 0
        while parents[step] >= 0 and k < depth:
            code[j, k * branch + slot[step]] = 1.0
            step, k = parents[step], k + 1
        code[j, -1] = rig.skeleton.depths[j] / 16.0
    return code


def _sinusoids(x: torch.Tensor, freqs: int) -> torch.Tensor:
    """``x (J, D)`` -> ``(J, D (2F + 1))``: x, sin(2^k pi x), cos(2^k pi x) for k < F."""
    parts = [x]
    for k in range(freqs):
        parts += [torch.sin((2.0**k) * math.pi * x), torch.cos((2.0**k) * math.pi * x)]
    return torch.cat(parts, dim=-1)


def _rest_code(rig: Rig, freqs: int) -> torch.Tensor:
    skel = rig.skeleton
    J = skel.num_joints
    rest = skel.rest_rotations
    if rest is None:
        rest = torch.zeros(J, 4, dtype=torch.float64)
        rest[:, 0] = 1.0
    G, P = forward_kinematics(rest[None], torch.zeros(1, 3, dtype=torch.float64), skel.offsets, skel.parents)
    geo = torch.cat([skel.offsets, P[0] - P[0, rig.root]], dim=-1)
    return torch.cat([_sinusoids(geo, freqs), quat_to_sixd(G[0])], dim=-1).float()


def skeleton_codes(rig: Rig, config: AnyRigConfig) -> SkeletonCodes:
    """The codes of ``rig`` (in its own units: the creatures model works on rigs scaled to ~1 across)."""
    flags = torch.zeros(rig.num_joints, 2)
    flags[rig.root, 0] = 1.0
    flags[list(rig.contacts), 1] = 1.0
    return SkeletonCodes(
        tree=_tree_code(rig, config.tree_depth, config.tree_branch),
        rest=_rest_code(rig, config.rest_freqs),
        hops=rig.skeleton.tree_distances().clamp_max(config.max_hops),
        flags=flags,
    )


def batch_codes(codes: list[SkeletonCodes], num_joints: int | None = None, max_hops: int = 8) -> CodeBatch:
    """Pad the codes of several rigs to ``num_joints`` (default: the largest) into a `CodeBatch`."""
    B = len(codes)
    J = num_joints or max(c.num_joints for c in codes)
    tree = torch.zeros(B, J, codes[0].tree.shape[1])
    rest = torch.zeros(B, J, codes[0].rest.shape[1])
    hops = torch.full((B, J, J), max_hops, dtype=torch.long)
    flags = torch.zeros(B, J, 2)
    joint_mask = torch.zeros(B, J, dtype=torch.bool)
    for i, c in enumerate(codes):
        n = c.num_joints
        tree[i, :n], rest[i, :n], hops[i, :n, :n], flags[i, :n] = c.tree, c.rest, c.hops, c.flags
        joint_mask[i, :n] = True
    return CodeBatch(tree, rest, hops, flags, joint_mask)
