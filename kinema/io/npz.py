"""The kinema ``.npz`` motion format (contract documented in docs/formats.md).

Keys: ``joint_names`` (J,) str, ``parents`` (J,) int, ``fps`` float, ``positions`` (T, J, 3) global
joint positions in metres Y-up, ``local_quats`` (T, J, 4) wxyz, ``root_translation`` (T, 3) metres,
``offsets`` (J, 3) metres; optional ``foot_contacts`` (T, 4) [L heel, L toe, R heel, R toe].
Arrays only, loaded with ``allow_pickle=False``.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import torch

from kinema.errors import KinemaError
from kinema.io.atomic import atomic_write_bytes

REQUIRED_KEYS = ("joint_names", "parents", "fps", "local_quats", "root_translation", "offsets")


def save_npz(motion, path: str | Path) -> Path:
    """Write a Motion as ``.npz`` atomically (compressed)."""
    if not motion.is_finite():
        raise KinemaError(f"{path}: motion contains NaN or inf values; nothing written")
    skel = motion.skeleton
    arrays = {
        "joint_names": np.array(skel.names, dtype=str),
        "parents": np.array(skel.parents, dtype=np.int64),
        "fps": np.array(motion.fps, dtype=np.float64),
        "positions": motion.positions.detach().cpu().numpy().astype(np.float32),
        "local_quats": motion.local_rotations.detach().cpu().numpy().astype(np.float32),
        "root_translation": motion.root_translation.detach().cpu().numpy().astype(np.float32),
        "offsets": skel.offsets.numpy().astype(np.float64),
    }
    if motion.foot_contacts is not None:
        arrays["foot_contacts"] = motion.foot_contacts.detach().cpu().numpy().astype(np.float32)
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)


def load_npz(path: str | Path):
    """Read a kinema ``.npz`` motion; missing keys or bad shapes raise KinemaError naming the key."""
    from kinema.motion.core import Motion
    from kinema.skeleton import Skeleton

    path = Path(path)
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise KinemaError(f"{path}: not a readable .npz file ({err})") from None
    with data:
        missing = [k for k in REQUIRED_KEYS if k not in data.files]
        if missing:
            raise KinemaError(f"{path}: missing keys {missing} (see docs/formats.md)")
        names = [str(n) for n in data["joint_names"]]
        skel = Skeleton(names, data["parents"].tolist(), data["offsets"])
        contacts = torch.from_numpy(data["foot_contacts"]) if "foot_contacts" in data.files else None
        return Motion(
            skel,
            float(data["fps"]),
            torch.from_numpy(data["root_translation"].astype(np.float32)),
            torch.from_numpy(data["local_quats"].astype(np.float32)),
            contacts,
        )
