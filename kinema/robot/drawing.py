"""A robot motion as a kinema `Motion` of its body frames, so that kinema.render draws robots (a stick
figure through the body origins, with the head, hands and soles as end points) with no code of its own.

Positions come from MuJoCo's forward kinematics of the MJCF and are turned from MuJoCo's world (Z up,
+X forward) into kinema's (Y up, +Z forward) by the inverse of kinema.robot.targets.AXES. The soles'
planted flags become the foot contacts the renderer marks.
"""

from __future__ import annotations

import mujoco
import numpy as np
import torch

from kinema.motion.core import Motion
from kinema.robot.description import Robot
from kinema.robot.motion import RobotMotion
from kinema.robot.targets import AXES, SIDES
from kinema.skeleton import Skeleton

#: End points drawn beyond the body frames: name -> landmark (or sole) they stand for.
_TIPS = {"head": "head", "left_palm": "left_hand", "right_palm": "right_hand"}


def _tips(robot: Robot) -> list[tuple[str, int, np.ndarray]]:
    """(name, body id, point in the body frame) of the drawn end points: head, hands, sole centres."""
    out = [(name, robot.body_ids[key], np.asarray(robot.points[key].offset)) for name, key in _TIPS.items()]
    out += [(f"{s}_sole", robot.soles[s].body, robot.soles[s].centre) for s in SIDES]
    return [(n, b, p) for n, b, p in out if n.endswith("sole") or np.linalg.norm(p) > 1e-6]


def robot_skeleton(robot: Robot) -> Skeleton:
    """The robot's body tree (world left out) plus end points, in kinema's axes, with roles named."""
    m = robot.model
    names = [m.body(b).name for b in range(1, m.nbody)]
    parents = [int(m.body_parentid[b]) - 1 for b in range(1, m.nbody)]
    offsets = [AXES.T @ m.body_pos[b] for b in range(1, m.nbody)]
    for name, body, point in _tips(robot):
        names.append(name)
        parents.append(body - 1)
        offsets.append(AXES.T @ point)
    body = {k: m.body(robot.body_ids[k]).name for k in robot.body_ids}
    roles = {"pelvis": body["pelvis"], "neck": body["torso"]}
    for s in SIDES:
        roles.update(
            {
                f"{s}_hip": body[f"{s}_hip"],
                f"{s}_upper_arm": body[f"{s}_shoulder"],
                f"{s}_ankle": body[f"{s}_foot"],
                f"{s}_toe": f"{s}_sole",
            }
        )
    if "head" in names:
        roles["head"] = "head"
    return Skeleton(names, parents, np.array(offsets), role_overrides=roles, name=robot.name)


def _world_frames(robot: Robot, motion: RobotMotion, tips) -> tuple[np.ndarray, np.ndarray]:
    """(positions (T, N, 3), rotation matrices (T, N, 3, 3)) of bodies and end points in MuJoCo's world."""
    m, data = robot.model, mujoco.MjData(robot.model)
    T, B = motion.num_frames, m.nbody - 1
    P, R = np.zeros((T, B + len(tips), 3)), np.zeros((T, B + len(tips), 3, 3))
    for t in range(T):
        data.qpos[:] = robot.qpos(motion.root_position[t], motion.root_quaternion[t], motion.joint_angles[t])
        mujoco.mj_kinematics(m, data)
        P[t, :B], R[t, :B] = data.xpos[1:], data.xmat[1:].reshape(B, 3, 3)
        for k, (_, body, point) in enumerate(tips):
            rot = data.xmat[body].reshape(3, 3)
            P[t, B + k], R[t, B + k] = data.xpos[body] + rot @ point, rot
    return P, R


def _quaternions(R: np.ndarray) -> np.ndarray:
    q = np.zeros(R.shape[:-2] + (4,))
    for idx in np.ndindex(R.shape[:-2]):
        mujoco.mju_mat2Quat(q[idx], R[idx].reshape(-1))
    return q


def robot_motion_for_drawing(motion: RobotMotion, robot: Robot) -> Motion:
    """A kinema `Motion` (Y up) of the robot's bodies and end points, with planted soles as contacts."""
    motion.check_joints(robot.joint_names, robot.name)
    sk = robot_skeleton(robot)
    P, R = _world_frames(robot, motion, _tips(robot))
    P = P @ AXES  # row vectors: AXES.T @ p
    R = np.einsum("ij,tnjk,kl->tnil", AXES.T, R, AXES)
    contacts = None
    if motion.sole_planted is not None:
        contacts = torch.as_tensor(np.repeat(motion.sole_planted.astype(float), 2, axis=1))
    return Motion.from_global(
        sk,
        motion.fps,
        torch.as_tensor(P[:, 0]),
        torch.as_tensor(_quaternions(R)),
        foot_contacts=contacts,
        positions=torch.as_tensor(P),
    )
