"""Rest-pose alignment: each mapped bone of the target points, in the world, where the source's points.

With ``G0`` the world rest rotations and ``P0`` the world rest positions of a skeleton (its rest
rotations, else identity), a source joint ``a`` animated to ``G_s(t)`` has turned by the world rotation
``Q(t) = G_s(t) G0_s^-1`` since its rest pose. Its target joint ``b`` gets

    ``G_t(t) = Q(t) R_b G0_t``

where ``R_b`` is the constant world rotation taking the target's rest bone directions (from ``b`` to
its mapped children) onto the source's: the shortest arc for the primary child (the only one, or the
spine above the hips, the neck above the chest), then a turn about that bone that lines up the other
children and, for humanoids, the body's forward and left directions at rest (the roll: a knee keeps
facing forward even when the source's rest pose lies along +X, as Bandai's does). So a T-pose source
drives an A-pose target, and bones whose local axes differ (Bandai's lie along +X, Mixamo's along +Y)
do not matter: only world directions are compared. A mapped joint without mapped children (a hand, a
foot without toes) borrows the ``R`` of its chain parent (kinema.retarget.mapping). Unmapped joints
keep their rest rotation relative to their parent (twist bones, fingers, extra spine joints: they
follow their chain).

Shapes: rotations ``(..., J, 4)`` wxyz, positions ``(..., J, 3)``, float64.
"""

from __future__ import annotations

import torch

from kinema.geometry.rotations import (
    quat_between,
    quat_inverse,
    quat_mul,
    quat_normalize,
    quat_rotate,
)
from kinema.kinematics import forward_kinematics
from kinema.skeleton import Skeleton

#: bones shorter than this fraction of the skeleton's rest height give no direction
SHORT_BONE = 1e-4


def short_length(P0: torch.Tensor) -> float:
    """Length under which a bone of a skeleton whose rest positions are ``P0 (J, 3)`` gives no direction:
    ``SHORT_BONE`` of its rest height."""
    return SHORT_BONE * float(max(P0[:, 1].max() - P0[:, 1].min(), 1e-9))


def rest_locals(skeleton: Skeleton) -> torch.Tensor:
    """(J, 4) local rest rotations: the skeleton's, else identity."""
    if skeleton.rest_rotations is not None:
        return skeleton.rest_rotations.double()
    out = torch.zeros(skeleton.num_joints, 4, dtype=torch.float64)
    out[:, 0] = 1.0
    return out


def rest_frames(skeleton: Skeleton) -> tuple[torch.Tensor, torch.Tensor]:
    """(world rest rotations (J, 4), world rest positions (J, 3)), the root at ``offsets[0]``."""
    G, P = forward_kinematics(rest_locals(skeleton), skeleton.offsets[0].double(), skeleton.offsets, skeleton.parents)
    return G, P


def _roll(R1: torch.Tensor, axis: torch.Tensor, sec_t: torch.Tensor, sec_s: torch.Tensor) -> torch.Tensor:
    """``R1`` followed by the turn about ``axis`` (unit, 3) that best lines up the secondary directions
    ``sec_t`` (after ``R1``) with ``sec_s`` (both (K, 3)) seen across the axis."""
    a = quat_rotate(R1.expand(sec_t.shape[0], 4), sec_t)
    a = a - (a @ axis)[:, None] * axis
    b = sec_s - (sec_s @ axis)[:, None] * axis
    sin = (torch.linalg.cross(a, b) @ axis).sum()
    cos = (a * b).sum()
    if float(sin.abs() + cos.abs()) < 1e-9:
        return R1
    half = torch.atan2(sin, cos) / 2
    turn = torch.cat([half.cos().reshape(1), half.sin() * axis])
    return quat_mul(turn, R1)


def _align_one(vt: torch.Tensor, vs: torch.Tensor, frames) -> torch.Tensor:
    """Rotation taking the target's child directions ``vt (C, 3)`` onto the source's ``vs``: the exact
    shortest arc for the first (primary) child, then the turn about it that best lines up the other
    children and the body frames (when given)."""
    ut, us = vt / vt.norm(dim=-1, keepdim=True), vs / vs.norm(dim=-1, keepdim=True)
    R1 = quat_between(ut[0], us[0])
    sec_t, sec_s = ut[1:], us[1:]
    if frames is not None:
        sec_t, sec_s = torch.cat([sec_t, frames[0]]), torch.cat([sec_s, frames[1]])
    return _roll(R1, us[0], sec_t, sec_s) if sec_t.shape[0] else R1


def bone_alignment(
    target: Skeleton,
    source: Skeleton,
    pairs: dict[int, int],
    chain_parent: dict[int, int],
    frames: tuple[torch.Tensor, torch.Tensor] | None = None,
    primary: dict[int, int] | None = None,
) -> torch.Tensor:
    """(J_t, 4) world rotations ``R_b`` of every mapped target joint (identity elsewhere).

    ``pairs``: target joint -> source joint; ``chain_parent``: target joint -> the mapped target joint
    whose ``R`` it borrows when it has no mapped child; ``frames``: the body's (forward, left) unit
    directions at rest, ``(2, 3)`` for the target and for the source, which fix each bone's roll
    about itself (humanoids); ``primary``: target joint -> the mapped child whose direction is met
    exactly (the spine above the hips, the neck above the chest), default the child with the most
    mapped joints below it. The other children only set the roll."""
    _, P0t = rest_frames(target)
    _, P0s = rest_frames(source)
    tiny, tiny_s = short_length(P0t), short_length(P0s)
    kids: dict[int, list[int]] = {b: [] for b in pairs}
    for c in pairs:
        p = target.parents[c]
        while p >= 0 and p not in pairs:
            p = target.parents[p]
        if p >= 0:
            kids[p].append(c)
    below = {b: sum(1 for c in pairs if b in target.path_from_root(c)) for b in pairs}
    for b, cs in kids.items():
        first = (primary or {}).get(b)
        cs.sort(key=lambda c: (c != first, -below[c], c))
    R = torch.zeros(target.num_joints, 4, dtype=torch.float64)
    R[:, 0] = 1.0
    for b in sorted(pairs):  # parents before children
        a = pairs[b]
        vt = torch.stack([P0t[c] - P0t[b] for c in kids[b]]) if kids[b] else torch.zeros(0, 3, dtype=torch.float64)
        vs = (
            torch.stack([P0s[pairs[c]] - P0s[a] for c in kids[b]])
            if kids[b]
            else torch.zeros(0, 3, dtype=torch.float64)
        )
        ok = (vt.norm(dim=-1) > tiny) & (vs.norm(dim=-1) > tiny_s)
        if ok.any():
            R[b] = _align_one(vt[ok], vs[ok], frames)
        elif b in chain_parent:
            R[b] = R[chain_parent[b]]
    return quat_normalize(R)


def transfer_rotations(
    source_globals: torch.Tensor,
    target: Skeleton,
    source: Skeleton,
    pairs: dict[int, int],
    R: torch.Tensor,
) -> torch.Tensor:
    """(T, J_t, 4) target world rotations from the source's ``(T, J_s, 4)`` (module docstring)."""
    G0s, _ = rest_frames(source)
    G0t, _ = rest_frames(target)
    Gs = source_globals.double()
    T = Gs.shape[0]
    out = torch.empty(T, target.num_joints, 4, dtype=torch.float64)
    for b, a in pairs.items():
        Q = quat_mul(Gs[:, a], quat_inverse(G0s[a]).expand(T, 4))
        out[:, b] = quat_mul(Q, quat_mul(R[b], G0t[b]).expand(T, 4))
    fill_chain(out, target, set(pairs))
    return quat_normalize(out)


def least_twist_globals(source_globals: torch.Tensor, source: Skeleton) -> torch.Tensor:
    """(T, J, 4) world rotations like ``source_globals`` with the twist of every single-child bone (about
    itself) rebuilt as the least turn from its parent: joint positions do not change.

    A bone with one child shows its direction in the joint positions but not its twist, and a model's
    output need not agree with itself there: the default human model's spine and shoulders come out
    turned 90-180 degrees about themselves against the captures (its training clips include mirrored
    ones, and a mirror turns such a twist the other way). A skinned character driven by those twists
    wrings its torso. Here such a bone takes its parent's turn since rest, then the shortest arc onto its
    own direction. A joint with several children (hips, chest) keeps its rotation, which its children's
    positions fix; a joint with none (head, hand) keeps its rotation relative to its parent, so a hand
    turns with its rebuilt forearm and keeps the wrist's own bend and turn."""
    G0, P0 = rest_frames(source)
    Gs = source_globals.double()
    T = Gs.shape[0]
    tiny = short_length(P0)
    kids: dict[int, list[int]] = {j: [] for j in range(source.num_joints)}
    for c, p in enumerate(source.parents):
        if p >= 0 and float((P0[c] - P0[p]).norm()) > tiny:
            kids[p].append(c)
    given = quat_mul(Gs, quat_inverse(G0).expand(T, -1, 4))  # each joint's turn since rest
    Q = given.clone()
    for j, p in enumerate(source.parents):  # parents before children
        if p < 0 or len(kids[j]) > 1:
            continue
        if not kids[j]:  # the parent's change, so the rotation relative to it stays
            Q[:, j] = quat_mul(quat_mul(Q[:, p], quat_inverse(given[:, p])), given[:, j])
            continue
        d0 = (P0[kids[j][0]] - P0[j]).expand(T, 3)
        carried = quat_rotate(Q[:, p], d0)
        Q[:, j] = quat_mul(quat_between(carried, quat_rotate(given[:, j], d0)), Q[:, p])
    return quat_normalize(quat_mul(Q, G0.expand(T, -1, 4)))


def fill_chain(G: torch.Tensor, target: Skeleton, fixed: set[int]) -> None:
    """In place: every joint not in ``fixed`` gets its parent's world rotation times its rest local
    rotation (a root not in ``fixed`` keeps its rest rotation)."""
    G0t, _ = rest_frames(target)
    L0 = rest_locals(target)
    T = G.shape[0]
    for b, p in enumerate(target.parents):
        if b in fixed:
            continue
        G[:, b] = G0t[b] if p < 0 else quat_mul(G[:, p], L0[b].expand(T, 4))


def positions_from_globals(target: Skeleton, G: torch.Tensor, placed: dict[int, torch.Tensor]) -> torch.Tensor:
    """(T, J, 3) positions: ``placed`` joints at their given (T, 3) world positions, every other joint
    at its parent plus its offset turned by the parent's world rotation ``G (T, J, 4)``; an unplaced
    root stays at its rest position."""
    T = G.shape[0]
    off = target.offsets.double()
    P = torch.empty(T, target.num_joints, 3, dtype=torch.float64)
    for j, p in enumerate(target.parents):
        if j in placed:
            P[:, j] = placed[j]
        elif p < 0:
            P[:, j] = off[j]
        else:
            P[:, j] = P[:, p] + quat_rotate(G[:, p], off[j].expand(T, 3))
    return P


def body_frame(skeleton: Skeleton, hips: int, chest: int, left_leg: int, right_leg: int) -> torch.Tensor:
    """(2, 3) unit (forward, left) directions of a humanoid's rest pose: left from the right to the
    left upper leg, up from the hips to the chest, forward = left x up (kinema: +Z when left is +X)."""
    _, P0 = rest_frames(skeleton)
    up = P0[chest] - P0[hips]
    up = up / up.norm().clamp_min(1e-12)
    left = P0[left_leg] - P0[right_leg]
    left = left - (left @ up) * up
    left = left / left.norm().clamp_min(1e-12)
    return torch.stack([torch.linalg.cross(left, up), left])
