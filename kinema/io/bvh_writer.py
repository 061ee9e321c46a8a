"""BVH writing: `motion_to_bvh_data` (Motion -> raw `BVHData`), `format_bvh` (raw -> text) and
`write_bvh` (both, written atomically; a ``.gz`` name is gzip-compressed).

Files are plain, widely readable BVH: the root has ``Xposition Yposition Zposition`` plus three
rotation channels, every other joint three rotation channels (plus position channels when the motion
animates its translation, ``Motion.local_translations``), and each leaf joint an End Site.
Lengths are written as ``metres * scale``: the default ``scale=1`` writes metres, which Blender's
BVH importer (scale 1.0) brings in at the right size; ``scale=100`` writes centimetres.
"""

from __future__ import annotations

import gzip
import math
import os
from pathlib import Path

import numpy as np
import torch

from kinema.atomic_files import atomic_write_bytes
from kinema.errors import KinemaError
from kinema.geometry.rotations import quat_to_euler
from kinema.io.bvh import BVHData
from kinema.motion.core import Motion
from kinema.motion.rest import rebase_rest_pose

_EULER_ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")


def motion_to_bvh_data(motion: Motion, *, scale: float = 1.0, order: str = "ZXY") -> BVHData:
    """Raw BVH data for ``motion``: lengths ``* scale``, rotations as Euler degrees in ``order``.

    Raises `KinemaError` (before anything is written) for a non-finite motion, a bad scale or
    order, or joint names that cannot appear in a BVH file.
    """
    order = order.upper()
    if order not in _EULER_ORDERS:
        raise KinemaError(f"bad Euler order {order!r}; use one of {', '.join(_EULER_ORDERS)}")
    if not (math.isfinite(scale) and scale > 0):
        raise KinemaError(f"scale must be a positive number, got {scale}")
    if not motion.is_finite():
        raise KinemaError("cannot write a motion with NaN or infinite rotations or root translation")
    sk = motion.skeleton
    for name in sk.names:
        if not name.strip() or " ".join(name.split()) != name or "{" in name or "}" in name:
            raise KinemaError(f"joint name {name!r} cannot be written to BVH (braces or odd whitespace)")
    T, J = motion.num_frames, sk.num_joints
    quats = motion.local_rotations.detach().to("cpu", torch.float64)
    degrees = torch.rad2deg(quat_to_euler(quats, order)).numpy().reshape(T, J * 3)
    root = motion.root_translation.detach().to("cpu", torch.float64).numpy() * scale
    rot_names = [f"{axis}rotation" for axis in order]
    pos_names = ["Xposition", "Yposition", "Zposition"]
    columns = [root, degrees[:, :3]]
    channels = [[*pos_names, *rot_names]]
    trans = None if motion.local_translations is None else motion.local_translations.detach().to("cpu", torch.float64)
    for j in range(1, J):
        moves = trans is not None and bool((trans[:, j] - sk.offsets[j]).abs().max() > 1e-9)
        channels.append([*pos_names, *rot_names] if moves else list(rot_names))
        if moves:
            columns.append(trans[:, j].numpy() * scale)
        columns.append(degrees[:, 3 * j : 3 * j + 3])
    has_child = {p for p in sk.parents if p >= 0}
    end_sites = {
        j: np.asarray(sk.end_sites.get(j, (0.0, 0.0, 0.0)), dtype=np.float64) * scale
        for j in range(J)
        if j not in has_child
    }
    return BVHData(
        names=list(sk.names),
        parents=list(sk.parents),
        offsets=sk.offsets.detach().to("cpu", torch.float64).numpy() * scale,
        channels=channels,
        end_sites=end_sites,
        frame_time=1.0 / motion.fps,
        values=np.concatenate(columns, axis=1),
        path="",
    )


def format_bvh(data: BVHData, *, precision: int = 6) -> str:
    """BVH text for raw data; numbers get ``precision`` decimals, Frame Time 10 significant digits.

    End Sites are written for leaf joints only (BVH readers expect them nowhere else).
    """
    values = np.round(np.asarray(data.values, dtype=np.float64), precision) + 0.0  # + 0.0: no "-0.000"
    if values.ndim != 2 or values.shape[1] != data.num_channels or values.shape[0] == 0:
        raise KinemaError(f"values have shape {values.shape}, expected (frames > 0, {data.num_channels})")
    if not np.isfinite(values).all() or not np.isfinite(data.offsets).all():
        raise KinemaError("cannot write NaN or infinite values to BVH")
    if not (math.isfinite(data.frame_time) and data.frame_time > 0):
        raise KinemaError(f"bad frame time {data.frame_time}")
    children: list[list[int]] = [[] for _ in data.names]
    for j, p in enumerate(data.parents):
        if p >= 0:
            children[p].append(j)
    num = f"{{:.{precision}f}}"

    def vec(v) -> str:
        return " ".join(num.format(round(float(x), precision) + 0.0) for x in v)

    out = ["HIERARCHY"]
    visit: list[int] = []  # joints in the order the hierarchy is written (depth-first)
    # iterative depth-first walk: ("open", joint, depth) or ("close", None, depth)
    todo: list[tuple[str, int | None, int]] = [("open", 0, 0)]
    while todo:
        kind, j, depth = todo.pop()
        pad = "\t" * depth
        if kind == "close":
            out.append(pad + "}")
            continue
        visit.append(j)
        out.append(f"{pad}{'ROOT' if depth == 0 else 'JOINT'} {data.names[j]}")
        out.append(pad + "{")
        out.append(f"{pad}\tOFFSET {vec(data.offsets[j])}")
        out.append(f"{pad}\tCHANNELS {len(data.channels[j])} {' '.join(data.channels[j])}".rstrip())
        if not children[j]:
            site = data.end_sites.get(j, np.zeros(3))
            out += [f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {vec(site)}", f"{pad}\t}}"]
        todo.append(("close", None, depth))
        todo.extend(("open", c, depth + 1) for c in reversed(children[j]))
    # motion columns follow the written hierarchy, which differs from the joint order when the skeleton
    # lists joints breadth-first or otherwise non-depth-first
    starts = np.cumsum([0] + [len(c) for c in data.channels])
    columns = np.concatenate([np.arange(starts[j], starts[j + 1]) for j in visit]).astype(np.int64)
    values = values[:, columns]
    out += ["MOTION", f"Frames: {values.shape[0]}", f"Frame Time: {data.frame_time:.10g}"]
    row = " ".join([f"%.{precision}f"] * values.shape[1])
    out += [row % tuple(r) for r in values.tolist()]
    return "\n".join(out) + "\n"


def write_bvh(
    motion: Motion, path: str | os.PathLike, *, scale: float = 1.0, order: str = "ZXY", precision: int = 6
) -> Path:
    """Write ``motion`` as BVH (lengths ``metres * scale``, Euler ``order``) and return the path.

    The file appears atomically (temp file in the same folder, then rename), so a failure leaves
    no partial file; a name ending in ``.gz`` is gzip-compressed.
    """
    path = Path(path)
    text = format_bvh(motion_to_bvh_data(motion, scale=scale, order=order), precision=precision)
    payload = text.encode("utf-8")
    if path.name.lower().endswith(".gz"):
        payload = gzip.compress(payload, compresslevel=6, mtime=0)
    atomic_write_bytes(path, payload)
    return path


def save_bvh(motion: Motion, path: str | os.PathLike, *, clean_rest: bool = True, **options) -> Path:
    """The registry's ``.bvh``/``.bvh.gz`` writer: :func:`write_bvh` of the motion re-based so that its
    rest pose is the skeleton's clean standing pose when it carries ``rest_rotations``
    (kinema.motion.rest; joint positions unchanged). ``options``: ``scale``, ``order``, ``precision``."""
    return write_bvh(rebase_rest_pose(motion) if clean_rest else motion, path, **options)
