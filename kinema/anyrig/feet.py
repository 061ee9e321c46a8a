"""Foot locking for feet that move by translation (Quaternius-style IK foot bones under the armature).

Many game rigs drive each foot with an IK bone parented to a static armature joint on the floor and
animate that bone's *translation*; the leg chain follows it in the engine, not in the skeleton, so
kinema's leg IK (kinema.postprocess.footlock) cannot lock it. Here such a foot (`TranslatedFoot`: the
bone and the rig's contact joints it carries, its *soles*) is cleaned up directly:

- **jitter**: its world path is low-passed (Gaussian, ``SMOOTH_SECONDS``): the model's x0 prediction
  shakes these bones frame to frame, and post-processing's rotation smoothing does not reach them;
- **planted** where a sole is within ``GROUND`` of its rest height (where it stands), or within
  ``BELIEVE`` of it and either flagged by the model's contact channel (> 0.5) or within ``GROUND`` of
  the lowest it comes within ``BASELINE_SECONDS`` (a foot that hovers a little above the floor at a
  steady height is a standing foot the model put too high: the gun robot's left foot in an attack).
  No speed test: a foot the model slides along the floor is exactly the one to lock (the former
  0.6 size/s rule let those through: measured on the shipped model, 0 of 4 feet of the husky were ever
  locked);
- **locked**: on a planted run the foot is held at one ground point with its sole on the floor (and
  its rotation held, so the toes it carries stand still too). When
  the model's own foot wanders more than ``REACH`` from that point (its body drifts) the foot takes a
  step: over ``STEP_FRAMES`` frames it moves to where the model has it plus half ``REACH`` further the
  same way (feet land ahead of a moving body), lifted by ``STEP_HEIGHT`` at mid-step, and is planted
  again there. Both decisions look through the shaking of the model's feet (planted on heights smoothed
  over ``DETECT_SECONDS``, steps on the ground path smoothed over ``DRIFT_SECONDS``): on the robots the
  raw feet jump 0.1 rig sizes from frame to frame, which otherwise makes them step every few frames
  and hover between steps. Locks blend in and out over ``BLEND`` frames;
- **above the floor** elsewhere: a sole never ends below its rest height;
- frames with a joint target on the foot (``hold``) keep the foot exactly as generated.

The result is written back as the bone's local translation, so no bone of the body changes length.
Lengths are in rig units scaled by the rig's size (rest-pose extent), so the thresholds mean the same
on a fish and a T-rex. Shapes: positions ``(T, J, 3)``, contacts ``(T, C)`` in the rig's contact order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import torch

from kinema.geometry.rotations import quat_inverse, quat_mul, quat_rotate
from kinema.motion.core import Motion
from kinema.motion.smoothing import smooth_time
from kinema.postprocess.footlock import contact_segments
from kinema.representation.joint import POS, ROOT_HEADING_COS, ROOT_HEADING_SIN, JointRepresentation, yaw_quat
from kinema.rig import Rig
from kinema.rig.find import rest_positions
from kinema.skeleton import Skeleton

GROUND = 0.04  # x rig size: a sole this close to its rest height is planted ...
BELIEVE = 0.15  # ... and so is one this close to it that the model flags as in contact or that is at
BASELINE_SECONDS = 1.0  # its lowest within a window this long (give or take GROUND)
REACH = 0.15  # x rig size: a planted foot steps when the model's foot is further than this from the lock
STEP_FRAMES = 4
STEP_HEIGHT = 0.05  # x rig size, at mid-step
SMOOTH_SECONDS = 0.05
DETECT_SECONDS = 0.1  # heights are smoothed this much more to decide where a foot is planted ...
DRIFT_SECONDS = 0.25  # ... and the ground path this much to decide when it steps
MIN_FRAMES = 2
BLEND = 3


@dataclass(frozen=True)
class TranslatedFoot:
    """A bone moved by translation under a floor-level armature that carries contact joints: ``soles``
    (the bone itself and/or its descendants), their ``channels`` in the rig's contact order (empty when
    the rig layer names none) and the heights they stand at (``rest``): their rest heights above the
    rig's lowest rest joint, lowered together so the lowest stands as low as the lowest sole of any foot
    (rest poses of game rigs may hold a foot up: the two-legged robot's right foot is 0.066 up, its left
    0.017, and both stand at 0.017 in its clips)."""

    joint: int
    soles: tuple[int, ...]
    channels: tuple[int, ...]
    rest: tuple[float, ...]


def floor_root_children(skeleton: Skeleton, band: float = 0.05) -> list[int]:
    """Children of joint 0 when joint 0 is an armature helper on the floor (its rest height within
    ``band`` of the lowest joint, relative to the rig's size) with several children: Quaternius rigs
    move their body and IK-driven feet by animating these bones' translations, not rotations."""
    P = rest_positions(skeleton)
    extent = float((P.max(0).values - P.min(0).values).max())
    kids = skeleton.children[0]
    if extent <= 0 or len(kids) < 2 or float(P[0, 1] - P[:, 1].min()) > band * extent:
        return []
    return list(kids)


def rest_extent(skeleton: Skeleton) -> float:
    """Largest side of the rest pose's bounding box (skeleton units): the unit the model works in, as
    the data builds normalise every rig to it (kinema.data.motion_cache.rest_extent)."""
    P = rest_positions(skeleton)
    return float((P.max(0).values - P.min(0).values).max())


def floor_height(skeleton: Skeleton, joint: int) -> float:
    """Rest height of ``joint`` above the skeleton's lowest joint (skeleton units)."""
    P = rest_positions(skeleton)
    return float(P[joint, 1] - P[:, 1].min())


def descendants(skeleton: Skeleton, joints: list[int]) -> list[int]:
    """``joints`` and every joint below them."""
    out, stack = [], list(joints)
    while stack:
        k = stack.pop()
        out.append(k)
        stack.extend(skeleton.children[k])
    return out


def translated_feet(rig: Rig, root: int) -> list[TranslatedFoot]:
    """The feet of ``rig`` moved by translation: bones under a floor-level armature, off the path to
    ``root``, that carry contact joints of the rig, or (a rig layer that names none there) sit within
    ``GROUND`` of the floor at rest (the bone is then its own sole)."""
    skel = rig.skeleton
    size = rest_extent(skel)
    path = set(skel.path_from_root(root))
    out = []
    for j in floor_root_children(skel):
        if j in path:
            continue
        soles = tuple(k for k in sorted(descendants(skel, [j])) if k in rig.contacts)
        if not soles and floor_height(skel, j) < GROUND * size:
            soles = (j,)
        if soles:
            channels = tuple(rig.contacts.index(k) for k in soles if k in rig.contacts)
            out.append(TranslatedFoot(j, soles, channels, tuple(floor_height(skel, k) for k in soles)))
    low = min((min(f.rest) for f in out), default=0.0)
    return [replace(f, rest=tuple(r - (min(f.rest) - low) for r in f.rest)) for f in out]


def lock_translated_feet(
    motion: Motion,
    feet: list[TranslatedFoot],
    size: float,
    *,
    contacts: torch.Tensor | None = None,
    hold: dict[int, list[int]] | None = None,
) -> tuple[Motion, dict]:
    """``motion`` with ``feet`` de-jittered, planted feet locked (stepping after a drifting body) and
    kept above the floor (see the module docstring). ``contacts (T, C)``: the model's contact channel;
    ``hold``: joint -> frames of joint targets (a foot carrying one keeps its generated path there).
    Returns the motion and ``{"translated_feet_segments", "translated_feet_steps"}``."""
    report = {"translated_feet_segments": 0, "translated_feet_steps": 0}
    if not feet or motion.local_translations is None or motion.num_frames < 3:
        return motion, report
    G, P = motion.global_transforms()
    new, rots = P.clone(), motion.local_rotations.clone()
    for foot in feet:
        path, segs, steps = _foot_path(P, foot, size, motion.fps, contacts)
        keep = _hold_weights(foot, hold or {}, motion.skeleton, motion.num_frames).to(P.dtype)
        new[:, foot.joint] = keep[:, None] * P[:, foot.joint] + (1 - keep[:, None]) * path
        world = G[:, foot.joint]  # held in the world: joint 0 may turn with the body
        held = _nlerp(_held_rotation(world, segs), world, keep.to(world.dtype))
        rots[:, foot.joint] = quat_mul(quat_inverse(G[:, 0]), held).to(rots.dtype)
        report["translated_feet_segments"] += len(segs)
        report["translated_feet_steps"] += steps
    lt = motion.local_translations.clone()
    inv = quat_inverse(G[:, 0])
    for foot in feet:
        lt[:, foot.joint] = quat_rotate(inv, new[:, foot.joint] - P[:, 0])
    out = Motion(motion.skeleton, motion.fps, motion.root_translation, rots, motion.foot_contacts, lt)
    return out, report


def _nlerp(a: torch.Tensor, b: torch.Tensor, w: torch.Tensor) -> torch.Tensor:
    """Per frame, quaternions ``a (T, 4)`` turned towards ``b`` by weight ``w (T,)`` (normalised lerp)."""
    b = torch.where(((a * b).sum(-1, keepdim=True) < 0), -b, b)
    q = (1 - w[:, None]) * a + w[:, None] * b
    return q / q.norm(dim=-1, keepdim=True).clamp_min(1e-12)


def _held_rotation(q: torch.Tensor, segments: list[tuple[int, int]]) -> torch.Tensor:
    """The foot bone's world rotations ``q (T, 4)`` held at the middle frame's over each planted run
    (blended in and out like the position): its rotation swings the toes it carries, which would
    otherwise slide while the bone stands still."""
    out = q.clone()
    for a, b in segments:
        w = _ramp(a, b, q.shape[0], q.dtype)
        out = _nlerp(out, q[(a + b - 1) // 2].expand_as(q), w)
    return out


def _foot_path(
    P: torch.Tensor, foot: TranslatedFoot, size: float, fps: float, contacts: torch.Tensor | None
) -> tuple[torch.Tensor, list[tuple[int, int]], int]:
    """The foot bone's new world path ``(T, 3)`` (the floor is y = 0), its planted runs ``[a, b)`` and
    its number of steps."""
    j = foot.joint
    pos = smooth_time(P[:, j], SMOOTH_SECONDS * fps)
    rest = torch.tensor(foot.rest, dtype=P.dtype)
    clear = (P[:, list(foot.soles), 1] - rest).amin(1) + (pos[:, 1] - P[:, j, 1])  # lowest sole above its stand
    planted = _planted(smooth_time(clear[:, None], DETECT_SECONDS * fps)[:, 0], foot, size, fps, contacts)
    slow = smooth_time(P[:, j], DRIFT_SECONDS * fps)  # where the body takes the foot, without the shaking
    lifted = pos.clone()
    lifted[:, 1] += (-clear).clamp_min(0.0)  # never below the floor
    out, segs, steps = lifted.clone(), [], 0
    T = P.shape[0]
    for a, b in contact_segments(planted):
        if b - a < MIN_FRAMES:
            continue
        target, n = _planted_target(pos[a:b], slow[a:b], clear[a:b], size)
        segs, steps = [*segs, (a, b)], steps + n
        w = _ramp(a, b, T, P.dtype)
        full = lifted.clone()
        full[a:b] = target
        full[:a, [0, 2]] = target[0, [0, 2]]
        full[b:, [0, 2]] = target[-1, [0, 2]]
        out = (1 - w[:, None]) * out + w[:, None] * full
    return out, segs, steps


def _planted(clear: torch.Tensor, foot: TranslatedFoot, size: float, fps: float, contacts) -> torch.Tensor:
    """``(T,)`` planted flags of a foot from its (smoothed) clearance and the model's contact channel."""
    w = max(1, round(BASELINE_SECONDS * fps / 2))
    baseline = -torch.nn.functional.max_pool1d(-clear[None, None], 2 * w + 1, stride=1, padding=w)[0, 0]
    planted = (clear < GROUND * size) | ((clear - baseline < GROUND * size) & (clear < BELIEVE * size))
    if contacts is not None and foot.channels:
        said = torch.as_tensor(contacts)[:, list(foot.channels)].to(clear.dtype).amax(1) > 0.5
        planted |= said & (clear < BELIEVE * size)
    return planted


def _planted_target(
    pos: torch.Tensor, slow: torch.Tensor, clear: torch.Tensor, size: float
) -> tuple[torch.Tensor, int]:
    """Where a planted foot is over its run ``pos (n, 3)``: sole on the floor, held at one ground point
    until the model's foot, followed without its shaking (``slow``), is ``REACH`` away, then a lifted
    step to where it goes; and the number of steps."""
    n = pos.shape[0]
    out = pos.clone()
    out[:, 1] = pos[:, 1] - clear  # the lowest sole exactly at its rest height
    anchor, starts = slow[0, [0, 2]], []
    xz = torch.empty(n, 2, dtype=pos.dtype)
    for t in range(n):
        if float((slow[t, [0, 2]] - anchor).norm()) > REACH * size:
            land = slow[min(t + STEP_FRAMES // 2, n - 1), [0, 2]]
            ahead = land - anchor
            anchor = land + 0.5 * REACH * size * ahead / ahead.norm().clamp_min(1e-12)  # lands ahead, as feet do
            starts.append(t)
        xz[t] = anchor
    for s in starts:  # the step: from the old anchor to the new one, lifted in the middle
        a, b = max(s - STEP_FRAMES // 2, 0), min(s + STEP_FRAMES - STEP_FRAMES // 2, n)
        old, new = xz[max(a - 1, 0)].clone(), xz[s].clone()
        for t in range(a, b):
            u = (t - a + 1) / (b - a + 1)
            xz[t] = old + (new - old) * (3 * u**2 - 2 * u**3)
            out[t, 1] += STEP_HEIGHT * size * math.sin(math.pi * u)
    out[:, 0], out[:, 2] = xz[:, 0], xz[:, 1]
    return out, len(starts)


def _ramp(a: int, b: int, T: int, dtype) -> torch.Tensor:
    """``(T,)`` weight: 1 on frames ``[a, b)``, falling linearly to 0 over ``BLEND`` frames each side."""
    w = torch.zeros(T, dtype=dtype)
    w[a:b] = 1.0
    for k in range(1, BLEND + 1):
        v = 1.0 - k / (BLEND + 1)
        if a - k >= 0:
            w[a - k] = v
        if b - 1 + k < T:
            w[b - 1 + k] = v
    return w


def _hold_weights(foot: TranslatedFoot, hold: dict[int, list[int]], skeleton: Skeleton, T: int) -> torch.Tensor:
    """``(T,)`` weight of the generated path: 1 on frames with a joint target on the foot or a joint it
    carries (so the exact pass's result stands), falling to 0 over ``BLEND`` frames."""
    w = torch.zeros(T, dtype=torch.float64)
    for j, frames in hold.items():
        if foot.joint not in skeleton.path_from_root(j):
            continue
        for f in frames:
            w = torch.maximum(w, _ramp(int(f), int(f) + 1, T, torch.float64))
    return w


def with_floor_translations(m: Motion, feats: torch.Tensor, rep: JointRepresentation) -> Motion:
    """``m`` (posed from rotations) with the bones under a floor-level armature joint (`floor_root_children`)
    moved as in the data: the armature stays on the floor (y = 0) below the root, the root keeps the
    position the root row gave it, and every other such bone takes its translation from the predicted
    joint positions ``feats (T, J, 13)`` (the motion's units), so feet driven by IK bones follow the model."""
    root = rep.rig.root
    path = m.skeleton.path_from_root(root)
    kids = floor_root_children(m.skeleton)
    joints = [j for j in kids if j not in path]
    move_root = len(path) == 2 and root in kids  # the root hangs directly from the armature
    if not joints and not move_root:
        return m
    G, P = m.global_transforms()
    f = feats.to(P.dtype)
    psi = torch.atan2(f[:, root, ROOT_HEADING_SIN], f[:, root, ROOT_HEADING_COS])
    T = m.num_frames
    world = P[:, root : root + 1] + quat_rotate(yaw_quat(psi)[:, None].expand(T, len(joints), 4), f[:, joints, POS])
    trans = m.root_translation.to(P.dtype).clone()
    if move_root:
        trans[:, 1] -= P[:, 0, 1]  # joint 0 back on the floor; the root's own translation carries the height
        joints, world = [*joints, root], torch.cat([world, P[:, root : root + 1]], dim=1)
    base = P[:, :1] - (m.root_translation.to(P.dtype) - trans)[:, None]
    lt = m.skeleton.offsets.to(P.dtype)[None].repeat(T, 1, 1)
    lt[:, joints] = quat_rotate(quat_inverse(G[:, :1]).expand(T, len(joints), 4), world - base)
    return Motion(m.skeleton, m.fps, trans, m.local_rotations, m.foot_contacts, lt)
