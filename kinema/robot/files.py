"""Robot motion files: a CSV of MuJoCo poses (one row a frame) and an npz with the same arrays.

CSV header: ``time, root_x, root_y, root_z, root_qw, root_qx, root_qy, root_qz`` then one column per hinge
joint named as in the MJCF; seconds, metres, radians, MuJoCo world (Z up), root quaternion (w, x, y, z).
The npz holds ``time``, ``root_position`` (T, 3), ``root_quaternion`` (T, 4), ``joint_angles`` (T, J),
``joint_names`` (J,), ``fps``, ``robot`` (the robot's name or MJCF path) and, when known,
``sole_planted`` (T, 2) for the left and right soles. Both are written atomically.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from kinema.atomic_files import atomic_write_bytes
from kinema.errors import KinemaError
from kinema.input_files import read_text_bounded
from kinema.limits import MAX_ASSET_BYTES

ROOT_COLUMNS = ("time", "root_x", "root_y", "root_z", "root_qw", "root_qx", "root_qy", "root_qz")
NPZ_KEYS = ("time", "root_position", "root_quaternion", "joint_angles", "joint_names", "fps", "robot")


def write_csv(path: Path, arrays: dict) -> Path:
    T = len(arrays["time"])
    table = np.concatenate(
        [arrays["time"][:, None], arrays["root_position"], arrays["root_quaternion"], arrays["joint_angles"]], axis=1
    ).reshape(T, -1)
    text = io.StringIO()
    text.write(",".join(ROOT_COLUMNS + tuple(arrays["joint_names"])) + "\n")
    np.savetxt(text, table, delimiter=",", fmt="%.9g")
    atomic_write_bytes(path, text.getvalue().encode())
    return path


def write_npz(path: Path, arrays: dict) -> Path:
    buf = io.BytesIO()
    np.savez_compressed(buf, **{k: np.asarray(v) for k, v in arrays.items() if v is not None})
    atomic_write_bytes(path, buf.getvalue())
    return path


def read_csv(path: Path) -> dict:
    lines = read_text_bounded(path, "robot motion CSV", MAX_ASSET_BYTES).splitlines()
    header = [h.strip() for h in lines[0].split(",")] if lines else []
    if tuple(header[: len(ROOT_COLUMNS)]) != ROOT_COLUMNS:
        raise KinemaError(f"{path}: header must start with {','.join(ROOT_COLUMNS)}")
    try:
        table = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
    except ValueError as err:
        raise KinemaError(f"{path}: rows must be numbers ({err})") from None
    if table.shape[0] == 0 or table.shape[1] != len(header):
        raise KinemaError(f"{path}: expected rows of {len(header)} numbers, got shape {table.shape}")
    time = table[:, 0]
    span = float(time[-1] - time[0]) if len(time) > 1 else 0.0
    if len(time) > 1 and not (span > 0 and (np.diff(time) > 0).all()):
        raise KinemaError(f"{path}: the time column must increase")
    fps = (len(time) - 1) / span if len(time) > 1 else 30.0
    return {
        "time": time,
        "root_position": table[:, 1:4],
        "root_quaternion": table[:, 4:8],
        "joint_angles": table[:, 8:],
        "joint_names": header[8:],
        "fps": fps,
        "robot": None,
    }


def read_npz(path: Path) -> dict:
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError) as err:
        raise KinemaError(f"{path}: not a robot motion npz ({err})") from None
    missing = [k for k in NPZ_KEYS if k not in data]
    if missing:
        raise KinemaError(f"{path}: not a robot motion npz (missing {missing})")
    data["fps"] = float(data["fps"])
    data["robot"] = str(data["robot"])
    data["joint_names"] = [str(n) for n in data["joint_names"]]
    return data


def is_robot_npz(path: Path) -> bool:
    """Whether an .npz file is a robot motion (it has ``joint_angles``), not a kinema skeleton motion."""
    try:
        with np.load(path, allow_pickle=False) as z:
            return "joint_angles" in z.files
    except (OSError, ValueError):
        return False
