"""Constraint residuals after post-processing, and the plain-words list of targets left unmet.

Units: positions in cm, rotations in degrees, skate in cm/s; frames at the motion's fps.
"""

from __future__ import annotations

import torch

from kinema.geometry.rotations import quat_angle_deg
from kinema.motion.contacts import contact_joints
from kinema.motion.core import Motion
from kinema.motion.smoothing import smooth_time
from kinema.postprocess.targets import PostTargets

#: residuals above these are reported as unmet: a joint position (cm), a joint rotation (degrees) and a
#: smoothed-root waypoint (cm; dense paths are fitted, not inverted: kinema.postprocess.waypoints)
UNMET_POSITION_CM = 1.0
UNMET_ROTATION_DEG = 2.0
UNMET_ROOT_CM = 5.0


def _stats(x: torch.Tensor) -> dict:
    return {"mean": float(x.mean()), "max": float(x.max()), "count": int(x.numel())}


def constraint_residuals(motion: Motion, targets: PostTargets) -> dict:
    """Residuals per constraint kind: full-body / end-effector positions (cm) and rotations (deg),
    smoothed-root x/z (cm), and the horizontal skate (cm/s) of joints flagged as planted."""
    G, P = motion.to(torch.float64).global_transforms()
    fb = set(targets.full_body_frames(motion.num_joints).tolist())
    errs: dict[str, list[torch.Tensor]] = {}
    for kind, table, err in (
        ("position_cm", targets.joint_positions, lambda f, j, v: (P[f, j] - v).norm(dim=-1) * 100),
        ("rotation_deg", targets.joint_rotations, lambda f, j, v: quat_angle_deg(G[f, j], v)),
    ):
        for j, (f, v) in table.items():
            on_fb = torch.tensor([int(k) in fb for k in f.tolist()], dtype=torch.bool)
            e = err(f, j, v)
            errs.setdefault("full_body_" + kind, []).append(e[on_fb])
            errs.setdefault(kind, []).append(e[~on_fb])
    out = {k: _stats(torch.cat(v)) for k, v in errs.items() if sum(x.numel() for x in v)}
    if targets.root_xz is not None and targets.root_xz[0].numel():
        f, xz = targets.root_xz
        pelvis = motion.skeleton.roles.get("pelvis", 0)
        smooth = smooth_time(P[:, pelvis][:, [0, 2]], targets.root_sigma * motion.fps)
        out["root_xz_cm"] = _stats((smooth[f] - xz).norm(dim=-1) * 100)
    if targets.contacts is not None and targets.contacts[0].numel():
        planted = torch.zeros(motion.num_frames, 4, dtype=torch.bool)
        planted[targets.contacts[0]] = targets.contacts[1] > 0.5
        both = planted[1:] & planted[:-1]
        xz = P[:, contact_joints(motion.skeleton)][..., [0, 2]]
        speed = (xz[1:] - xz[:-1]).norm(dim=-1) * motion.fps * 100
        if both.any():
            out["contact_skate_cm_s"] = _stats(speed[both])
    return out


def _joint_label(skeleton, j: int) -> str:
    """A joint as users name it: its role with dashes ("right-hand") where it has one, else its name."""
    for role, index in skeleton.roles.items():
        if index == j:
            return role.replace("_", "-")
    return skeleton.names[j]


def _worst(errors: torch.Tensor, frames: torch.Tensor, limit: float) -> tuple[int, float, int] | None:
    """(frame, error, how many over ``limit``) of the largest error over ``limit``, else None."""
    over = errors > limit
    if not bool(over.any()):
        return None
    k = int(torch.argmax(errors))
    return int(frames[k]), float(errors[k]), int(over.sum())


def _distance(cm: float) -> str:
    return f"{cm / 100:.2f} m" if cm >= 100 else f"{cm:.1f} cm"


def unmet_targets(motion: Motion, targets: PostTargets) -> list[str]:
    """One line per constrained joint (or the root path) whose residual after post-processing exceeds
    the ``UNMET_*`` tolerance, e.g. ``right-hand target at frame 40 (2.00 s) is 48.30 m out of reach``."""
    G, P = motion.to(torch.float64).global_transforms()
    fps, skel, out = float(motion.fps), motion.skeleton, []

    def line(what: str, hit: tuple[int, float, int], how: str) -> str:
        frame, _, count = hit
        more = f" ({count} frames in all)" if count > 1 else ""
        return f"{what} target at frame {frame} ({frame / fps:.2f} s) {how}{more}"

    for j, (f, v) in sorted(targets.joint_positions.items()):
        hit = _worst((P[f, j] - v).norm(dim=-1) * 100, f, UNMET_POSITION_CM)
        if hit:
            out.append(line(_joint_label(skel, j), hit, f"is {_distance(hit[1])} out of reach"))
    for j, (f, q) in sorted(targets.joint_rotations.items()):
        hit = _worst(quat_angle_deg(G[f, j], q), f, UNMET_ROTATION_DEG)
        if hit:
            out.append(line(_joint_label(skel, j) + " rotation", hit, f"is missed by {hit[1]:.1f} degrees"))
    if targets.root_xz is not None and targets.root_xz[0].numel():
        f, xz = targets.root_xz
        pelvis = skel.roles.get("pelvis", 0)
        smooth = smooth_time(P[:, pelvis][:, [0, 2]], targets.root_sigma * fps)
        hit = _worst((smooth[f] - xz).norm(dim=-1) * 100, f, UNMET_ROOT_CM)
        if hit:
            out.append(line("root path", hit, f"is missed by {_distance(hit[1])}"))
    return out
