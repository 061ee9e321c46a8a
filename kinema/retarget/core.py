"""`retarget`: a motion on one skeleton -> the same motion on another rig (its names, offsets, units,
rest pose and skin).

Steps (each in its own module):

1. map joints (kinema.retarget.mapping): humanoid slots, same names, or an explicit table;
2. world rotations (kinema.retarget.align): every mapped bone points where the source's points,
   unmapped joints keep their rest rotation relative to their parent;
3. placement and scale (kinema.retarget.proportions): the hips at the source's displacement scaled by
   leg length;
4. legs (kinema.retarget.legs): each ankle to the scaled source ankle, held where the source's
   contacts are planted, by two-bone IK; a foot hanging off the leg (an IK foot bone under the root)
   is put at the leg chain's end, and IK helpers that stand for the foot follow it;
5. floor: the lowest joint where the target's rest pose puts it; a static root above the hips carries
   the root motion across the floor;
6. `Motion.from_global` on the target skeleton: bone translations come out as
   ``local_translations`` wherever a joint was placed rather than hung from its parent.

The source's contacts are ``motion.foot_contacts`` when they match its rig's contact joints, else
estimated from its joint heights and speeds (kinema.motion.contacts, metres); the result carries
contacts for the target rig's contact joints.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

from kinema.geometry.rotations import quat_inverse, quat_mul, quat_rotate
from kinema.motion.contacts import foot_contacts
from kinema.motion.core import Motion
from kinema.retarget import legs as leg_ik
from kinema.retarget.align import (
    bone_alignment,
    fill_chain,
    least_twist_globals,
    positions_from_globals,
    rest_frames,
    transfer_rotations,
)
from kinema.retarget.mapping import JointMap, build_joint_map
from kinema.retarget.proportions import (
    body_scale,
    floor_shift,
    foot_pitch_turns,
    ground_root,
    lowest_rest_height,
    placed_positions,
    planted_floor_shift,
    rest_on_floor,
    source_foot_height,
    target_body,
)
from kinema.rig import Rig
from kinema.skeleton import Skeleton

#: a bone translation that moves less than this fraction of the skeleton's summed bone length is static
MOVING = 1e-4


def source_planted(motion: Motion) -> dict[int, torch.Tensor]:
    """{source contact joint: (T,) bool planted} from the motion's contacts or its joint motion."""
    rig = Rig.from_skeleton(motion.skeleton)
    joints = list(rig.contacts)
    if not joints:
        return {}
    c = motion.foot_contacts
    if c is None or c.shape[1] != len(joints):
        c = foot_contacts(motion.positions.double(), motion.fps, motion.skeleton, joints=joints)
    return {j: c[:, k] > 0.5 for k, j in enumerate(joints)}


def moving_joints(motion: Motion) -> list[int]:
    """Joints whose bone translation the motion animates by more than ``MOVING`` of the skeleton's
    size (float noise of a file read back, 1e-6 to 1e-5 m from FBX, is no animation)."""
    if motion.local_translations is None:
        return []
    off = motion.skeleton.offsets.to(motion.local_translations)
    size = float(motion.skeleton.offsets.norm(dim=-1).sum())
    moved = (motion.local_translations - off).abs().amax(dim=(0, 2)) > MOVING * size
    return [j for j in range(1, motion.num_joints) if bool(moved[j])]


def body_forward(G: torch.Tensor, jm: JointMap) -> torch.Tensor:
    """(T, 3) the target hips' forward (the source hips' forward turned like the hips)."""
    t, _ = jm.hips if jm.hips is not None else (0, 0)
    G0t, _ = rest_frames(jm.target)
    rest_fwd = torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64)
    local = quat_rotate(quat_inverse(G0t[t]), rest_fwd)
    return quat_rotate(G[:, t], local.expand(G.shape[0], 3))


def _leg_goals(G, P, jm: JointMap, Ps, planted, s: float, fps: float) -> list[torch.Tensor]:
    """Per leg, the (T, 3) ankle goal with the source's planted contacts held (kinema.retarget.legs)."""
    G0t, P0t = rest_frames(jm.target)
    _, P0s = rest_frames(jm.source)
    hips_t, hips_s = jm.hips
    low_t = lowest_rest_height(jm.target, target_body(jm))
    on_floor = rest_on_floor(jm)  # else the rest pose gives no foot height: the source's, scaled
    base = float(P0t[hips_t, 1]) - s * float(P0s[hips_s, 1])  # target y = base + s * source y at the hips
    goals = []
    for leg in jm.legs:
        goal = P[:, leg.upper] + s * (Ps[:, leg.source_foot] - Ps[:, leg.source_upper])
        heel = planted.get(leg.source_foot, torch.zeros(goal.shape[0], dtype=torch.bool))
        lift = (float(P0t[leg.foot, 1]) - low_t) - s * source_foot_height(jm, leg, Ps, heel) if on_floor else 0.0
        goal[:, 1] = base + s * Ps[:, leg.source_foot, 1] + lift
        toe_off = None
        if leg.toes is not None:
            toe_off = quat_rotate(G[:, leg.foot], leg_ik.segment(G0t, P0t, leg.foot, leg.toes).expand_as(goal))
        toe = planted.get(leg.source_toes) if leg.source_toes is not None else None
        goals.append(leg_ik.planted_goals(goal, heel, toe, toe_off, fps))
    return goals


def _solve_legs(G, P, placed, jm: JointMap, Ps, planted, s: float, fps: float) -> torch.Tensor:
    """Legs to their (held) goals, the hips lowered where a planted leg cannot reach; detached feet and
    followers placed (``G`` and ``placed`` are changed in place). Returns the new positions."""
    G0t, P0t = rest_frames(jm.target)
    segs = [(leg_ik.segment(G0t, P0t, g.upper, g.lower), leg_ik.segment(G0t, P0t, g.lower, g.foot)) for g in jm.legs]
    goals = _leg_goals(G, P, jm, Ps, planted, s, fps)
    on = [planted.get(g.source_foot, torch.zeros(P.shape[0], dtype=torch.bool)) for g in jm.legs]
    drop = leg_ik.reach_drop(P, jm.legs, segs, goals, on, fps)
    if drop is not None:
        placed[jm.hips[0]] = placed[jm.hips[0]] - drop[:, None] * torch.tensor([0.0, 1.0, 0.0], dtype=P.dtype)
        P = positions_from_globals(jm.target, G, placed)
        goals = _leg_goals(G, P, jm, Ps, planted, s, fps)
    fwd = body_forward(G, jm)
    for leg, (seg1, seg2), goal in zip(jm.legs, segs, goals, strict=True):
        end = leg_ik.two_bone_ik(G, P, (leg.upper, leg.lower), seg1, seg2, goal, fwd)
        if leg.detached:
            placed[leg.foot] = end
        for f in jm.followers.get(leg.foot, ()):
            rel = quat_mul(quat_inverse(G0t[leg.foot]), G0t[f])
            G[:, f] = quat_mul(G[:, leg.foot], rel.expand(G.shape[0], 4))
            placed[f] = end + quat_rotate(G[:, leg.foot], leg_ik.segment(G0t, P0t, leg.foot, f).expand_as(end))
    return P


def _target_contacts(jm: JointMap, planted: dict[int, torch.Tensor], T: int) -> torch.Tensor | None:
    rig = Rig.from_skeleton(jm.target)
    if not rig.contacts:
        return None
    cols = []
    for j in rig.contacts:
        a = jm.pairs.get(j)
        cols.append(planted[a].double() if a in planted else torch.zeros(T, dtype=torch.float64))
    return torch.stack(cols, dim=1)


def retarget_with_map(motion: Motion, jm: JointMap) -> Motion:
    """:func:`retarget` with a ready joint map (kinema.retarget.mapping.build_joint_map)."""
    Gs, Ps = (x.double() for x in motion.global_transforms())
    if jm.frames is not None:  # humanoids: no twist a skin would show that the joints do not
        Gs = least_twist_globals(Gs, jm.source)
    s = body_scale(jm)
    R = bone_alignment(jm.target, jm.source, dict(jm.pairs), dict(jm.chain_parent), jm.frames, dict(jm.primary))
    planted = source_planted(motion)
    for j, turn in foot_pitch_turns(jm, Gs, R, planted).items():
        R[j] = quat_mul(R[j], turn)
    G = transfer_rotations(Gs, jm.target, jm.source, dict(jm.pairs), R)
    placed = placed_positions(jm, Ps, moving_joints(motion), s)
    P = positions_from_globals(jm.target, G, placed)
    if jm.legs:
        _solve_legs(G, P, placed, jm, Ps, planted, s, motion.fps)
        fixed = set(jm.pairs) | {f for fs in jm.followers.values() for f in fs}
        fill_chain(G, jm.target, fixed)
        P = positions_from_globals(jm.target, G, placed)
    lift = planted_floor_shift(jm, P, Ps, planted) if jm.legs else None
    lift = floor_shift(jm, P) if lift is None else lift
    placed = {j: p + torch.tensor([0.0, lift, 0.0], dtype=p.dtype) for j, p in placed.items()}
    placed.update(ground_root(jm, placed))
    P = positions_from_globals(jm.target, G, placed)
    contacts = _target_contacts(jm, planted, motion.num_frames)
    out = Motion.from_global(jm.target, motion.fps, P[:, 0], G, contacts, positions=P)
    return out.to(motion.dtype)


def retarget(
    motion: Motion,
    target: Skeleton | Rig,
    mapping: Mapping[str, str] | None = None,
    *,
    overrides=None,
    source_overrides=None,
) -> Motion:
    """``motion`` on ``target`` (a Skeleton, or a Rig whose skeleton is used): the target's joint names,
    offsets, units, rest pose and skin (``Skeleton.mesh``, carried when the target came from a GLB or
    FBX). ``mapping``: {target joint: source joint} names that replace the found correspondence;
    ``overrides`` / ``source_overrides``: rig overrides JSON (path or mapping) for odd joint names
    (kinema.retarget.detect). Raises `KinemaError` when the rigs share nothing to map."""
    skeleton = target.skeleton if isinstance(target, Rig) else target
    jm = build_joint_map(motion.skeleton, skeleton, mapping, overrides, source_overrides)
    return retarget_with_map(motion, jm)
