"""A robot motion in the files two motion-tracking frameworks read.

- **BeyondMimic** (HybridRobotics/whole_body_tracking): the npz that its ``scripts/csv_to_npz.py`` writes
  and ``tasks/tracking/mdp/commands.py``'s ``MotionLoader`` reads with ``np.load``: ``fps`` (shape (1,),
  an integer where the frame rate is one, as that script writes it),
  ``joint_pos`` and ``joint_vel`` (T, J), ``body_pos_w`` (T, B, 3), ``body_quat_w`` (T, B, 4, w x y z, Isaac
  Lab's order), ``body_lin_vel_w`` and ``body_ang_vel_w`` (T, B, 3), float32, world frame, Z up. Isaac Lab
  orders an articulation's joints and bodies breadth-first through the kinematic tree (for the G1:
  left_hip_pitch, right_hip_pitch, waist_yaw, left_hip_roll, ...), so the joints and bodies are written in
  that order of the MJCF's tree, and ``joint_names`` and ``body_names`` are added so that a loader can
  check or remap them (``MotionLoader`` reads only the keys above; it picks bodies by the indexes of its
  own articulation's ``find_bodies``). Positions and orientations are of the body (link) frames; linear
  velocities of the bodies' centres of mass, as Isaac Lab's ``body_lin_vel_w`` (its ``body_state_w``:
  link pose, centre-of-mass velocity).
- **GMR** (YanjieZe/GMR): the pickle its ``scripts/smplx_to_robot.py --save_path`` writes and its
  ``load_robot_motion`` reads with ``pickle.load``: a dict of ``fps`` (float), ``root_pos`` (T, 3),
  ``root_rot`` (T, 4, **x y z w**), ``dof_pos`` (T, J, the MJCF's hinge order, as ``qpos[7:]``),
  ``local_body_pos`` and ``link_body_list``. GMR writes None for the last two; kinema fills them with each
  body's position relative to the root in the root's frame (T, B, 3) and the body names (MJCF order).

Velocities are central differences of the poses (MuJoCo's ``mj_differentiatePos``), as the dynamics
report's (kinema.robot.dynamics). The layouts are written from the frameworks' public code as of 2025
(docs/robots.md); tests/test_robot_exports.py loads each file the way that code does.
"""

from __future__ import annotations

import io
import pickle
from pathlib import Path

import mujoco
import numpy as np

from kinema.atomic_files import atomic_write_bytes
from kinema.errors import KinemaError
from kinema.robot.description import Robot
from kinema.robot.dynamics import finite_differences
from kinema.robot.motion import RobotMotion

TRACKERS = ("beyondmimic", "gmr")


def breadth_first(model: mujoco.MjModel) -> list[int]:
    """Body ids (world left out) ordered by depth in the tree, then by MJCF order: Isaac Lab's order."""
    depth = np.zeros(model.nbody, dtype=int)
    for b in range(1, model.nbody):
        depth[b] = depth[model.body_parentid[b]] + 1
    return sorted(range(1, model.nbody), key=lambda b: (depth[b], b))


def _poses(motion: RobotMotion, robot: Robot) -> np.ndarray:
    motion.check_joints(robot.joint_names, robot.name)
    return np.array([robot.qpos(motion.root_position[t], motion.root_quaternion[t], motion.joint_angles[t])
                     for t in range(motion.num_frames)])


def beyondmimic_arrays(motion: RobotMotion, robot: Robot) -> dict[str, np.ndarray]:
    """The BeyondMimic npz's arrays (see the module docstring)."""
    m, data = robot.model, mujoco.MjData(robot.model)
    Q = _poses(motion, robot)
    qvel, _ = finite_differences(m, Q, motion.fps)
    bodies = breadth_first(m)
    joints = sorted(range(robot.num_joints), key=lambda j: bodies.index(int(m.jnt_bodyid[j + 1])))
    T, B = len(Q), len(bodies)
    pos, quat, lin, ang = np.zeros((T, B, 3)), np.zeros((T, B, 4)), np.zeros((T, B, 3)), np.zeros((T, B, 3))
    velocity = np.zeros(6)
    for t in range(T):
        data.qpos[:], data.qvel[:] = Q[t], qvel[t]
        mujoco.mj_forward(m, data)
        for i, b in enumerate(bodies):
            pos[t, i], quat[t, i] = data.xpos[b], data.xquat[b]
            mujoco.mj_objectVelocity(m, data, mujoco.mjtObj.mjOBJ_BODY, b, velocity, 0)  # at its COM, world axes
            ang[t, i], lin[t, i] = velocity[:3], velocity[3:]
    f32 = np.float32
    return {
        "fps": np.array([round(motion.fps) if float(motion.fps).is_integer() else motion.fps]),
        "joint_pos": Q[:, robot.qpos_adr[joints]].astype(f32),
        "joint_vel": qvel[:, robot.dof_adr[joints]].astype(f32),
        "body_pos_w": pos.astype(f32),
        "body_quat_w": quat.astype(f32),
        "body_lin_vel_w": lin.astype(f32),
        "body_ang_vel_w": ang.astype(f32),
        "joint_names": np.array([robot.joint_names[j] for j in joints]),
        "body_names": np.array([m.body(b).name for b in bodies]),
    }


def gmr_motion(motion: RobotMotion, robot: Robot) -> dict:
    """The GMR pickle's dict (see the module docstring)."""
    m, data = robot.model, mujoco.MjData(robot.model)
    Q = _poses(motion, robot)
    local = np.zeros((len(Q), m.nbody - 1, 3))
    for t in range(len(Q)):
        data.qpos[:] = Q[t]
        mujoco.mj_kinematics(m, data)
        root = data.xmat[1].reshape(3, 3)
        local[t] = (data.xpos[1:] - data.xpos[1]) @ root
    return {
        "fps": float(motion.fps),
        "root_pos": Q[:, 0:3].copy(),
        "root_rot": Q[:, [4, 5, 6, 3]].copy(),  # MuJoCo's w x y z -> x y z w
        "dof_pos": Q[:, 7:].copy(),
        "local_body_pos": local,
        "link_body_list": [m.body(b).name for b in range(1, m.nbody)],
    }


def save_for_tracker(motion: RobotMotion, robot: Robot, path: str | Path, tracker: str) -> Path:
    """Write ``motion`` for ``tracker`` (``"beyondmimic"``: .npz, ``"gmr"``: .pkl) atomically."""
    path = Path(path)
    suffix = {"beyondmimic": ".npz", "gmr": ".pkl"}.get(tracker)
    if suffix is None:
        raise KinemaError(f"tracker {tracker!r}: expected one of {list(TRACKERS)}")
    if path.suffix.lower() != suffix:
        raise KinemaError(f"{path}: a {tracker} motion is written as {suffix}")
    if tracker == "gmr":
        atomic_write_bytes(path, pickle.dumps(gmr_motion(motion, robot)))
        return path
    buf = io.BytesIO()
    np.savez(buf, **beyondmimic_arrays(motion, robot))
    atomic_write_bytes(path, buf.getvalue())
    return path
