"""Inverse dynamics of robot motions in MuJoCo (kinema.robot.dynamics): physics checked against cases whose
answer is known (a robot standing still, one floating, one teleported), then a captured walk and the faces
that carry the report (the request's report, the server's JSON; the `kinema robot` command's lines are
checked in tests/test_robot_exports.py)."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

import kinema
from kinema.robot import RobotMotion, load_robot, retarget_to_robot
from kinema.robot.dynamics import RESIDUAL_LIMIT, dynamics_report, torque_limits


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


def _standing(g1, frames: int = 20, lift: float = 0.0) -> RobotMotion:
    """The G1 at rest with its soles on the floor (raised by ``lift`` metres), held still."""
    data = mujoco.MjData(g1.model)
    mujoco.mj_kinematics(g1.model, data)
    low = min(g1.sole_points(data, s)[:, 2].min() for s in ("left", "right"))
    root = g1.model.qpos0[0:3] - np.array([0.0, 0.0, low - lift])
    return RobotMotion("g1", 20.0, g1.joint_names, np.tile(root, (frames, 1)),
                       np.tile(g1.model.qpos0[3:7], (frames, 1)), np.tile(g1.model.qpos0[g1.qpos_adr], (frames, 1)))


def test_standing_still_needs_no_residual_and_gravity_torques(g1):
    rep = dynamics_report(_standing(g1), g1)
    assert rep.residual_force.value < 0.005 and rep.residual_moment_arm.value < 0.002
    assert rep.feasible and rep.warning() is None and rep.contact_fraction == 1.0
    assert rep.mass == pytest.approx(33.34, abs=0.1)
    # an arm carries no contact force, so its torque is exactly gravity's pull on it (MuJoCo's bias force at rest)
    data = mujoco.MjData(g1.model)
    data.qpos[:] = g1.qpos(*(_standing(g1, 1).root_position[0], g1.model.qpos0[3:7], g1.model.qpos0[g1.qpos_adr]))
    mujoco.mj_forward(g1.model, data)
    limits = torque_limits(g1.model, g1)
    for name in ("left_shoulder_pitch_joint", "right_elbow_joint"):
        j = g1.joint_names.index(name)
        gravity = abs(data.qfrc_bias[g1.dof_adr[j]])
        assert gravity > 0.5  # N m: the arm's weight does pull on it
        assert rep.joint_torque_share[name] * limits[j] == pytest.approx(gravity, rel=0.02)
    # the legs hold the body up: the ankles pitch against its weight, far from their limits
    assert 0.01 < rep.joint_torque_share["left_ankle_pitch_joint"] < 0.5


def test_floating_and_teleported_motions_need_a_hand_of_god(g1):
    floating = dynamics_report(_standing(g1, lift=0.1), g1)
    assert floating.residual_force.value == pytest.approx(1.0, abs=0.01)  # all of its weight
    assert floating.residual_force.what == "no sole on the floor" and not floating.feasible
    assert floating.warning().startswith("robot motion not feasible: the floating base needs 100% of body weight")
    jump = _standing(g1, frames=30)
    jump.root_position[15:, 2] -= 0.08  # a drop of 8 cm between two frames: a fall faster than gravity
    rep = dynamics_report(jump, g1)
    assert rep.residual_force.value > 1.0 and rep.residual_force.time == pytest.approx(14 / 20)
    assert "pull" in rep.residual_force.what and rep.residual_force_window.value > RESIDUAL_LIMIT


def test_torque_speed_and_collision_limits(g1):
    limits, speeds = torque_limits(g1.model, g1), g1.velocity_limits
    knee = g1.joint_names.index("left_knee_joint")
    assert limits[knee] == 139.0 and speeds[knee] == 20.0  # the MJCF's actuatorfrcrange, Unitree's URDF
    motion = _standing(g1, frames=30)
    t = np.arange(30) / 20.0
    shoulder = g1.joint_names.index("left_shoulder_pitch_joint")
    motion.joint_angles[:, shoulder] = 1.2 * np.sin(2 * np.pi * 4.0 * t)  # 4 Hz, +-1.2 rad: 30 rad/s
    roll = g1.joint_names.index("left_hip_roll_joint")
    motion.joint_angles[10:, roll] = -0.5  # the left leg swung into the right one
    rep = dynamics_report(motion, g1)
    assert rep.speed.what == "left_shoulder_pitch_joint" and rep.speed.value > 0.6
    assert rep.torque.what == "left_shoulder_pitch_joint" and rep.torque.value > 1.0
    assert rep.collision.value > 0.01 and "left" in rep.collision.what and "right" in rep.collision.what
    assert "left_shoulder_pitch_joint needs" in rep.warning() and "into each other" in rep.warning()
    assert dynamics_report(_standing(g1), g1).collision.value == 0.0  # touching at rest does not count


def test_captured_walk_dynamics(walk_clip, g1):
    """A captured human walk on the G1: the contacts it implies carry the body, within the stated share."""
    robot_motion = retarget_to_robot(kinema.load_motion(walk_clip, scale=0.01), g1)
    rep = dynamics_report(robot_motion, g1)
    assert rep.contact_fraction > 0.95
    assert rep.residual_force_window.value <= RESIDUAL_LIMIT  # the stated share (docs/robots.md)
    assert rep.residual_force_mean < 0.3 and rep.speed.value < 1.0
    # the swinging hands brush the hips (the IK does not avoid the MJCF's capsules); the legs stay apart
    assert rep.collision.value < 0.05 and "wrist" in rep.collision.what
    assert set(rep.as_dict()) >= {"torque", "residual_force", "speed", "collision", "feasible", "problems"}


def test_request_report_and_server_json_carry_dynamics():
    import json

    from fastapi.testclient import TestClient

    from kinema.server.app import create_app
    from kinema.server.config import ServerConfig, ServerLimits
    from kinema.server.models import ModelRegistry

    res = kinema.load_model("default").generate("A person walks.", seconds=1.0, steps=2, robot="g1")
    (measured,) = res.report.robot
    dynamics = json.loads(json.dumps(measured["dynamics"]))  # plain JSON
    assert dynamics["residual_force"]["value"] >= 0.0 and dynamics["feasible"] == measured["feasible"]
    assert (measured["warning"] in res.report.warnings) if not measured["feasible"] else measured["warning"] is None
    client = TestClient(create_app(ServerConfig(limits=ServerLimits(max_steps=4)), ModelRegistry.load(["default"])))
    answer = client.post("/v1/generate", json={"prompt": "A person waves.", "seconds": 1.0, "steps": 2, "robot": "h1",
                                               "format": "csv"})  # the second shipped robot, by name
    assert answer.status_code == 200, answer.text
    (robot,) = answer.json()["report"]["robot"]
    assert "base residual" in robot["dynamics_summary"] and "torque" in robot["dynamics"] and robot["robot"] == "h1"
    assert answer.json()["motions"][0]["data"].startswith("time,root_x")
