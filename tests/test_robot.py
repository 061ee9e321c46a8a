"""Human motions on the Unitree G1, replayed with MuJoCo's forward kinematics of the shipped MJCF.

Sources: the default model with few sampling steps (a walk, a raised left hand) and a captured Bandai
Namco walk. Every check reads the robot's poses back through `mujoco` (kinema.robot.replay), not the
retargeting's own bookkeeping.
"""

from __future__ import annotations

import re
import time

import mujoco
import numpy as np
import pytest

import kinema
from kinema.robot import BUILTIN_ROBOTS, RobotMotion, dynamics_report, load_robot, replay_report, retarget_to_robot
from kinema.robot.replay import leg_geoms

SLIDE_LIMIT = 0.15  # m/s, planted soles (issue 39)
FLOOR_LIMIT = -0.02  # m, lowest sole point
CLEARANCE_LIMIT = 0.03  # m, the swing foot's lowest sole point at the top of every step (issue 62)


@pytest.fixture(scope="module")
def g1():
    return load_robot("g1")


@pytest.fixture(scope="module")
def model():
    return kinema.load_model()


@pytest.fixture(scope="module")
def walk(model, g1):
    human = model.generate("A person walks forward.", seconds=4, steps=10)[0]
    return human, retarget_to_robot(human, g1)


@pytest.fixture(scope="module")
def left_hand(model, g1):
    human = model.generate("A person raises their left hand.", seconds=4, steps=10)[0]
    return human, retarget_to_robot(human, g1)


def test_g1_description(g1):
    assert g1.num_joints == 29 and g1.model.nq == 7 + 29
    assert "left_knee_joint" in g1.joint_names and "waist_pitch_joint" in g1.joint_names
    assert np.isfinite(g1.ranges).all() and (g1.ranges[:, 0] < g1.ranges[:, 1]).all()
    # the sole is the bottom of the foot box, 3.7 cm below the ankle-roll frame
    assert g1.soles["left"].centre[2] == pytest.approx(-0.037, abs=1e-3)


def test_walk_on_g1_replayed_in_mujoco(walk, g1):
    human, robot_motion = walk
    rep = replay_report(robot_motion, g1)
    assert robot_motion.num_frames == human.num_frames and robot_motion.fps == human.fps
    assert rep.range_overshoot == 0.0
    assert rep.lowest_sole >= FLOOR_LIMIT
    assert rep.planted_fraction > 0.0  # the source plants its feet, so there is something to hold
    assert rep.planted_slide <= SLIDE_LIMIT
    # it travels, in the direction and (scaled by leg length) the distance the human does
    root = human.positions[:, human.skeleton.roles["pelvis"]].numpy()
    human_travel = np.linalg.norm(root[-1, [0, 2]] - root[0, [0, 2]])
    assert 0.6 * human_travel < rep.travel < 0.95 * human_travel
    assert rep.leg_overlap <= 0.01
    # soles stay on the floor where planted: the planted sole centres sit within 1 cm of it
    planted = robot_motion.sole_planted
    assert np.abs(rep.sole_centres[..., 2][planted]).max() < 0.01


def test_walk_is_smooth_and_upright(walk):
    _, robot_motion = walk
    velocity = np.abs(np.diff(robot_motion.joint_angles, axis=0)) * robot_motion.fps
    assert velocity.max() < 15.0  # rad/s: no IK flips between frames
    q = robot_motion.root_quaternion
    assert (np.sum(q[1:] * q[:-1], axis=1) > 0.98).all()  # continuous root orientation
    up = 1 - 2 * (q[:, 1] ** 2 + q[:, 2] ** 2)  # z of the root's z axis
    assert up.min() > 0.8


def test_raised_left_hand_is_the_robots_left(left_hand, g1):
    human, robot_motion = left_hand
    P, roles = human.positions.numpy(), human.skeleton.roles
    assert (P[:, roles["left_hand"], 1] - P[:, roles["head"], 1]).max() > 0.0  # the source does raise it
    rep = replay_report(robot_motion, g1)
    head, lhand, rhand = rep.points["head"][:, 2], rep.points["left_hand"][:, 2], rep.points["right_hand"][:, 2]
    assert (lhand - head).max() >= 0.0  # the G1's left wrist reaches head height
    assert (rhand - head).max() < -0.2  # its right hand stays down
    top = int(np.argmax(lhand))
    assert rep.points["left_hand"][top, 1] > rep.points["right_hand"][top, 1]  # and it is on the +Y (left) side
    assert rep.range_overshoot == 0.0 and rep.lowest_sole >= FLOOR_LIMIT


def test_captured_walk_on_g1(walk_clip, g1):
    human = kinema.load_motion(walk_clip, scale=0.01)
    robot_motion = retarget_to_robot(human, g1)
    rep = replay_report(robot_motion, g1)
    assert rep.range_overshoot == 0.0
    assert rep.lowest_sole >= FLOOR_LIMIT
    assert rep.planted_fraction > 0.2 and rep.planted_slide <= SLIDE_LIMIT
    assert rep.travel > 2.0 and rep.leg_overlap <= 0.01
    assert rep.steps >= 8 and rep.swing_clearance >= CLEARANCE_LIMIT  # steps, not shuffles (issue 62)


def test_replay_measures_catch_bad_poses(walk, g1):
    """The measures are not vacuous: a joint pushed out of range, a sunk root, crossed legs are reported."""
    _, good = walk
    bad = RobotMotion(
        good.robot,
        good.fps,
        good.joint_names,
        good.root_position - [0, 0, 0.1],
        good.root_quaternion,
        good.joint_angles.copy(),
        good.sole_planted,
    )
    knee = g1.joint_names.index("left_knee_joint")
    bad.joint_angles[5, knee] = g1.ranges[knee, 1] + 0.3
    bad.joint_angles[7] = 0.0  # standing straight, both legs swung inwards across each other
    bad.joint_angles[7, g1.joint_names.index("left_hip_roll_joint")] = -0.5
    bad.joint_angles[7, g1.joint_names.index("right_hip_roll_joint")] = 0.5
    rep = replay_report(bad, g1)
    assert rep.range_overshoot == pytest.approx(0.3)
    assert rep.lowest_sole < -0.09
    assert rep.leg_overlap > 0.02


def test_leg_capsules_are_the_mjcf_geoms(g1):
    geoms = leg_geoms(g1)
    names = {s: {g1.model.geom(g).name for g in ids} for s, ids in geoms.items()}
    assert "left_thigh_collision" in names["left"] and "right_shin_collision" in names["right"]
    assert not names["left"] & names["right"]
    kinds = {int(g1.model.geom_type[g]) for g in geoms["left"]}
    assert kinds <= {int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_SPHERE)}


def test_retargeting_a_walk_takes_seconds_not_minutes(walk, g1):
    human, _ = walk
    start = time.perf_counter()
    retarget_to_robot(human, g1)
    assert time.perf_counter() - start < 10.0  # about 0.3 s for 4 s at 20 fps on one free core


def test_walk_steps_clear_the_floor_within_velocity_limits(walk, g1):
    """Swing feet lift their lowest sole point 3 cm at least, and the IK keeps the robot's joint velocity
    limits: with limits of 3 rad/s (the G1's are 20-37) no joint turns faster than that between frames."""
    human, robot_motion = walk
    rep = replay_report(robot_motion, g1)
    assert rep.steps >= 3 and rep.swing_clearance >= CLEARANCE_LIMIT
    speed = np.abs(np.diff(robot_motion.joint_angles, axis=0)) * robot_motion.fps
    assert speed.max() > 3.0 and (speed <= g1.velocity_limits).all()
    slow = load_robot("g1")
    slow.velocity_limits = np.full(slow.num_joints, 3.0)
    slowed = retarget_to_robot(human, slow)
    assert np.abs(np.diff(slowed.joint_angles, axis=0)).max() * slowed.fps <= 3.0 + 1e-9


@pytest.fixture(scope="module")
def h1():
    return load_robot("h1")


def test_h1_walks_and_raises_its_left_hand(walk, left_hand, h1):
    """The second shipped robot (Unitree H1, 19 joints, motor torque limits from ctrlrange), untuned: in its
    ranges and velocity limits, soles on the floor, steps that clear it, the left hand above the head."""
    assert h1.num_joints == 19 and h1.velocity_limits[h1.joint_names.index("left_knee")] == 14.0
    for human, _ in (walk, left_hand):
        robot_motion = retarget_to_robot(human, h1)
        rep = replay_report(robot_motion, h1)
        assert rep.range_overshoot == 0.0 and rep.lowest_sole >= FLOOR_LIMIT
        speed = np.abs(np.diff(robot_motion.joint_angles, axis=0)) * robot_motion.fps
        assert (speed <= h1.velocity_limits + 1e-9).all()
        if human is walk[0]:
            assert rep.steps >= 3 and rep.swing_clearance >= CLEARANCE_LIMIT and rep.travel > 1.0
        else:
            head, lhand, rhand = (rep.points[k][:, 2] for k in ("head", "left_hand", "right_hand"))
            assert (lhand - head).max() > 0.0 and (rhand - head).max() < -0.2
    dynamics = dynamics_report(robot_motion, h1)
    assert dynamics.mass == pytest.approx(51.4, abs=0.1) and "left_knee" in dynamics.joint_torque_share


def test_steps_clear_the_floor_on_an_untuned_mjcf(walk, tmp_path):
    """A G1 whose feet are the four 5-mm sole spheres of Unitree's URDF instead of Menagerie's box."""
    spheres = "".join(f'<geom type="sphere" size="0.005" pos="{x} {y} -0.03"/>'
                      for x, y in ((-0.05, 0.025), (-0.05, -0.025), (0.12, 0.03), (0.12, -0.03)))
    text = re.sub(r'<geom name="(left|right)_foot_box_collision"[^>]*/>', spheres, BUILTIN_ROBOTS["g1"].read_text())
    text = re.sub(r'<geom name="(left|right)_foot[123]_collision"[^>]*/>', "", text, flags=re.S)
    (tmp_path / "g1_spheres.xml").write_text(text)
    robot = load_robot(tmp_path / "g1_spheres.xml")
    assert len(robot.soles["left"].points) == 16  # the corners of the four spheres' boxes
    rep = replay_report(retarget_to_robot(walk[0], robot), robot)
    assert rep.steps >= 3 and rep.swing_clearance >= CLEARANCE_LIMIT and rep.lowest_sole >= FLOOR_LIMIT
