"""The kinema ``.npz`` motion format (contract documented in docs/formats.md).

Keys: ``joint_names`` (J,) str, ``parents`` (J,) int, ``fps`` float, ``positions`` (T, J, 3) global
joint positions in metres Y-up, ``local_quats`` (T, J, 4) wxyz, ``root_translation`` (T, 3) metres,
``offsets`` (J, 3) metres; optional ``foot_contacts`` (T, C), one column per contact joint of the rig
(human: [L heel, L toe, R heel, R toe]),
``local_translations`` (T, J, 3) metres (animated bone translations, see kinema.motion.core), and
``rest_rotations`` (J, 4) wxyz (the skeleton's rest/bind rotations: the default model's standing rest
pose, a GLB/FBX character's bind pose; retargeting measures every bone's turn from it).
Arrays only, loaded with ``allow_pickle=False``.
"""

from __future__ import annotations

import io
import math
from pathlib import Path

import numpy as np
import torch

from kinema.atomic_files import atomic_write_bytes
from kinema.errors import KinemaError
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

REQUIRED_KEYS = ("joint_names", "parents", "fps", "local_quats", "root_translation", "offsets")
#: shortest ``local_quats`` entry accepted as a rotation (it is normalised on reading)
MIN_QUAT_NORM = 1e-6


def _float32(t: torch.Tensor) -> np.ndarray:
    with np.errstate(over="ignore"):  # overflow becomes inf, reported by save_npz
        return t.detach().cpu().numpy().astype(np.float32)


def save_npz(motion: Motion, path: str | Path) -> Path:
    """Write a Motion as ``.npz`` atomically (compressed)."""
    if not motion.is_finite():
        raise KinemaError(f"{path}: motion contains NaN or inf values; nothing written")
    skel = motion.skeleton
    arrays = {
        "joint_names": np.array(skel.names, dtype=str),
        "parents": np.array(skel.parents, dtype=np.int64),
        "fps": np.array(motion.fps, dtype=np.float64),
        "positions": _float32(motion.positions),
        "local_quats": _float32(motion.local_rotations),
        "root_translation": _float32(motion.root_translation),
        "offsets": skel.offsets.numpy().astype(np.float64),
    }
    if motion.foot_contacts is not None:
        arrays["foot_contacts"] = motion.foot_contacts.detach().cpu().numpy().astype(np.float32)
    if motion.local_translations is not None:
        arrays["local_translations"] = _float32(motion.local_translations)
    if skel.rest_rotations is not None:
        arrays["rest_rotations"] = skel.rest_rotations.numpy().astype(np.float64)
    for key, arr in arrays.items():
        if arr.dtype.kind == "f" and not np.isfinite(arr).all():
            raise KinemaError(f"{path}: '{key}' does not fit the npz format's float32 (values too large); "
                              "nothing written")
    buf = io.BytesIO()
    np.savez_compressed(buf, **arrays)
    atomic_write_bytes(Path(path), buf.getvalue())
    return Path(path)


def _arrays(path: Path, data) -> dict[str, np.ndarray]:
    """Every array of an opened npz; an object (pickled) array is a one-line error naming its key."""
    out = {}
    for key in data.files:
        try:
            out[key] = data[key]
        except ValueError:
            raise KinemaError(f"{path}: '{key}' is an object array (pickled Python objects); kinema motions hold "
                              "plain number and string arrays only (see docs/formats.md)") from None
    return out


def _check_finite(path: Path, data: dict[str, np.ndarray]) -> None:
    """Numeric arrays must be finite and fps positive: a one-line error naming the key and where."""
    for key in ("fps", "offsets", "root_translation", "local_quats", "positions", "foot_contacts",
                "local_translations", "rest_rotations"):
        if key not in data:
            continue
        arr = data[key]
        if arr.dtype.kind not in "biuf":
            raise KinemaError(f"{path}: '{key}' must hold numbers, found dtype {arr.dtype}")
        bad = ~np.isfinite(arr)
        if bad.any():
            at = f" (first at index {np.argwhere(bad)[0].tolist()})" if bad.ndim else ""
            raise KinemaError(f"{path}: '{key}' holds NaN or infinite values{at}; not a valid kinema motion")
    fps = data["fps"]
    if fps.size != 1 or not float(fps.reshape(-1)[0]) > 0:
        raise KinemaError(f"{path}: 'fps' must be one positive number, got {fps.tolist()}")


def _check_quats(path: Path, quats: np.ndarray, key: str = "local_quats") -> None:
    """A quaternion of (near) zero length is no rotation at all: refused, naming the frame and joint
    (normalising it would silently turn it into an arbitrary pose)."""
    if quats.ndim != 3 or quats.shape[-1] != 4:
        return  # Motion names the expected shape
    norms = np.linalg.norm(quats.astype(np.float64), axis=-1)
    bad = norms < MIN_QUAT_NORM
    if bad.any():
        frame, joint = np.argwhere(bad)[0].tolist()
        raise KinemaError(f"{path}: '{key}' holds {int(bad.sum())} quaternion(s) of zero length (first at "
                          f"frame {frame}, joint {joint}); each must be a rotation (w, x, y, z) of length 1")


def load_npz(path: str | Path, *, scale: float = 1.0) -> Motion:
    """Read a kinema ``.npz`` motion (lengths multiplied by ``scale``, which is 1 for files kinema
    wrote: they are in metres); missing keys or bad shapes raise KinemaError naming the key."""
    if not (isinstance(scale, (int, float)) and math.isfinite(scale) and scale > 0):
        raise KinemaError(f"scale must be a positive number, got {scale!r}")
    path = Path(path)
    try:
        data = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise KinemaError(f"{path}: not a readable .npz file ({err})") from None
    with data:
        missing = [k for k in REQUIRED_KEYS if k not in data.files]
        if missing:
            raise KinemaError(f"{path}: missing keys {missing} (see docs/formats.md)")
        arrays = _arrays(path, data)
    _check_finite(path, arrays)
    _check_quats(path, arrays["local_quats"])
    names = [str(n) for n in arrays["joint_names"]]
    rest = arrays.get("rest_rotations")
    if rest is not None:
        _check_quats(path, rest[None], "rest_rotations")
    skel = Skeleton(names, arrays["parents"].tolist(), arrays["offsets"] * scale, rest)
    contacts = torch.from_numpy(arrays["foot_contacts"]) if "foot_contacts" in arrays else None
    trans = None
    if "local_translations" in arrays:
        trans = torch.from_numpy(arrays["local_translations"].astype(np.float32))
    return Motion(
        skel,
        float(arrays["fps"]),
        torch.from_numpy(arrays["root_translation"].astype(np.float32) * np.float32(scale)),
        torch.from_numpy(arrays["local_quats"].astype(np.float32)),
        contacts,
        trans,
    )
