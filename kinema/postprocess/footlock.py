"""Foot locking on predicted contacts (Kimodo Sec. 4.4: "simple foot locking and IK").

The model predicts per-frame contact probabilities ``[L heel, L toe, R heel, R toe]``
(``motion.foot_contacts``). They are thresholded at 0.5 and cleaned (short gaps filled, isolated
spikes dropped). Every contact segment of a heel or toe joint (the ankle stands in for the heel on
rigs without heels, see kinema.motion.contacts) gets one fixed world point: the segment's mean x/z of
that joint, with y taken frame by frame from the motion and clamped to the floor. Per frame, the foot
is then moved rigidly onto its locked points (both locked: rotate the foot about the vertical-ish
minimal arc so heel->toe points at the locked toe, then translate the heel onto its lock; one
locked: translate only) and the leg is solved with two-bone IK so the ankle lands there. Corrections
are blended in and out over ``blend_seconds`` with raised-cosine ramps (kinema.postprocess.ik
``spread_corrections``), so frames away from contacts are untouched and nothing pops.

Foot skate is measured like the paper's metric: the mean horizontal speed (cm/s) of contact joints
over consecutive frames that are both flagged as planted.
"""

from __future__ import annotations

import torch

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
from kinema.postprocess.ik import limb_chain, single_thread, solve_ik, spread_corrections


def contact_segments(flags: torch.Tensor) -> list[tuple[int, int]]:
    """``[start, end)`` frame ranges where boolean ``flags (T,)`` are true."""
    f = flags.to(torch.int8)
    edges = torch.diff(torch.cat([f.new_zeros(1), f, f.new_zeros(1)]))
    starts = torch.nonzero(edges == 1).flatten().tolist()
    ends = torch.nonzero(edges == -1).flatten().tolist()
    return list(zip(starts, ends, strict=True))


def clean_contacts(
    contacts: torch.Tensor, fps: float, threshold: float = 0.5, max_gap_seconds: float = 0.1,
    min_seconds: float = 0.1,
) -> torch.Tensor:
    """Boolean ``(T, 4)`` planted flags: thresholded, gaps up to ``max_gap_seconds`` between two
    contacts filled, then contacts shorter than ``min_seconds`` dropped (classifier flicker)."""
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
    return out


def foot_skate(motion: Motion, planted: torch.Tensor) -> float:
    """Mean horizontal speed (cm/s) of the contact joints over consecutive planted frames (0 if none)."""
    P = motion.positions[:, contact_joints(motion.skeleton)][..., [0, 2]].to(torch.float64)
    if P.shape[0] < 2:
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
    min_seconds: float = 0.1,
) -> tuple[Motion, dict]:
    """Lock planted heels/toes in place with leg IK; returns the new motion and a report.

    ``contacts (T, 4)`` defaults to ``motion.foot_contacts`` and, when the motion has none, to
    contacts estimated from joint heights and speeds. The report holds ``skate_before``/
    ``skate_after`` (cm/s), the number of locked segments and the largest remaining distance
    (cm) between a locked ankle and its target (non-zero only where the leg could not reach).
    """
    with single_thread():
        return _foot_lock(motion, contacts, threshold, blend_seconds, floor, max_gap_seconds, min_seconds)


def _foot_lock(motion, contacts, threshold, blend_seconds, floor, max_gap_seconds, min_seconds):
    if contacts is None:
        contacts = motion.foot_contacts
    if contacts is None:
        contacts = estimate_contacts(motion.positions, motion.fps, motion.skeleton)
    dtype = motion.dtype
    m = motion.to(torch.float64)
    planted = clean_contacts(torch.as_tensor(contacts), m.fps, threshold, max_gap_seconds, min_seconds)
    T = m.num_frames
    radius = max(blend_seconds * m.fps, 1.0)
    G, P = m.global_transforms()
    cj = contact_joints(m.skeleton)
    report = {"skate_before": foot_skate(m, planted), "segments": 0, "max_ik_error_cm": 0.0}
    out = m
    for side, (hk, tk) in (("left", (0, 1)), ("right", (2, 3))):
        chain = limb_chain(m.skeleton, f"{side}_leg")
        ankle = chain[2]
        heel, toe = cj[hk], cj[tk]
        heel_lock, heel_segs = _locked_points(P[:, heel], planted[:, hk], floor)
        toe_lock, toe_segs = _locked_points(P[:, toe], planted[:, tk], floor)
        report["segments"] += len(heel_segs) + len(toe_segs)
        hl, tl = planted[:, hk], planted[:, tk]
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
        out = solve_ik(out, chain, target, weight=(env > 0).to(torch.float64), end_rotation=end_rot)
        err = (out.positions[:, ankle] - target)[any_lock].norm(dim=-1).max()
        report["max_ik_error_cm"] = max(report["max_ik_error_cm"], float(err) * 100.0)
    report["skate_after"] = foot_skate(out, planted)
    result = Motion(out.skeleton, out.fps, out.root_translation, out.local_rotations, motion.foot_contacts)
    return result.to(dtype), report
