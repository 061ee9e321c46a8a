"""`retarget_to_robot(motion, robot)`: a human kinema Motion onto a robot by per-frame inverse kinematics.

Targets are read off the human motion (kinema.robot.targets: limb directions, scaled feet and hands,
planted soles held flat on the floor), then every frame is solved by kinema.robot.ik from the previous
frame's pose; the first frame starts from the robot's rest pose placed and turned like the human's root
and is solved longer.
"""

from __future__ import annotations

import mujoco
import numpy as np

from kinema.errors import KinemaError
from kinema.robot.description import Robot, load_robot
from kinema.robot.ik import HingeIK, IKWeights
from kinema.robot.motion import RobotMotion
from kinema.robot.targets import SIDES, RobotSizes, frame_targets

FIRST_ITERATIONS, ITERATIONS = 80, 20


def robot_sizes(robot: Robot) -> RobotSizes:
    """Segment lengths and standing root height of a robot at rest (qpos0)."""
    data = mujoco.MjData(robot.model)
    mujoco.mj_kinematics(robot.model, data)

    def dist(a: str, b: str) -> float:
        return float(np.linalg.norm(robot.point(data, a) - robot.point(data, b)))

    lowest = min(robot.sole_points(data, s)[:, 2].min() for s in SIDES)
    root = data.xmat[robot.body_ids["pelvis"]].reshape(3, 3)
    hips = {s: root.T @ (robot.point(data, f"{s}_hip") - robot.point(data, "pelvis")) for s in SIDES}
    ankle = robot.point(data, "left_foot")[2] - robot.sole_centre(data, "left")[2]
    return RobotSizes(
        thigh=dist("left_hip", "left_knee"),
        shin=dist("left_knee", "left_foot"),
        upper_arm=dist("left_shoulder", "left_elbow"),
        forearm=dist("left_elbow", "left_hand"),
        stand_height=float(robot.point(data, "pelvis")[2] - lowest),
        hips=hips,
        ankle_height=float(ankle),
        sole_half_length=float(np.ptp(robot.soles["left"].points[:, 0]) / 2),
    )


def _quaternion(R: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, R.reshape(-1))
    return q


def _continuous(quats: np.ndarray) -> np.ndarray:
    """Quaternions (T, 4) with signs flipped so that neighbours lie in the same hemisphere."""
    out = quats.copy()
    for t in range(1, len(out)):
        if out[t] @ out[t - 1] < 0:
            out[t] = -out[t]
    return out


def retarget_to_robot(motion, robot: Robot | str, weights: IKWeights | None = None) -> RobotMotion:
    """The robot's motion (MuJoCo poses at the motion's fps) for a human kinema ``Motion``; ``robot`` is a
    `Robot` or anything `load_robot` takes (``"g1"``, an MJCF path)."""
    if not motion.is_finite():
        raise KinemaError("cannot retarget a motion with NaN or infinite values onto a robot")
    robot = robot if isinstance(robot, Robot) else load_robot(robot)
    sizes = robot_sizes(robot)
    targets = frame_targets(motion, sizes)
    ik = HingeIK(robot, sizes, weights or IKWeights(), motion.fps)
    q = robot.model.qpos0.copy()
    q[0:3] = targets.pelvis[0]
    q[3:7] = _quaternion(targets.pelvis_frame[0] @ ik.rest["pelvis"])
    poses = []
    for t in range(motion.num_frames):
        q = ik.solve(q, targets, t, FIRST_ITERATIONS if t == 0 else ITERATIONS, first=t == 0)
        poses.append(q.copy())
    Q = np.array(poses)
    quats = _continuous(Q[:, 3:7] / np.linalg.norm(Q[:, 3:7], axis=1, keepdims=True))
    return RobotMotion(
        robot.name,
        motion.fps,
        robot.joint_names,
        Q[:, 0:3],
        quats,
        Q[:, robot.qpos_adr],
        np.stack([targets.planted[s] for s in SIDES], axis=1),
    )
