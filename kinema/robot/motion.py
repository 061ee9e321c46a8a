"""`RobotMotion`: a robot's motion as MuJoCo poses: root position and quaternion in MuJoCo's world (Z up)
and one angle per hinge joint (radians, MJCF order), at ``fps`` frames per second.

``save(path)`` writes ``.csv`` or ``.npz`` by suffix (kinema.robot.files); ``load_robot_motion`` reads
either back. ``sole_planted`` (T, 2) says on which frames the left and right soles were planted in the
source motion (None when unknown, e.g. read from CSV).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kinema.errors import KinemaError
from kinema.robot.files import read_csv, read_npz, write_csv, write_npz

WRITERS = {".csv": write_csv, ".npz": write_npz}


@dataclass(eq=False)
class RobotMotion:
    """A motion of a robot (see the module docstring)."""

    robot: str  # the robot's name ("g1") or its MJCF path
    fps: float
    joint_names: tuple[str, ...]
    root_position: np.ndarray  # (T, 3) metres
    root_quaternion: np.ndarray  # (T, 4) w, x, y, z
    joint_angles: np.ndarray  # (T, J) radians
    sole_planted: np.ndarray | None = None  # (T, 2) bool, left and right

    def __post_init__(self) -> None:
        self.joint_names = tuple(self.joint_names)
        T = len(self.root_position)
        shapes = {"root_position": (T, 3), "root_quaternion": (T, 4), "joint_angles": (T, len(self.joint_names))}
        for name, shape in shapes.items():
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.shape != shape or not np.isfinite(value).all():
                raise KinemaError(f"robot motion {name} must be finite {shape}, got {value.shape}")
            setattr(self, name, value)
        if T == 0 or not (self.fps > 0 and np.isfinite(self.fps)):
            raise KinemaError(f"a robot motion needs frames and a positive fps (got {T} frames, fps {self.fps})")

    @property
    def num_frames(self) -> int:
        return len(self.root_position)

    @property
    def time(self) -> np.ndarray:
        return np.arange(self.num_frames) / self.fps

    def check_joints(self, joint_names: tuple[str, ...], robot: str) -> None:
        """A one-line KinemaError unless this motion's joints are ``joint_names`` (a robot's hinges), in order."""
        if self.joint_names != tuple(joint_names):
            wrong = next((a for a, b in zip(self.joint_names, joint_names, strict=False) if a != b), None)
            raise KinemaError(
                f"the motion's {len(self.joint_names)} joints do not match robot {robot}'s "
                f"{len(joint_names)} hinge joints" + (f" (first difference: {wrong!r})" if wrong else "")
            )

    def arrays(self) -> dict:
        """The arrays the files hold (kinema.robot.files)."""
        return {
            "time": self.time,
            "root_position": self.root_position,
            "root_quaternion": self.root_quaternion,
            "joint_angles": self.joint_angles,
            "joint_names": np.array(self.joint_names),
            "fps": np.float64(self.fps),
            "robot": np.array(self.robot),
            "sole_planted": self.sole_planted,
        }

    def save(self, path: str | Path) -> Path:
        """Write ``.csv`` (MuJoCo qpos table) or ``.npz`` by the suffix of ``path``."""
        path = Path(path)
        writer = WRITERS.get(path.suffix.lower())
        if writer is None:
            raise KinemaError(f"{path}: a robot motion is written as .csv or .npz")
        return writer(path, self.arrays())


def load_robot_motion(path: str | Path, robot: str | None = None) -> RobotMotion:
    """Read a robot motion written by `RobotMotion.save`; ``robot`` names the robot for a CSV."""
    path = Path(path)
    if not path.is_file():
        raise KinemaError(f"{path}: no such file")
    suffix = path.suffix.lower()
    if suffix not in WRITERS:
        raise KinemaError(f"{path}: a robot motion is a .csv or .npz file")
    data = read_csv(path) if suffix == ".csv" else read_npz(path)
    planted = data.get("sole_planted")
    return RobotMotion(
        robot if robot is not None else (data["robot"] or "g1"),
        data["fps"],
        tuple(data["joint_names"]),
        data["root_position"],
        data["root_quaternion"],
        data["joint_angles"],
        None if planted is None else np.asarray(planted, dtype=bool),
    )
