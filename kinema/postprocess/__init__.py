"""Motion post-processing (Kimodo Sec. 4.4): de-jittering, foot locking with IK, exact constraint hitting.

Generated motions are good but not exact: feet may skate a little where the model predicts contact,
and kinematic constraints are met within centimetres. ``postprocess`` first removes frame-to-frame
jitter with a light Gaussian (kinema.postprocess.smooth; not in the paper), then locks planted feet
(kinema.postprocess.footlock) and then runs a short optimisation plus an exact pass
(kinema.postprocess.exact) so constrained frames are hit to within a millimetre. The exact pass runs
last so constraints win over foot locks where they disagree.

Constraints are described by ``PostTargets`` (frames are LongTensors ``(K,)``; positions in metres,
world frame; rotations global wxyz quaternions; ``root_xz`` targets the *smoothed* root, i.e. the
Gaussian-smoothed pelvis x/z, see kinema.motion.smoothing). A full-body keyframe is a frame with
position and rotation targets for every joint (positions alone also work: rotations are then derived
by aiming every bone at its child's target).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import torch

from kinema.errors import KinemaError
from kinema.motion.core import Motion
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS
from kinema.postprocess.guard import DEFAULT_BOUNDS, GuardBounds, Plausibility, plausibility, violations
from kinema.postprocess.smooth import DEFAULT_ROT_SIGMA_SECONDS, DEFAULT_SIGMA_SECONDS, smooth_motion

Pair = tuple[torch.Tensor, torch.Tensor]


@dataclass
class PostTargets:
    """Kinematic targets for post-processing (all optional).

    - ``joint_positions``: joint index -> (frames (K,), positions (K, 3) metres, world)
    - ``joint_rotations``: joint index -> (frames (K,), global quaternions (K, 4) wxyz)
    - ``root_xz``: (frames (K,), smoothed-root x/z (K, 2))
    - ``contacts``: (frames (K,), planted flags (K, 4) [L heel, L toe, R heel, R toe])
    - ``root_sigma``: seconds of the Gaussian that defines the smoothed root
    """

    joint_positions: dict[int, Pair] = field(default_factory=dict)
    joint_rotations: dict[int, Pair] = field(default_factory=dict)
    root_xz: Pair | None = None
    contacts: Pair | None = None
    root_sigma: float = DEFAULT_ROOT_SIGMA_SECONDS

    def is_empty(self) -> bool:
        return not (self.joint_positions or self.joint_rotations or self.root_xz is not None
                    or self.contacts is not None)

    def validate(self, motion: Motion) -> PostTargets:
        """A copy with frames as LongTensors and values as float64, checked against ``motion``."""
        T, J = motion.num_frames, motion.num_joints

        def check(pair: Pair, width: int, what: str) -> Pair:
            frames = torch.as_tensor(pair[0]).long().reshape(-1)
            values = torch.as_tensor(pair[1]).to(torch.float64).reshape(-1, width)
            if frames.numel() != values.shape[0]:
                raise KinemaError(f"{what}: {frames.numel()} frames but {values.shape[0]} values")
            if frames.numel() and (frames.min() < 0 or frames.max() >= T):
                raise KinemaError(f"{what}: frames must lie in [0, {T}), got {frames.min()}..{frames.max()}")
            return frames, values

        def joints(d: dict[int, Pair], width: int, what: str) -> dict[int, Pair]:
            out = {}
            for j, pair in d.items():
                if not 0 <= int(j) < J:
                    raise KinemaError(f"{what}: joint {j} outside [0, {J})")
                out[int(j)] = check(pair, width, f"{what}[{motion.skeleton.names[int(j)]}]")
            return out

        return PostTargets(
            joints(self.joint_positions, 3, "joint_positions"),
            joints(self.joint_rotations, 4, "joint_rotations"),
            None if self.root_xz is None else check(self.root_xz, 2, "root_xz"),
            None if self.contacts is None else check(self.contacts, 4, "contacts"),
            self.root_sigma,
        )

    def full_body_frames(self, num_joints: int) -> torch.Tensor:
        """Frames (sorted LongTensor) where every joint has a rotation target or every joint has a
        position target: full-body keyframes, set as a whole pose by the exact pass."""
        frames: set[int] = set()
        for table in (self.joint_rotations, self.joint_positions):
            if all(j in table for j in range(num_joints)):
                sets = [set(torch.as_tensor(table[j][0]).tolist()) for j in range(num_joints)]
                frames |= set.intersection(*sets)
        return torch.tensor(sorted(frames), dtype=torch.long)

    @classmethod
    def from_motion(
        cls,
        motion: Motion,
        full_body: list[int] | None = None,
        positions: dict[int, list[int]] | None = None,
        rotations: dict[int, list[int]] | None = None,
        root_xz: list[int] | None = None,
        root_sigma: float = DEFAULT_ROOT_SIGMA_SECONDS,
    ) -> PostTargets:
        """Targets read off a reference motion at the given frames (handy for tests and retiming)."""
        from kinema.motion.smoothing import smooth_time

        G, P = motion.global_transforms()
        pos = {j: list(f) for j, f in (positions or {}).items()}
        rot = {j: list(f) for j, f in (rotations or {}).items()}
        for k in full_body or []:
            for j in range(motion.num_joints):
                pos.setdefault(j, []).append(k)
                rot.setdefault(j, []).append(k)
        out = cls(root_sigma=root_sigma)
        for j, f in pos.items():
            f = torch.tensor(f, dtype=torch.long)
            out.joint_positions[j] = (f, P[f, j].to(torch.float64))
        for j, f in rot.items():
            f = torch.tensor(f, dtype=torch.long)
            out.joint_rotations[j] = (f, G[f, j].to(torch.float64))
        if root_xz:
            pelvis = motion.skeleton.require_roles(["pelvis"])["pelvis"]
            smooth = smooth_time(P[:, pelvis][:, [0, 2]].to(torch.float64), root_sigma * motion.fps)
            f = torch.tensor(root_xz, dtype=torch.long)
            out.root_xz = (f, smooth[f])
        return out


def postprocess(
    motion: Motion,
    targets: PostTargets | None = None,
    foot_lock: bool = True,
    exact: bool = True,
    smooth: float = DEFAULT_SIGMA_SECONDS,
    smooth_rotations: float = DEFAULT_ROT_SIGMA_SECONDS,
    bounds: GuardBounds = DEFAULT_BOUNDS,
    **exact_kwargs,
) -> tuple[Motion, dict]:
    """De-jittering (Gaussians of ``smooth`` seconds on the root x/z and ``smooth_rotations`` seconds on
    local rotations; 0 = off), foot locking (on ``motion.foot_contacts``, overridden by
    ``targets.contacts`` where given), then the exact constraint pass, each stage guarded
    (kinema.postprocess.guard): a stage that would make the motion less plausible than the raw one beyond
    ``bounds`` is undone. Returns the motion and ``{"smooth", "foot_lock", "exact", "plausibility",
    "warnings"}``; ``warnings`` lists undone stages and constraints left unmet, in words."""
    report: dict = {"warnings": []}
    targets = None if targets is None else targets.validate(motion)
    guard = _Guard(plausibility(motion), bounds, report)
    if smooth > 0 or smooth_rotations > 0:
        new, report["smooth"] = smooth_motion(motion, smooth, smooth_rotations)
        motion = guard.accept("de-jittering", motion, new, report["smooth"])
    if foot_lock:
        motion = _guarded_foot_lock(motion, targets, guard, report)
    if exact and targets is not None and not targets.is_empty():
        motion = _guarded_exact(motion, targets, guard, report, exact_kwargs)
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

    def accept(self, stage: str, old: Motion, new: Motion, stage_report: dict, extra: list[str] = (),
               checked: tuple[Plausibility, list[str]] | None = None) -> Motion:
        """``new`` if it passes (``checked``: its ``check`` result when already known), else ``old``."""
        measured, problems = checked if checked is not None else self.check(new, extra)
        stage_report["added_pelvis_speed_m_s"] = round(measured.added_speed(self.before), 3)
        if not problems:
            self.before = measured
            return new
        stage_report["undone"] = problems
        self.report["warnings"].append(f"post-processing: {stage} undone, it would have made the motion worse "
                                       f"than the raw one: {'; '.join(problems)}")
        return old


def _guarded_foot_lock(motion: Motion, targets: PostTargets | None, guard: _Guard, report: dict) -> Motion:
    """Foot locking; if moving the pelvis to reach the locks trips the guard, lock without moving it."""
    from kinema.postprocess.footlock import foot_lock as lock_feet

    contacts = motion.foot_contacts
    if targets is not None and targets.contacts is not None:
        if contacts is None:
            from kinema.motion.contacts import foot_contacts as estimate

            contacts = estimate(motion.positions, motion.fps, motion.skeleton)
        contacts = contacts.clone().to(motion.dtype)
        frames, flags = targets.contacts
        contacts[frames] = flags.to(contacts.dtype)
    new, rep = lock_feet(motion, contacts)
    checked = guard.check(new)
    if checked[1]:
        new, rep = lock_feet(motion, contacts, reach_passes=0)
        rep["pelvis_moves_off"] = checked[1]
        checked = None
    report["foot_lock"] = rep
    return guard.accept("foot locking", motion, new, rep, checked=checked)


def _guarded_exact(motion: Motion, targets: PostTargets, guard: _Guard, report: dict, kwargs: dict) -> Motion:
    """The exact constraint pass, undone as a whole when it trips the guard; unmet targets are warned of."""
    from kinema.postprocess.exact import hit_constraints
    from kinema.postprocess.residuals import unmet_targets

    new, rep = hit_constraints(motion, targets, **kwargs)
    outside = rep["max_change_outside_blend_cm"]
    extra = [] if outside <= guard.bounds.outside_change_cm else [
        f"joints moved {outside:.1f} cm on frames no constraint may touch"]
    kept = guard.accept("the exact constraint pass", motion, new, rep, extra)
    if kept is motion:  # undone: the residuals are those of the motion kept, measured before the pass
        rep["after"] = rep["before"]
        rep["unmet"] = unmet_targets(motion, targets)
    report["exact"] = rep
    report["warnings"] += [f"constraint not met: {u}" for u in rep["unmet"]]
    return kept


__all__ = ["PostTargets", "postprocess"]
