"""Multi-prompt timelines: parsing, and the blending that joins their pieces.

Each segment is sampled on its own prompt, then every join is regenerated as a transition window
(kinema.human.segments says how and why); :func:`splice` puts a window into the motion, cross-fading
(root lerp, rotation slerp with raised-cosine weights, :func:`crossfade`) over its first and last
frames so the join has no seam.
"""

from __future__ import annotations

import difflib
import math
import reprlib
from dataclasses import dataclass
from pathlib import Path

import torch

from kinema.errors import KinemaError
from kinema.finite import is_finite_real
from kinema.geometry.rotations import quat_make_continuous, quat_normalize, quat_slerp
from kinema.input_files import read_json_bounded
from kinema.motion.core import Motion
from kinema.pipeline.request import request_bounds, segment_json

#: Keys of a timeline segment object (besides ``comment`` and keys starting with ``_``, ignored).
SEGMENT_KEYS = ("prompt", "seconds")


@dataclass(frozen=True)
class Segment:
    """One prompt held for ``seconds``."""

    prompt: str
    seconds: float


def parse_timeline(obj, source: str = "timeline") -> list[Segment]:
    """Segments from a JSON list of ``{"prompt": str, "seconds": float}`` (or ``[prompt, seconds]``)."""
    if isinstance(obj, (str, Path)) and Path(obj).suffix.lower() == ".json":
        path = Path(obj)
        obj = read_json_bounded(path, "timeline file")
        source = str(path)
    if not isinstance(obj, list) or not obj:
        raise KinemaError(f"{source}: a timeline is a non-empty JSON list of {{'prompt', 'seconds'}} objects")
    out = []
    for i, item in enumerate(obj):
        if isinstance(item, Segment):
            out.append(item)
            continue
        item = segment_json(item, i, source)
        _check_keys(item, source, i)
        prompt, seconds = item.get("prompt"), item.get("seconds")
        if not isinstance(prompt, str):
            raise KinemaError(f"{source}: segment {i}: field 'prompt' must be a string")
        if not is_finite_real(seconds) or seconds <= 0:
            raise KinemaError(f"{source}: segment {i}: field 'seconds' must be a positive number, "
                              f"got {reprlib.repr(seconds)}")
        out.append(Segment(prompt, float(seconds)))
    total, limit = sum(seg.seconds for seg in out), request_bounds().max_seconds
    if total > limit + 1e-9:  # before any work: 1e9 s used to hang prompt matching (issue 36)
        raise KinemaError(f"{source}: the timeline lasts {total:g} s; at most {limit:g} s")
    return out


def _check_keys(item: dict, source: str, i: int) -> None:
    """Unknown keys are an error (typos such as "promt"); ``comment`` and ``_...`` keys are ignored."""
    for key in item:
        if key in SEGMENT_KEYS or key == "comment" or (isinstance(key, str) and key.startswith("_")):
            continue
        close = difflib.get_close_matches(str(key), SEGMENT_KEYS, n=1)
        hint = f" (did you mean '{close[0]}'?)" if close else ""
        raise KinemaError(f"{source}: segment {i}: unknown key {key!r}{hint}; expected 'prompt' and 'seconds' "
                          "(and 'comment', '_...')")


def split_long(prompt: str, seconds: float, max_seconds: float) -> list[Segment]:
    """A single prompt longer than the model's window becomes equal segments of the same prompt."""
    n = max(1, math.ceil(seconds / max_seconds - 1e-9))
    return [Segment(prompt, seconds / n)] * n


def crossfade(prev: Motion, new: Motion, overlap: int) -> Motion:
    """``prev`` followed by ``new`` whose first ``overlap`` frames re-play prev's last ``overlap`` frames.

    The shared frames are blended from prev (weight 1 at the start) to new (weight 1 at the end)."""
    if overlap <= 0:
        return prev.concatenate(new)
    head = prev.crop(0, prev.num_frames - overlap) if prev.num_frames > overlap else None
    a = prev.crop(prev.num_frames - overlap)
    b = new.crop(0, overlap)
    w = 0.5 - 0.5 * torch.cos(math.pi * (torch.arange(overlap, dtype=a.dtype) + 1) / (overlap + 1))
    qa = quat_make_continuous(a.local_rotations, dim=0)
    qb = b.local_rotations
    # align hemispheres frame by frame before slerp
    sign = torch.where((qa * qb).sum(-1, keepdim=True) < 0, -1.0, 1.0).to(qb.dtype)
    rots = quat_slerp(qa, qb * sign, w[:, None])
    root = a.root_translation * (1 - w[:, None]) + b.root_translation * w[:, None]
    contacts = None
    if a.foot_contacts is not None and b.foot_contacts is not None:
        contacts = torch.where(w[:, None] < 0.5, a.foot_contacts, b.foot_contacts)
    blended = Motion(prev.skeleton, prev.fps, root, quat_normalize(rots), contacts)
    out = blended if head is None else head.concatenate(blended)
    if new.num_frames > overlap:
        out = out.concatenate(new.crop(overlap))
    return out


def splice(motion: Motion, window: Motion, lo: int, fade_in: int, fade_out: int) -> Motion:
    """``motion`` with frames ``[lo, lo + window.num_frames)`` replaced by ``window``: its first
    ``fade_in`` frames blend from ``motion`` to the window, its last ``fade_out`` back to ``motion``."""
    hi = lo + window.num_frames
    # a window may start at frame 0 or end on the last frame (a first or last segment shorter than the
    # join): nothing of ``motion`` is left on that side (issue 36: "crop [0, 0) ... is empty")
    out = crossfade(motion.crop(0, lo + fade_in), window, fade_in) if lo + fade_in > 0 else window
    return crossfade(out, motion.crop(hi - fade_out), fade_out) if hi - fade_out < motion.num_frames else out


def segment_bounds(segments, fps: float) -> list[int]:
    """Frame boundaries ``[0, b_1, ..., T]`` of consecutive segments: ``b_k = round(fps * (s_1 + ... + s_k))``.

    Rounding the running total (not each segment) gives exactly the frames asked for: 60 s at 20 fps in
    seven 8.57-s windows is 1200 frames, not 7 x 171. A segment that would get no frame is an error."""
    bounds, total = [0], 0.0
    for i, s in enumerate(segments):
        total += s.seconds
        bounds.append(int(math.floor(total * fps + 0.5)))
        if bounds[-1] <= bounds[-2]:
            raise KinemaError(f"timeline segment {i} ({s.prompt!r}) lasts {s.seconds:g} s, shorter than one "
                              f"frame at {fps:g} fps ({1 / fps:.3f} s)")
    return bounds
