"""Steps of any-rig post-processing around kinema.postprocess: de-jittering with its own check
(`dejitter`), the root put back where keyframes and root waypoints placed it (`root_pins`, `pin_root`) and
one warning for the targets left unmet on the finished motion (`unmet_warnings`, in centimetres of the rig
in metres). Shapes: motions ``(T, J, ...)``; frames at the motion's fps.
"""

from __future__ import annotations

import math
from dataclasses import replace

import torch

from kinema.anyrig.feet import floor_root_children
from kinema.geometry.rotations import quat_angle_deg, quat_inverse, quat_rotate
from kinema.motion.core import Motion
from kinema.postprocess.guard import DEFAULT_BOUNDS, plausibility, violations
from kinema.postprocess.ik import spread_corrections
from kinema.postprocess.smooth import DEFAULT_ROT_SIGMA_SECONDS, DEFAULT_SIGMA_SECONDS, smooth_motion
from kinema.postprocess.targets import PostTargets


def dejitter(m: Motion) -> tuple[Motion, dict, list[str]]:
    """``m`` de-jittered as kinema.postprocess does (Gaussians on the root x/z and the local rotations),
    its report and warnings. Checked here, not by the shared guard: the guard undoes a stage that drags
    the pelvis faster than 3 units/s, and smoothing a shaking pelvis "drags" it at the speed of the
    shaking (the held-out alpaca's de-jittering was undone and its jerk stayed 58x its own clips').
    Smoothing cannot throw a body anywhere; it is held to the guard's other bounds (joint acceleration,
    pelvis speed; kinema.postprocess.guard.violations without the drag rule) and undone, with a warning,
    beyond them."""
    new, report = smooth_motion(m, DEFAULT_SIGMA_SECONDS, DEFAULT_ROT_SIGMA_SECONDS)
    raw = plausibility(m)
    no_drag = replace(DEFAULT_BOUNDS, added_pelvis_speed=math.inf)
    problems = violations(raw, raw, plausibility(new), no_drag)
    if problems:
        report["undone"] = problems
        return m, report, [f"post-processing: de-jittering undone, it made the motion worse: {'; '.join(problems)}"]
    return new, report, []


def unmet_warnings(worst: list[tuple[float, str, int]], fps: float, said: list[str], tol_cm: float = 1.0) -> list[str]:
    """One warning naming the joint targets left more than ``tol_cm`` away after post-processing
    (``worst``: per joint, its largest error in cm, its name and that frame), the worst three first."""
    bad = sorted((w for w in worst if w[0] > tol_cm), reverse=True)
    if not bad:
        return []
    named = ", ".join(f"{name} at frame {f} ({f / fps:.2f} s) {cm:.1f} cm away" for cm, name, f in bad[:3])
    more = f" and {len(bad) - 3} more joint(s)" if len(bad) > 3 else ""
    text = f"constraint not met after post-processing: {named}{more}"
    return [] if text in said else [text]


def root_pins(
    targets: PostTargets | None, root: int, waypoint_frames: list[int], before: Motion, after: Motion
) -> dict[int, torch.Tensor]:
    """Frame -> where the root joint must be after post-processing: a keyframe's root target (3D), and
    on a root path's waypoint frames the ground position the sampled motion ``before`` post-processing
    had (it meets the waypoints exactly) at the height post-processing gave it (``after``); frames with
    other joint targets keep ``after``'s root (the exact pass placed those joints around it)."""
    pins: dict[int, torch.Tensor] = {}
    P = after.positions
    if targets is not None and root in targets.joint_positions:
        frames, pos = targets.joint_positions[root]
        for f, p in zip(frames.tolist(), pos.to(P.dtype), strict=True):
            pins.setdefault(int(f), p)
    B = before.positions.to(P.dtype)
    for f in waypoint_frames:
        if f not in pins and 0 <= f < after.num_frames:
            pins[f] = torch.stack([B[f, root, 0], P[f, root, 1], B[f, root, 2]])
    if pins and targets is not None:  # frames whose joint targets the exact pass met: the root stays
        for frames, _ in targets.joint_positions.values():
            for f in frames.tolist():
                pins.setdefault(int(f), P[int(f), root])
    return pins


def pin_root(m: Motion, pins: dict[int, torch.Tensor], root: int, reach_s: float = 0.5) -> Motion:
    """``m`` moved so that its root joint is exactly at ``pins`` (frame -> position; `root_pins`):
    de-jittering moves the root (on a rig whose body hangs from a floor-level armature, also by
    smoothing the armature's rotation), and the exact pass turns joints but does not move the root back.
    The offsets at the pinned frames are interpolated linearly between them and fade to zero over
    ``reach_s`` seconds before the first and after the last; other frames keep post-processing's root."""
    if not pins:
        return m
    P = m.positions
    T, n = m.num_frames, max(1, round(reach_s * m.fps))
    keys = sorted(pins)
    anchors = [(f, pins[f].to(P.dtype) - P[f, root]) for f in keys]
    if keys[0] > 0:
        anchors.insert(0, (max(0, keys[0] - n), torch.zeros(3, dtype=P.dtype)))
    if keys[-1] < T - 1:
        anchors.append((min(T - 1, keys[-1] + n), torch.zeros(3, dtype=P.dtype)))
    shift = torch.zeros(T, 3, dtype=P.dtype)
    for (fa, da), (fb, db) in zip(anchors, anchors[1:], strict=False):
        w = torch.linspace(0.0, 1.0, fb - fa + 1, dtype=P.dtype)[:, None]
        shift[fa : fb + 1] = (1 - w) * da + w * db
    if len(anchors) == 1:
        shift[anchors[0][0]] = anchors[0][1]
    root_t = m.root_translation.to(P.dtype) + shift
    return Motion(m.skeleton, m.fps, root_t, m.local_rotations, m.foot_contacts, m.local_translations)


def translatable_bones(skeleton, root: int, root_fixed: bool) -> set[int]:
    """Joints whose translation `reach_by_translation` may change: joint 0 and the bones under a
    floor-level armature (kinema.anyrig.feet.floor_root_children), but not the rig root or its
    path when keyframes, root paths or a copied root motion (``root_fixed``) decide where the root is."""
    movable = {0, *floor_root_children(skeleton)}
    return movable - set(skeleton.path_from_root(root)) if root_fixed else movable


def translation_carrier(skeleton, joint: int, movable: set[int]) -> int | None:
    """The nearest of ``joint`` and its ancestors whose translation post-processing may change (``movable``:
    joint 0, whose translation is the root's, and the bones that carry animated translations), or None."""
    j = joint
    while j >= 0:
        if j in movable:
            return j
        j = skeleton.parents[j]
    return None


def reach_by_translation(
    m: Motion, targets: PostTargets, movable: set[int], *, tol: float = 0.005, limit: float = 0.25, blend_s: float = 0.3
) -> tuple[Motion, dict[str, float]]:
    """Joint-position targets still missed after the exact pass, met by translating the nearest bone
    that carries a translation (`translation_carrier`; the whole body when that is joint 0) by what is
    left, blended in and out over ``blend_s`` (kinema.postprocess.ik.spread_corrections). Why: on rigs
    whose body hangs from a floor-level armature the bones' translations are set after the rotation-only
    exact pass (the snake's head was left 10-16 cm off), and a joint right below joint 0 (a dolphin's
    head) has no two-bone chain. Misses above ``limit`` (rig units; the rest pose is 1 across) are left
    to the unmet-constraint warning rather than dragging the body. Returns the motion and
    {joint name: largest shift}; ``m`` itself when nothing moved."""
    skel, T = m.skeleton, m.num_frames
    moved: dict[str, float] = {}
    for j, (frames, pos) in targets.joint_positions.items():
        carrier = translation_carrier(skel, j, movable)
        G, P = m.global_transforms()
        miss = pos.to(P.dtype) - P[frames, j]
        size = miss.norm(dim=-1)
        if carrier is None or float(size.max()) <= tol or float(size.max()) > limit:
            continue
        field, env = spread_corrections(frames, miss, T, max(1.0, blend_s * m.fps))
        delta = field * env[:, None]
        if carrier == 0:
            m = replace(m, root_translation=m.root_translation + delta.to(m.root_translation.dtype))
        else:
            parent = skel.parents[carrier]
            lt = (skel.offsets[None].repeat(T, 1, 1) if m.local_translations is None else m.local_translations).clone()
            local = quat_rotate(quat_inverse(G[:, parent]), delta)
            lt[:, carrier] += local.to(lt.dtype)
            m = replace(m, local_translations=lt)
        moved[skel.names[j]] = float(size.max())
    return m, moved


def rotation_errors_deg(m: Motion, targets: PostTargets) -> list[float]:
    """Angle (degrees) between each joint-rotation target and the joint's global rotation in ``m`` (any
    uniform scale of ``m`` leaves rotations alone, so targets of the rig in its units apply)."""
    G = m.global_rotations.to(torch.float64)
    out: list[float] = []
    for j, (frames, q) in targets.joint_rotations.items():
        out += quat_angle_deg(G[frames, j], q.to(torch.float64)).tolist()
    return out
