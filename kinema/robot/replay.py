"""Replaying a robot motion with MuJoCo's forward kinematics (from the MJCF itself) and measuring what a
kinematic demonstration must respect: joint ranges, soles above the floor, planted soles that do not
slide, how far it travels, and whether the legs pass through each other.

Planted frames are the motion's ``sole_planted`` flags (from the source's contacts) when it has them;
otherwise a sole counts as planted on frames where all of it is within 1 cm of the floor (flat on it) on
this frame and the next. Leg self-intersection uses the MJCF's capsule and sphere geoms of the two legs
(the bodies below each hip): the deepest overlap of a left-leg geom with a right-leg geom, in metres.

Steps: a sole steps where its centre moves over the floor faster than ``STEP_SPEED`` for at least
kinema.robot.feet.STEP_MIN and at least kinema.robot.feet.MIN_SWING; a step's clearance is how high the sole's lowest
point gets above the floor during it (a foot that shuffles clears little or nothing), and
``swing_clearance`` is the lowest over all steps of both soles; steps cut by the clip's first or last
frame are left out. A shorter move of that length is a ``slide`` (a foot that jumps along the floor
between two frames: where a source foot skates into its landing).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from kinema.robot.description import Robot, subtree
from kinema.robot.feet import MIN_SWING, STEP_MIN, spans
from kinema.robot.motion import RobotMotion
from kinema.robot.targets import SIDES

_PLANTED_HEIGHT = 0.01
STEP_SPEED = 0.2  # m/s


@dataclass(frozen=True)
class ReplayReport:
    """Measurements of a replayed robot motion (metres, radians, seconds)."""

    range_overshoot: float  # the furthest any joint is outside its range (0 when none is)
    lowest_sole: float  # the lowest sole point over the motion (negative: below the floor)
    planted_slide: float  # the fastest horizontal sole-centre speed while planted (m/s); 0 if never planted
    planted_fraction: float  # share of sole-frames that are planted
    travel: float  # horizontal distance from the root's first to its last position
    leg_overlap: float  # deepest overlap of left- and right-leg capsules (0 when apart)
    steps: int  # steps of both soles (see the module docstring)
    slides: int  # moves too short to be steps (see the module docstring)
    swing_clearance: float  # the least clearance of any step (m; inf without steps)
    sole_centres: np.ndarray  # (T, 2, 3) left and right sole centres
    points: dict[str, np.ndarray]  # landmark -> (T, 3) world positions


def _capsule(model: mujoco.MjModel, data: mujoco.MjData, g: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(end a, end b, radius) of a capsule or sphere geom in world coordinates."""
    centre, radius = data.geom_xpos[g], float(model.geom_size[g][0])
    if int(model.geom_type[g]) == int(mujoco.mjtGeom.mjGEOM_SPHERE):
        return centre, centre, radius
    axis = data.geom_xmat[g].reshape(3, 3)[:, 2] * model.geom_size[g][1]
    return centre - axis, centre + axis, radius


def segment_distance(p1: np.ndarray, q1: np.ndarray, p2: np.ndarray, q2: np.ndarray) -> float:
    """Shortest distance between segments p1-q1 and p2-q2 (by sampling one and projecting on the other)."""
    d2 = q2 - p2
    n2 = max(float(d2 @ d2), 1e-12)
    s = np.linspace(0.0, 1.0, 9)[:, None]
    pts = p1 + s * (q1 - p1)
    u = np.clip((pts - p2) @ d2 / n2, 0.0, 1.0)[:, None]
    return float(np.linalg.norm(pts - (p2 + u * d2), axis=1).min())


def leg_geoms(robot: Robot) -> dict[str, list[int]]:
    """Capsule and sphere geoms of each leg: geoms of the bodies from the hip body down."""
    m = robot.model
    kinds = {int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_SPHERE)}
    out = {}
    for s in SIDES:
        below = set(subtree(m, robot.body_ids[f"{s}_hip"]))
        out[s] = [g for g in range(m.ngeom) if int(m.geom_bodyid[g]) in below and int(m.geom_type[g]) in kinds]
    return out


def _overlap(robot: Robot, data: mujoco.MjData, geoms: dict[str, list[int]]) -> float:
    worst = 0.0
    for a in geoms["left"]:
        ca = _capsule(robot.model, data, a)
        for b in geoms["right"]:
            cb = _capsule(robot.model, data, b)
            worst = max(worst, ca[2] + cb[2] - segment_distance(ca[0], ca[1], cb[0], cb[1]))
    return worst


def _planted(motion: RobotMotion, highest: np.ndarray) -> np.ndarray:
    """(T - 1, 2) whether each sole is planted on a frame and the next."""
    flags = motion.sole_planted if motion.sole_planted is not None else highest < _PLANTED_HEIGHT
    return flags[1:] & flags[:-1]


def step_clearances(centres: np.ndarray, lowest: np.ndarray, speed: np.ndarray, fps: float) -> tuple[list, int]:
    """(each step's clearance (m), the number of slides), both soles: ``centres`` (T, 2, 3), ``lowest``
    (T, 2) lowest sole points, ``speed`` (T - 1, 2) horizontal sole-centre speeds (see the module
    docstring)."""
    out, slides = [], 0
    for i in range(2):
        for a, b in spans(speed[:, i] > STEP_SPEED):  # moving between frames a and b + 1
            inside = a > 0 and b + 2 < len(lowest)
            if not inside or np.linalg.norm(centres[b + 1, i, :2] - centres[a, i, :2]) < STEP_MIN:
                continue
            if (b + 1 - a) / fps < MIN_SWING:
                slides += 1
            else:
                out.append(float(lowest[a : b + 2, i].max()))
    return out, slides


def replay_report(motion: RobotMotion, robot: Robot) -> ReplayReport:
    """Replay ``motion`` on ``robot`` frame by frame and measure it (see the module docstring)."""
    motion.check_joints(robot.joint_names, robot.name)
    data, geoms = mujoco.MjData(robot.model), leg_geoms(robot)
    T = motion.num_frames
    centres, lowest, highest, overlap = np.zeros((T, 2, 3)), np.zeros((T, 2)), np.zeros((T, 2)), 0.0
    points = {k: np.zeros((T, 3)) for k in robot.points}
    for t in range(T):
        data.qpos[:] = robot.qpos(motion.root_position[t], motion.root_quaternion[t], motion.joint_angles[t])
        mujoco.mj_kinematics(robot.model, data)
        for i, s in enumerate(SIDES):
            centres[t, i] = robot.sole_centre(data, s)
            heights = robot.sole_points(data, s)[:, 2]
            lowest[t, i], highest[t, i] = heights.min(), heights.max()
        for k in points:
            points[k][t] = robot.point(data, k)
        overlap = max(overlap, _overlap(robot, data, geoms))
    lo, hi = robot.ranges[:, 0], robot.ranges[:, 1]
    over = np.maximum(lo - motion.joint_angles, motion.joint_angles - hi).max(initial=0.0)
    speed = np.linalg.norm(np.diff(centres[..., :2], axis=0), axis=-1) * motion.fps
    clearances, slides = step_clearances(centres, lowest, speed, motion.fps)
    planted = _planted(motion, highest)
    return ReplayReport(
        range_overshoot=float(max(over, 0.0)),
        lowest_sole=float(lowest.min()),
        planted_slide=float(speed[planted].max(initial=0.0)),
        planted_fraction=float(planted.mean()) if T > 1 else 0.0,
        travel=float(np.linalg.norm(motion.root_position[-1, :2] - motion.root_position[0, :2])),
        leg_overlap=float(overlap),
        steps=len(clearances),
        slides=slides,
        swing_clearance=float(min(clearances, default=np.inf)),
        sole_centres=centres,
        points=points,
    )
