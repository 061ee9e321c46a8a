"""Steps of any-rig post-processing around kinema.postprocess: de-jittering with its own check
(`dejitter`), the exact pass on character-frame targets that never moves the character frame
(`exact_in_character_frame`), the guard against stages that lift the body (`lift_problem`), the root put
back where keyframes and root waypoints placed it (`root_pins`, `pin_root`) and one warning for the
targets left unmet on the finished motion (`unmet_warnings`, in centimetres of the rig in metres).
Shapes: motions ``(T, J, ...)``; frames at the motion's fps.
"""

from __future__ import annotations

import math
from dataclasses import replace

import torch

from kinema.anyrig.feet import floor_root_children
from kinema.geometry.rotations import quat_angle_deg, quat_inverse, quat_mul, quat_rotate
from kinema.motion.core import Motion
from kinema.postprocess import postprocess as run_postprocess
from kinema.postprocess.guard import DEFAULT_BOUNDS, plausibility, violations
from kinema.postprocess.ik import spread_corrections
from kinema.postprocess.smooth import DEFAULT_ROT_SIGMA_SECONDS, DEFAULT_SIGMA_SECONDS, smooth_motion
from kinema.postprocess.targets import PostTargets
from kinema.representation.joint import yaw_quat


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


#: rounds of the exact pass on character-frame targets (`exact_in_character_frame`); each round meets
#: what the limbs can of the miss the root's return left (measured, rig units: a world foot target 5 cm
#: above the first pass's foot 0.14 -> 0.047 -> 0.017 -> 0.005; the test quadruped's head target
#: 0.044 -> 0.029 -> 0.022 -> 0.019) and costs one exact pass
EXACT_ROUNDS = 4
#: x rig size: how far a stage after grounding may raise the root above its input (`lift_problem`)
LIFT_TOL = 0.02


def root_at(m: Motion, where: torch.Tensor, root: int, lean: bool = False) -> Motion:
    """``m`` translated, frame by frame, so that its root joint is at ``where (T, 3)``; ``lean``: only
    where it rose above ``where`` (it keeps moves across the ground and down)."""
    P = m.positions
    shift = where.to(P.dtype) - P[:, root]
    if lean:
        shift[:, [0, 2]] = 0.0
        shift[:, 1] = shift[:, 1].clamp(max=0.0)
    return replace(m, root_translation=m.root_translation + shift.to(m.root_translation.dtype))


def heading_at(m: Motion, psi: torch.Tensor, rep) -> Motion:
    """``m`` turned rigidly about its root joint, frame by frame, so that its heading (``rep.heading``,
    kinema.representation.joint) is ``psi (T,)``: joint 0's rotation and translation are turned, so every
    joint's position relative to the root and in the character frame stays as it was."""
    m64 = m.to(torch.float64)
    G, P = m64.global_transforms()
    d = torch.remainder(psi.to(torch.float64) - rep.heading(G) + math.pi, 2 * math.pi) - math.pi
    q = yaw_quat(d)
    pivot = P[:, rep.rig.root]
    rot = m64.local_rotations.clone()
    rot[:, 0] = quat_mul(q, rot[:, 0])
    trans = pivot + quat_rotate(q, m64.root_translation - pivot)
    return replace(
        m, root_translation=trans.to(m.root_translation.dtype), local_rotations=rot.to(m.local_rotations.dtype)
    )


def target_miss(m: Motion, targets: PostTargets) -> float:
    """Largest distance between a joint and its position target (the motion's units; 0 without any)."""
    P = m.positions
    return max((float((P[f, j] - p.to(P.dtype)).norm(dim=-1).max()) for j, (f, p) in targets.joint_positions.items()),
               default=0.0)


def exact_in_character_frame(
    m: Motion, raw: Motion, targets_of, rep, tol: float = 2e-3, lean: bool = False
) -> tuple[Motion, dict, PostTargets]:
    """The exact constraint pass of kinema.postprocess on targets given in the *character frame* (relative
    to the root joint and its heading), without moving or turning that frame. ``targets_of(motion)``
    places the targets in the world at ``motion``'s own root and heading
    (kinema.anyrig.targets.post_targets); ``rep``: the motion's representation (rig, root, heading).

    Why: the shared exact pass moves the body towards a target beyond its limb's reach (up to 0.5 rig
    sizes, kinema.postprocess.reach) and its optimisation moves the root; for a world target that is a
    lean or a step, but a character-frame target moves with the body, so the stag's head target above its
    reach lifted the whole animal into a hop the raw motion did not have while the residual, measured
    against the target placed before the move, said 0.00 cm (and a head rotation target turned the whole
    test quadruped 14 degrees). Here each round runs the pass, turns the body back to its heading and puts
    the root joint back on its path before the pass (`heading_at`, `root_at`), rigidly, unless the pass
    left both where they were (`_frame_kept`), and places the targets again in the frame of the result;
    the round with the smallest miss is kept (a target out of the body's reach stays unmet, and the
    caller reports it). ``lean``: the targets are fixed in the world (read in the frame
    of a copied root motion, kinema.anyrig.world): the body may move across the ground and down towards
    them (a lean, a step or a crouch, as for the human model) and turn, but not rise (no hop). Returns
    the motion, the pass's report and the targets it met."""
    root, rig = rep.rig.root, rep.rig
    G, P = m.to(torch.float64).global_transforms()
    path, psi = P[:, root].clone(), rep.heading(G)
    best = None
    for _ in range(EXACT_ROUNDS):
        targets = targets_of(m)
        new, report = run_postprocess(m, targets, rig=rig, foot_lock=False, smooth=0.0, smooth_rotations=0.0, raw=raw)
        if not _frame_kept(new, path, psi, rep, lean):
            new = root_at(new if lean else heading_at(new, psi, rep), path, root, lean)
        placed = targets_of(new)
        miss = target_miss(new, placed)
        if best is not None and miss > 0.9 * best[0]:  # no longer getting closer
            best = min(best, (miss, new, report, placed), key=lambda b: b[0])
            break
        best = (miss, new, report, placed)
        if miss <= tol:
            break
        m = new
    return best[1], best[2], best[3]


#: a pass that moves the root less than this (x rig size) and turns it less than `TURN_TOL_DEG` keeps the
#: frame: its result stands as it is (every target exact in it)
FRAME_TOL = 0.002
TURN_TOL_DEG = 0.2


def _frame_kept(m: Motion, path: torch.Tensor, psi: torch.Tensor, rep, lean: bool) -> bool:
    """Whether ``m``'s root is still on ``path`` (``lean``: not above it) and its heading ``psi``."""
    G, P = m.to(torch.float64).global_transforms()
    off = P[:, rep.rig.root] - path
    moved = float(off[:, 1].clamp(min=0.0).max()) if lean else float(off.norm(dim=-1).max())
    turn = torch.remainder(rep.heading(G) - psi + math.pi, 2 * math.pi) - math.pi
    return moved <= FRAME_TOL and (lean or math.degrees(float(turn.abs().max())) <= TURN_TOL_DEG)


def lift_problem(before: Motion, after: Motion, root: int, size: float, stage: str) -> str | None:
    """A warning when ``stage`` raised the root joint more than ``LIFT_TOL`` x ``size`` above where it
    was in its input ``before`` (a hop or lift the motion as generated does not have), else None."""
    rise = after.positions[:, root, 1] - before.positions[:, root, 1].to(after.positions.dtype)
    f = int(rise.argmax())
    if float(rise[f]) <= LIFT_TOL * size:
        return None
    return (f"post-processing: {stage} undone, it lifted the body {float(rise[f]) / size:.2f} rig sizes above "
            f"the motion as generated at frame {f}")


def unmet_warnings(
    worst: list[tuple[float, str, int]], fps: float, said: list[str], tol_cm: float = 1.0, post: bool = True
) -> list[str]:
    """One warning naming the joint targets left more than ``tol_cm`` away on the finished motion
    (``worst``: per joint, its largest error in cm, its name and that frame), the worst three first;
    ``post``: whether the motion was post-processed (the warning says which)."""
    bad = sorted((w for w in worst if w[0] > tol_cm), reverse=True)
    if not bad:
        return []
    named = ", ".join(f"{name} at frame {f} ({f / fps:.2f} s) {cm:.1f} cm away" for cm, name, f in bad[:3])
    more = f" and {len(bad) - 3} more joint(s)" if len(bad) > 3 else ""
    when = "after post-processing" if post else "(post-processing off)"
    text = f"constraint not met {when}: {named}{more}"
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


def translatable_bones(skeleton, root: int) -> set[int]:
    """Bones whose translation `reach_by_translation` may change: those under a floor-level armature
    (kinema.anyrig.feet.floor_root_children), never joint 0 or the path to the rig root: a target in
    the character frame moves with the root, so moving the root towards it only lifts or drags the whole
    body (the hop of issue 34) while the target, measured where it was placed before, looks met."""
    return set(floor_root_children(skeleton)) - {0, *skeleton.path_from_root(root)}


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
