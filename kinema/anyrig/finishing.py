"""From sampled any-rig features to the finished motion in metres (`finish_motion`): the post-processing
chain of the any-rig pipeline, in rig units (rest pose 1 across, so the human-tuned thresholds of
kinema.postprocess mean the same on a fish and a T-rex).

Order: features -> motion; put on the floor and settled onto its legs (kinema.anyrig.ground); de-jittered
and post-processed (kinema.postprocess); the exact pass on joint targets and keyframes in the character
frame (kinema.anyrig.post); the root pinned back to its keyframes and waypoints; the translations of bones
under a floor-level armature restored and targets they carry reached by translation; translated feet
locked (kinema.anyrig.feet) and joint ties held (kinema.anyrig.tied); scaled to metres; the residuals of
the targets measured on that final motion. Every stage that would lift the body or make the motion less
plausible is undone with a warning in the report.
"""

from __future__ import annotations

import torch

from kinema.anyrig.feet import (
    descendants,
    floor_height,
    floor_root_children,
    lock_translated_feet,
    rest_extent,
    translated_feet,
    with_floor_translations,
)
from kinema.anyrig.ground import ground_motion, leg_ends, settle_offsets, steady_height
from kinema.anyrig.post import (
    dejitter,
    exact_in_character_frame,
    lift_problem,
    pin_root,
    reach_by_translation,
    root_pins,
    rotation_errors_deg,
    translatable_bones,
    unmet_warnings,
)
from kinema.anyrig.targets import post_targets as make_post_targets
from kinema.anyrig.tied import hold_ties
from kinema.constraints.character import JointTarget, Keyframe, RootMotion, RootPath
from kinema.motion.core import Motion
from kinema.postprocess import postprocess as run_postprocess
from kinema.postprocess.guard import plausibility, violations
from kinema.representation.joint import JointRepresentation
from kinema.rig import Rig


def finish_motion(f, rep_n, rig_m: Rig, scale: float, constraints, postprocess: bool, report, ties=None) -> Motion:
    """One sample's features ``f`` ``(T, J, C)`` of the normalised representation ``rep_n`` (scale
    ``scale`` from ``rig_m`` in metres) -> the motion on ``rig_m`` in metres, post-processed when
    ``postprocess`` (the stages in the module docstring; ``report``, a GenerationReport, collects what each
    did). The floor is not moved when a keyframe or a copied root motion fixes the root. Bones under a
    floor-level armature get their translations after post-processing (which works on rotations) and their
    feet are cleaned up and locked directly (kinema.anyrig.feet). ``ties``: the rig's joint ties in its
    units (kinema.anyrig.tied), held last."""
    m = rep_n.to_motion(f)
    targets = None
    moved = floor_root_children(m.skeleton)
    if postprocess:
        m, f = _ground(m, f, rep_n, constraints, report)
        if _leading_context(constraints):  # a stream's context is continued, not hit again (kinema.stream)
            constraints = [c for c in constraints if not isinstance(c, (Keyframe, RootMotion))]
        targets = make_post_targets(constraints, m, rep_n, scale, moved) if constraints else None
        before, root = m, rep_n.rig.root
        m, smoothed, warned = dejitter(m)
        m, post = run_postprocess(m, None, rig=rep_n.rig, smooth=0.0, smooth_rotations=0.0, raw=before)
        post["smooth"] = smoothed
        report.warnings += [w for w in warned if w not in report.warnings]
        if targets is not None:
            m, targets = _hit(m, before, constraints, rep_n, scale, moved, post, report)
        m = pin_root(m, root_pins(targets, root, _waypoint_frames(constraints), before, m), root)
        # unmet constraints are said once, measured on the finished motion in metres (below)
        news = [w for w in post.get("warnings", []) if not w.startswith("constraint not met")]
        report.warnings += [w for w in news if w not in report.warnings]
    m = with_floor_translations(m, f, rep_n)
    if targets is not None:
        reached, shifts = reach_by_translation(m, targets, translatable_bones(m.skeleton, rep_n.rig.root))
        m = _unless_lifted(m, reached, rep_n.rig.root, "reaching targets by translation", report)
        if m is reached:
            for name, size in shifts.items():
                report.reached_by_translation[name] = max(size, report.reached_by_translation.get(name, 0.0))
    if postprocess:
        m, locked = _lock_feet(m, rep_n, targets, report)
        m, held = hold_ties(m, ties, rep_n.rig.root) if ties is not None else (m, {})  # kinema.anyrig.tied
        report.foot_lock.append({**post.get("foot_lock", {}), **locked, **held})
    lt = None if m.local_translations is None else m.local_translations / scale
    motion = Motion(rig_m.skeleton, m.fps, m.root_translation / scale, m.local_rotations, m.foot_contacts, lt)
    if any(isinstance(c, (JointTarget, Keyframe)) for c in constraints):
        _measure(motion, constraints, rig_m, moved, postprocess, report)
    return motion


def _hit(m: Motion, raw: Motion, constraints, rep_n, scale: float, moved, post: dict, report):
    """The exact pass on the joint targets and keyframes, in the character frame of the motion it
    edits (kinema.anyrig.post.exact_in_character_frame), undone when it lifts the body. Returns the
    motion and the world targets it aimed at (those of its input when undone)."""

    def placed(x: Motion):
        return make_post_targets(constraints, x, rep_n, scale, moved)

    world = any(isinstance(c, RootMotion) for c in constraints)  # targets read in a copied root's frame
    hit, exact, targets = exact_in_character_frame(m, raw, placed, rep_n, lean=world)
    post["exact"] = exact.get("exact", {})
    post["warnings"] = post.get("warnings", []) + exact.get("warnings", [])
    kept = _unless_lifted(m, hit, rep_n.rig.root, "the exact constraint pass", report)
    return kept, (targets if kept is hit else placed(m))


def _unless_lifted(old: Motion, new: Motion, root: int, stage: str, report) -> Motion:
    """``new``, or ``old`` with a warning when ``stage`` lifted the body (kinema.anyrig.post.lift_problem;
    rig units)."""
    problem = lift_problem(old, new, root, 1.0, stage)
    if problem is None:
        return new
    report.warnings.append(problem)
    return old


def _measure(motion: Motion, constraints, rig_m: Rig, moved, post: bool, report) -> None:
    """Residuals of the joint targets and keyframes on the finished ``motion`` (metres), in *its*
    character frame (its own root and heading at each target frame: what a character-frame target
    asks for), and one warning naming the targets left unmet."""
    final = make_post_targets(constraints, motion.to(torch.float64), JointRepresentation(rig_m, motion.fps), 1.0, moved)
    P, worst = motion.positions.to(torch.float64), []
    for j, (frames, pos) in final.joint_positions.items():
        err = 100 * (P[frames, j] - pos).norm(dim=-1)
        report.residuals_cm += err.tolist()
        k = int(err.argmax())
        worst.append((float(err[k]), rig_m.skeleton.names[j], int(frames[k])))
    report.warnings += unmet_warnings(worst, motion.fps, report.warnings, post=post)
    report.residuals_deg += rotation_errors_deg(motion, final)


def _ground(m: Motion, f, rep_n, constraints, report) -> tuple[Motion, torch.Tensor]:
    """``m`` with a steadied root height, put on the floor by its contact joints and settled onto its
    legs (kinema.anyrig.ground), unless a keyframe or a copied root motion decides where the
    root is (but not a leading context alone: `_leading_context`); and the features ``f`` (the
    translated feet's moved to keep their world heights)."""
    rig = rep_n.rig
    context = _leading_context(constraints)
    alone = context is not None and context[0] == context[1]
    if any(isinstance(c, (Keyframe, RootMotion)) for c in constraints) and not alone:
        return m, f
    m, change = steady_height(m)
    report.height_smoothed = max(report.height_smoothed, change)
    if not rig.contacts:
        return m, f
    skel = rig.skeleton
    probe = with_floor_translations(m, f, rep_n)
    stands = {k: h for foot in translated_feet(rig, rig.root) for k, h in zip(foot.soles, foot.rest, strict=True)}
    rest = [stands.get(j, floor_height(skel, j)) for j in rig.contacts]
    m, off = ground_motion(m, probe, list(rig.contacts), rest, rest_extent(skel))
    report.grounded = max(report.grounded, off)
    return _settle(m, f, rep_n, report)


def _settle(m: Motion, f, rep_n, report) -> tuple[Motion, torch.Tensor]:
    """The body lowered (or raised) onto its legs where the model put its translated feet too far from
    them (kinema.anyrig.ground.settle_offsets); the feet keep their world heights (their
    root-relative features are moved the other way). Returns the motion and the features."""
    skel = rep_n.rig.skeleton
    kids = [j for j in floor_root_children(skel) if j not in skel.path_from_root(rep_n.rig.root)]
    feet = [foot.joint for foot in translated_feet(rep_n.rig, rep_n.rig.root)]
    legs = leg_ends(skel, feet, descendants(skel, kids), rest_extent(skel))
    if not legs:
        return m, f
    probe = with_floor_translations(m, f, rep_n)
    g = settle_offsets(probe.positions, legs, m.fps, rest_extent(skel))
    root = m.root_translation.clone()
    root[:, 1] -= g.to(root.dtype)
    f = f.clone()
    f[:, kids, 1] += g.to(f.dtype)[:, None]
    report.settled = max(report.settled, float(g.abs().max()))
    return Motion(m.skeleton, m.fps, root, m.local_rotations, m.foot_contacts, m.local_translations), f


def _lock_feet(m: Motion, rep_n, targets, report) -> tuple[Motion, dict]:
    """Translated feet locked (kinema.anyrig.feet), undone with a warning when that makes
    the motion less plausible than before by the post-processing guard's bounds."""
    skel = rep_n.rig.skeleton
    feet = translated_feet(rep_n.rig, rep_n.rig.root)
    hold = {} if targets is None else {j: fr.tolist() for j, (fr, _) in targets.joint_positions.items()}
    new, locked = lock_translated_feet(m, feet, rest_extent(skel), contacts=m.foot_contacts, hold=hold)
    if new is m:
        return m, locked
    was = plausibility(m)
    problems = violations(was, was, plausibility(new))
    if problems:
        why = "; ".join(problems)
        report.warnings.append(f"post-processing: translated foot locking undone, it made the motion worse: {why}")
        return m, {**locked, "undone": problems}
    return new, locked


def _leading_context(constraints) -> tuple[int, int] | None:
    """``(n, until)`` when the keyframes and root motions are one leading context: a keyframe on each
    of frames ``0..n-1`` and one root motion over frames ``[0, until)``, ``until >= n`` (a live stream's
    window continuing the frames before it, which were put on the floor; ``until > n`` while steered,
    its root carried on along the path: kinema.stream); else None. The raw model's root height drifts
    (a fox's body sank from 0.61 to 0.13 m over a 2-s window), so a context alone is put on the floor
    like any other motion (the context frames, already standing, move little); the context is not
    hit again by the exact pass (the stream cross-fades those frames)."""
    keys = sorted(c.frame for c in constraints if isinstance(c, Keyframe))
    untils = [c.until for c in constraints if isinstance(c, RootMotion)]
    if keys and len(untils) == 1 and untils[0] >= len(keys) and keys == list(range(len(keys))):
        return len(keys), untils[0]
    return None


def _waypoint_frames(constraints) -> list[int]:
    """Frame 0 and the waypoint frames of every root path (where the sampled root meets them exactly)."""
    paths = [c for c in constraints if isinstance(c, RootPath)]
    return sorted({0, *(int(f) for c in paths for f in c.frames)}) if paths else []
