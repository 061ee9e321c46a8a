"""Could a robot motion be tracked? Inverse dynamics along it in MuJoCo, with the contacts it implies.

For every frame the motion's velocities and accelerations come from finite differences of its poses
(``mj_differentiatePos``: central for velocities, second differences for accelerations), and MuJoCo's
inverse dynamics (``mj_inverse``, with every constraint off: joint limits, friction loss) gives the
generalised force the whole motion needs, ``qfrc = M(q) qacc + bias(q, qvel)``. Its six floating-base rows
are what the floor has to supply through the feet; the rest is what the actuators have to supply.

- **Contacts.** The points of the soles (kinema.robot.description) within ``CONTACT_HEIGHT`` of the floor
  on a frame are in contact on it: the retargeting holds the source's planted feet flat on the floor
  (kinema.robot.feet), so this is where the motion puts its feet. Each contact point takes a force in a
  friction pyramid (4 edges, friction coefficient ``FRICTION``), pushing only.
- **Base residual.** Contact forces are solved per frame by non-negative least squares (scipy's ``nnls``
  over the pyramid edges) so that they supply the base wrench as closely as they can; what they cannot
  supply is the residual, a force no real floor gives (a "hand of God"). It is reported as a share of
  body weight (force) and as a moment arm (moment / weight, metres: how far outside the soles the centre
  of pressure would have to be), with the frame where it peaks and why: no sole on the floor, a pull
  (the body falls faster than gravity), more sideways force than friction allows, or a tipping moment.
  Moments are weighed against forces at ``MOMENT_ARM`` (a residual moment of weight x 0.1 m counts like
  a residual force of one body weight).
- **Joint torques**: the hinge rows of ``qfrc`` minus what the contact forces supply through the legs,
  as a share of each joint's actuator limit: the joint's ``actuatorfrcrange``, else its actuator's
  ``forcerange``, else ``gear x ctrlrange`` of a motor; a joint with none of these has no stated limit.
- **Joint speeds** against the robot's velocity limits (kinema.robot.description: MJCF has no attribute
  for them, the shipped G1 has them from Unitree's URDF). Without them the report says so and gives the
  fastest joint only.
- **Self-collision**: with the MJCF's collision geoms (those with ``contype``/``conaffinity``; where all are
  switched off, as in Menagerie's MJX variants, the geoms of group 3, Menagerie's collision group), the
  deepest penetration between bodies that are not parent and child and do not already touch at rest.

A motion is not feasible when a torque or speed exceeds its limit, when the base residual peaks above
``RESIDUAL_LIMIT`` of body weight, or when bodies pass more than ``COLLISION_LIMIT`` into each other;
``DynamicsReport.warning`` is then the one line that says so.
"""

from __future__ import annotations

import copy
from dataclasses import asdict, dataclass, field

import mujoco
import numpy as np
from scipy.optimize import nnls

from kinema.robot.description import Robot
from kinema.robot.motion import RobotMotion
from kinema.robot.targets import SIDES

CONTACT_HEIGHT = 0.015  # m: a sole point this close to the floor (or below it) is in contact
FRICTION = 0.7  # rubber sole on a floor
MOMENT_ARM = 0.1  # m: weighs residual moments against residual forces in the contact solve
#: share of body weight the base may need, averaged over WINDOW: captured human walks (Bandai Namco, 6 clips)
#: on the G1 need 18-28 % (docs/robots.md), so a reference needing more than a real walk does is flagged
RESIDUAL_LIMIT = 0.3
WINDOW = 0.25  # s: residual forces are averaged over this long, as a tracker smooths a one-frame jolt
COLLISION_LIMIT = 0.01  # m of penetration between two bodies
_GRAVITY = 9.81
_REGULARISE = 1e-3  # relative weight on contact forces, so that they spread over the contact points


@dataclass(frozen=True)
class Peak:
    """Where a measure peaks: its value, the frame and time, and what (a joint, a pair of bodies, a cause)."""

    value: float
    frame: int
    time: float
    what: str


@dataclass(frozen=True)
class DynamicsReport:
    """Inverse dynamics of a robot motion (see the module docstring); shares are fractions (1 = the limit)."""

    mass: float  # kg
    torque: Peak | None  # largest |torque| / limit over limited joints (None: the MJCF states no torque limit)
    joint_torque_share: dict[str, float]  # joint -> peak |torque| / limit
    residual_force: Peak  # largest residual force / body weight, ``what`` says why
    residual_force_mean: float  # mean over frames of residual force / body weight
    residual_force_window: Peak  # largest |residual force averaged over WINDOW| / body weight (the limit's measure)
    residual_moment_arm: Peak  # largest residual moment / body weight (m)
    speed: Peak | None  # largest |joint speed| / limit (None: the MJCF states no velocity limits)
    fastest_joint: Peak  # largest |joint speed| (rad/s)
    collision: Peak | None  # deepest self-penetration (m) (None: the MJCF has no collision geoms)
    contact_fraction: float  # share of frames with at least one sole point on the floor
    problems: list[str] = field(default_factory=list)

    @property
    def feasible(self) -> bool:
        return not self.problems

    def warning(self) -> str | None:
        """One line when the motion is not feasible, else None."""
        return None if self.feasible else "robot motion not feasible: " + "; ".join(self.problems)

    def summary(self) -> str:
        """The report in one line."""
        t, v = self.torque, self.speed
        torque = (f"peak torque {100 * t.value:.0f}% of limit ({t.what} at {t.time:.2f} s)"
                  if self.torque else "no torque limits in the MJCF")
        speed = (f"peak joint speed {100 * v.value:.0f}% of limit ({v.what} at {v.time:.2f} s)"
                 if self.speed else f"no velocity limits in the MJCF (fastest {self.fastest_joint.what} "
                                    f"{self.fastest_joint.value:.1f} rad/s)")
        collision = ("no collision geoms" if self.collision is None else
                     f"self-penetration {100 * self.collision.value:.1f} cm" +
                     (f" ({self.collision.what} at {self.collision.time:.2f} s)" if self.collision.value > 0 else ""))
        r = self.residual_force
        w = self.residual_force_window
        return (f"{torque}; base residual {100 * w.value:.0f}% of body weight over {WINDOW:g} s at {w.time:.2f} s "
                f"({w.what}; one frame: {100 * r.value:.0f}% at {r.time:.2f} s, "
                f"mean {100 * self.residual_force_mean:.0f}%), "
                f"moment arm {100 * self.residual_moment_arm.value:.1f} cm; "
                f"{speed}; {collision}")

    def as_dict(self) -> dict:
        """Plain JSON-ready values."""
        out = asdict(self)
        out["feasible"] = self.feasible
        return out


def finite_differences(model: mujoco.MjModel, Q: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """(qvel (T, nv), qacc (T, nv)) of poses Q (T, nq): central differences; the ends copy their neighbours."""
    T, nv = len(Q), model.nv
    step = np.zeros((max(T - 1, 0), nv))
    for t in range(T - 1):
        mujoco.mj_differentiatePos(model, step[t], 1.0 / fps, Q[t], Q[t + 1])
    qvel, qacc = np.zeros((T, nv)), np.zeros((T, nv))
    if T >= 2:
        qvel[1:-1] = (step[1:] + step[:-1]) / 2
        qvel[0], qvel[-1] = step[0], step[-1]
    if T >= 3:
        qacc[1:-1] = (step[1:] - step[:-1]) * fps
        qacc[0], qacc[-1] = qacc[1], qacc[-2]
    return qvel, qacc


def torque_limits(model: mujoco.MjModel, robot: Robot) -> np.ndarray:
    """(J,) each hinge's torque limit (N m; inf where the MJCF states none), see the module docstring."""
    limits = np.full(robot.num_joints, np.inf)
    joints = {int(j): i for i, j in enumerate(range(1, model.njnt))}
    for a in range(model.nu):
        on_joint = int(model.actuator_trntype[a]) == int(mujoco.mjtTrn.mjTRN_JOINT)
        if not on_joint or int(model.actuator_trnid[a, 0]) not in joints:
            continue
        i, gear = joints[int(model.actuator_trnid[a, 0])], abs(float(model.actuator_gear[a, 0]))
        if model.actuator_forcelimited[a]:
            limits[i] = gear * np.abs(model.actuator_forcerange[a]).max()
        elif (model.actuator_ctrllimited[a] and int(model.actuator_gaintype[a]) == int(mujoco.mjtGain.mjGAIN_FIXED)
              and int(model.actuator_biastype[a]) == int(mujoco.mjtBias.mjBIAS_NONE)):
            limits[i] = gear * abs(float(model.actuator_gainprm[a, 0])) * np.abs(model.actuator_ctrlrange[a]).max()
    for i, j in enumerate(range(1, model.njnt)):
        if model.jnt_actfrclimited[j]:
            limits[i] = np.abs(model.jnt_actfrcrange[j]).max()
    return limits


def collision_geoms(model: mujoco.MjModel) -> np.ndarray:
    """Ids of the geoms that stand for the robot's volume (see the module docstring)."""
    colliding = np.flatnonzero((model.geom_contype != 0) | (model.geom_conaffinity != 0))
    if len(colliding):
        return colliding
    return np.flatnonzero(model.geom_group == 3)


class _Collisions:
    """Self-penetration of a robot's collision geoms, pairs that touch at rest left out."""

    def __init__(self, robot: Robot):
        m = copy.deepcopy(robot.model)
        geoms = collision_geoms(m)
        m.geom_contype[:], m.geom_conaffinity[:] = 0, 0
        m.geom_contype[geoms], m.geom_conaffinity[geoms] = 1, 1
        bodies = np.unique(m.geom_bodyid[geoms])  # the broadphase filters bodies by their geoms' types, too
        m.body_contype[:], m.body_conaffinity[:] = 0, 0
        m.body_contype[bodies], m.body_conaffinity[bodies] = 1, 1
        m.geom_margin[:] = 0.0
        self.model, self.data, self.any = m, mujoco.MjData(m), len(geoms) > 0
        self.resting = {pair for pair, _ in self._contacts(m.qpos0)}

    def _contacts(self, q: np.ndarray) -> list[tuple[tuple[int, int], float]]:
        self.data.qpos[:] = q
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_collision(self.model, self.data)
        out = []
        for c in self.data.contact[: self.data.ncon]:
            a, b = int(self.model.geom_bodyid[c.geom1]), int(self.model.geom_bodyid[c.geom2])
            out.append(((min(a, b), max(a, b)), -float(c.dist)))
        return out

    def deepest(self, q: np.ndarray) -> tuple[float, tuple[int, int] | None]:
        worst, pair = 0.0, None
        for bodies, depth in self._contacts(q):
            if bodies not in self.resting and depth > worst:
                worst, pair = depth, bodies
        return worst, pair


def _pyramid() -> np.ndarray:
    """(3, 4) edges of the linearised friction cone of a point on a floor with normal +Z."""
    edges = [(FRICTION, 0.0), (-FRICTION, 0.0), (0.0, FRICTION), (0.0, -FRICTION)]
    return np.array([[fx, fy, 1.0] for fx, fy in edges]).T


class _ContactSolve:
    """Per-frame contact forces that best supply the floating base's wrench (see the module docstring)."""

    def __init__(self, robot: Robot):
        self.robot, self.model = robot, robot.model
        self.jac = np.zeros((3, robot.model.nv))
        self.edges = _pyramid()

    def points(self, data: mujoco.MjData) -> list[tuple[int, np.ndarray]]:
        """(foot body, world point) of every sole point in contact on this frame."""
        out = []
        for s in SIDES:
            body = self.robot.soles[s].body
            out += [(body, p) for p in self.robot.sole_points(data, s) if p[2] <= CONTACT_HEIGHT]
        return out

    def solve(self, data: mujoco.MjData, qfrc: np.ndarray, weight: float):
        """(contact generalised force (nv,), residual base force (3,) world, residual base moment (3,),
        contact points) for the generalised force ``qfrc`` (nv,) the motion needs on this frame."""
        contacts = self.points(data)
        if not contacts:
            return np.zeros_like(qfrc), qfrc[0:3].copy(), qfrc[3:6].copy(), contacts
        jacobians = []
        for body, p in contacts:
            mujoco.mj_jac(self.model, data, self.jac, None, p, body)
            jacobians.append(self.jac.copy())
        J = np.concatenate(jacobians)  # (3K, nv)
        E = np.kron(np.eye(len(contacts)), self.edges)  # (3K, 4K): edge weights -> point forces
        G = J.T @ E  # (nv, 4K) generalised force per unit edge weight
        scale = np.concatenate([np.full(3, 1.0 / weight), np.full(3, 1.0 / (weight * MOMENT_ARM))])
        A = np.concatenate([scale[:, None] * G[0:6], np.eye(G.shape[1]) * (_REGULARISE / weight)])
        b = np.concatenate([scale * qfrc[0:6], np.zeros(G.shape[1])])
        beta, _ = nnls(A, b, maxiter=50 * A.shape[1])
        supplied = G @ beta
        return supplied, qfrc[0:3] - supplied[0:3], qfrc[3:6] - supplied[3:6], contacts


def _cause(force: np.ndarray, moment: np.ndarray, weight: float, contacts: list) -> str:
    """Why the base needs a residual on a frame: the largest part of it, in words."""
    if not contacts:
        return "no sole on the floor"
    if np.linalg.norm(force) < 1e-3 * weight and np.linalg.norm(moment) < 1e-3 * weight * MOMENT_ARM:
        return "the soles supply it"
    parts = {
        "the floor would have to pull (the body falls faster than gravity)": max(-force[2], 0.0),
        "more force up than the soles give": max(force[2], 0.0),
        "more sideways force than friction allows": float(np.linalg.norm(force[:2])),
        "a tipping moment (centre of pressure outside the soles)": float(np.linalg.norm(moment)) / MOMENT_ARM,
    }
    return max(parts, key=parts.get)


def dynamics_report(motion: RobotMotion, robot: Robot) -> DynamicsReport:
    """Inverse dynamics of ``motion`` on ``robot`` with the contacts it implies (see the module docstring)."""
    motion.check_joints(robot.joint_names, robot.name)
    m = copy.deepcopy(robot.model)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONSTRAINT)
    data, T, fps = mujoco.MjData(m), motion.num_frames, motion.fps
    Q = np.array([robot.qpos(motion.root_position[t], motion.root_quaternion[t], motion.joint_angles[t])
                  for t in range(T)])
    qvel, qacc = finite_differences(m, Q, fps)
    mass = float(m.body_subtreemass[1])
    weight = mass * float(np.linalg.norm(m.opt.gravity)) if np.linalg.norm(m.opt.gravity) > 0 else mass * _GRAVITY
    solver, collisions = _ContactSolve(robot), _Collisions(robot)
    torque = np.zeros((T, robot.num_joints))
    residual, arm, causes, in_contact = np.zeros((T, 3)), np.zeros(T), [], np.zeros(T, dtype=bool)
    depth, pairs = np.zeros(T), []
    for t in range(T):
        data.qpos[:], data.qvel[:], data.qacc[:] = Q[t], qvel[t], qacc[t]
        mujoco.mj_inverse(m, data)
        qfrc = data.qfrc_inverse.copy()
        supplied, force, moment, contacts = solver.solve(data, qfrc, weight)
        torque[t] = (qfrc - supplied)[robot.dof_adr]
        residual[t], arm[t] = force / weight, np.linalg.norm(moment) / weight
        causes.append(_cause(force, moment, weight, contacts))
        in_contact[t] = bool(contacts)
        if collisions.any:
            depth[t], pair = collisions.deepest(Q[t])
            pairs.append(pair)
    return _report(motion, robot, m, mass, torque, residual, arm, causes, in_contact,
                   depth if collisions.any else None, pairs, qvel)


def _peak(values: np.ndarray, fps: float, what) -> Peak:
    """The largest of (T,) or (T, J) values, with its frame, time and ``what(frame, column)``."""
    flat = np.nan_to_num(np.atleast_2d(values.T).T, nan=-np.inf)
    t, j = np.unravel_index(int(np.argmax(flat)), flat.shape)
    return Peak(float(flat[t, j]), int(t), float(t / fps), what(int(t), int(j)))


def _windowed(values: np.ndarray, frames: int) -> np.ndarray:
    """(T, D) centred moving averages over ``frames`` frames (fewer at the ends)."""
    cum = np.concatenate([np.zeros((1, values.shape[1])), np.cumsum(values, axis=0)])
    T, half = len(values), frames // 2
    lo, hi = np.clip(np.arange(T) - half, 0, T), np.clip(np.arange(T) - half + frames, 0, T)
    return (cum[hi] - cum[lo]) / (hi - lo)[:, None]


def _worst_frame(share: np.ndarray, t: int, fps: float) -> int:
    """The frame of the largest residual within the window centred on frame ``t``."""
    frames = max(1, round(WINDOW * fps))
    lo = max(0, t - frames // 2)
    return lo + int(np.argmax(share[lo : lo + frames]))


def _report(motion, robot, model, mass, torque, residual, arm, causes, in_contact, depth, pairs, qvel):
    fps, names = motion.fps, robot.joint_names
    force_share = np.linalg.norm(residual, axis=1)
    window = np.linalg.norm(_windowed(residual, max(1, round(WINDOW * fps))), axis=1)
    limits = torque_limits(model, robot)
    limited = np.isfinite(limits)
    share = np.abs(torque) / np.where(limited, limits, 1.0)
    which = np.flatnonzero(limited)
    torque_peak = _peak(share[:, limited], fps, lambda t, j: names[which[j]]) if limited.any() else None
    speeds = np.abs(qvel[:, robot.dof_adr])
    vlimits = robot.velocity_limits
    speed_peak = None
    if vlimits is not None:
        speed_peak = _peak(speeds / vlimits, fps, lambda t, j: names[j])
    collision = None
    if depth is not None:
        def body_pair(t, _):
            pair = pairs[t]
            return "" if pair is None else f"{model.body(pair[0]).name} / {model.body(pair[1]).name}"
        collision = _peak(depth, fps, body_pair)
    rep = DynamicsReport(
        mass=mass,
        torque=torque_peak,
        joint_torque_share={n: float(share[:, i].max()) for i, n in enumerate(names) if limited[i]},
        residual_force=_peak(force_share, fps, lambda t, _: causes[t]),
        residual_force_mean=float(force_share.mean()),
        residual_force_window=_peak(window, fps, lambda t, _: causes[_worst_frame(force_share, t, fps)]),
        residual_moment_arm=_peak(arm, fps, lambda t, _: causes[t]),
        speed=speed_peak,
        fastest_joint=_peak(speeds, fps, lambda t, j: names[j]),
        collision=collision,
        contact_fraction=float(in_contact.mean()),
    )
    rep.problems.extend(_problems(rep))
    return rep


def _problems(rep: DynamicsReport) -> list[str]:
    out = []
    if rep.torque is not None and rep.torque.value > 1.0:
        t = rep.torque
        out.append(f"{t.what} needs {100 * t.value:.0f}% of its torque limit at {t.time:.2f} s")
    if rep.residual_force_window.value > RESIDUAL_LIMIT:
        r = rep.residual_force_window
        out.append(f"the floating base needs {100 * r.value:.0f}% of body weight over {WINDOW:g} s at {r.time:.2f} s "
                   f"({r.what}; limit {100 * RESIDUAL_LIMIT:.0f}%)")
    if rep.speed is not None and rep.speed.value > 1.0:
        v = rep.speed
        out.append(f"{v.what} turns at {100 * v.value:.0f}% of its speed limit at {v.time:.2f} s")
    if rep.collision is not None and rep.collision.value > COLLISION_LIMIT:
        c = rep.collision
        out.append(f"{c.what} pass {100 * c.value:.1f} cm into each other at {c.time:.2f} s")
    return out
