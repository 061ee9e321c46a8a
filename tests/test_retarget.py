"""Full-body poses from a BVH whose bones point elsewhere at rest land on the model skeleton with every
bone pointing where the file's does (kinema.constraints.retarget)."""

from __future__ import annotations

import torch

from kinema.constraints.io import poses_from_bvh
from kinema.constraints.retarget import rest_alignment
from kinema.generate import resolve_model_path
from kinema.geometry.rotations import axis_angle_to_quat
from kinema.io.bvh import read_bvh
from kinema.kinematics import forward_kinematics
from kinema.model.loading import load_denoiser

WALK = "Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh.gz"


def _bone_directions(P: torch.Tensor, parents) -> torch.Tensor:
    d = torch.stack([P[:, c] - P[:, max(p, 0)] for c, p in enumerate(parents) if p >= 0], dim=1)
    return d / d.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def test_synthetic_clip_poses_the_bandai_skeleton_bone_for_bone(synthetic_bandai):
    skel = load_denoiser(resolve_model_path("default")).skeleton  # Bandai's rest pose (along +X)
    path = synthetic_bandai / WALK  # identity rest rotations, standing along +Y
    src = read_bvh(path, scale=0.01).prune(["joint_Root"]).resample(20)
    assert rest_alignment(skel, src.skeleton.offsets) is not None
    frames = [0, 10, 25]
    aa, root = poses_from_bvh(path, frames, skeleton=skel, fps=20, scale=0.01)
    _, P = forward_kinematics(axis_angle_to_quat(aa), root, skel.offsets.to(aa.dtype), skel.parents)
    want = _bone_directions(src.positions[frames].to(P.dtype), skel.parents)
    got = _bone_directions(P, skel.parents)
    angle = torch.rad2deg(torch.arccos((want * got).sum(-1).clamp(-1, 1)))
    assert float(angle.max()) < 2.0, float(angle.max())  # without the alignment: tens of degrees


def test_matching_rest_pose_is_left_alone():
    skel = load_denoiser(resolve_model_path("default")).skeleton
    assert rest_alignment(skel, skel.offsets * 100.0) is None  # same directions, centimetres
