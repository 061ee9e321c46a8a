"""A small synthetic GLB rig for the app tests (no dataset needed): a four-legged 11-joint skeleton
with kinema's generated bone skin and one walking-in-place clip, written with kinema's GLB writer."""

from __future__ import annotations

import math
from pathlib import Path

import torch

from kinema.io.gltf_writer import glb_bytes
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

NAMES = ["root", "body", "head", "fl", "fl_foot", "fr", "fr_foot", "bl", "bl_foot", "br", "br_foot"]
PARENTS = [-1, 0, 1, 1, 3, 1, 5, 1, 7, 1, 9]
OFFSETS = [[0, 0.5, 0], [0, 0, 0], [0, 0.1, 0.4], [0.15, 0, 0.3], [0, -0.45, 0], [-0.15, 0, 0.3], [0, -0.45, 0]]
OFFSETS += [[0.15, 0, -0.3], [0, -0.45, 0], [-0.15, 0, -0.3], [0, -0.45, 0]]


def quad_motion(frames: int = 24, fps: float = 24.0) -> Motion:
    skeleton = Skeleton(NAMES, PARENTS, torch.tensor(OFFSETS, dtype=torch.float64), name="quad")
    rot = torch.zeros(frames, len(NAMES), 4)
    rot[..., 0] = 1.0
    swing = 0.4 * torch.sin(torch.linspace(0, 2 * math.pi, frames))
    for j, sign in ((3, 1), (5, -1), (7, -1), (9, 1)):  # legs swing about X
        rot[:, j, 0], rot[:, j, 1] = torch.cos(sign * swing / 2), torch.sin(sign * swing / 2)
    return Motion(skeleton, fps, torch.tensor([[0.0, 0.5, 0.0]]).repeat(frames, 1), rot)


def synthetic_rig_glb(path: Path) -> Path:
    path.write_bytes(glb_bytes({"Walk": quad_motion()}))
    return path
