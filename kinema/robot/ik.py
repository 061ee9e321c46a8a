"""Damped least-squares inverse kinematics over a robot's floating base and hinge joints, with MuJoCo's
forward kinematics and Jacobians (``mj_kinematics``, ``mj_comPos``, ``mj_jac``, ``mj_jacBody``).

Each frame is solved from the previous frame's solution (warm start), so the solver never jumps to
another IK branch; a small pull towards that previous pose and towards the zero pose keeps redundant
joints (wrists, waist) still. Sole points below the floor (raised in a step's swing) are pushed up by
one-sided rows. Joint limits are enforced inside the iterations: a joint at a bound whose step points
outwards is frozen for that step and the step is solved again without it, and every step is clamped into
the bounds, so later iterations work with the clamped pose. The bounds are the joint ranges and, from the
previous frame's pose, how far each joint may turn in one frame at its velocity limit (where the robot
gives them, kinema.robot.description).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from kinema.robot.description import Robot
from kinema.robot.targets import SIDES, FrameTargets, RobotSizes

_MAX_STEP = 0.4  # radians (and metres) per iteration


@dataclass(frozen=True)
class IKWeights:
    """Task weights (squared-error weights) and regularisation of the per-frame solve."""

    sole: float = 20.0
    sole_height: float = 60.0
    foot_rotation: float = 4.0
    pelvis: float = 6.0
    pelvis_height: float = 1.0
    pelvis_rotation: float = 1.0
    torso_rotation: float = 2.0
    hand: float = 4.0
    elbow: float = 1.0
    knee: float = 1.0
    floor: float = 200.0
    to_previous: float = 0.1
    to_zero: float = 0.005
    damping: float = 1e-2


def rotation_error(target: np.ndarray, current: np.ndarray) -> np.ndarray:
    """World-frame rotation vector (3,) taking ``current`` to ``target`` (both 3x3)."""
    R = target @ current.T
    angle = np.arccos(np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0))
    axis = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])
    s = np.sin(angle)
    return axis * (0.5 if s < 1e-6 else angle / (2.0 * s))


class HingeIK:
    """Per-frame IK for one robot (see the module docstring)."""

    def __init__(self, robot: Robot, sizes: RobotSizes, weights: IKWeights | None = None, fps: float = 30.0):
        weights = weights or IKWeights()
        self.robot, self.sizes, self.w = robot, sizes, weights
        self.model, self.data = robot.model, mujoco.MjData(robot.model)
        nv = robot.model.nv
        self.hinge = np.zeros(nv, dtype=bool)
        self.hinge[robot.dof_adr] = True
        speeds = robot.velocity_limits if robot.velocity_limits is not None else np.full(robot.num_joints, np.inf)
        self.turn = speeds / fps  # radians a joint may turn between frames
        self.lo, self.hi = robot.ranges[:, 0].copy(), robot.ranges[:, 1].copy()
        self._jacp, self._jacr = np.zeros((3, nv)), np.zeros((3, nv))
        self.pelvis_weights = np.array([weights.pelvis, weights.pelvis, weights.pelvis_height])
        self.sole_weights = np.array([weights.sole, weights.sole, weights.sole_height])
        mujoco.mj_kinematics(self.model, self.data)
        self.rest = {k: self.data.xmat[robot.body_ids[k]].reshape(3, 3).copy() for k in ("pelvis", "torso")}
        self.rest.update({s: self.data.xmat[robot.soles[s].body].reshape(3, 3).copy() for s in SIDES})

    def _point_rows(self, body: int, point: np.ndarray, target: np.ndarray, weight: float):
        mujoco.mj_jac(self.model, self.data, self._jacp, None, point, body)
        return self._jacp.copy(), target - point, weight

    def _relative_rows(self, key: str, anchor: str, target: np.ndarray, weight: float):
        """Rows that bring landmark ``key`` to ``target``, a point given relative to landmark ``anchor`` (a
        knee from its hip, an elbow or hand from its shoulder): the Jacobian is the difference of the two,
        since moving the anchor moves the target with it."""
        r, d = self.robot, self.data
        J, e, w = self._point_rows(r.body_ids[key], r.point(d, key), target, weight)
        mujoco.mj_jac(self.model, d, self._jacp, None, r.point(d, anchor), r.body_ids[anchor])
        return J - self._jacp, e, w

    def _rotation_rows(self, body: int, target: np.ndarray, weight: float):
        mujoco.mj_jacBody(self.model, self.data, None, self._jacr, body)
        return self._jacr.copy(), rotation_error(target, self.data.xmat[body].reshape(3, 3)), weight

    def _floor_rows(self, side: str, floor: float) -> list:
        """Rows pushing up every sole point that is below ``floor`` (z = 0, higher in a step's swing): an
        inequality, active only where it is violated."""
        foot = self.robot.soles[side].body
        rows = []
        for p in self.robot.sole_points(self.data, side):
            if p[2] < floor:
                mujoco.mj_jac(self.model, self.data, self._jacp, None, p, foot)
                rows.append((self._jacp[2:3].copy(), np.array([floor - p[2]]), self.w.floor))
        return rows

    def _tasks(self, tg: FrameTargets, t: int) -> list:
        r, w, d = self.robot, self.w, self.data
        ids = r.body_ids
        rows = [
            self._point_rows(ids["pelvis"], r.point(d, "pelvis"), tg.pelvis[t], self.pelvis_weights),
            self._rotation_rows(ids["pelvis"], tg.pelvis_frame[t] @ self.rest["pelvis"], w.pelvis_rotation),
            self._rotation_rows(ids["torso"], tg.torso_frame[t] @ self.rest["torso"], w.torso_rotation),
        ]
        for s in SIDES:
            foot = r.soles[s].body
            rows.append(self._point_rows(foot, r.sole_centre(d, s), tg.sole[s][t], self.sole_weights))
            rows += self._floor_rows(s, tg.sole_floor[s][t])
            rows.append(self._rotation_rows(foot, tg.foot_frame[s][t] @ self.rest[s], w.foot_rotation))
            knee = r.point(d, f"{s}_hip") + self.sizes.thigh * tg.knee_dir[s][t]
            rows.append(self._relative_rows(f"{s}_knee", f"{s}_hip", knee, w.knee))
            shoulder = r.point(d, f"{s}_shoulder")
            elbow = shoulder + self.sizes.upper_arm * tg.elbow_dir[s][t]
            rows.append(self._relative_rows(f"{s}_elbow", f"{s}_shoulder", elbow, w.elbow))
            hand = shoulder + tg.hand_reach[s][t]
            rows.append(self._relative_rows(f"{s}_hand", f"{s}_shoulder", hand, w.hand))
        return rows

    def _step(self, q: np.ndarray, q_prev: np.ndarray | None, tg: FrameTargets, t: int) -> np.ndarray:
        """One limited DLS step (nv,) from pose ``q``; ``q_prev`` None: no pull towards a previous pose."""
        rows = self._tasks(tg, t)
        A = np.concatenate([np.reshape(np.sqrt(wt), (-1, 1)) * J for J, _, wt in rows])
        b = np.concatenate([np.sqrt(wt) * e for _, e, wt in rows])
        r, w = self.robot, self.w
        pull = 0.0 if q_prev is None else w.to_previous
        H = A.T @ A + np.diag(np.where(self.hinge, pull + w.to_zero, 0.0) + w.damping)
        g = A.T @ b
        angles = q[r.qpos_adr]
        prev = angles if q_prev is None else q_prev[r.qpos_adr]
        g[r.dof_adr] += pull * (prev - angles) - w.to_zero * angles
        dq = np.linalg.solve(H, g)
        lo, hi = self.lo, self.hi
        step = dq[r.dof_adr]
        frozen = ((angles <= lo + 1e-9) & (step < 0)) | ((angles >= hi - 1e-9) & (step > 0))
        if frozen.any():
            idx = r.dof_adr[frozen]
            H[idx, :], H[:, idx], g[idx] = 0.0, 0.0, 0.0
            H[idx, idx] = 1.0
            dq = np.linalg.solve(H, g)
        return dq * min(1.0, _MAX_STEP / max(np.abs(dq).max(), 1e-12))

    def solve(self, q: np.ndarray, tg: FrameTargets, t: int, iterations: int, first: bool = False) -> np.ndarray:
        """The pose (nq,) for frame ``t`` starting from ``q``: the previous frame's pose, which the solve is
        pulled towards, or (``first``) a starting guess it is not."""
        r, m, d = self.robot, self.model, self.data
        q_prev, q = (None if first else q.copy()), q.copy()
        self.lo, self.hi = r.ranges[:, 0].copy(), r.ranges[:, 1].copy()
        if q_prev is not None:
            angles = q_prev[r.qpos_adr]
            self.lo = np.minimum(np.maximum(self.lo, angles - self.turn), angles)  # a joint outside its range
            self.hi = np.maximum(np.minimum(self.hi, angles + self.turn), angles)  # may stay where it is
        for _ in range(iterations):
            d.qpos[:] = q
            mujoco.mj_kinematics(m, d)
            mujoco.mj_comPos(m, d)
            dq = self._step(q, q_prev, tg, t)
            mujoco.mj_integratePos(m, q, dq, 1.0)
            q[r.qpos_adr] = np.clip(q[r.qpos_adr], self.lo, self.hi)
            if np.abs(dq).max() < 1e-4:
                break
        return q
