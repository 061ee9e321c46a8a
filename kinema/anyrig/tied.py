"""Tied joints in generated motion: the leg chain follows a rig's IK foot bone, so the mesh never tears.

The model generates every joint of a rig, but on game rigs some joints are not free: an IK foot bone
that hangs from the armature (``IKFrontLeg.L``, ``BackFoot.L``, ``Foot.L``) is where the engine's IK
puts the leg chain's end, pole targets follow the knee, static helpers never move (kinema.rig.ties
finds these *ties* from the rig's own clips). Generated independently, the foot drifts off its leg and
the skin between them stretches. `hold_ties` decides it after generation and foot locking, per tie:

- **chain solved to reach the foot** (a tie with an ``offset``, i.e. found from clips with rotations,
  whose anchor hangs from a two-joint chain off the root path): the anchor (the lower leg) and its
  parent (the upper leg) are turned by the analytic two-bone IK of kinema.postprocess.ik so that the
  point the rig's own clips keep the foot at in the anchor's frame (``offset``: the shin's end) lies on
  the foot, on every frame, keeping the knee's bend plane. The foot itself (planted and locked by
  kinema.anyrig.feet) does not move;
- **foot derived from the chain** where the chain cannot reach (the foot further than the upper and
  lower leg together, or closer than their difference) and for ties without a usable chain: the foot
  bone is moved, as little as needed, to within ``max_distance`` of its anchor (the largest distance
  the rig's own clips show), so the gap never exceeds what the rig itself does;
- **fixed** helpers keep their rest offset from their parent.

Where the ties come from (`ties_for`): the rig's own clips when the rig is a file with animations (a
GLB/glTF's clips, a BVH's motion), the ties stored with a training rig (``rig_ties`` of the checkpoint,
found from its training clips), else the rest pose (kinema.rig.ties.rest_ties).

Pole targets and other tied helpers are moved the same way (never left free). Only local rotations of
the two chain joints and the local translations of tied/fixed joints change. Lengths are in the
motion's units (the ties must be in the same units). ``report``: ``ties_solved`` (chains turned),
``ties_clamped_frames`` (frames where a foot had to be moved to its chain), ``tie_gap_ratio_max`` (the
largest joint -> anchor distance over ``max_distance`` after the pass; at most 1 up to rounding).
"""

from __future__ import annotations

from pathlib import Path

import torch

from kinema.anyrig.rig_file import read_rig_file
from kinema.geometry.rotations import quat_inverse, quat_rotate
from kinema.kinematics import forward_kinematics
from kinema.motion.core import Motion
from kinema.postprocess.ik import two_bone_ik
from kinema.rig import Rig
from kinema.rig.ties import RigTies, Tie, find_ties, rest_ties, tie_ratios
from kinema.skeleton import Skeleton

#: relative slack kept below a tie's largest distance when a foot is pulled to its chain
SLACK = 1e-4


def _solvable(skeleton: Skeleton, root: int, tie: Tie) -> bool:
    """Whether the anchor hangs from a parent that is off the path to the root (so turning it does not
    turn the body) and the tie knows where the foot sits in the anchor's frame."""
    parent = skeleton.parents[tie.anchor]
    return (
        tie.offset is not None
        and parent >= 0
        and parent not in skeleton.path_from_root(root)
        and float(torch.tensor(tie.offset).norm()) > 1e-9
    )


def _with_tail(skeleton: Skeleton, tie: Tie) -> Skeleton:
    """``skeleton`` plus one leaf under the anchor at the tie's offset (the point the foot sits on)."""
    offsets = torch.cat([skeleton.offsets, torch.tensor([tie.offset], dtype=skeleton.offsets.dtype)])
    return Skeleton([*skeleton.names, "__tie_end__"], [*skeleton.parents, tie.anchor], offsets)


def _solve_chain(motion: Motion, tie: Tie) -> Motion:
    """``motion`` with the anchor and its parent turned so the tie's end lies on the tied joint."""
    skel = motion.skeleton
    L = motion.local_rotations.to(torch.float64)
    T = L.shape[0]
    _, P = motion.global_transforms()
    P = P.to(torch.float64)
    aug = _with_tail(skel, tie)
    ident = torch.zeros(T, 1, 4, dtype=torch.float64)
    ident[..., 0] = 1.0
    L_aug = torch.cat([L, ident], dim=1)
    root = motion.root_translation.to(torch.float64)
    _, P_fk = forward_kinematics(L_aug, root, aug.offsets.to(torch.float64), aug.parents)
    a = skel.parents[tie.anchor]
    shift = P[:, a] - P_fk[:, a]  # bone translations above the chain (the armature's children) move it
    target = P[:, tie.joint] - shift
    new = two_bone_ik(L_aug, root, aug, (a, tie.anchor, skel.num_joints), target, keep_end_rotation=False)
    rots = motion.local_rotations.clone()
    rots[:, [a, tie.anchor]] = new[:, [a, tie.anchor]].to(rots.dtype)
    return Motion(skel, motion.fps, motion.root_translation, rots, motion.foot_contacts, motion.local_translations)


def _end_point(motion: Motion, tie: Tie) -> torch.Tensor:
    """``(T, 3)`` where the tie's end is: the anchor's position plus its rotation applied to ``offset``."""
    G, P = motion.global_transforms()
    off = torch.tensor(tie.offset, dtype=P.dtype).expand(P.shape[0], 3)
    return P[:, tie.anchor] + quat_rotate(G[:, tie.anchor], off)


def _place(motion: Motion, joint: int, world: torch.Tensor, frames: torch.Tensor) -> Motion:
    """``motion`` with ``joint`` moved (by its local translation) to ``world (T, 3)`` on ``frames``."""
    if not bool(frames.any()):
        return motion
    G, P = motion.global_transforms()
    p = motion.skeleton.parents[joint]
    lt = motion.translations_or_offsets().clone()
    local = quat_rotate(quat_inverse(G[:, p]), world.to(P.dtype) - P[:, p]) if p >= 0 else world.to(P.dtype)
    lt[frames, joint] = local[frames].to(lt.dtype)
    return Motion(
        motion.skeleton, motion.fps, motion.root_translation, motion.local_rotations, motion.foot_contacts, lt
    )


def _clamp(motion: Motion, tie: Tie, end: torch.Tensor | None) -> tuple[Motion, int]:
    """The tied joint pulled to ``end (T, 3)`` where it is off it (a chain that could not reach), or, with
    no end, to within ``max_distance`` of the anchor; returns the motion and the frames moved."""
    _, P = motion.global_transforms()
    pj, pa = P[:, tie.joint], P[:, tie.anchor]
    if end is not None:
        off = (pj - end).norm(dim=-1) > SLACK * max(tie.max_distance, 1e-9) + 1e-9
        world = end
    else:
        d = (pj - pa).norm(dim=-1)
        bound = tie.max_distance * (1 - SLACK)
        off = d > tie.max_distance
        world = pa + (pj - pa) * (bound / d.clamp_min(1e-12))[:, None]
    return _place(motion, tie.joint, world, off), int(off.sum())


def hold_ties(motion: Motion, ties: RigTies, root: int) -> tuple[Motion, dict]:
    """``motion`` with its tied joints held by their chains and fixed helpers at rest (see the module);
    ``root`` is the rig's root joint. Returns the motion and the report."""
    report = {"ties_solved": 0, "ties_clamped_frames": 0, "tie_gap_ratio_max": 0.0}
    if not ties.ties and not ties.fixed:
        return motion, report
    skel = motion.skeleton
    m = motion
    if ties.fixed:
        lt = m.translations_or_offsets().clone()
        lt[:, list(ties.fixed)] = skel.offsets[list(ties.fixed)].to(lt.dtype)
        m = Motion(skel, m.fps, m.root_translation, m.local_rotations, m.foot_contacts, lt)
    for tie in ties.ties:
        end = None
        if _solvable(skel, root, tie):
            m = _solve_chain(m, tie)
            report["ties_solved"] += 1
            end = _end_point(m, tie)
        m, n = _clamp(m, tie, end)
        report["ties_clamped_frames"] += n
    if ties.ties:
        report["tie_gap_ratio_max"] = round(float(tie_ratios(m.positions.to(torch.float64), ties.ties).max()), 4)
    return m, report


def ties_for(rig: Rig, clips: list[Motion] | None, stored: dict | None) -> RigTies:
    """The ties of ``rig`` (its units): from ``clips`` (its own animations, on its skeleton) when there
    are any, else ``stored`` (`RigTies.to_dict` of a training rig, by joint name), else its rest pose."""
    names = rig.skeleton.names
    if clips:
        return find_ties(rig.skeleton, rig.root, [m.global_transforms()[::-1] for m in clips])
    if stored is not None:
        try:
            return RigTies.from_dict(stored, names)
        except (KeyError, TypeError, ValueError):
            pass  # stored for another skeleton: fall back to the rest pose
    return rest_ties(rig.skeleton, rig.root)


def rig_clips(rig, fps: float) -> list[Motion] | None:
    """The animations of a rig given as a GLB/glTF, FBX or BVH file (at ``fps``; read once per file version),
    None for any other rig (a skeleton, a rig object, a training rig id)."""
    if not isinstance(rig, str | Path) or not Path(rig).is_file():
        return None
    p = Path(rig)
    return list(read_rig_file(p, fps).clips)
