"""Foot locking for feet that move by translation (Quaternius-style IK foot bones under the armature).

Many game rigs drive each foot with an IK bone parented to a static armature joint on the floor and
animate that bone's *translation*; the leg chain follows it in the engine, not in the skeleton, so
kinema's leg IK (kinema.postprocess.footlock) cannot lock it. Here such a foot is locked directly:
where it is planted (within ``GROUND`` of the floor, slower than ``SPEED``, at least ``MIN_FRAMES``
frames) its ground position is held at the segment's mean, blended in and out over ``BLEND`` frames,
and written back as the bone's local translation. Lengths are rig units scaled by the rig's size
(rest-pose extent), so thresholds mean the same on a fish and a T-rex. Shapes ``(T, J, 3)``.
"""

from __future__ import annotations

import torch

from kinema.geometry.rotations import quat_inverse, quat_rotate
from kinema.motion.core import Motion
from kinema.postprocess.footlock import contact_segments

GROUND = 0.04  # x rig size: planted when this close to the floor ...
SPEED = 0.6  # x rig size per second: ... and slower than this
MIN_FRAMES = 2
BLEND = 3


def lock_translated_feet(motion: Motion, joints: list[int], size: float) -> tuple[Motion, int]:
    """``motion`` with the planted segments of ``joints`` (bones animated by translation, children of
    joint 0) held in place; returns the motion and the number of locked segments."""
    if not joints or motion.local_translations is None or motion.num_frames < 3:
        return motion, 0
    G, P = motion.global_transforms()
    floor = float(P[:, joints, 1].min())  # the feet themselves: joint 0 may ride along with the root
    speed = torch.zeros(P.shape[:2], dtype=P.dtype)
    speed[1:] = (P[1:, :, [0, 2]] - P[:-1, :, [0, 2]]).norm(dim=-1) * motion.fps
    new = P.clone()
    count = 0
    for j in joints:
        planted = (P[:, j, 1] < floor + GROUND * size) & (speed[:, j] < SPEED * size)
        for a, b in contact_segments(planted):
            if b - a < MIN_FRAMES:
                continue
            count += 1
            target = P[a:b, j, [0, 2]].mean(0)
            w = torch.zeros(motion.num_frames, dtype=P.dtype)
            w[a:b] = 1.0
            for k in range(1, BLEND + 1):
                if a - k >= 0:
                    w[a - k] = torch.maximum(w[a - k], torch.tensor(1.0 - k / (BLEND + 1), dtype=P.dtype))
                if b - 1 + k < motion.num_frames:
                    w[b - 1 + k] = torch.maximum(w[b - 1 + k], torch.tensor(1.0 - k / (BLEND + 1), dtype=P.dtype))
            new[:, j, 0] = (1 - w) * new[:, j, 0] + w * target[0]
            new[:, j, 2] = (1 - w) * new[:, j, 2] + w * target[1]
    lt = motion.local_translations.clone()
    inv = quat_inverse(G[:, 0])
    for j in joints:
        lt[:, j] = quat_rotate(inv, new[:, j] - P[:, 0])
    return Motion(
        motion.skeleton, motion.fps, motion.root_translation, motion.local_rotations, motion.foot_contacts, lt
    ), count
