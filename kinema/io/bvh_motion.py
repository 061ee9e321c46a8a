"""Raw BVH data -> `Motion` (`read_bvh`, `bvh_data_to_motion`): lengths in metres (file units times
``scale``), rotations as quaternions wxyz of shape (T, J, 4), root translation (T, 3)."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import torch

from kinema.errors import BVHError
from kinema.geometry.rotations import euler_to_quat, quat_rotate
from kinema.io.bvh_data import MAX_METRES, BVHData
from kinema.io.bvh_parse import parse_bvh
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton


def read_bvh(path: str | os.PathLike, *, scale: float = 1.0, root_follows_child: bool = True) -> Motion:
    """Read a ``.bvh``/``.bvh.gz`` file as a `Motion`; every length is multiplied by ``scale``
    (0.01 for centimetre files such as Bandai Namco). See `bvh_data_to_motion` for the rules."""
    return bvh_data_to_motion(parse_bvh(path), scale=scale, root_follows_child=root_follows_child)


def bvh_data_to_motion(data: BVHData, *, scale: float = 1.0, root_follows_child: bool = True) -> Motion:
    """Convert raw BVH data to a `Motion` (float64, metres, full local rotations).

    - Rotation channels, in the order listed, are intrinsic Euler angles in degrees
      (``ZXY`` means ``R = Rz @ Rx @ Ry``); missing rotation axes count as zero, no rotation
      channels give the identity.
    - Position channels replace the joint's offset (missing axes keep the OFFSET value). A
      `Skeleton` has constant offsets, so the first frame's values become the offset; channels that
      move (by more than 1e-6 m) are kept per frame in ``Motion.local_translations``.
    - The root's world position is its position channels (its OFFSET when it has none).
    - When the root has a single child with position channels (Bandai Namco: a static
      ``joint_Root`` whose child ``Hips`` carries the translation), that child's movement is moved
      into ``root_translation``: every joint below the root keeps its exact file position, and only
      the root joint itself is displaced by the child's movement since frame 1 (Bandai's dummy root
      then follows the hips). ``Motion.prune(["joint_Root"])`` removes it exactly. With
      ``root_follows_child=False`` the root stays where the file puts it and the child's movement is
      kept in ``local_translations`` (every joint exact: creatures whose root is a real bone, e.g.
      BVH written from a GLB).
    - ``fps = 1 / frame_time``, snapped to the nearest integer when within 0.01 % (``0.0333333``
      is 30 fps).
    """
    if not (math.isfinite(scale) and scale > 0):
        raise BVHError(f"scale must be a positive number, got {scale}", data.path)
    _check_lengths(data, scale)
    vals = np.concatenate([data.values, np.zeros((data.num_frames, 1))], axis=1)  # column C is a constant zero
    offsets = data.offsets * scale
    positions, by_order = _split_channels(data, vals, offsets, scale)
    quats = _rotations(vals, by_order, data.num_frames, data.num_joints)
    root, local_t = _translations(data, positions, offsets, quats, root_follows_child)
    ends = {j: tuple(float(x) for x in v * scale) for j, v in data.end_sites.items()}
    skeleton = Skeleton(data.names, data.parents, offsets, end_sites=ends, name=_clip_name(data.path))
    return Motion(skeleton, _fps(data.frame_time), root, quats, None, local_t)


def _split_channels(
    data: BVHData, vals: np.ndarray, offsets: np.ndarray, scale: float
) -> tuple[dict[int, np.ndarray], dict[str, tuple[list[int], list[list[int]]]]]:
    """Per-joint position tracks and rotation columns grouped by Euler order, so that each order
    converts in one call. Position joints get their first frame's position as offset (``offsets``
    is updated in place); ``vals`` has an extra zero column standing in for missing rotation axes.
    """
    T, C = data.num_frames, data.num_channels
    positions: dict[int, np.ndarray] = {}  # joint -> (T, 3) scaled, for joints with position channels
    by_order: dict[str, tuple[list[int], list[list[int]]]] = {}
    for j, (start, chans) in enumerate(zip(data.column_starts, data.channels, strict=True)):
        pos_cols = {c[0]: start + k for k, c in enumerate(chans) if c.endswith("position")}
        rot_cols = {c[0]: start + k for k, c in enumerate(chans) if c.endswith("rotation")}
        if pos_cols:
            p = np.repeat(offsets[j][None], T, axis=0)
            for axis, col in pos_cols.items():
                p[:, "XYZ".index(axis)] = vals[:, col] * scale
            positions[j] = p
            offsets[j] = p[0]
        if rot_cols:
            order = "".join(rot_cols) + "".join(a for a in "XYZ" if a not in rot_cols)
            joints, cols = by_order.setdefault(order, ([], []))
            joints.append(j)
            cols.append([rot_cols.get(a, C) for a in order])
    return positions, by_order


def _rotations(
    vals: np.ndarray, by_order: dict[str, tuple[list[int], list[list[int]]]], T: int, J: int
) -> torch.Tensor:
    """(T, J, 4) float64 local quaternions from the Euler columns; identity for joints without any."""
    quats = torch.zeros(T, J, 4, dtype=torch.float64)
    quats[..., 0] = 1.0
    for order, (joints, cols) in by_order.items():
        angles = torch.from_numpy(np.deg2rad(vals[:, np.array(cols)]))  # (T, n, 3)
        quats[:, joints] = euler_to_quat(angles, order)
    return quats


def _translations(
    data: BVHData,
    positions: dict[int, np.ndarray],
    offsets: np.ndarray,
    quats: torch.Tensor,
    root_follows_child: bool,
) -> tuple[torch.Tensor, torch.Tensor | None]:
    """(root translation (T, 3), per-frame local translations (T, J, 3) or None when no bone below the
    root moves); a single moving child of the root is carried by the root (see `bvh_data_to_motion`)."""
    T, J = data.num_frames, data.num_joints
    root = torch.from_numpy(positions.get(0, np.repeat(offsets[:1], T, axis=0)).copy())
    children = [j for j in range(J) if data.parents[j] == 0]
    carried = children[0] if root_follows_child and len(children) == 1 and children[0] in positions else None
    if carried is not None:
        moved = torch.from_numpy(positions[carried] - positions[carried][:1])
        root = root + quat_rotate(quats[:, 0], moved)
    moving = [j for j, p in positions.items() if j not in (0, carried) and float(np.abs(p - p[:1]).max()) > 1e-6]
    local_t = None
    if moving:  # bones whose translation is animated (e.g. glTF creatures written by kinema)
        local_t = torch.from_numpy(np.repeat(offsets[None], T, axis=0))
        for j in moving:
            local_t[:, j] = torch.from_numpy(positions[j])
    return root, local_t


def _fps(frame_time: float) -> float:
    """Frames per second, snapped to the nearest integer within 0.01 % (files round the frame time)."""
    fps = 1.0 / frame_time
    if round(fps) > 0 and abs(fps - round(fps)) <= 1e-4 * fps:
        fps = float(round(fps))
    return fps


def _clip_name(path: str) -> str:
    """The file name without ``.gz`` / ``.bvh``: the skeleton's name."""
    name = Path(path).name
    for suffix in (".gz", ".bvh"):
        name = name[: -len(suffix)] if name.lower().endswith(suffix) else name
    return name


def _check_lengths(data: BVHData, scale: float) -> None:
    """OFFSETs and position channels, times ``scale``, must be finite and at most `MAX_METRES`."""
    for j, off in enumerate(data.offsets):
        if not np.all(np.abs(off * scale) <= MAX_METRES):
            raise BVHError(
                f"OFFSET of joint {data.names[j]} is {off.tolist()} x scale {scale:g}: not a "
                f"length within {MAX_METRES:g} m",
                data.path,
            )
    for j, site in data.end_sites.items():
        if not np.all(np.abs(site * scale) <= MAX_METRES):
            raise BVHError(
                f"End Site OFFSET of joint {data.names[j]} is {site.tolist()} x scale {scale:g}: "
                f"not a length within {MAX_METRES:g} m",
                data.path,
            )
    cols = [
        (start + k, j, c)
        for j, (start, chans) in enumerate(zip(data.column_starts, data.channels, strict=True))
        for k, c in enumerate(chans)
        if c.endswith("position")
    ]
    if not cols or data.values.size == 0:
        return
    pos = data.values[:, [c for c, _, _ in cols]] * scale
    bad = ~(np.abs(pos) <= MAX_METRES)
    if bad.any():
        frame, k = (int(i[0]) for i in np.nonzero(bad))
        _, j, chan = cols[k]
        raise BVHError(
            f"{data.names[j]} {chan} in frame {frame + 1} is {data.values[frame, cols[k][0]]:g} x scale "
            f"{scale:g}: not a position within {MAX_METRES:g} m",
            data.path,
        )
