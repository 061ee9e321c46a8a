"""World targets for a character's hands and feet, met after retargeting (constraints on the character).

A constraint written for the character (``mixamorig:LeftHand`` at (x, y, z) on frame 30, in the
character's world and units) is met on the retargeted motion by two-bone IK on that limb
(upper arm -> lower arm -> hand, or upper leg -> lower leg -> foot, kinema.retarget.detect): the
correction is exact on the constrained frames and eased in and out over ``blend_seconds``
(kinema.postprocess.ik.spread_corrections), the hand or foot keeps its world rotation, and everything
else is untouched. Elbows bend backward and knees forward where the limb is straight.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import torch

from kinema.errors import KinemaError
from kinema.geometry.rotations import quat_inverse, quat_mul
from kinema.motion.core import Motion
from kinema.postprocess.ik import spread_corrections
from kinema.retarget.align import positions_from_globals, rest_frames
from kinema.retarget.core import moving_joints
from kinema.retarget.detect import HumanoidMap, find_humanoid
from kinema.retarget.legs import segment, two_bone_ik
from kinema.retarget.names import SIDES

#: end slot -> the two slots of its chain
CHAINS = {
    **{f"{s}_hand": (f"{s}_upper_arm", f"{s}_lower_arm") for s in SIDES},
    **{f"{s}_foot": (f"{s}_upper_leg", f"{s}_lower_leg") for s in SIDES},
}


def _chain(h: HumanoidMap, joint: int, name: str) -> tuple[int, int, bool]:
    """(upper, lower, is an arm) of the limb ending at ``joint``; raises for any other joint."""
    slot = next((k for k, j in h.slots.items() if j == joint and k in CHAINS), None)
    if slot is None or not all(k in h.slots for k in CHAINS[slot]):
        raise KinemaError(
            f"target joint {name!r} is no hand or foot of this character; use one of "
            + ", ".join(h.skeleton.names[h.slots[k]] for k in CHAINS if k in h.slots)
        )
    upper, lower = (h.slots[k] for k in CHAINS[slot])
    return upper, lower, slot.endswith("_hand")


def _goal(P: torch.Tensor, joint: int, frames: Mapping[int, Sequence[float]], fps: float, blend: float) -> torch.Tensor:
    T = P.shape[0]
    idx = torch.tensor([int(f) for f in frames], dtype=torch.long)
    if idx.numel() and (int(idx.min()) < 0 or int(idx.max()) >= T):
        raise KinemaError(f"target frames must lie in 0..{T - 1}, got {sorted(int(f) for f in frames)}")
    want = torch.tensor([list(v) for v in frames.values()], dtype=P.dtype).reshape(-1, 3)
    field, _ = spread_corrections(idx, want - P[idx, joint], T, blend * fps)
    return P[:, joint] + field


def _carry_helpers(skel, G: torch.Tensor, before: torch.Tensor, upper: int, lower: int, end: int) -> None:
    """Joints hanging off the turned upper and lower bones (twist bones, elbow helpers; not the end and
    what hangs below it) turn with them, in place."""
    turn = {b: quat_mul(G[:, b], quat_inverse(before[:, b])) for b in (upper, lower)}
    for k in range(skel.num_joints):
        path = skel.path_from_root(k)
        if k in (upper, lower) or upper not in path or end in path:
            continue
        G[:, k] = quat_mul(turn[lower if lower in path else upper], before[:, k])


def meet_targets(
    motion: Motion,
    targets: Mapping[str, Mapping[int, Sequence[float]]],
    *,
    overrides=None,
    blend_seconds: float = 0.15,
) -> Motion:
    """``motion`` (on a humanoid character) with each named hand or foot at its world positions on the
    given frames: ``targets = {joint name: {frame: (x, y, z)}}`` (module docstring)."""
    h = find_humanoid(motion.skeleton, overrides)
    skel = motion.skeleton
    G, P = (x.double() for x in motion.global_transforms())
    G0, P0 = rest_frames(skel)
    placed = {j: P[:, j] for j in [0, *moving_joints(motion)]}
    left = P[:, h.slots["left_upper_leg"]] - P[:, h.slots["right_upper_leg"]]
    forward = torch.linalg.cross(left, P[:, h.slots["chest"]] - P[:, h.slots["hips"]])
    for name, frames in targets.items():
        joint = skel.index(name)
        upper, lower, arm = _chain(h, joint, name)
        goal = _goal(P, joint, frames, motion.fps, blend_seconds)
        before = G.clone()
        end = two_bone_ik(
            G,
            P,
            (upper, lower),
            segment(G0, P0, upper, lower),
            segment(G0, P0, lower, joint),
            goal,
            -forward if arm else forward,
        )
        _carry_helpers(skel, G, before, upper, lower, joint)
        if joint in placed:
            placed[joint] = end
        P = positions_from_globals(skel, G, placed)
    return Motion.from_global(skel, motion.fps, P[:, 0], G, motion.foot_contacts, positions=P).to(motion.dtype)
