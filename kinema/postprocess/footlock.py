"""Foot locking on predicted contacts (Kimodo Sec. 4.4: "simple foot locking and IK").

The model predicts per-frame contact probabilities ``[L heel, L toe, R heel, R toe]``
(``motion.foot_contacts``). They are thresholded at 0.5, short gaps are filled, and every contact is
widened by ``PAD_SECONDS`` (one frame at 20 fps) on both sides. Single-frame contacts are kept: a
run's stance lasts 3-5 frames at 20 fps and the classifier often flags only one of them; dropping
them left runs skating at 1.2 m/s. The padding makes the foot arrive at (and leave) its lock over the
blend ramp outside the predicted contact instead of on its first frame (measured on 8 prompts: pooled
skate 17.2 -> 6.2 cm/s with padding and single frames kept).

Every contact segment of a heel or toe joint (the ankle stands in for the heel on
rigs without heels, see kinema.motion.contacts) gets one fixed world point: the segment's mean x/z of
that joint, with y taken frame by frame from the motion and clamped to the floor. Per frame, the foot
is then moved rigidly onto its locked points (both locked: rotate the foot about the vertical-ish
minimal arc so heel->toe points at the locked toe, then translate the heel onto its lock; one
locked: translate only) and the leg is solved with two-bone IK so the ankle lands there. Corrections
are blended in and out over ``blend_seconds`` with raised-cosine ramps (kinema.postprocess.ik
``spread_corrections``), so frames away from contacts are untouched and nothing pops.

Where a leg cannot reach its lock (the model's body travels faster than its planted feet allow) the
pelvis is moved horizontally by the mean ankle shortfall of the planted legs, spread smoothly over
twice the blend radius and Gaussian-smoothed over the blend radius, and the locks are solved again
(``REACH_PASSES`` times, each pass only while some shortfall exceeds ``REACH_TOLERANCE``). Measured
on the same 8 prompts (three passes, before the smoothing): skate 6.2 -> 3.2 cm/s, largest IK miss
33 -> 3 cm, pelvis moved by up to 0.5 m (walks, dances), 0.1 s per 5-s motion. Not in the paper.
The smoothing is issue 36's: the shortfall jumps from one contact to the next, and the unsmoothed
shift made one- or two-frame pelvis pops (a slow walk 1.7 -> 4.4 m/s for a frame, pelvis
acceleration 65 m/s^2). Smoothed, six passes keep skate and IK misses near the unsmoothed three (6
walks and timelines: skate 1.5-5.9 vs 1.2-5.4 cm/s, largest IK miss 4.3 vs 3.3 cm) and the pelvis'
peak acceleration at the de-jittered input's (8-15 m/s^2 instead of 37-73).

Any rig: the contact joints and legs come from a `kinema.rig.Rig` (human: [L heel, L toe, R heel, R toe]
on the left and right legs). Each leg (a rig limb holding contact joints) locks its last two contacts
as heel and toe (one contact: translate only) with two-bone IK on the three joints ending at its
ankle (the heel joint, or the heel's parent when the heel is a side branch). An insect's six legs lock
one after another; a rig without contacts (a fish) is returned unchanged.

Foot skate is measured like the paper's metric: the mean horizontal speed (cm/s) of contact joints
over consecutive frames that are both flagged as planted.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import torch

from kinema.errors import KinemaError
from kinema.geometry.rotations import (
    axis_angle_to_quat,
    quat_between,
    quat_mul,
    quat_rotate,
    quat_to_axis_angle,
)
from kinema.motion.contacts import contact_joints
from kinema.motion.contacts import foot_contacts as estimate_contacts
from kinema.motion.core import Motion
from kinema.motion.smoothing import smooth_time
from kinema.postprocess.ik import (
    bend_fallback,
    chain_end_position,
    check_chain,
    facing,
    single_thread,
    spread_corrections,
    two_bone_ik_posed,
)
from kinema.rig import Rig

PAD_SECONDS = 0.05
REACH_TOLERANCE = 0.005  # metres of ankle shortfall below which the pelvis is left alone
REACH_PASSES = 6


def contact_segments(flags: torch.Tensor) -> list[tuple[int, int]]:
    """``[start, end)`` frame ranges where boolean ``flags (T,)`` are true."""
    f = flags.to(torch.int8)
    edges = torch.diff(torch.cat([f.new_zeros(1), f, f.new_zeros(1)]))
    starts = torch.nonzero(edges == 1).flatten().tolist()
    ends = torch.nonzero(edges == -1).flatten().tolist()
    return list(zip(starts, ends, strict=True))


def clean_contacts(
    contacts: torch.Tensor, fps: float, threshold: float = 0.5, max_gap_seconds: float = 0.1,
    min_seconds: float = 0.1, pad_seconds: float = 0.0,
) -> torch.Tensor:
    """Boolean ``(T, 4)`` planted flags: thresholded, gaps up to ``max_gap_seconds`` between two
    contacts filled, contacts shorter than ``min_seconds`` dropped (classifier flicker), then every
    contact widened by ``pad_seconds`` on both sides."""
    flags = contacts > threshold
    max_gap = int(round(max_gap_seconds * fps))
    min_len = max(int(round(min_seconds * fps)), 1)
    out = flags.clone()
    T = flags.shape[0]
    for k in range(flags.shape[1]):
        segs = contact_segments(flags[:, k])
        for (_, e0), (s1, _) in zip(segs[:-1], segs[1:], strict=True):
            if s1 - e0 <= max_gap:
                out[e0:s1, k] = True
        for s, e in contact_segments(out[:, k]):
            if e - s < min_len and not (s == 0 or e == T):  # clip edges may hold partial contacts
                out[s:e, k] = False
    pad = int(round(pad_seconds * fps))
    if pad > 0:
        grown = torch.nn.functional.max_pool1d(out.T[:, None].float(), 2 * pad + 1, stride=1, padding=pad)
        out = grown[:, 0].T > 0
    return out


@dataclass(frozen=True)
class LegLock:
    """One leg's locking: IK ``chain`` (a, b, ankle), the contact channels of its heel and toe (``toe``
    None for a leg with one contact joint) and their joints."""

    chain: tuple[int, int, int]
    heel: int
    toe: int | None
    heel_joint: int
    toe_joint: int


def leg_locks(rig: Rig) -> list[LegLock]:
    """The legs of ``rig`` that foot locking can solve, in the rig's limb order (see module)."""
    skel, out = rig.skeleton, []
    for limb in rig.legs().values():
        ks = sorted((k for k, j in enumerate(rig.contacts) if j in limb), key=lambda k: limb.index(rig.contacts[k]))
        heel, toe = (ks[-2], ks[-1]) if len(ks) > 1 else (ks[0], None)
        end = rig.contacts[heel]
        if toe is not None and end not in skel.path_from_root(rig.contacts[toe]):
            end = skel.parents[end]  # a heel beside the toe: the ankle is their common parent
        path = skel.path_from_root(end)
        if len(path) < 3 or not set(path[-3:]) <= set(limb):
            continue  # IK only bends the leg's own joints (never a shared body joint above the leg)
        chain = (path[-3], path[-2], path[-1])
        check_chain(skel, chain)
        toe_joint = rig.contacts[heel] if toe is None else rig.contacts[toe]
        out.append(LegLock(chain, heel, toe, rig.contacts[heel], toe_joint))
    return out


def foot_skate(motion: Motion, planted: torch.Tensor, joints: Sequence[int] | None = None) -> float:
    """Mean horizontal speed (cm/s) of the contact ``joints`` (default: the human four) over consecutive
    planted frames (0 if none)."""
    joints = contact_joints(motion.skeleton) if joints is None else list(joints)
    P = motion.positions[:, joints][..., [0, 2]].to(torch.float64)
    if P.shape[0] < 2 or not joints:
        return 0.0
    both = planted[1:] & planted[:-1]
    speed = (P[1:] - P[:-1]).norm(dim=-1) * motion.fps
    return float(speed[both].mean() * 100.0) if both.any() else 0.0


def _locked_points(positions: torch.Tensor, flags: torch.Tensor, floor: float) -> tuple[torch.Tensor, list]:
    """(T, 3) lock point of one joint (NaN where not planted) and its segments."""
    lock = torch.full_like(positions, float("nan"))
    segs = contact_segments(flags)
    for s, e in segs:
        lock[s:e, 0] = positions[s:e, 0].mean()
        lock[s:e, 2] = positions[s:e, 2].mean()
        lock[s:e, 1] = positions[s:e, 1].clamp(min=floor)
    return lock, segs


def foot_lock(
    motion: Motion,
    contacts: torch.Tensor | None = None,
    *,
    threshold: float = 0.5,
    blend_seconds: float = 0.15,
    floor: float = 0.0,
    max_gap_seconds: float = 0.1,
    min_seconds: float = 0.0,
    pad_seconds: float | None = None,
    reach_passes: int | None = None,
    rig: Rig | None = None,
) -> tuple[Motion, dict]:
    """Lock planted heels/toes in place with leg IK; returns the new motion and a report.

    ``rig`` (default: found from the motion's skeleton) names the contact joints and legs. ``contacts
    (T, C)``, one column per contact joint, defaults to ``motion.foot_contacts`` and, when the motion has
    none, to contacts estimated from joint heights and speeds. The report holds ``skate_before``/
    ``skate_after`` (cm/s), the number of locked segments and the largest remaining distance
    (cm) between a locked ankle and its target (non-zero only where the leg could not reach).
    """
    with single_thread():
        pad = PAD_SECONDS if pad_seconds is None else pad_seconds
        passes = REACH_PASSES if reach_passes is None else reach_passes
        rig = Rig.from_skeleton(motion.skeleton) if rig is None else rig
        legs = leg_locks(rig)
        if not legs:  # a fish, or a rig whose contacts sit on no solvable leg: nothing to lock
            return motion, {"skate_before": 0.0, "segments": 0, "root_shift_cm": 0.0, "max_ik_error_cm": 0.0,
                            "skate_after": 0.0}
        return _foot_lock(motion, contacts, threshold, blend_seconds, floor, max_gap_seconds, min_seconds, pad,
                          passes, rig, legs)


def _foot_lock(motion, contacts, threshold, blend_seconds, floor, max_gap_seconds, min_seconds, pad_seconds,
               reach_passes, rig: Rig, legs: list[LegLock]):
    if contacts is None:
        contacts = motion.foot_contacts
    if contacts is None:
        contacts = estimate_contacts(motion.positions, motion.fps, motion.skeleton, joints=rig.contacts)
    if torch.as_tensor(contacts).shape[-1] != len(rig.contacts):
        raise KinemaError(f"{torch.as_tensor(contacts).shape[-1]} contact channels for a rig with "
                          f"{len(rig.contacts)} contact joints {rig.joint_names(rig.contacts)}")
    dtype = motion.dtype
    m = motion.to(torch.float64)
    planted = clean_contacts(torch.as_tensor(contacts), m.fps, threshold, max_gap_seconds, min_seconds,
                             pad_seconds)
    radius = max(blend_seconds * m.fps, 1.0)
    locks, segments = _lock_points(m, planted, floor, rig.contacts)
    report = {"skate_before": foot_skate(m, planted, rig.contacts), "segments": segments, "root_shift_cm": 0.0}
    out, deficit = _apply_locks(m, planted, locks, radius, legs)
    moved = torch.zeros_like(m.root_translation)
    for _ in range(reach_passes):
        frames = torch.nonzero(deficit.norm(dim=-1) > REACH_TOLERANCE).flatten()
        if frames.numel() == 0:
            break
        shift, _ = spread_corrections(frames, deficit[frames], m.num_frames, 2 * radius)
        shift = smooth_time(shift, radius)  # per-frame shortfalls jump between contacts: no pelvis pops
        m = Motion(m.skeleton, m.fps, m.root_translation + shift, m.local_rotations, m.foot_contacts)
        moved = moved + shift
        report["root_shift_cm"] = float(moved.norm(dim=-1).max()) * 100.0
        out, deficit = _apply_locks(m, planted, locks, radius, legs)
    report["max_ik_error_cm"] = float(deficit.norm(dim=-1).max()) * 100.0 if deficit.numel() else 0.0
    report["skate_after"] = foot_skate(out, planted, rig.contacts)
    result = Motion(out.skeleton, out.fps, out.root_translation, out.local_rotations, motion.foot_contacts)
    return result.to(dtype), report


def _lock_points(m: Motion, planted: torch.Tensor, floor: float, contacts: Sequence[int]) -> tuple[dict, int]:
    """Per contact channel, its (T, 3) lock points (NaN off contact); and the number of segments."""
    P = m.positions
    locks, segments = {}, 0
    for k, j in enumerate(contacts):
        locks[k], segs = _locked_points(P[:, j], planted[:, k], floor)
        segments += len(segs)
    return locks, segments


def _apply_locks(m: Motion, planted: torch.Tensor, locks: dict, radius: float,
                 legs: list[LegLock]) -> tuple[Motion, torch.Tensor]:
    """Move planted feet onto their lock points with leg IK. Returns the motion and, per frame, the
    mean horizontal ankle shortfall ``(T, 3)`` (metres, y = 0) over the legs planted on that frame:
    how far the pelvis would have to move for the legs to reach their locks.

    One forward kinematics pass for all legs: a leg's IK turns only its own joints, so every other
    leg's chain, the hips the facing is read from and the ankle each leg reaches
    (kinema.postprocess.ik.chain_end_position) come out bit for bit as from FK of the updated pose."""
    T, skel = m.num_frames, m.skeleton
    G, P = m.global_transforms()
    L = m.local_rotations
    fwd = facing(P, skel)
    shortfall = torch.zeros(T, 3, dtype=torch.float64)
    count = torch.zeros(T, dtype=torch.float64)
    for leg in legs:
        chain, hk, tk = leg.chain, leg.heel, leg.toe
        ankle = chain[2]
        heel, toe = leg.heel_joint, leg.toe_joint
        heel_lock, hl = locks[hk], planted[:, hk]
        toe_lock, tl = (locks[tk], planted[:, tk]) if tk is not None else (P[:, heel], torch.zeros_like(hl))
        any_lock = hl | tl
        if not any_lock.any():
            continue
        # rigid foot correction on planted frames: rotation about the ankle, then translation
        h, o, pa, Ga = P[:, heel], P[:, toe], P[:, ankle], G[:, ankle]
        q = quat_between(o - h, torch.where(tl[:, None], toe_lock, o) - torch.where(hl[:, None], heel_lock, h))
        both = (hl & tl)[:, None]
        q = torch.where(both, q, torch.tensor([1.0, 0.0, 0.0, 0.0], dtype=q.dtype))
        new_pa = torch.where(
            hl[:, None],
            heel_lock - quat_rotate(q, h - pa),
            torch.where(tl[:, None], pa + (toe_lock - o), pa),
        )
        frames = torch.nonzero(any_lock).flatten()
        shift, env = spread_corrections(frames, (new_pa - pa)[frames], T, radius)
        turn, _ = spread_corrections(frames, quat_to_axis_angle(q[frames]), T, radius)
        target = pa + shift
        end_rot = quat_mul(axis_angle_to_quat(turn), Ga)
        L = two_bone_ik_posed(L, G, P, skel, chain, target, (env > 0).to(torch.float64), None,
                              bend_fallback(skel, chain, fwd), end_rot)
        reached = chain_end_position(L, G, P, skel, chain)
        miss = torch.where(any_lock[:, None], target - reached, torch.zeros_like(target))
        shortfall += miss * torch.tensor([1.0, 0.0, 1.0], dtype=torch.float64)
        count += any_lock.to(torch.float64)
    out = Motion(skel, m.fps, m.root_translation, L, m.foot_contacts)
    return out, shortfall / count.clamp_min(1.0)[:, None]
