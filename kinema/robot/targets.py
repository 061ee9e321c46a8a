"""What the robot should do on each frame, read off a human motion: targets in MuJoCo's world (Z up, +X
forward, +Y left), scaled to the robot.

The human world (Y up, +Z forward, +X left; docs/conventions.md) turns into the robot's by the cyclic axis
permutation ``AXES`` (a rotation, so left stays left). Lengths are scaled by the ratio of leg lengths
(hip to knee to ankle) for the root and the feet (the feet then moved apart by how much wider the robot's
hips are than the scaled human's), and of arm lengths for the hands' reach from the
shoulders; knees and elbows keep the human limb *directions* at the robot's own segment lengths. Soles:
kinema.robot.feet.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from kinema.motion.contacts import ContactThresholds, contact_joints, foot_contacts
from kinema.robot.feet import CLEARANCE, DOWN_HEIGHT, SWING_SPEED, clean_flags, hold_planted, swing_arches
from kinema.skeleton import Skeleton

#: robot = AXES @ human: human +Z (forward) -> robot +X, human +X (left) -> +Y, human +Y (up) -> +Z.
AXES = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
SIDES = ("left", "right")
MAX_FOOT_TURN = 0.6  # radians a foot may point away from the root's heading
MAX_FOOT_PITCH = 1.2  # radians a foot may pitch from flat
#: A source foot near the floor moving slower than this is planted; looser than kinema's default (0.3 m/s)
#: so that a generated foot that skates a little while down is held still on the robot.
CONTACTS = ContactThresholds(speed=0.6)
HUMAN_ROLES = ("pelvis", "spine", "neck") + tuple(
    f"{s}_{p}" for s in SIDES for p in ("hip", "knee", "ankle", "toe", "upper_arm", "elbow", "hand")
)


@dataclass(frozen=True)
class RobotSizes:
    """Robot measurements at rest (metres): segment lengths and the root's height above the soles."""

    thigh: float
    shin: float
    upper_arm: float
    forearm: float
    stand_height: float
    hips: dict[str, np.ndarray]  # (3,) each hip in the root's frame at rest
    ankle_height: float  # foot body origin above the sole at rest
    sole_half_length: float = 0.1  # from the sole's centre to its toe (or heel), m


@dataclass
class FrameTargets:
    """Per-frame targets (T, ...) in the robot's world; ``planted[side]`` (T,) bool."""

    pelvis: np.ndarray  # (T, 3) root position
    pelvis_frame: np.ndarray  # (T, 3, 3) columns: forward, left, up
    torso_frame: np.ndarray  # (T, 3, 3)
    knee_dir: dict[str, np.ndarray]  # (T, 3) unit hip -> knee
    elbow_dir: dict[str, np.ndarray]  # (T, 3) unit shoulder -> elbow
    hand_reach: dict[str, np.ndarray]  # (T, 3) shoulder -> wrist at robot scale
    sole: dict[str, np.ndarray]  # (T, 3) sole centre
    foot_frame: dict[str, np.ndarray]  # (T, 3, 3)
    sole_floor: dict[str, np.ndarray]  # (T,) no sole point below this height (0, or higher in a step's swing)
    planted: dict[str, np.ndarray]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def frames_from(left: np.ndarray, up: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations with columns forward, left, up from left and (roughly) up vectors (T, 3)."""
    left = _unit(left)
    forward = _unit(np.cross(left, up))
    return np.stack([forward, left, np.cross(forward, left)], axis=-1)


def yaw_pitch_frames(yaw: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """(T, 3, 3) ``Rz(yaw) @ Ry(pitch)``: heading about Z, then toe-down pitch about the foot's left axis."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    zero = np.zeros_like(yaw)
    return np.stack(
        [np.stack([cy * cp, -sy, cy * sp], -1), np.stack([sy * cp, cy, sy * sp], -1), np.stack([-sp, zero, cp], -1)],
        axis=-2,
    )


def _planted_height(height: np.ndarray, planted: np.ndarray) -> float:
    """A contact joint's height when planted: the median over planted frames (else its 5th percentile)."""
    return float(np.median(height[planted])) if planted.any() else float(np.percentile(height, 5))


def _foot(P: np.ndarray, roles: dict, side: str, planted: np.ndarray, scale: float, root: np.ndarray, widen: float):
    """(ground position (T, 2), height (T,), yaw and pitch (T, 2)) of one side's sole centre, before steps
    are lifted (_lift_steps). ``root`` (T, 3, 3) is the root's frame: its heading steadies the foot's when
    the foot points steeply up or down, and the foot moves ``widen`` metres outwards along its left axis
    (the robot's hips are further apart than the scaled human's)."""
    heading = root[:, :, 0]
    ankle, toe = P[:, roles[f"{side}_ankle"]], P[:, roles[f"{side}_toe"]]
    a0, t0 = _planted_height(ankle[:, 2], planted), _planted_height(toe[:, 2], planted)
    lift = np.maximum(np.minimum(ankle[:, 2] - a0, toe[:, 2] - t0), 0.0)
    outwards = (widen if side == "left" else -widen) * _unit(root[:, :2, 1])
    ground = hold_planted(scale * (ankle[:, :2] + toe[:, :2]) / 2 + outwards, planted)
    up = np.maximum(hold_planted(scale * lift[:, None], planted, held=np.zeros(1)), 0.0)
    f = np.einsum("tji,tj->ti", root, toe - ankle)  # heel-to-toe in the root's frame: forward, left, up
    sagittal = np.arctan2(-f[:, 2], f[:, 0])  # toe-down pitch; past 90 degrees when the toe trails the heel
    rest = float(np.median(sagittal[planted])) if planted.any() else float(np.percentile(sagittal, 50))
    pitch = np.clip(sagittal - rest, -MAX_FOOT_PITCH, MAX_FOOT_PITCH)
    turn = np.arctan2(f[:, 1], np.abs(f[:, 0]) + 0.5 * np.linalg.norm(f, axis=1))  # never flips backwards
    root_yaw = np.unwrap(np.arctan2(heading[:, 1], heading[:, 0]))
    yaw = root_yaw + np.clip(turn, -MAX_FOOT_TURN, MAX_FOOT_TURN)
    angles = hold_planted(np.stack([yaw, pitch], 1), planted)
    angles[:, 1] = hold_planted(pitch[:, None], planted, held=np.zeros(1))[:, 0]
    return ground, up[:, 0], angles


def _feet_down(feet: dict, planted: dict, fps: float) -> dict[str, np.ndarray]:
    """(T,) bool per side: the frames on which a foot is down (kinema.robot.feet): planted, or near its
    planted height and slow; a foot near the floor that moves fast is stepping."""
    out = {}
    for s in SIDES:
        ground, up, _ = feet[s]
        speed = np.linalg.norm(np.gradient(ground, axis=0), axis=1) * fps if len(up) > 1 else np.zeros(1)
        out[s] = planted[s] | ((up < DOWN_HEIGHT) & (speed < SWING_SPEED))
    return out


def _lift_steps(feet: dict, planted: dict, sizes: RobotSizes, fps: float):
    """Per side (sole centre (T, 3), foot frame (T, 3, 3), sole floor (T,)): a step's swing lifts the sole's
    lowest point at least kinema.robot.feet.CLEARANCE (swing_arches): the floor under it rises, and its
    centre rises more where the foot pitches (its toe or heel hangs lower)."""
    down, out = _feet_down(feet, planted, fps), {}
    for s in SIDES:
        ground, up, angles = feet[s]
        arch = swing_arches(ground, down[s], fps)
        up = np.maximum(up, arch * (CLEARANCE + sizes.sole_half_length * np.abs(np.sin(angles[:, 1]))))
        out[s] = (np.concatenate([ground, up[:, None]], axis=1), yaw_pitch_frames(angles[:, 0], angles[:, 1]),
                  CLEARANCE * arch)
    return out


def _human_stand_height(P: np.ndarray, roles: dict, sk: Skeleton, planted_ankle: float) -> float:
    """The human root's height when standing straight: hip drop + thigh + shin + planted ankle height."""
    hips = (P[:, roles["left_hip"], 2] + P[:, roles["right_hip"], 2]) / 2
    drop = float(np.median(P[:, roles["pelvis"], 2] - hips))
    thigh = float(sk.offsets[roles["left_knee"]].norm())
    shin = float(sk.offsets[roles["left_ankle"]].norm())
    return drop + thigh + shin + planted_ankle


def leg_scale(motion, sizes: RobotSizes) -> float:
    """The robot's leg length over the human's (hip-knee-ankle): root travel and steps are scaled by it."""
    return _limb_scales(motion.skeleton, motion.skeleton.roles, sizes)[0]


def _limb_scales(sk: Skeleton, roles: dict, sizes: RobotSizes) -> tuple[float, float]:
    """(leg scale, arm scale): robot over human lengths of hip-knee-ankle and shoulder-elbow-wrist."""
    leg = float(sk.offsets[roles["left_knee"]].norm() + sk.offsets[roles["left_ankle"]].norm())
    arm = float(sk.offsets[roles["left_elbow"]].norm() + sk.offsets[roles["left_hand"]].norm())
    return (sizes.thigh + sizes.shin) / leg, (sizes.upper_arm + sizes.forearm) / arm


def _reachable_height(pelvis: np.ndarray, frame: np.ndarray, soles: dict, sizes: RobotSizes) -> np.ndarray:
    """(T,) root heights lowered where a straight-enough leg could not reach its sole target (97 % of the
    leg's length), smoothed over three frames so that lowering does not jerk."""
    reach = 0.97 * (sizes.thigh + sizes.shin)
    z = pelvis[:, 2].copy()
    for s in SIDES:
        hip = pelvis + frame @ sizes.hips[s]
        ankle = soles[s] + np.array([0.0, 0.0, sizes.ankle_height])
        across = np.linalg.norm(hip[:, :2] - ankle[:, :2], axis=1)
        rise = np.sqrt(np.maximum(reach**2 - across**2, 0.0))
        z = np.minimum(z, ankle[:, 2] + rise + (pelvis[:, 2] - hip[:, 2]))
    if len(z) >= 3:
        z[1:-1] = np.minimum(z[1:-1], (z[:-2] + z[1:-1] + z[2:]) / 3)
    return z


def frame_targets(motion, sizes: RobotSizes) -> FrameTargets:
    """Targets for every frame of a kinema ``Motion`` (any human rig with the roles of HUMAN_ROLES)."""
    sk = motion.skeleton
    sk.require_roles(list(HUMAN_ROLES))
    roles = sk.roles
    world = motion.positions.detach().double().numpy()
    contacts = foot_contacts(motion.positions.detach().double(), motion.fps, sk, CONTACTS).numpy() > 0.5
    P = world @ AXES.T  # robot axes, human metres
    leg_scale, arm_scale = _limb_scales(sk, roles, sizes)
    planted = {s: clean_flags(contacts[:, 2 * i] & contacts[:, 2 * i + 1]) for i, s in enumerate(SIDES)}
    ankle0 = _planted_height(P[:, contact_joints(sk)[0], 2], planted["left"])
    root = P[:, roles["pelvis"]]
    height = sizes.stand_height + leg_scale * (root[:, 2] - _human_stand_height(P, roles, sk, ankle0))
    pelvis = np.concatenate([leg_scale * root[:, :2], height[:, None]], axis=1)
    hip_line = P[:, roles["left_hip"]] - P[:, roles["right_hip"]]
    shoulder_line = P[:, roles["left_upper_arm"]] - P[:, roles["right_upper_arm"]]
    pelvis_frame = frames_from(hip_line, P[:, roles["spine"]] - root)
    human_hips = float(np.median(np.linalg.norm(hip_line, axis=1))) / 2
    widen = max((sizes.hips["left"][1] - sizes.hips["right"][1]) / 2 - leg_scale * human_hips, 0.0)
    feet = _lift_steps({s: _foot(P, roles, s, planted[s], leg_scale, pelvis_frame, widen) for s in SIDES}, planted,
                       sizes, motion.fps)
    pelvis[:, 2] = _reachable_height(pelvis, pelvis_frame, {s: feet[s][0] for s in SIDES}, sizes)

    def limb(a: str, b: str, s: str) -> np.ndarray:
        return P[:, roles[f"{s}_{b}"]] - P[:, roles[f"{s}_{a}"]]

    return FrameTargets(
        pelvis=pelvis,
        pelvis_frame=pelvis_frame,
        torso_frame=frames_from(shoulder_line, P[:, roles["neck"]] - P[:, roles["spine"]]),
        knee_dir={s: _unit(limb("hip", "knee", s)) for s in SIDES},
        elbow_dir={s: _unit(limb("upper_arm", "elbow", s)) for s in SIDES},
        hand_reach={s: arm_scale * limb("upper_arm", "hand", s) for s in SIDES},
        sole={s: feet[s][0] for s in SIDES},
        foot_frame={s: feet[s][1] for s in SIDES},
        sole_floor={s: feet[s][2] for s in SIDES},
        planted=planted,
    )
