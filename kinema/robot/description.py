"""A robot read from MJCF with the `mujoco` package: its floating base, its hinge joints and their ranges,
the bodies that stand for human joints (kinema.robot.mapping), its soles, and its rest-pose measurements.

Conventions are MuJoCo's: metres, radians, world Z up; the robot is expected to face +X with its left
side towards +Y in its rest pose (``qpos0``), as Menagerie's humanoids do; this is checked.
``load_robot("g1")`` reads the Unitree G1 shipped in kinema/assets/robots/g1, ``load_robot("h1")`` the Unitree
H1 in kinema/assets/robots/h1 (see their READMEs and LICENSEs).

Joint velocity limits: MJCF has no attribute for them, so kinema reads
``<custom><numeric name="velocity_limit/JOINT" data="RAD_PER_S"/></custom>`` (the shipped G1 has them,
from Unitree's URDF); a robot without any has ``velocity_limits`` None.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from kinema.errors import KinemaError
from kinema.input_files import check_input_file
from kinema.limits import MAX_JSON_BYTES
from kinema.robot.mapping import BodyPoint, read_mapping, resolve_mapping

ROBOTS_DIR = Path(__file__).resolve().parent.parent / "assets" / "robots"
#: Robots shipped with kinema, by name.
BUILTIN_ROBOTS = {"g1": ROBOTS_DIR / "g1" / "g1.xml", "h1": ROBOTS_DIR / "h1" / "h1.xml"}
#: how far (degrees) a robot's rest pose may lean from Z up with its left towards +Y
MAX_REST_TILT_DEG = 30.0
_SOLE_BAND = 0.005  # geom bottoms within 5 mm of the lowest belong to the sole
VELOCITY_PREFIX = "velocity_limit/"


@dataclass(frozen=True)
class Sole:
    """The bottom of one foot: ``points`` (K, 3) and its ``centre`` (3,) in the foot body's frame."""

    body: int
    points: np.ndarray
    centre: np.ndarray


@dataclass(eq=False)
class Robot:
    """A robot description ready for retargeting (see the module docstring)."""

    name: str  # "g1", "h1" or the MJCF path it was read from
    model: mujoco.MjModel
    points: dict[str, BodyPoint]  # landmark -> body and point in it
    body_ids: dict[str, int]  # landmark -> body id
    joint_names: tuple[str, ...]  # hinge joints in MJCF order
    qpos_adr: np.ndarray  # (J,) int: each hinge's address in qpos
    dof_adr: np.ndarray  # (J,) int: each hinge's address in qvel
    ranges: np.ndarray  # (J, 2) radians; unlimited joints are (-inf, inf)
    soles: dict[str, Sole]  # "left" / "right"
    velocity_limits: np.ndarray | None = None  # (J,) rad/s, inf where not given; None: the MJCF gives none

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    def qpos(self, root_position, root_quaternion, joint_angles) -> np.ndarray:
        """The MuJoCo qpos vector (nq,) of a pose; other joints stay at qpos0."""
        q = self.model.qpos0.copy()
        q[0:3], q[3:7] = root_position, root_quaternion
        q[self.qpos_adr] = joint_angles
        return q

    def point(self, data: mujoco.MjData, key: str) -> np.ndarray:
        """World position (3,) of a landmark in ``data`` after forward kinematics."""
        b = self.body_ids[key]
        return data.xpos[b] + data.xmat[b].reshape(3, 3) @ np.asarray(self.points[key].offset)

    def sole_points(self, data: mujoco.MjData, side: str) -> np.ndarray:
        """World positions (K, 3) of one sole's points in ``data`` after forward kinematics."""
        sole = self.soles[side]
        return data.xpos[sole.body] + sole.points @ data.xmat[sole.body].reshape(3, 3).T

    def sole_centre(self, data: mujoco.MjData, side: str) -> np.ndarray:
        sole = self.soles[side]
        return data.xpos[sole.body] + data.xmat[sole.body].reshape(3, 3) @ sole.centre


def _read_model(path: Path) -> mujoco.MjModel:
    check_input_file(path, "robot file (use 'g1', 'h1' or a MuJoCo MJCF .xml)")
    if path.stat().st_size > MAX_JSON_BYTES:
        raise KinemaError(f"{path}: larger than {MAX_JSON_BYTES} bytes, too large for an MJCF robot file")
    if path.suffix.lower() != ".xml":
        raise KinemaError(f"{path}: a robot must be a MuJoCo MJCF .xml file")
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except ValueError as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else "unreadable"
        raise KinemaError(f"{path}: not a valid MJCF robot ({first})") from None


def _hinges(model: mujoco.MjModel, where: str) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, np.ndarray]:
    """Names, qpos and qvel addresses and ranges of the hinge joints; the first joint must be a freejoint."""
    types = [int(model.jnt_type[j]) for j in range(model.njnt)]
    if not types or types[0] != mujoco.mjtJoint.mjJNT_FREE or model.jnt_bodyid[0] != 1:
        raise KinemaError(f"{where}: the robot's first body needs a <freejoint/> (a floating base)")
    others = [j for j in range(1, model.njnt) if types[j] != mujoco.mjtJoint.mjJNT_HINGE]
    if others:
        raise KinemaError(
            f"{where}: only hinge joints are supported below the base; not {model.joint(others[0]).name!r}"
        )
    if model.njnt == 1:
        raise KinemaError(f"{where}: the robot has no hinge joints below its base (nothing to drive)")
    hinge = list(range(1, model.njnt))
    names = tuple(model.joint(j).name or f"joint{j}" for j in hinge)
    ranges = np.array([model.jnt_range[j] if model.jnt_limited[j] else (-np.inf, np.inf) for j in hinge]).reshape(-1, 2)
    return names, model.jnt_qposadr[hinge].copy(), model.jnt_dofadr[hinge].copy(), ranges


def subtree(model: mujoco.MjModel, root: int) -> list[int]:
    """Body ids of ``root`` and every body below it."""
    return [b for b in range(model.nbody) if b == root or _is_below(model, b, root)]


def _is_below(model: mujoco.MjModel, body: int, root: int) -> bool:
    while body > 0:
        body = int(model.body_parentid[body])
        if body == root:
            return True
    return False


def _sole(model: mujoco.MjModel, data: mujoco.MjData, foot: int, where: str) -> Sole:
    """The lowest geom-box corners (world z at rest) of a foot body and the bodies below it."""
    corners = []
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=float)
    bodies = subtree(model, foot)
    for g in range(model.ngeom):
        if int(model.geom_bodyid[g]) not in bodies:
            continue
        centre, half = model.geom_aabb[g][:3], model.geom_aabb[g][3:]
        local = centre + signs * half  # box corners in the geom frame
        corners.append(data.geom_xpos[g] + local @ data.geom_xmat[g].reshape(3, 3).T)
    if not corners:
        raise KinemaError(f"{where}: foot body {model.body(foot).name!r} has no geoms to find its sole from")
    world = np.concatenate(corners)
    bottom = world[world[:, 2] <= world[:, 2].min() + _SOLE_BAND]
    R, p = data.xmat[foot].reshape(3, 3), data.xpos[foot]
    points = (bottom - p) @ R  # into the foot frame
    lo, hi = points.min(0), points.max(0)
    centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    return Sole(foot, points, centre)


def read_velocity_limits(model: mujoco.MjModel, joint_names: tuple[str, ...]) -> np.ndarray | None:
    """(J,) each hinge's speed limit (rad/s; inf where none is given), or None when the MJCF gives none."""
    given = {}
    for n in range(model.nnumeric):
        name = model.numeric(n).name
        if name.startswith(VELOCITY_PREFIX) and model.numeric_size[n] >= 1:
            given[name[len(VELOCITY_PREFIX):]] = float(model.numeric_data[model.numeric_adr[n]])
    if not given:
        return None
    return np.array([given.get(name, np.inf) for name in joint_names])


def _check_facing(robot: Robot, data: mujoco.MjData, where: str) -> None:
    """At rest the pelvis-to-head line is within `MAX_REST_TILT_DEG` of +Z and the right-to-left hip line
    within it of +Y (a robot lying down has its head above its pelvis too)."""
    left, right = robot.point(data, "left_hip"), robot.point(data, "right_hip")
    head, pelvis = robot.point(data, "head"), robot.point(data, "pelvis")
    tilt = _degrees_from(head - pelvis, (0.0, 0.0, 1.0))
    across = _degrees_from(left - right, (0.0, 1.0, 0.0))
    if tilt > MAX_REST_TILT_DEG or across > MAX_REST_TILT_DEG:
        raise KinemaError(f"{where}: at rest the robot must stand Z up, face +X, with its left side towards +Y "
                          f"(pelvis to head is {tilt:.0f} deg from +Z, right to left hip {across:.0f} deg from +Y; "
                          f"at most {MAX_REST_TILT_DEG:g})")


def _degrees_from(v: np.ndarray, axis: tuple[float, float, float]) -> float:
    """The angle between ``v`` and a unit ``axis`` (180 for a zero ``v``)."""
    norm = float(np.linalg.norm(v))
    return 180.0 if norm < 1e-9 else float(np.degrees(np.arccos(np.clip(np.dot(v, axis) / norm, -1.0, 1.0))))


def load_robot(name_or_path: str | Path, mapping: str | Path | dict | None = None) -> Robot:
    """A robot by built-in name (``"g1"``) or MJCF path; ``mapping`` is a JSON file path or an inline
    dict (kinema.robot.mapping.read_mapping) for robots whose body names are not recognised."""
    key = str(name_or_path)
    path = BUILTIN_ROBOTS.get(key.lower(), Path(key))
    model = _read_model(Path(path))
    where = key if key.lower() in BUILTIN_ROBOTS else str(path)
    names, qadr, dadr, ranges = _hinges(model, where)
    given = None if mapping is None else read_mapping(mapping)
    bodies = [model.body(b).name for b in range(1, model.nbody)]
    points = resolve_mapping(bodies, given, key.lower() if key.lower() in BUILTIN_ROBOTS else None, where)
    body_ids = {k: model.body(p.body).id for k, p in points.items()}
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    soles = {side: _sole(model, data, body_ids[f"{side}_foot"], where) for side in ("left", "right")}
    robot = Robot(
        key.lower() if key.lower() in BUILTIN_ROBOTS else str(path),
        model,
        points,
        body_ids,
        names,
        qadr,
        dadr,
        ranges,
        soles,
        read_velocity_limits(model, names),
    )
    _check_facing(robot, data, where)
    return robot
