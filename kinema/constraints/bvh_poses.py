"""Poses from a BVH clip as constraints (the in-betweening workflow): `poses_from_bvh` reads a clip
onto the model skeleton (joints matched by name, rest-pose aligned, resampled to the model's fps) and
`fullbody_from_bvh` wraps the poses in a `FullBodyConstraint`. Rotations: local axis-angle (K, J, 3)
radians; positions (K, 3) metres. The JSON form (``"bvh": ...`` in a constraints file) is read by
kinema.constraints.io.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from pathlib import Path

import torch

from kinema.constraints.json_values import int_list, time_list
from kinema.constraints.retarget import rest_alignment, retarget_globals
from kinema.constraints.types import ConstraintError, FullBodyConstraint, frames_from_times
from kinema.errors import KinemaError
from kinema.geometry.rotations import quat_inverse, quat_mul, quat_normalize, quat_to_axis_angle
from kinema.io.bvh import read_bvh
from kinema.motion.core import Motion
from kinema.skeleton import Skeleton

#: Bone-length ratio (BVH / model) outside [1/LIMIT, LIMIT] means a wrong ``scale``.
SCALE_RATIO_LIMIT = 4.0


def fullbody_from_bvh(
    path,
    source_frames: Sequence[int] | None,
    frames: Sequence[int] | None = None,
    *,
    skeleton: Skeleton,
    fps: float,
    scale: float = 1.0,
    times: Sequence[float] | None = None,
    source_times: Sequence[float] | None = None,
    recenter: bool = False,
) -> FullBodyConstraint:
    """A `FullBodyConstraint` with poses taken from a BVH file (the in-betweening workflow).

    ``source_frames`` index the clip *after* resampling to ``fps`` (or ``source_times``, seconds);
    the poses go to ``frames`` (or ``times``; default: the same frames/times as the source). Joints
    are matched by name; ``scale`` multiplies the file's lengths (0.01 for centimetres). See
    :func:`poses_from_bvh`.
    """
    rots, root = poses_from_bvh(
        path, source_frames, skeleton=skeleton, fps=fps, scale=scale, recenter=recenter, source_times=source_times
    )
    if frames is None and times is None:
        frames = None if source_frames is None else list(source_frames)
        times = None if source_times is None else list(source_times)
    return FullBodyConstraint(frame_indices=frames, times=times, local_rotations=rots, root_positions=root)


def poses_from_bvh(
    path,
    source_frames: Sequence[int] | None,
    *,
    skeleton: Skeleton,
    fps: float,
    scale: float = 1.0,
    recenter: bool = False,
    source_times: Sequence[float] | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Poses of a BVH clip on the model skeleton: ``(local axis-angle (K, J, 3), root position (K, 3))``.

    The file is read with `kinema.io.bvh.read_bvh` (lengths times ``scale``), joints the model lacks
    are pruned (Bandai's static ``joint_Root`` above ``Hips`` included), the clip is resampled to
    ``fps`` and ``source_frames`` index that resampled clip (or ``source_times``: seconds into the clip,
    frame ``floor(t * fps + 0.5)``). Joints are matched by name; the model's
    joints missing from the file are an error naming them. Global rotations are kept exactly (after a
    rest-pose alignment where the file's bones point elsewhere at rest: kinema.constraints.retarget) and
    turned into local rotations with the model's parents. ``recenter`` shifts the poses horizontally
    so that the first one's root is above the origin (where the model's training clips start).
    """
    motion, idx = _read_clip_on_model(path, skeleton=skeleton, fps=fps, scale=scale)
    frames = _source_frame_list(source_frames, source_times, fps, motion.num_frames)
    G, P = motion.global_transforms()
    G, P = G[frames][:, idx], P[frames][:, idx]
    G = retarget_globals(G, rest_alignment(skeleton, motion.skeleton.offsets[idx]))
    parents = [max(p, 0) for p in skeleton.parents]
    local = quat_mul(quat_inverse(G[:, parents]), G)
    local[:, 0] = G[:, 0]
    root = P[:, 0].clone()
    if recenter:
        root[:, [0, 2]] -= root[:1, [0, 2]].clone()
    return quat_to_axis_angle(quat_normalize(local)), root


def _read_clip_on_model(path, *, skeleton: Skeleton, fps: float, scale) -> tuple[Motion, list[int]]:
    """The BVH clip pruned to the model's joints and resampled to ``fps``, with the index of each
    model joint in it; a missing joint or a clip of implausible size (wrong ``scale``) is an error."""
    if isinstance(scale, bool) or not isinstance(scale, int | float) or not (math.isfinite(scale) and scale > 0):
        raise ConstraintError(f"expected a positive number, got {scale!r}", field="scale")
    if not Path(path).is_file():
        raise ConstraintError(f"BVH file not found: {path}", field="bvh")
    try:
        motion = read_bvh(path, scale=float(scale))
    except KinemaError as err:
        raise ConstraintError(str(err), field="bvh") from None
    names = motion.skeleton.names
    missing = [n for n in skeleton.names if n not in names]
    if missing:
        raise ConstraintError(
            f"{path}: joints of the model skeleton missing from the BVH (matched by name): {missing}", field="bvh"
        )
    extra = [n for n in names if n not in skeleton.names]
    try:
        motion = motion.prune(extra).resample(fps)
    except KinemaError as err:
        raise ConstraintError(f"{path}: cannot prune joints {extra}: {err}", field="bvh") from None
    idx = [motion.skeleton.names.index(n) for n in skeleton.names]
    model_len = float(skeleton.offsets.norm(dim=-1).sum())
    clip_len = float(motion.skeleton.offsets[idx].norm(dim=-1).sum())
    ratio = clip_len / max(model_len, 1e-12)
    if not 1.0 / SCALE_RATIO_LIMIT <= ratio <= SCALE_RATIO_LIMIT:
        raise ConstraintError(
            f"the BVH skeleton is {ratio:.3g} times the model skeleton's size: wrong scale? "
            "(use 0.01 for centimetre files such as Bandai Namco's)",
            field="scale",
        )
    return motion, idx


def _source_frame_list(
    source_frames: Sequence[int] | None, source_times: Sequence[float] | None, fps: float, T: int
) -> list[int]:
    """The clip frames to take, from exactly one of ``source_frames`` and ``source_times`` (seconds),
    each checked to lie inside the resampled clip of ``T`` frames."""
    if (source_frames is None) == (source_times is None):
        raise ConstraintError("give exactly one of 'source_frames' and 'source_times'", field="source_frames")
    if source_times is not None:
        times = time_list(list(source_times), "source_times")
        if any(not math.isfinite(t) or t < 0 for t in times):
            raise ConstraintError(f"times must be finite and not negative, got {times}", field="source_times")
        source_frames = frames_from_times(times, fps)
    frames = int_list(list(source_frames), "source_frames")
    frames = [int(f) if isinstance(f, numbers.Integral) and not isinstance(f, bool) else f for f in frames]
    for f in frames:
        if isinstance(f, bool) or not isinstance(f, numbers.Integral) or not 0 <= f < T:
            raise ConstraintError(
                f"source frame {f!r} is outside the clip ({T} frames at {fps:g} fps after resampling)",
                field="source_frames",
            )
    if not frames:
        raise ConstraintError("needs at least one frame", field="source_frames")
    return frames
