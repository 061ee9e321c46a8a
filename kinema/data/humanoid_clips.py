"""Quaternius humanoid clips onto the human skeleton: chain, pad with the character's idle, retarget,
measure the side.

Game clips are short (a kick is 0.6-1 s, a punch 0.6 s) and start and end in the character's own
stance; the captures the human model learned from start and end standing for seconds. So each action
is *padded* on the character, before retargeting: `PAD_SECONDS` of the character's idle (once with
each length), the action (its clips chained: a platformer jump is take-off, airborne loop, landing),
then idle again (or the last pose held, for a fall), each join cross-faded over `BLEND_SECONDS` (local
rotations slerped, root and bone translations lerped). Looping clips (dance) are repeated to
`LOOP_SECONDS` first.

The padded clip is then retargeted onto the human skeleton (kinema.retarget: humanoid slots, rest-pose
alignment, leg-length scale, planted feet held) as one motion, so a jump that ends in the air in its
take-off clip lands again; the pelvis is straightened against the spine (`upright_pelvis`), and the clip
is put on the floor by its standing idle (`on_the_floor`).

Root motion: the file's root is kept (kinema.data.humanoid_build says why no travel is recovered).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from kinema.data.creature_captions import clean_clip_name
from kinema.data.humanoid_actions import HUMANOID_ACTIONS, IDLE_NAMES, HumanoidAction
from kinema.geometry.rotations import quat_between, quat_inverse, quat_mul, quat_normalize, quat_slerp
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

#: idle on each side of an action; every action is built once per length. With 1 s alone (a 2.9-s punch
#: clip) an expert punched at 2.85 s and not at 4; with 2 s alone it kicked in 5-s requests and timeline
#: segments but no longer in 3-s ones (issue 38, stop 54: docs/training.md). Both: clips 2.8-7 s
PAD_SECONDS = (1.0, 2.0)
BLEND_SECONDS = 0.2
LOOP_SECONDS = 3.0


@dataclass
class HumanoidClip:
    """One action clip on the human skeleton, before mirroring."""

    file: str  # path relative to the dataset root
    clip: str  # the action's first clip name, as in the file
    chained: tuple[str, ...]  # every clip name chained into it
    action: HumanoidAction
    side: str | None  # measured: left/right (kicks, punches), forward/backward (falls), None
    motion: Motion  # on the human skeleton
    action_frames: tuple[int, int]  # [start, end) of the action inside the padded clip
    pad_seconds: float  # the idle on either side (one of PAD_SECONDS)


def _blend(a: Motion, b: Motion, overlap: int) -> Motion:
    """``a`` then ``b``, the last ``overlap`` frames of ``a`` cross-faded into the first of ``b``."""
    overlap = min(overlap, a.num_frames - 1, b.num_frames - 1)
    if overlap <= 0:
        return a.concatenate(b)
    w = 0.5 - 0.5 * torch.cos(math.pi * (torch.arange(overlap, dtype=a.dtype) + 1) / (overlap + 1))
    qa, qb = a.local_rotations[-overlap:], b.local_rotations[:overlap]
    qb = torch.where((qa * qb).sum(-1, keepdim=True) < 0, -qb, qb)
    rots = quat_normalize(quat_slerp(qa, qb, w[:, None]))
    root = a.root_translation[-overlap:] * (1 - w[:, None]) + b.root_translation[:overlap] * w[:, None]
    ta, tb = a.translations_or_offsets()[-overlap:], b.translations_or_offsets()[:overlap].to(a.dtype)
    trans = ta * (1 - w[:, None, None]) + tb * w[:, None, None]
    mid = Motion(a.skeleton, a.fps, root, rots, None, trans)
    head = a.crop(0, a.num_frames - overlap) if a.num_frames > overlap else None
    out = mid if head is None else _concat(head, mid)
    return _concat(out, b.crop(overlap)) if b.num_frames > overlap else out


def _concat(a: Motion, b: Motion) -> Motion:
    """``a`` then ``b`` (Motion.concatenate; contacts dropped: they are estimated again after retargeting)."""
    out = a.concatenate(b)
    out.foot_contacts = None
    return out


def _repeat_to(motion: Motion, frames: int) -> Motion:
    """``motion`` played again and again until it has ``frames`` frames (the last repeat cut short)."""
    out = motion
    while out.num_frames < frames:
        out = _concat(out, motion)
    return out.crop(0, frames) if out.num_frames > frames else out


def _hold(motion: Motion, frames: int) -> Motion:
    """The last pose of ``motion`` held for ``frames`` frames."""
    last = motion.crop(motion.num_frames - 1)
    return _repeat_to(last, frames)


def pad_action(clips: list[Motion], idle: Motion | None, *, loop: bool, after: str,
               pad_seconds: float) -> tuple[Motion, tuple[int, int]]:
    """The chained action clips padded with ``pad_seconds`` of idle (or a held last pose) on both sides;
    returns the padded motion (on the character) and the action's [start, end) frames in it."""
    fps = clips[0].fps
    action = clips[0]
    for c in clips[1:]:
        action = _concat(action, c)
    if loop:
        action = _repeat_to(action, round(LOOP_SECONDS * fps))
    pad, blend = round(pad_seconds * fps), round(BLEND_SECONDS * fps)
    before = _repeat_to(idle, pad + blend) if idle is not None else _hold(action.crop(0, 1), pad + blend)
    out = _blend(before, action, blend)
    start = before.num_frames - min(blend, before.num_frames - 1, action.num_frames - 1)
    end = out.num_frames
    tail = _hold(action, pad + blend) if after == "hold" or idle is None else _repeat_to(idle, pad + blend)
    return _blend(out, tail, blend), (start, end)


def measured_side(action: HumanoidAction, motion: Motion, frames: tuple[int, int]) -> str | None:
    """The side the motion shows on the human skeleton (Bandai names ``Foot_L`` ...), over the action's
    frames: the foot that rises higher (kicks), the hand that reaches farther forward of the hips
    relative to its own start (punches; the body faces +Z after retargeting), the direction the hips
    travel (falls)."""
    if action.sided is None:
        return None
    P = motion.positions[frames[0] : frames[1]]
    names = list(motion.skeleton.names)
    j = {n: names.index(n) for n in ("Hips", "Foot_L", "Foot_R", "Hand_L", "Hand_R")}
    if action.sided == "foot":
        return "left" if float(P[:, j["Foot_L"], 1].max()) > float(P[:, j["Foot_R"], 1].max()) else "right"
    if action.sided == "hand":
        reach = {s: P[:, j[f"Hand_{s[0].upper()}"], 2] - P[:, j["Hips"], 2] for s in ("left", "right")}
        gain = {s: float(r.max() - r[0]) for s, r in reach.items()}
        return max(gain, key=gain.get)
    travel = float(P[-1, j["Hips"], 2] - P[0, j["Hips"], 2])
    return "forward" if travel > 0 else "backward"


def on_the_floor(motion: Motion, standing: int) -> Motion:
    """``motion`` (on the human skeleton) moved up or down so that over its first ``standing`` frames (the
    idle before the action) the lower toe is where the skeleton's rest pose has it. The retargeting's
    floor is the clip's lowest joint over all frames, which a hand on the ground (a mech's pick-up) or a
    body lying down can take below the toes: those clips came out floating by up to 0.36 m."""
    from kinema.retarget.align import rest_frames

    names = list(motion.skeleton.names)
    toes = [names.index("Toes_L"), names.index("Toes_R")]
    _, rest = rest_frames(motion.skeleton)
    lift = float(rest[toes, 1].min()) - float(motion.positions[: max(standing, 1), toes, 1].min())
    root = motion.root_translation.clone()
    root[:, 1] += lift
    return Motion(motion.skeleton, motion.fps, root, motion.local_rotations)


def upright_pelvis(motion: Motion) -> Motion:
    """``motion`` (on the human skeleton) with the pelvis turned, per frame, so that its bone to the spine
    continues the spine's bone to the chest; the children of the pelvis keep their world rotations.

    Why: a Quaternius trunk starts with short ``Body`` / ``Hips`` bones that bend against the rest of the
    spine, and the human's pelvis follows them. Measured on the first (standing) frame: pelvis -> spine
    40-70 degrees from vertical while spine -> chest is within 0-13 (the captures: 2-5 and 1-3), a kink at
    the waist that put the pelvis rotation channel 35-60 standard deviations away from every capture's."""
    names = list(motion.skeleton.names)
    hips, spine, chest = (names.index(n) for n in ("Hips", "Spine", "Chest"))
    G, P = (x.double() for x in motion.global_transforms())
    low, high = P[:, spine] - P[:, hips], P[:, chest] - P[:, spine]
    swing = quat_between(low / low.norm(dim=-1, keepdim=True), high / high.norm(dim=-1, keepdim=True))
    pelvis = quat_normalize(quat_mul(swing, G[:, hips]))
    local = motion.local_rotations.double().clone()
    local[:, hips] = pelvis
    for child in motion.skeleton.children[hips]:
        local[:, child] = quat_normalize(quat_mul(quat_inverse(pelvis), G[:, child]))
    return Motion(motion.skeleton, motion.fps, motion.root_translation, local.to(motion.dtype))


def spine_mapping(character: Skeleton, human: Skeleton) -> dict[str, str]:
    """``{human spine: character joint}`` when the character's detected spine hangs *below* its hips.

    Quaternius rigs have ``Root -> Body -> Hips -> Abdomen -> Torso``: detection takes ``Body`` (where
    the legs and the chest meet) as the hips and the next joint towards the chest, Quaternius' ``Hips``,
    which points down from ``Body``, as the spine. The human's pelvis then follows that downward bone:
    retargeted this way its pelvis came out turned 141 degrees about the hip axis from every capture
    (the pelvis rotation channel 120-140 standard deviations off the captures') with the trunk folded
    at the waist (the head 0.1-0.3 m low). The human's spine is therefore mapped to the first joint
    on the way to the chest that sits above the hips at rest (``Abdomen``); empty when the spine is
    already above the hips."""
    from kinema.retarget import find_humanoid
    from kinema.retarget.align import rest_frames

    slots = find_humanoid(character).slots
    hips, spine, chest = slots.get("hips"), slots.get("spine"), slots.get("chest")
    if None in (hips, spine, chest):
        return {}
    _, rest = rest_frames(character)
    if float(rest[spine, 1]) > float(rest[hips, 1]):
        return {}
    path = character.path_from_root(chest)
    above = [j for j in path[path.index(hips) + 1 :] if float(rest[j, 1]) > float(rest[hips, 1]) and j != chest]
    human_spine = find_humanoid(human).slots.get("spine")
    if not above or human_spine is None:
        return {}
    return {human.names[human_spine]: character.names[above[0]]}


def find_idle(clips: dict[str, Motion]) -> Motion | None:
    """The character's idle clip (`IDLE_NAMES`, first found), or None."""
    by_name = {clean_clip_name(n): m for n, m in clips.items()}
    return next((by_name[n] for n in IDLE_NAMES if n in by_name), None)


def action_clips(rel: str, clips: dict[str, Motion], human: Skeleton) -> list[HumanoidClip]:
    """Every `HUMANOID_ACTIONS` clip of one character file, padded (once per `PAD_SECONDS`), retargeted
    onto ``human``, its side measured. A chained part the file lacks (a jump with no airborne loop) is
    skipped; a clip that is only a part of another action (``jump_land``) is not an action of its own."""
    from kinema.retarget import retarget

    by_name = {clean_clip_name(n): n for n in clips}
    idle = find_idle(clips)
    mapping = spine_mapping(next(iter(clips.values())).skeleton, human) or None
    out = []
    for key, (action, chain) in HUMANOID_ACTIONS.items():
        if key not in by_name:
            continue
        names = [by_name[c] for c in chain if c in by_name]
        for pad in PAD_SECONDS:
            padded, frames = pad_action([clips[n] for n in names], idle, loop=action.loop, after=action.after,
                                        pad_seconds=pad)
            motion = on_the_floor(upright_pelvis(retarget(padded, human, mapping)), frames[0])
            out.append(HumanoidClip(rel, names[0], tuple(names), action, measured_side(action, motion, frames),
                                    motion, frames, pad))
    return out
