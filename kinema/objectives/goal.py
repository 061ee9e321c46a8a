"""Goal-driven synthesis (SFControl Sec. 3.1.1): start from a given pose, end with a joint on a goal.

The start pose is a full-body keyframe on frame 0 (the last frame of a previous motion, or a BVH frame
through a constraints file's ``"bvh"`` form); the goal is a ``reach`` objective whose window is the
last ``hold`` seconds, so *when* the joint arrives inside that window, and how the body gets there, is
left to the model (noise optimisation picks it, kinema.objectives.snap imposes it). Both come out in
their JSON form, so they can be written into a constraints file or passed to ``generate`` directly::

    prev = model.generate("A person walks forward.", seconds=3)[0]
    res = model.generate("A person reaches forward.", seconds=3,
                         constraints=[start_pose(prev)], objectives=[goal_reach("Hand_R", (0.3, 1.2, 4.0),
                                                                                seconds=3, fps=model.fps)])
"""

from __future__ import annotations

from kinema.errors import KinemaError
from kinema.geometry.rotations import quat_to_axis_angle
from kinema.motion.core import Motion


def start_pose(motion: Motion, frame: int = -1, *, recenter: bool = False) -> dict:
    """A ``fullbody`` constraint (JSON dict) putting frame ``frame`` of ``motion`` (on the model's skeleton)
    on frame 0 of the next motion, where it stands in the world (``recenter``: above the origin)."""
    T = motion.num_frames
    if not -T <= frame < T:
        raise KinemaError(f"start frame {frame} is outside the motion's {T} frames")
    root = motion.root_translation[frame].double().clone()
    if recenter:
        root[0], root[2] = 0.0, 0.0
    rots = quat_to_axis_angle(motion.local_rotations[frame].double())
    return {
        "type": "fullbody",
        "frame_indices": [0],
        "local_joints_rot": [rots.tolist()],
        "root_positions": [root.tolist()],
    }


def goal_reach(joint: str, target, *, seconds: float, fps: float, hold: float = 0.5, weight: float = 1.0) -> dict:
    """A ``reach`` objective (JSON dict): ``joint`` on ``target`` (x, y, z metres) during the last ``hold``
    seconds of a ``seconds``-long motion at ``fps``."""
    last = (round(seconds * fps) - 1) / fps
    if not 0 < hold <= last:
        raise KinemaError(f"hold must be in (0, {last:g}] s for a {seconds:g}-s motion, got {hold!r}")
    return {
        "type": "reach",
        "joint": joint,
        "target": [float(v) for v in target],
        "window": [last - hold, last],
        "weight": weight,
    }
