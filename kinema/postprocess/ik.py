"""Analytic two-bone IK (batched over frames) and the correction-blending helper of post-processing.

A two-bone chain is three joints ``a -> b -> c`` where ``b``'s parent is ``a`` and ``c``'s parent is
``b`` (hip-knee-ankle, upper_arm-elbow-hand). Given a target for ``c`` on every frame, the solver
(all in float64, then cast back):

1. bends ``b`` about its current hinge axis so that ``|c - a|`` equals the (clamped) target distance
   (law of cosines; the hinge axis is the current bend normal, so the knee keeps its bend sense),
2. swings the chain at ``a`` (shortest arc) so that ``c`` lies on the line from ``a`` to the target,
3. twists the chain about that line so that ``b`` points to the bend side: the current knee/elbow
   position by default (the bend plane is kept), or a pole point when given.

Targets beyond reach land on the segment from ``a`` towards the target at the full chain length (or
at ``|l1 - l2|`` when too close). ``weight`` moves the target from ``c``'s current position
(weight 0: frame untouched, bit for bit) to the given target (weight 1: reached exactly).

``spread_corrections`` turns corrections known on a few frames into a smooth per-frame field that is
exact on those frames and fades out with a raised cosine: foot locking and the exact-constraint
pass both blend their edits with it so nothing pops.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import torch

from kinema.errors import KinemaError
from kinema.geometry.rotations import (
    axis_angle_to_quat,
    quat_between,
    quat_identity,
    quat_inverse,
    quat_mul,
    quat_normalize,
    quat_rotate,
    quat_slerp,
)
from kinema.kinematics import forward_kinematics
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

_LIMBS = {"leg": ("hip", "knee", "ankle"), "arm": ("upper_arm", "elbow", "hand")}


def _unit(v: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    return v / v.norm(dim=-1, keepdim=True).clamp_min(eps)


def _dot(u: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    return (u * v).sum(-1, keepdim=True)


def _any_perpendicular(v: torch.Tensor) -> torch.Tensor:
    """A unit vector perpendicular to each ``v (..., 3)`` (deterministic, for degenerate fallbacks)."""
    basis = torch.nn.functional.one_hot(v.abs().argmin(-1), 3).to(v.dtype)
    return _unit(torch.linalg.cross(v, basis, dim=-1))


def limb_chain(skeleton: Skeleton, limb: str) -> tuple[int, int, int]:
    """Joint indices ``(a, b, c)`` of ``left_leg``/``right_leg`` (hip, knee, ankle) or arms (upper arm,
    elbow, hand), found through the skeleton's roles."""
    side, _, kind = limb.partition("_")
    if side not in ("left", "right") or kind not in _LIMBS:
        raise KinemaError(f"unknown limb {limb!r}: use left_leg, right_leg, left_arm or right_arm")
    roles = skeleton.require_roles([f"{side}_{r}" for r in _LIMBS[kind]])
    chain = tuple(roles[f"{side}_{r}"] for r in _LIMBS[kind])
    check_chain(skeleton, chain)
    return chain  # type: ignore[return-value]


def chain_for_joint(skeleton: Skeleton, joint: int | str) -> tuple[int, int, int]:
    """The two-bone chain ending at ``joint``: (grandparent, parent, joint)."""
    c = skeleton.index(joint) if isinstance(joint, str) else int(joint)
    b = skeleton.parents[c]
    a = skeleton.parents[b] if b >= 0 else -1
    if a < 0:
        raise KinemaError(f"joint {skeleton.names[c]!r} is too close to the root for a two-bone chain")
    return a, b, c


def check_chain(skeleton: Skeleton, chain: Sequence[int]) -> None:
    """Raise unless ``chain`` is (a, b, c) with ``parent(b) == a`` and ``parent(c) == b``."""
    a, b, c = chain
    if skeleton.parents[b] != a or skeleton.parents[c] != b:
        names = [skeleton.names[j] for j in chain]
        raise KinemaError(f"{names} is not a parent -> child -> grandchild chain")


def _axis_angle_quat(axis: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    return axis_angle_to_quat(_unit(axis) * angle)


def two_bone_ik(
    local_rotations: torch.Tensor,
    root_translation: torch.Tensor,
    skeleton: Skeleton,
    chain: Sequence[int],
    target: torch.Tensor,
    weight: torch.Tensor | None = None,
    pole: torch.Tensor | None = None,
    fallback_bend: torch.Tensor | None = None,
    end_rotation: torch.Tensor | None = None,
    keep_end_rotation: bool = True,
) -> torch.Tensor:
    """New local rotations ``(T, J, 4)`` moving joint ``c`` of ``chain = (a, b, c)`` onto ``target``.

    ``target (T, 3)`` world metres; ``weight (T,)`` in [0, 1] (default 1); ``pole (T, 3)`` optional
    world points the middle joint should point towards (default: its current position, which keeps
    the bend plane); ``fallback_bend (T, 3)`` or ``(3,)`` a world direction used only where the limb is
    straight and the bend side is otherwise undefined; ``end_rotation (T, 4)`` optional global rotation
    for ``c`` (slerped in by ``weight``); without it ``c`` keeps its global rotation when
    ``keep_end_rotation`` (feet stay flat, hands keep their orientation), else rides along with ``b``.
    Only the local rotations of ``a``, ``b`` and ``c`` change.
    """
    check_chain(skeleton, chain)
    L = local_rotations.to(torch.float64)
    G, P = forward_kinematics(L, root_translation.to(torch.float64), skeleton.offsets, skeleton.parents)
    out = two_bone_ik_posed(L, G, P, skeleton, chain, target, weight, pole, fallback_bend, end_rotation,
                            keep_end_rotation)
    return out.to(local_rotations.dtype)


def two_bone_ik_posed(
    L: torch.Tensor,
    G: torch.Tensor,
    P: torch.Tensor,
    skeleton: Skeleton,
    chain: Sequence[int],
    target: torch.Tensor,
    weight: torch.Tensor | None = None,
    pole: torch.Tensor | None = None,
    fallback_bend: torch.Tensor | None = None,
    end_rotation: torch.Tensor | None = None,
    keep_end_rotation: bool = True,
) -> torch.Tensor:
    """:func:`two_bone_ik` on a posed motion: float64 local rotations ``L (T, J, 4)`` with their global
    rotations ``G`` and positions ``P`` already known (forward kinematics), for callers that solve several
    chains on one pose (foot locking's legs: no leg moves another's joints). Returns the new float64 local
    rotations (a copy)."""
    a, b, c = chain
    T = L.shape[0]
    pa, pb, pc = P[:, a], P[:, b], P[:, c]
    w = torch.ones(T, dtype=torch.float64) if weight is None else torch.as_tensor(weight).to(torch.float64)
    w = w.clamp(0.0, 1.0)
    tgt = pc + w[:, None] * (torch.as_tensor(target).to(torch.float64) - pc)
    l1, l2 = skeleton.offsets[b].norm().item(), skeleton.offsets[c].norm().item()

    # target direction and clamped distance
    d = tgt - pa
    D = d.norm(dim=-1, keepdim=True)
    dhat = torch.where(D > 1e-9, d / D.clamp_min(1e-12), _unit(pc - pa))
    Dc = D.clamp(abs(l1 - l2), l1 + l2)
    bend = _bend_side(pa, pb, dhat, pole, fallback_bend)
    q_knee = _knee_rotation(pa, pb, pc, bend, Dc, l1, l2)  # 1. knee angle about the current hinge axis
    q_a = _swing_twist(pa, pb, pb + quat_rotate(q_knee, pc - pb), dhat, bend, l1)
    if end_rotation is not None:
        Gc_new = quat_slerp(G[:, c], torch.as_tensor(end_rotation).to(torch.float64), w)
    elif keep_end_rotation:
        Gc_new = G[:, c]
    else:
        Gc_new = quat_mul(q_a, quat_mul(q_knee, G[:, c]))
    Ga_new, Gb_new = quat_mul(q_a, G[:, a]), quat_mul(q_a, quat_mul(q_knee, G[:, b]))
    out = _chain_locals(L, G, skeleton.parents[a], chain, Ga_new, Gb_new, Gc_new)
    active = (w > 0)[:, None, None]
    return torch.where(active, out, L)


def chain_end_position(L: torch.Tensor, G: torch.Tensor, P: torch.Tensor, skeleton: Skeleton,
                       chain: Sequence[int]) -> torch.Tensor:
    """Position ``(T, 3)`` of the chain's end joint ``c`` once the chain ``(a, b, c)`` has the local
    rotations ``L``, the rest of the pose (``G``, ``P``: its parents) as before; the same arithmetic as
    forward kinematics, so the result is bit for bit what FK of the whole new pose gives."""
    a, b, c = chain
    p = skeleton.parents[a]
    offsets = skeleton.offsets.to(torch.float64)
    Ga = L[:, a] if p < 0 else quat_mul(G[:, p], L[:, a])
    pb = P[:, a] + quat_rotate(Ga, offsets[b].expand_as(P[:, a]))
    Gb = quat_mul(Ga, L[:, b])
    return pb + quat_rotate(Gb, offsets[c].expand_as(pb))


def _bend_side(
    pa: torch.Tensor,
    pb: torch.Tensor,
    dhat: torch.Tensor,
    pole: torch.Tensor | None,
    fallback_bend: torch.Tensor | None,
) -> torch.Tensor:
    """Unit (T, 3) direction, perpendicular to the target line, the middle joint should point to:
    the pole's (default: the current middle joint's) perpendicular part, the fallback where it vanishes."""
    hint = (pb if pole is None else torch.as_tensor(pole).to(torch.float64)) - pa
    fb = _any_perpendicular(dhat) if fallback_bend is None else torch.as_tensor(fallback_bend).to(torch.float64)
    fb = fb.expand_as(dhat)
    fb_perp = _unit(fb - _dot(fb, dhat) * dhat)
    perp = hint - _dot(hint, dhat) * dhat
    return _unit(perp + 1e-10 * fb_perp)  # the fallback only decides where perp vanishes


def _knee_rotation(
    pa: torch.Tensor, pb: torch.Tensor, pc: torch.Tensor, bend: torch.Tensor, Dc: torch.Tensor, l1: float, l2: float
) -> torch.Tensor:
    """Step 1: (T, 4) world rotation of the middle joint about its current hinge axis that makes
    ``|c - a|`` equal ``Dc`` (law of cosines); a straight limb bends towards ``bend``."""
    # theta = angle between ab and bc, 0 when straight
    ab, bc = pb - pa, pc - pb
    n0 = torch.linalg.cross(ab, bc, dim=-1)
    s0 = n0.norm(dim=-1, keepdim=True)
    straight_axis = torch.linalg.cross(bend, ab, dim=-1)  # bends bc towards -bend, knee towards +bend
    straight_axis = torch.where(straight_axis.norm(dim=-1, keepdim=True) > 1e-9, straight_axis, _any_perpendicular(ab))
    n0 = torch.where(s0 > 1e-9 * l1 * l2, n0, straight_axis)
    theta0 = torch.atan2(s0, _dot(ab, bc))
    cos1 = ((Dc**2 - l1 * l1 - l2 * l2) / (2 * l1 * l2)).clamp(-1.0, 1.0)
    return _axis_angle_quat(n0, torch.acos(cos1) - theta0)


def _swing_twist(
    pa: torch.Tensor, pb: torch.Tensor, c1: torch.Tensor, dhat: torch.Tensor, bend: torch.Tensor, l1: float
) -> torch.Tensor:
    """Steps 2 and 3: (T, 4) world rotation at ``a`` that swings the bent chain (end at ``c1``) onto
    the target line ``dhat``, then twists it about that line so the middle joint points to ``bend``."""
    q_swing = quat_between(c1 - pa, dhat)
    kb = quat_rotate(q_swing, pb - pa)
    kperp = kb - _dot(kb, dhat) * dhat
    kn = kperp.norm(dim=-1, keepdim=True)
    phi = torch.atan2(_dot(dhat, torch.linalg.cross(kperp, bend, dim=-1)), _dot(kperp, bend))
    phi = phi * (kn / (0.01 * l1)).clamp(max=1.0)  # undefined when the solved limb is straight: fade it out
    return quat_mul(_axis_angle_quat(dhat, phi), q_swing)


def _chain_locals(
    L: torch.Tensor,
    G: torch.Tensor,
    parent_a: int,
    chain: Sequence[int],
    Ga_new: torch.Tensor,
    Gb_new: torch.Tensor,
    Gc_new: torch.Tensor,
) -> torch.Tensor:
    """Copy of the local rotations ``L`` with the chain's new global rotations turned back into locals."""
    a, b, c = chain
    Gpa = G[:, parent_a] if parent_a >= 0 else quat_identity(L.shape[0], dtype=torch.float64)
    out = L.clone()
    out[:, a] = quat_normalize(quat_mul(quat_inverse(Gpa), Ga_new))
    out[:, b] = quat_normalize(quat_mul(quat_inverse(Ga_new), Gb_new))
    out[:, c] = quat_normalize(quat_mul(quat_inverse(Gb_new), Gc_new))
    return out


def forward_direction(motion: Motion) -> torch.Tensor:
    """Per-frame facing direction ``(T, 3)`` from the hips (world +Z where the rig has no hip roles)."""
    roles = motion.skeleton.roles
    if "left_hip" not in roles or "right_hip" not in roles:
        return torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).expand(motion.num_frames, 3)
    return facing(motion.positions.to(torch.float64), motion.skeleton)


def facing(P: torch.Tensor, skeleton: Skeleton) -> torch.Tensor:
    """:func:`forward_direction` from joint positions ``P (T, J, 3)`` (float64)."""
    roles = skeleton.roles
    if "left_hip" not in roles or "right_hip" not in roles:
        return torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64).expand(P.shape[0], 3)
    v = P[:, roles["right_hip"]] - P[:, roles["left_hip"]]
    fwd = torch.stack([v[:, 2], torch.zeros_like(v[:, 0]), -v[:, 0]], dim=-1)  # +Y cross (right - left)
    return _unit(fwd)


def bend_fallback(skeleton: Skeleton, chain: Sequence[int], fwd: torch.Tensor) -> torch.Tensor:
    """The side a straight limb bends to: forward (``fwd``, the facing) for knees, backward for elbows."""
    hands = {skeleton.roles.get("left_hand"), skeleton.roles.get("right_hand")}
    elbows = {skeleton.roles.get("left_elbow"), skeleton.roles.get("right_elbow")}
    return -fwd if (chain[2] in hands or chain[1] in elbows) else fwd


def solve_ik(
    motion: Motion,
    joint_or_chain: int | str | Sequence[int],
    target: torch.Tensor,
    weight: torch.Tensor | None = None,
    end_rotation: torch.Tensor | None = None,
    pole: torch.Tensor | None = None,
    keep_end_rotation: bool = True,
) -> Motion:
    """``two_bone_ik`` on a Motion: the chain is given, a limb name, or the joint it ends at.

    Straight limbs bend forward (knees) or backward (elbows) relative to the hips' facing.
    """
    skel = motion.skeleton
    if isinstance(joint_or_chain, str) and joint_or_chain.endswith(("_leg", "_arm")):
        chain = limb_chain(skel, joint_or_chain)
    elif isinstance(joint_or_chain, int | str):
        chain = chain_for_joint(skel, joint_or_chain)
    else:
        chain = tuple(int(j) for j in joint_or_chain)
    fallback = bend_fallback(skel, chain, forward_direction(motion))
    rots = two_bone_ik(
        motion.local_rotations,
        motion.root_translation,
        skel,
        chain,
        target,
        weight,
        pole,
        fallback,
        end_rotation,
        keep_end_rotation,
    )
    return Motion(skel, motion.fps, motion.root_translation, rots, motion.foot_contacts)


# ----------------------------------------------------------------------------- correction blending


_THREADS_LOCK = threading.Lock()
_THREADS_STATE = {"depth": 0, "before": 1}


@contextmanager
def single_thread() -> Iterator[None]:
    """Run tiny-tensor loops on one intra-op thread: with (T, J)-sized ops, thread hand-offs cost far
    more than they save, and on a busy machine spinning worker threads slow them down many times.

    torch's thread count is process-wide, so nested and concurrent users (several Python threads
    post-processing at once) share one count: the first to enter saves the setting, the last to leave
    restores it."""
    with _THREADS_LOCK:
        if _THREADS_STATE["depth"] == 0:
            _THREADS_STATE["before"] = torch.get_num_threads()
            torch.set_num_threads(1)
        _THREADS_STATE["depth"] += 1
    try:
        yield
    finally:
        with _THREADS_LOCK:
            _THREADS_STATE["depth"] -= 1
            if _THREADS_STATE["depth"] == 0:
                torch.set_num_threads(_THREADS_STATE["before"])


def raised_cosine(x: torch.Tensor) -> torch.Tensor:
    """``0.5 (1 + cos(pi x))`` for ``|x| < 1``, else 0: 1 at the centre, flat ends, no kink at 0."""
    x = x.abs()
    return torch.where(x < 1, 0.5 * (1 + torch.cos(math.pi * x.clamp(max=1.0))), torch.zeros_like(x))


def spread_corrections(
    frames: torch.Tensor, values: torch.Tensor, num_frames: int, radius: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-frame field ``(T, C)`` and envelope ``(T,)`` from corrections ``values (K, C)`` at ``frames``.

    The field equals ``values[k]`` exactly on ``frames[k]``, eases between neighbouring corrected
    frames (raised-cosine interpolation) and fades to zero within ``radius`` frames of the nearest
    one (raised-cosine envelope), so edits blend in and out without a step. Gaps up to ``radius``
    between corrected frames are bridged at full strength (fading out as the gap grows to twice the
    radius), so dense corrections do not wobble. Repeated frames keep the last value.
    """
    frames = torch.as_tensor(frames, dtype=torch.long).reshape(-1)
    values = torch.as_tensor(values)
    T = num_frames
    if frames.numel() == 0:
        return values.new_zeros(T, values.shape[-1]), values.new_zeros(T)
    # sort and keep the last occurrence of repeated frames
    order = torch.argsort(frames, stable=True)
    f, v = frames[order], values[order]
    keep = torch.ones_like(f, dtype=torch.bool)
    keep[:-1] = f[1:] != f[:-1]
    f, v = f[keep], v[keep]
    K = f.numel()
    t = torch.arange(T)
    iR = torch.searchsorted(f, t)  # first corrected frame >= t
    iL = iR - 1
    hasL, hasR = iL >= 0, iR < K
    fL, fR = f[iL.clamp(min=0)], f[iR.clamp(max=K - 1)]
    r = max(float(radius), 1e-6)
    rampL = torch.where(hasL, raised_cosine((t - fL).to(v.dtype) / r), torch.zeros((), dtype=v.dtype))
    rampR = torch.where(hasR, raised_cosine((fR - t).to(v.dtype) / r), torch.zeros((), dtype=v.dtype))
    # close corrections are bridged (no dip between them); the bridge fades as the gap grows to 2 radii
    gap = (fR - fL).to(v.dtype)
    bridge = torch.where(hasL & hasR, raised_cosine(((gap - r) / r).clamp(min=0)), torch.zeros((), dtype=v.dtype))
    env = torch.maximum(torch.maximum(rampL, rampR), bridge)
    s = torch.where(
        hasL & hasR,
        (t - fL).to(v.dtype) / (fR - fL).clamp(min=1).to(v.dtype),
        torch.where(hasL, 0.0, 1.0).to(v.dtype),
    )
    h = (0.5 - 0.5 * torch.cos(math.pi * s))[:, None]
    field = ((1 - h) * v[iL.clamp(min=0)] + h * v[iR.clamp(max=K - 1)]) * env[:, None]
    return field, env
