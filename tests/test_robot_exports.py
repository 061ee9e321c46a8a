"""Robot motions for trackers (kinema.robot.exports): each file is loaded the way the tracker's own code
loads it (BeyondMimic's MotionLoader: np.load and its keys; GMR's load_robot_motion: pickle.load, xyzw
quaternions) and checked against MuJoCo's forward kinematics of the motion kinema wrote."""

from __future__ import annotations

import contextlib
import io
import pickle

import mujoco
import numpy as np
import pytest

from kinema.cli import main
from kinema.robot import load_robot, load_robot_motion

#: Isaac Lab's joint order of the G1 29-DoF (breadth-first through the tree), as its configs list it
ISAAC_G1_JOINTS = [
    f"{name}_joint" for name in (
        "left_hip_pitch", "right_hip_pitch", "waist_yaw", "left_hip_roll", "right_hip_roll", "waist_roll",
        "left_hip_yaw", "right_hip_yaw", "waist_pitch", "left_knee", "right_knee", "left_shoulder_pitch",
        "right_shoulder_pitch", "left_ankle_pitch", "right_ankle_pitch", "left_shoulder_roll", "right_shoulder_roll",
        "left_ankle_roll", "right_ankle_roll", "left_shoulder_yaw", "right_shoulder_yaw", "left_elbow", "right_elbow",
        "left_wrist_roll", "right_wrist_roll", "left_wrist_pitch", "right_wrist_pitch", "left_wrist_yaw",
        "right_wrist_yaw")
]


@pytest.fixture(scope="module")
def walk_g1(walk_clip, tmp_path_factory):
    """The captured walk on the G1, written by `kinema robot` as kinema's npz; the command prints the replay
    and the dynamics (kinema.robot.dynamics) in a line each."""
    out, said = tmp_path_factory.mktemp("exports") / "walk_g1.npz", io.StringIO()
    with contextlib.redirect_stdout(said):
        assert main(["robot", str(walk_clip), "--scale", "0.01", "--robot", "g1", "--out", str(out)]) == 0
    replay, dynamics = said.getvalue().splitlines()[-2:]
    assert "steps clearing at least" in replay and "of the human's; legs 0.78" in replay
    assert dynamics.startswith("dynamics") and "% of limit" in dynamics and "of body weight" in dynamics
    return out


def _forward(robot, qpos):
    data = mujoco.MjData(robot.model)
    data.qpos[:] = qpos
    mujoco.mj_kinematics(robot.model, data)
    return data


def test_beyondmimic_npz_loads_as_its_motion_loader_reads_it(walk_g1, tmp_path):
    out = tmp_path / "walk_bm.npz"
    assert main(["robot", str(walk_g1), "--tracker", "beyondmimic", "--out", str(out)]) == 0
    data = np.load(out)  # whole_body_tracking's MotionLoader: np.load(motion_file), then these keys
    fps = data["fps"]
    joint_pos, joint_vel = data["joint_pos"], data["joint_vel"]
    body_pos_w, body_quat_w = data["body_pos_w"], data["body_quat_w"]
    body_lin_vel_w, body_ang_vel_w = data["body_lin_vel_w"], data["body_ang_vel_w"]
    g1, rm = load_robot("g1"), load_robot_motion(walk_g1)
    T, B = rm.num_frames, g1.model.nbody - 1
    assert fps.shape == (1,) and fps[0] == 30
    assert joint_pos.shape == joint_vel.shape == (T, 29) and joint_pos.dtype == np.float32
    assert body_pos_w.shape == body_lin_vel_w.shape == body_ang_vel_w.shape == (T, B, 3)
    assert body_quat_w.shape == (T, B, 4) and body_quat_w.dtype == np.float32
    assert list(data["joint_names"]) == ISAAC_G1_JOINTS and data["body_names"][0] == "pelvis"
    # joint angles by name, bodies where MuJoCo puts them, quaternions w x y z
    order = [g1.joint_names.index(n) for n in data["joint_names"]]
    np.testing.assert_allclose(joint_pos, rm.joint_angles[:, order], atol=1e-6)
    t = T // 2
    mj = _forward(g1, g1.qpos(rm.root_position[t], rm.root_quaternion[t], rm.joint_angles[t]))
    for i, name in enumerate(data["body_names"]):
        b = g1.model.body(str(name)).id
        np.testing.assert_allclose(body_pos_w[t, i], mj.xpos[b], atol=1e-5)
        assert abs(abs(float(body_quat_w[t, i] @ mj.xquat[b])) - 1.0) < 1e-5
    # velocities are the poses' rates of change
    np.testing.assert_allclose(joint_vel[t], (joint_pos[t + 1] - joint_pos[t - 1]) * 15.0, atol=1e-3)
    com = {k: _forward(g1, g1.qpos(rm.root_position[k], rm.root_quaternion[k], rm.joint_angles[k])).xipos
           for k in (t - 1, t + 1)}  # bodies' centres of mass, whose velocity Isaac Lab gives
    rows = [g1.model.body(str(name)).id for name in data["body_names"]]
    np.testing.assert_allclose(body_lin_vel_w[t], (com[t + 1][rows] - com[t - 1][rows]) * 15.0, atol=0.02)
    assert np.abs(body_ang_vel_w).max() > 0.1


def test_gmr_pickle_loads_as_its_load_robot_motion_reads_it(walk_g1, tmp_path):
    out = tmp_path / "walk.pkl"
    assert main(["robot", str(walk_g1), "--out", str(out)]) == 0  # .pkl: GMR's pickle
    with open(out, "rb") as f:  # GMR's load_robot_motion
        motion_data = pickle.load(f)
    motion_fps = motion_data["fps"]
    motion_root_pos = motion_data["root_pos"]
    motion_root_rot = motion_data["root_rot"][:, [3, 0, 1, 2]]  # from xyzw to wxyz
    motion_dof_pos = motion_data["dof_pos"]
    motion_local_body_pos = motion_data["local_body_pos"]
    motion_link_body_list = motion_data["link_body_list"]
    g1, rm = load_robot("g1"), load_robot_motion(walk_g1)
    assert motion_fps == pytest.approx(30.0) and motion_dof_pos.shape == (rm.num_frames, 29)
    np.testing.assert_allclose(motion_root_pos, rm.root_position)
    np.testing.assert_allclose(motion_root_rot, rm.root_quaternion)  # back to MuJoCo's w x y z
    t = rm.num_frames // 3
    qpos = np.concatenate([motion_root_pos[t], motion_root_rot[t], motion_dof_pos[t]])  # GMR's qpos
    mj = _forward(g1, qpos)
    knee = motion_link_body_list.index("left_knee_link")
    world = mj.xpos[1] + mj.xmat[1].reshape(3, 3) @ motion_local_body_pos[t, knee]
    np.testing.assert_allclose(world, mj.xpos[g1.model.body("left_knee_link").id], atol=1e-9)


def test_tracker_outputs_refuse_the_wrong_suffix(walk_g1, tmp_path, capsys):
    assert main(["robot", str(walk_g1), "--tracker", "beyondmimic", "--out", str(tmp_path / "x.pkl")]) == 2
    assert "a beyondmimic motion is written as .npz" in capsys.readouterr().err
    assert main(["robot", str(walk_g1), "--out", str(tmp_path / "x.csv")]) == 2
    assert "robot motion already: give --tracker" in capsys.readouterr().err
