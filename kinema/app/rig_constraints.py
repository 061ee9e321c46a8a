"""The app's constraints (JSON-form dicts, world frame, docs/constraints.md) as the any-rig model's:
the translation lives in kinema.anyrig.world (shared with ``kinema generate --constraints``)
and is re-exported here; `waypoint_residual` says how far the root is from a waypoint.
Units: metres, Y up; frames at the model's fps.
"""

from __future__ import annotations

import torch

from kinema.anyrig.world import planned_root, to_anyrig
from kinema.motion.core import Motion
from kinema.rig import Rig

__all__ = ["planned_root", "to_anyrig", "waypoint_residual"]


def waypoint_residual(c: dict, motion: Motion) -> str:
    """A waypoint's / path's largest ground distance (cm) of the rig's root at its frames: the joint the
    any-rig model's root path moves (unsmoothed, unlike the human model's waypoints)."""
    frames = [int(f) for f in c["frame_indices"]]
    if max(frames) >= motion.num_frames:
        return "beyond the motion"
    root = Rig.from_skeleton(motion.skeleton).root
    xz = motion.to(torch.float64).positions[frames, root][:, [0, 2]]
    err = (xz - torch.tensor(c["smooth_root_2d"], dtype=torch.float64)).norm(dim=-1).max()
    return f"{100 * float(err):.1f} cm"
