"""How far the shown motion is from each constraint, in words for the constraint list.

Waypoints and paths: ground distance (cm) of the smoothed root at their frames (the pelvis x/z under a
Gaussian of ``DEFAULT_ROOT_SIGMA_SECONDS``, what waypoints target; the pelvis itself sways and, when the
motion speeds up, lags or leads it by up to a few tens of cm); targets: joint position (cm) and rotation (degrees);
poses: mean joint position error (cm); foot contacts: frames whose detected contacts disagree."""

from __future__ import annotations

import numpy as np
import torch

from kinema.constraints.types import resolve_joint
from kinema.geometry.rotations import axis_angle_to_quat, quat_angle_deg
from kinema.motion.core import Motion
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS, smooth_time


def residual(c: dict, motion: Motion) -> str:
    """e.g. ``"3.1 cm"``, ``"2.0 cm, 4 deg"``, ``"2/11 frames differ"``; ``"beyond the motion"`` when a
    keyframe lies past its end."""
    frames = [int(f) for f in c["frame_indices"]]
    if max(frames) >= motion.num_frames:
        return "beyond the motion"
    G, P = motion.to(torch.float64).global_transforms()
    if c["type"] == "root2d":
        pelvis = motion.skeleton.roles.get("pelvis", 0)
        root = smooth_time(P[:, pelvis][:, [0, 2]], DEFAULT_ROOT_SIGMA_SECONDS * motion.fps)
        err = np.linalg.norm(root[frames].numpy() - np.asarray(c["smooth_root_2d"]), axis=1)
        return f"{100 * err.max():.1f} cm"
    if c["type"] == "end-effector":
        j = resolve_joint(motion.skeleton, c["joint"])
        out = []
        if "positions" in c:
            out.append(f"{100 * float((P[frames, j] - torch.tensor(c['positions'])).norm(dim=-1).max()):.1f} cm")
        if "rotations" in c:
            q = axis_angle_to_quat(torch.tensor(c["rotations"], dtype=torch.float64))
            out.append(f"{float(quat_angle_deg(G[frames, j], q).max()):.0f} deg")
        return ", ".join(out)
    if c["type"] == "fullbody":
        rots = torch.tensor(c["local_joints_rot"], dtype=torch.float64)
        pose = Motion(
            motion.skeleton,
            motion.fps,
            torch.tensor(c["root_positions"], dtype=torch.float64),
            axis_angle_to_quat(rots),
        )
        return f"{100 * float((pose.positions - P[frames]).norm(dim=-1).mean()):.1f} cm"
    if motion.foot_contacts is None:
        return ""
    got = motion.foot_contacts[frames].numpy() > 0.5
    want = np.asarray(c["contacts"]) > 0.5
    bad = int((got != want).any(axis=1).sum())
    return f"{bad}/{len(frames)} frames differ"
