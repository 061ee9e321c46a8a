"""Motion post-processing (Kimodo Sec. 4.4): de-jittering, foot locking with IK, exact constraint hitting.

Generated motions are good but not exact: feet may skate a little where the model predicts contact,
and kinematic constraints are met within centimetres. ``postprocess`` first removes frame-to-frame
jitter with a light Gaussian (kinema.postprocess.smooth; not in the paper), then locks planted feet
(kinema.postprocess.footlock) and then runs a short optimisation plus an exact pass
(kinema.postprocess.exact) so constrained frames are hit to within a millimetre. The exact pass runs
last so constraints win over foot locks where they disagree.

Constraints are described by ``PostTargets`` (kinema.postprocess.targets; frames are LongTensors
``(K,)``; positions in metres, world frame; rotations global wxyz quaternions; ``root_xz`` targets the
*smoothed* root, i.e. the
Gaussian-smoothed pelvis x/z, see kinema.motion.smoothing). A full-body keyframe is a frame with
position and rotation targets for every joint (positions alone also work: rotations are then derived
by aiming every bone at its child's target).
"""

from __future__ import annotations

from kinema.motion.contacts import foot_contacts as estimate_contacts
from kinema.motion.core import Motion
from kinema.postprocess.exact import hit_constraints
from kinema.postprocess.footlock import foot_lock as lock_feet
from kinema.postprocess.guard import (
    DEFAULT_BOUNDS,
    GuardBounds,
    Plausibility,
    floor_note,
    plausibility,
    violations,
)
from kinema.postprocess.residuals import unmet_targets
from kinema.postprocess.smooth import DEFAULT_ROT_SIGMA_SECONDS, DEFAULT_SIGMA_SECONDS, smooth_motion
from kinema.postprocess.targets import PostTargets
from kinema.rig import Rig


def postprocess(
    motion: Motion,
    targets: PostTargets | None = None,
    foot_lock: bool = True,
    exact: bool = True,
    smooth: float = DEFAULT_SIGMA_SECONDS,
    smooth_rotations: float = DEFAULT_ROT_SIGMA_SECONDS,
    bounds: GuardBounds = DEFAULT_BOUNDS,
    rig: Rig | None = None,
    raw: Motion | None = None,
    **exact_kwargs,
) -> tuple[Motion, dict]:
    """De-jittering (Gaussians of ``smooth`` seconds on the root x/z and ``smooth_rotations`` seconds on
    local rotations; 0 = off), foot locking (on ``motion.foot_contacts``, overridden by
    ``targets.contacts`` where given), then the exact constraint pass, each stage guarded
    (kinema.postprocess.guard): a stage that would make the motion less plausible than the raw one beyond
    ``bounds`` is undone. Returns the motion and ``{"smooth", "foot_lock", "exact", "plausibility",
    "warnings"}``; ``warnings`` lists undone stages and constraints left unmet, in words. ``rig`` names the
    contact joints and legs foot locking works on (default: found from the motion's skeleton,
    kinema.rig); a rig without contacts (a fish) skips foot locking. ``raw``: the motion as generated when
    the caller already de-jittered ``motion`` itself (the any-rig model): the stages are bounded by its
    plausibility, as they would be had de-jittering run here (default: ``motion``)."""
    report: dict = {"warnings": []}
    targets = None if targets is None else targets.validate(motion)
    guard = _Guard(plausibility(motion if raw is None else raw), bounds, report)
    if raw is not None:
        guard.before = plausibility(motion)
    if smooth > 0 or smooth_rotations > 0:
        new, report["smooth"] = smooth_motion(motion, smooth, smooth_rotations)
        motion = guard.accept("de-jittering", motion, new, report["smooth"])
    rig = rig or Rig.from_skeleton(motion.skeleton)
    pre, pre_state = motion, (guard.before, list(report["warnings"]))
    if foot_lock:
        motion = _guarded_foot_lock(motion, targets, guard, report, rig)
    if exact and targets is not None and not targets.is_empty():
        kept = _guarded_exact(motion, targets, guard, report, exact_kwargs)
        if "undone" in report["exact"] and motion is not pre:
            kept = _retry_unlocked(pre, pre_state, (kept, dict(report)), targets, guard, report, exact_kwargs)
        motion = kept
    report["plausibility"] = {"raw": guard.raw.as_dict(), "final": guard.before.as_dict()}
    return motion, report


class _Guard:
    """Accepts a stage's output only while it stays within ``bounds`` of the raw motion's plausibility;
    ``before`` is the plausibility of the last motion accepted (the raw one to start with)."""

    def __init__(self, raw: Plausibility, bounds: GuardBounds, report: dict):
        self.raw, self.before, self.bounds, self.report = raw, raw, bounds, report

    def check(self, new: Motion, extra: list[str] = ()) -> tuple[Plausibility, list[str]]:
        """``new``'s plausibility and what is wrong with it as the next stage's output."""
        measured = plausibility(new)
        return measured, violations(self.raw, self.before, measured, self.bounds) + list(extra)

    def accept(
        self,
        stage: str,
        old: Motion,
        new: Motion,
        stage_report: dict,
        extra: list[str] = (),
        checked: tuple[Plausibility, list[str]] | None = None,
    ) -> Motion:
        """``new`` if it passes (``checked``: its ``check`` result when already known), else ``old``."""
        measured, problems = checked if checked is not None else self.check(new, extra)
        stage_report["added_pelvis_speed_m_s"] = round(measured.added_speed(self.before), 3)
        if not problems:
            note = floor_note(self.raw, measured, new.skeleton.names, self.bounds)
            if note is not None and floor_note(self.raw, self.before, new.skeleton.names, self.bounds) is None:
                stage_report["below_floor"] = note
                self.report["warnings"].append(f"post-processing: {stage} kept, but {note}")
            self.before = measured
            return new
        stage_report["undone"] = problems
        self.report["warnings"].append(
            f"post-processing: {stage} undone, it would have made the motion worse "
            f"than the raw one: {'; '.join(problems)}"
        )
        return old


def _retry_unlocked(
    pre: Motion, pre_state, first, targets: PostTargets, guard: _Guard, report: dict, kwargs: dict
) -> Motion:
    """The exact pass was undone after foot locking: the exact pass again on ``pre`` (the motion before foot
    locking), foot locking undone and said. Kept when that pass is accepted, else the first attempt
    (``first``: its motion and report) stands. Why: locking the feet of a walk that skates shifts the whole
    body (1.1 m in the goal-reach example, off its start pose and its reach target); the exact pass then
    has to drag it back faster than the guard allows, and the final hand ended 117 cm off instead of the
    raw 40. Locking without moving the pelvis was tried: the feet stayed planted behind the gliding body
    and the legs stretched out flat (filmstrip, reports/sfc3.md). Constraints win over foot locks."""
    first_before, lock_report = guard.before, report.get("foot_lock", {})
    guard.before, report["warnings"] = pre_state[0], list(pre_state[1])
    kept = _guarded_exact(pre, targets, guard, report, kwargs)
    if "undone" not in report["exact"]:
        report["foot_lock"] = dict(lock_report, undone=["the exact constraint pass was undone after it"])
        report["warnings"].insert(
            len(pre_state[1]),
            "post-processing: foot locking undone, it moved the body off the constraints further than the "
            "exact pass may bring it back; feet skate as in the raw motion",
        )
        return kept
    report.clear()
    report.update(first[1])
    guard.before = first_before
    return first[0]


def _guarded_foot_lock(motion: Motion, targets: PostTargets | None, guard: _Guard, report: dict, rig: Rig) -> Motion:
    """Foot locking; if moving the pelvis to reach the locks trips the guard, lock without moving it."""
    contacts = motion.foot_contacts
    if targets is not None and targets.contacts is not None:
        if contacts is None:
            contacts = estimate_contacts(motion.positions, motion.fps, motion.skeleton, joints=rig.contacts)
        contacts = contacts.clone().to(motion.dtype)
        frames, flags = targets.contacts
        contacts[frames] = flags.to(contacts.dtype)
    new, rep = lock_feet(motion, contacts, rig=rig)
    checked = guard.check(new)
    if checked[1]:
        new, rep = lock_feet(motion, contacts, rig=rig, reach_passes=0)
        rep["pelvis_moves_off"] = checked[1]
        checked = None
    report["foot_lock"] = rep
    return guard.accept("foot locking", motion, new, rep, checked=checked)


def _guarded_exact(motion: Motion, targets: PostTargets, guard: _Guard, report: dict, kwargs: dict) -> Motion:
    """The exact constraint pass, undone as a whole when it trips the guard; unmet targets are warned of."""
    new, rep = hit_constraints(motion, targets, **kwargs)
    outside = rep["max_change_outside_blend_cm"]
    extra = (
        []
        if outside <= guard.bounds.outside_change_cm or outside != outside  # NaN: the guard says so
        else [f"joints moved {outside:.1f} cm on frames no constraint may touch"]
    )
    kept = guard.accept("the exact constraint pass", motion, new, rep, extra)
    if kept is motion:  # undone: the residuals are those of the motion kept, measured before the pass
        rep["after"] = rep["before"]
        rep["unmet"] = unmet_targets(motion, targets)
    report["exact"] = rep
    report["warnings"] += [f"constraint not met: {u}" for u in rep["unmet"]]
    return kept


__all__ = ["PostTargets", "postprocess"]
