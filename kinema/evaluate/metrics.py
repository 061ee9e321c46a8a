"""Per-motion metrics (Kimodo Sec. 6.1), computed identically on ground truth and generated motions.

Everything is evaluated in float64 on the motion's global joint positions ``P (T, J, 3)`` (metres,
Y up) from forward kinematics, at the motion's frame rate ``fps``. Reported units follow the paper's
tables: centimetres, cm/s and degrees; jerk and jitter stay in SI units (m/s^3, m/s^2).

Quality
    ``foot_skate``        cm/s   mean horizontal speed of contact joints on frames flagged in contact
    ``contact_accuracy``  [0,1]  agreement of predicted contacts with contacts derived from the motion
    ``jerk``              m/s^3  mean norm of the third time derivative of joint positions
    ``jitter``            m/s^2  mean norm of the second time derivative (acceleration) of joint positions

Constraint errors (``frames`` are the K constrained frame indices, targets in world coordinates)
    ``fullbody_position_error``      cm   mean joint distance to full-body position keyframes
    ``end_effector_position_error``  cm   mean distance of one (or several) joints to targets
    ``end_effector_rotation_error``  deg  mean geodesic angle between global rotations and targets
    ``root2d_error``                 cm   mean 2D distance of the *smoothed* root x/z to targets
    ``pelvis_deviation_p95``         cm   95th percentile of the 2D distance of the projected pelvis to
                                          smoothed-root targets (pool ``pelvis_deviations`` over a test set
                                          and take its 95th percentile for the paper's set-level number)
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from kinema.errors import KinemaError
from kinema.geometry.rotations import quat_angle_deg
from kinema.motion.contacts import ContactThresholds, contact_joints, foot_contacts
from kinema.motion.core import Motion
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS, smooth_time

CONTACT_THRESHOLD = 0.5  #: contact probabilities above this count as "in contact"

Frames = Sequence[int] | torch.Tensor
Joint = int | str


# ----------------------------------------------------------------------------- helpers


def _positions(motion: Motion) -> torch.Tensor:
    """Global joint positions (T, J, 3) in metres, float64."""
    return motion.to(torch.float64).positions


def _frames(motion: Motion, frames: Frames) -> torch.Tensor:
    idx = torch.as_tensor(frames, dtype=torch.long).reshape(-1)
    T = motion.num_frames
    if idx.numel() == 0:
        raise KinemaError("constraint metrics need at least one constrained frame")
    if (idx < -T).any() or (idx >= T).any():
        raise KinemaError(f"constrained frames {idx.tolist()} fall outside a {T}-frame motion")
    return idx % T


def _targets(targets, shape: tuple[int, ...], what: str) -> torch.Tensor:
    t = torch.as_tensor(targets, dtype=torch.float64)
    if tuple(t.shape) != shape:
        raise KinemaError(f"{what} must have shape {shape}, got {tuple(t.shape)}")
    return t


def _single(joint) -> bool:
    return isinstance(joint, str) or not isinstance(joint, Sequence)


def _joints(motion: Motion, joint: Joint | Sequence[Joint]) -> list[int]:
    items = [joint] if _single(joint) else list(joint)
    return [motion.skeleton.index(j) if isinstance(j, str) else int(j) for j in items]


def smoothed_root_xz(motion: Motion, sigma_seconds: float = DEFAULT_ROOT_SIGMA_SECONDS) -> torch.Tensor:
    """(T, 2) smoothed root x/z in metres: the pelvis x/z Gaussian-smoothed exactly as the features do it."""
    pelvis = motion.skeleton.require_roles(["pelvis"])["pelvis"]
    return smooth_time(_positions(motion)[:, pelvis][:, [0, 2]], sigma_seconds * motion.fps)


def _predicted_contacts(motion: Motion, contacts) -> torch.Tensor:
    c = motion.foot_contacts if contacts is None else torch.as_tensor(contacts)
    if c is None:
        raise KinemaError("the motion carries no foot contacts; pass contacts=(T, 4) explicitly")
    if tuple(c.shape) != (motion.num_frames, 4):
        raise KinemaError(f"contacts must have shape ({motion.num_frames}, 4), got {tuple(c.shape)}")
    return c.to(torch.float64) > CONTACT_THRESHOLD


# ----------------------------------------------------------------------------- quality


def foot_skate_with_count(motion: Motion, contacts=None) -> tuple[float, int]:
    """(foot skate in cm/s, number of (frame, contact joint) samples it averages over).

    ``skate = 100 * mean_{(t, c): contact[t, c] > 0.5} || v_xz(t, c) ||`` where c runs over the four
    contact joints [L heel, L toe, R heel, R toe] of :func:`kinema.motion.contacts.contact_joints`
    (ankles standing in for heels) and ``v_xz`` is their horizontal (x, z) velocity in m/s by finite
    differences: central ``(p[t+1] - p[t-1]) * fps / 2`` inside the clip, one-sided
    ``(p[1] - p[0]) * fps`` / ``(p[T-1] - p[T-2]) * fps`` at the ends (``torch.gradient``).
    ``contacts`` (T, 4) defaults to ``motion.foot_contacts`` (the model's prediction). With no contact
    sample the skate is 0.0 and the count 0, so a set-level mean can weight by the count.
    """
    on = _predicted_contacts(motion, contacts)
    count = int(on.sum())
    if count == 0:
        return 0.0, 0
    p = _positions(motion)[:, contact_joints(motion.skeleton)][..., [0, 2]]  # (T, 4, 2)
    if p.shape[0] < 2:
        return 0.0, count
    v = torch.gradient(p, spacing=1.0 / motion.fps, dim=0)[0]
    speed = v.norm(dim=-1)  # (T, 4) m/s
    return float(100.0 * speed[on].mean()), count


def foot_skate(motion: Motion, contacts=None) -> float:
    """Foot skate in cm/s (see :func:`foot_skate_with_count` for the formula); 0.0 without contacts."""
    return foot_skate_with_count(motion, contacts)[0]


def contact_accuracy(motion: Motion, thresholds: ContactThresholds | None = None) -> float:
    """Fraction in [0, 1] of the T x 4 contact labels where prediction and motion agree.

    ``acc = mean_{t, c} [ (motion.foot_contacts[t, c] > 0.5) == derived[t, c] ]`` with ``derived`` from
    :func:`kinema.motion.contacts.foot_contacts` on the motion's own joint positions (height and speed
    thresholds, floor y = 0; ``thresholds`` defaults to ``ContactThresholds()``) -- the labelling the
    training data uses, so ground truth scores 1.0.
    """
    predicted = _predicted_contacts(motion, None)
    thr = thresholds or ContactThresholds()
    derived = foot_contacts(_positions(motion), motion.fps, motion.skeleton, thr) > 0.5
    return float((predicted == derived).to(torch.float64).mean())


def jerk(motion: Motion) -> float:
    """Mean jerk magnitude in m/s^3.

    ``jerk = mean_{t, j} || (P[t+3] - 3 P[t+2] + 3 P[t+1] - P[t]) * fps^3 ||`` over the T - 3 third
    differences of every joint's global position; 0.0 for clips shorter than 4 frames. Exact for cubic
    trajectories: ``p(t) = a t^3`` gives ``6 a``.
    """
    return position_jerk(_positions(motion), motion.fps)


def position_jerk(positions: torch.Tensor, fps: float) -> float:
    """:func:`jerk` of joint positions ``(T, J, 3)`` in metres sampled at ``fps``."""
    P = positions
    if P.shape[0] < 4:
        return 0.0
    d3 = P[3:] - 3.0 * P[2:-1] + 3.0 * P[1:-2] - P[:-3]
    return float((d3.norm(dim=-1) * fps**3).mean())


def jitter(motion: Motion) -> float:
    """Mean acceleration magnitude in m/s^2 (our "jitter": high for shaky or abrupt motion).

    ``jitter = mean_{t, j} || (P[t+1] - 2 P[t] + P[t-1]) * fps^2 ||`` over the T - 2 interior frames and
    every joint; 0.0 for clips shorter than 3 frames. Zero for constant-velocity motion; the central
    second difference is exact for cubics (``p(t) = a t^3`` gives ``|6 a t|`` at each interior frame).
    """
    P = _positions(motion)
    if P.shape[0] < 3:
        return 0.0
    d2 = P[2:] - 2.0 * P[1:-1] + P[:-2]
    return float((d2.norm(dim=-1) * motion.fps**2).mean())


# ----------------------------------------------------------------------------- constraint errors


def fullbody_position_error(motion: Motion, frames: Frames, target_positions) -> float:
    """Mean joint position error in cm at full-body keyframes.

    ``err = 100 * mean_{k, j} || P[frames[k], j] - target[k, j] ||`` with ``target_positions (K, J, 3)``
    in metres (world frame).
    """
    idx = _frames(motion, frames)
    target = _targets(target_positions, (idx.numel(), motion.num_joints, 3), "target_positions")
    return float(100.0 * (_positions(motion)[idx] - target).norm(dim=-1).mean())


def end_effector_position_error(motion: Motion, joint: Joint | Sequence[Joint], frames: Frames, targets) -> float:
    """Mean end-effector position error in cm.

    ``err = 100 * mean_k || P[frames[k], joint] - targets[k] ||``; ``joint`` is an index, a joint name or
    a role (``left_hand``), targets ``(K, 3)`` metres. A list of N joints takes targets ``(K, N, 3)``
    and averages over both axes.
    """
    idx = _frames(motion, frames)
    joints = _joints(motion, joint)
    single = _single(joint)
    shape = (idx.numel(), 3) if single else (idx.numel(), len(joints), 3)
    target = _targets(targets, shape, "targets").reshape(idx.numel(), len(joints), 3)
    return float(100.0 * (_positions(motion)[idx][:, joints] - target).norm(dim=-1).mean())


def rotation_angle_deg(q_a: torch.Tensor, q_b: torch.Tensor) -> torch.Tensor:
    """Geodesic angle in degrees between unit quaternions ``(..., 4)`` (q and -q are the same rotation):
    kinema.geometry.rotations.quat_angle_deg, in [0, 180]."""
    return quat_angle_deg(q_a, q_b)


def end_effector_rotation_error(motion: Motion, joint: Joint | Sequence[Joint], frames: Frames, target_quats) -> float:
    """Mean end-effector global rotation error in degrees.

    ``err = mean_k angle(G[frames[k], joint], target_quats[k])`` with the geodesic angle of
    :func:`rotation_angle_deg`; targets are global (world-frame) quaternions ``(K, 4)`` wxyz, or
    ``(K, N, 4)`` for a list of N joints.
    """
    idx = _frames(motion, frames)
    joints = _joints(motion, joint)
    single = _single(joint)
    shape = (idx.numel(), 4) if single else (idx.numel(), len(joints), 4)
    target = _targets(target_quats, shape, "target_quats").reshape(idx.numel(), len(joints), 4)
    G = motion.to(torch.float64).global_rotations[idx][:, joints]
    return float(rotation_angle_deg(G, target).mean())


def root2d_error(motion: Motion, frames: Frames, targets, sigma_seconds: float = DEFAULT_ROOT_SIGMA_SECONDS) -> float:
    """Mean 2D root error in cm against smoothed-root (x, z) waypoints or paths.

    ``err = 100 * mean_k || S[frames[k]] - targets[k] ||`` with ``S`` = :func:`smoothed_root_xz` (pelvis
    x/z Gaussian-smoothed with sigma 0.5 s, the features' smoother) and ``targets (K, 2)`` metres.
    """
    idx = _frames(motion, frames)
    target = _targets(targets, (idx.numel(), 2), "targets")
    return float(100.0 * (smoothed_root_xz(motion, sigma_seconds)[idx] - target).norm(dim=-1).mean())


def pelvis_deviations(motion: Motion, frames: Frames, targets) -> torch.Tensor:
    """(K,) float64 2D distances in cm between the projected pelvis and smoothed-root targets.

    ``d_k = 100 * || (P[frames[k], pelvis].x, P[frames[k], pelvis].z) - targets[k] ||``, targets (K, 2) m.
    """
    idx = _frames(motion, frames)
    target = _targets(targets, (idx.numel(), 2), "targets")
    pelvis = motion.skeleton.require_roles(["pelvis"])["pelvis"]
    return 100.0 * (_positions(motion)[idx, pelvis][:, [0, 2]] - target).norm(dim=-1)


def pelvis_deviation_p95(motion: Motion, frames: Frames, targets) -> float:
    """95th percentile (cm) of :func:`pelvis_deviations` (Kimodo "2D Pelvis Pos@95%").

    ``p95 = quantile_{0.95}(d_1 .. d_K)`` with linear interpolation between order statistics
    (``numpy.percentile``'s default). For the paper's set-level number, concatenate
    ``pelvis_deviations`` over all root-constrained test cases and take the quantile of the pool.
    """
    return float(torch.quantile(pelvis_deviations(motion, frames, targets), 0.95))
