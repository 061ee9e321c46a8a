"""World-frame targets of the character-frame constraints (kinema.constraints.character) on a generated
any-rig motion, for the exact pass of post-processing (kinema.postprocess)."""

from __future__ import annotations

from collections.abc import Sequence

import torch

from kinema.constraints.character import Constraint, JointTarget, Keyframe, RootMotion
from kinema.geometry.rotations import quat_mul, quat_rotate
from kinema.motion.core import Motion
from kinema.postprocess.targets import PostTargets
from kinema.representation.joint import JointRepresentation, yaw_quat


def post_targets(
    constraints: Sequence[Constraint],
    motion: Motion,
    rep: JointRepresentation,
    scale: float = 1.0,
    translated: Sequence[int] = (),
) -> PostTargets:
    """World-frame targets of the joint and keyframe constraints (given in metres) on a generated
    ``motion`` in units of ``scale`` per metre on the same skeleton: the character frame is placed at
    the motion's own root and heading, except that a joint target on a frame a `RootMotion` covers is
    read in that copied motion's frame (its root and heading: world targets read in a first pass's
    frame stay where they were, kinema.anyrig.world). A keyframe's pose keeps its bone translations only on the
    ``translated`` joints (those generation moves by translation); elsewhere its bones have their rest
    lengths, as the generated motion has: the pose the rig can take, not one it cannot."""
    G, P = motion.global_transforms()
    psi = rep.heading(G)
    root = rep.rig.root
    copied = [c for c in constraints if isinstance(c, RootMotion)]
    frame_root, frame_psi = P[:, root].clone(), psi.clone()
    for c in copied:  # later ones win, as in encoding
        Gc, Pc = c.motion.to(P.dtype).global_transforms()
        n = min(c.until, motion.num_frames, c.motion.num_frames)
        frame_root[:n], frame_psi[:n] = Pc[:n, root] * scale, rep.heading(Gc)[:n]
    positions: dict[int, tuple[list[int], list[torch.Tensor]]] = {}
    rotations: dict[int, tuple[list[int], list[torch.Tensor]]] = {}

    def add(into: dict, j: int, f: int, value: torch.Tensor) -> None:
        into.setdefault(j, ([], []))[0].append(f)
        into[j][1].append(value)

    for c in constraints:
        if isinstance(c, JointTarget):
            j, turn = rep.joint_index(c.joint), yaw_quat(frame_psi[c.frame])
            if c.position is not None:
                local = torch.as_tensor(c.position, dtype=torch.float64) * scale
                add(positions, j, c.frame, frame_root[c.frame] + quat_rotate(turn, local))
            if c.rotation is not None:
                add(rotations, j, c.frame, quat_mul(turn, c.unit_rotation()))
        elif isinstance(c, Keyframe):  # the pose, turned to the generated heading and put at the generated root
            pose = _rest_lengths(c.pose.to(torch.float64), translated)
            Gp, Pp = pose.global_transforms()
            turn = quat_mul(yaw_quat(psi[c.frame]), yaw_quat(-rep.heading(Gp)[c.pose_frame]))
            for j in range(motion.num_joints):
                add(rotations, j, c.frame, quat_mul(turn, Gp[c.pose_frame, j]))
                if j == 0 and translated:  # a floor-level armature: generation keeps it on the floor
                    continue
                local = quat_rotate(turn, Pp[c.pose_frame, j] - Pp[c.pose_frame, root]) * scale
                add(positions, j, c.frame, P[c.frame, root] + local)  # the root itself stays where it was

    def pack(d: dict) -> dict:
        return {j: (torch.tensor(fs), torch.stack(vs)) for j, (fs, vs) in d.items()}

    return PostTargets(joint_positions=pack(positions), joint_rotations=pack(rotations))


def _rest_lengths(pose: Motion, keep: Sequence[int]) -> Motion:
    """``pose`` with the rest offsets as bone translations, except on the joints ``keep``."""
    if pose.local_translations is None:
        return pose
    lt = pose.skeleton.offsets.to(pose.local_translations)[None].repeat(pose.num_frames, 1, 1)
    lt[:, list(keep)] = pose.local_translations[:, list(keep)]
    return Motion(pose.skeleton, pose.fps, pose.root_translation, pose.local_rotations, pose.foot_contacts, lt)
