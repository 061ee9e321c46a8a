"""Per-segment targets for generation: user constraints split over a timeline plus the joins.

Frames of user constraints refer to the whole output. Segment k covers output frames
``[start_k, end_k)`` and is generated with ``overlap`` extra leading frames that re-play the end of the
motion so far (dense full-body keyframes: positions, velocities, rotations, root and heading).
Every segment is sampled in a local frame whose first root sits over the origin, as in training; the
shift is added back afterwards. Shapes: ``x_tgt``/``mask`` ``(T, D)``, ``world_xz (T, J, 2)``. The plan
works on an explicit representation (kinema.representation.flat), never on a model object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from kinema.errors import KinemaError
from kinema.generate.sampling import SampleTargets
from kinema.generate.targets import UserTargets, encode_user_constraints, run_postprocess
from kinema.motion.core import Motion
from kinema.representation.flat import FlatRepresentation


@dataclass
class PlannedSegment:
    prompt: str
    start: int  # first new output frame
    end: int  # one past the last output frame
    overlap: int  # leading frames shared with the previous segment

    @property
    def num_frames(self) -> int:
        return self.end - self.start + self.overlap


@dataclass(frozen=True)
class SegmentTargets:
    """One sample's conditions for one segment, in the segment's local frame: unnormalised
    ``x_tgt``/``mask (T, D)``, ``world_xz (T, J, 2)``/``world_mask (T, J)`` (or None), first-frame
    heading ``c_dir (2,)`` and the ground ``shift (2,)`` metres to add back to the sampled root."""

    x_tgt: torch.Tensor
    mask: torch.Tensor
    world_xz: torch.Tensor | None
    world_mask: torch.Tensor | None
    c_dir: torch.Tensor
    shift: torch.Tensor


def stack_targets(rows: list[SegmentTargets]) -> tuple[SampleTargets, torch.Tensor]:
    """Per-sample segment targets stacked on a leading batch axis: the sampler's `SampleTargets` and
    the shifts ``(B, 2)``."""
    def stack(name):
        values = [getattr(r, name) for r in rows]
        return None if values[0] is None else torch.stack(values)

    return SampleTargets(stack("c_dir"), stack("x_tgt"), stack("mask"), stack("world_xz"),
                         stack("world_mask")), stack("shift")


@dataclass
class SegmentPlan:
    """Everything needed to generate a timeline once the constraints are encoded."""

    rep: FlatRepresentation
    segments: list[PlannedSegment]
    total_frames: int
    targets: UserTargets
    constraints: list = field(default_factory=list)

    def segment_targets(self, k: int, motion: Motion | None, heading: float) -> SegmentTargets:
        """Segment k's targets in its local frame; ``motion`` is the sample's motion so far (None for
        the first segment, whose first frame faces ``heading`` unless a heading constraint says otherwise)."""
        seg, rep, user = self.segments[k], self.rep, self.targets
        lo = seg.start - seg.overlap
        x_tgt = user.x_tgt[lo : seg.end].clone()
        mask = user.mask[lo : seg.end].clone()
        wxz = None if user.world_xz is None else user.world_xz[lo : seg.end].clone()
        wm = None if user.world_mask is None else user.world_mask[lo : seg.end].clone()
        if motion is None:
            shift = torch.zeros(2)
            c_dir = torch.tensor([math.cos(heading), math.sin(heading)])
            if bool(mask[0, rep.heading].all()):  # a heading constraint on the first frame wins
                c_dir = x_tgt[0, rep.heading].float()
        else:
            join = rep.from_motion(motion).float()[motion.num_frames - seg.overlap :]
            shift = join[0, rep.root_xz].clone()
            c_dir = join[0, rep.heading].clone()
            channels = rep.motion_channels
            x_tgt[: seg.overlap, channels] = join[:, channels]
            mask[: seg.overlap, channels] = 1.0
        rep.shift_root_xz(x_tgt, -shift)
        if wxz is not None:
            wxz = wxz - shift
        return SegmentTargets(x_tgt, mask, wxz, wm, c_dir, shift)

    def postprocess(self, motion: Motion) -> tuple[Motion, dict]:
        """Guarded post-processing of one finished motion; returns it with its own report."""
        return run_postprocess(motion, self.constraints, self.rep)


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


def plan_segments(rep: FlatRepresentation, segments, constraints,
                  constraints_fps: float | None = None) -> SegmentPlan:
    """Frame ranges for every segment (at ``rep.fps``) and the encoded user constraints for the whole output."""
    overlap = max(1, round(0.5 * rep.fps))
    bounds = segment_bounds(segments, rep.fps)
    planned = []
    for i, (s, start, end) in enumerate(zip(segments, bounds[:-1], bounds[1:], strict=True)):
        ov = 0 if i == 0 else min(overlap, start)
        planned.append(PlannedSegment(s.prompt, start, end, ov))
    total_frames = bounds[-1]
    cons, targets = encode_user_constraints(rep, constraints, total_frames, constraints_fps)
    return SegmentPlan(rep, planned, total_frames, targets, cons)
