"""Per-segment and per-join targets of a timeline: user constraints split over segments and join windows.

Frames of user constraints refer to the whole output. The joins follow PriorMDM's DoubleTake (Shafir
et al., sequential composition): a first take samples every segment ``[start_k, end_k)`` on its own
prompt, with no context from the previous one, starting where the motion so far ends and facing its last
heading; a second take regenerates each join: output frames ``[lo, hi)`` (``JOIN_SECONDS`` each side of
the boundary plus ``JOIN_CONTEXT_SECONDS`` of full-body keyframes of the first take at each end, given
as *context* every guidance branch sees, ``join`` mask; kinema.model.denoiser.Denoiser.forward_guided),
with the later segment's prompt, over the last ``JOIN_STRENGTH`` of the DDIM steps starting from the
first take's hard cut (Gaussian-smoothed over ``JOIN_START_SMOOTHING`` frames, then noised: SDEdit);
the window is cross-faded into the motion over ``JOIN_FADE_SECONDS`` at each edge
(kinema.pipeline.timeline.splice).

Why (issue 18): the former joins re-played 0.5 s of the previous motion at the start of each segment
with its first 0.15 s as context, and that context outweighed the new text: after a walk the bow
segment kept shuffling forward at 0.3-0.5 m/s and leaned 8-9 degrees. Measured with the shipped model,
raw, 50 steps (scripts/timeline_joins.py, walk -> bow -> wave and bow -> wave -> walk, seeds 0-3):
the bow after a walk leans 14/12/25/19 degrees (former joins 9/8/23/9; the lone prompt 35/18/7/13;
over seeds 0-7 the timeline's bow and the lone prompt average 18 and 16 degrees); the closing walk of
bow -> wave -> walk 1.0-1.2 m/s (former 0.66-1.27). Window choices on the same cases and on the 8
timeline cases of `kinema evaluate` (test split, 26 segments): windows sampled from pure noise jumped
(the model snaps from the first keyframes to the later pose within 2 frames: join acceleration peaks
170-590 m/s^2, whatever the text, guidance, keyframe count or constraint-vs-context); starting from
the hard cut at 40/50/60/70 % of the steps gave evaluation join peaks 188/174/159/138 m/s^2, smoothing
that start over 3/5 frames 119/104 (inside p99 117); 0.75-s sides gave peaks 60 but raw skate 15.2 cm/s
(0.5-s: 12.9; former joins 11.9). Evaluation row with these settings: per-segment R@3 69.2 -> 92.3 %,
R@1 50.0 -> 80.8 %, mean join acceleration 6.2 -> 3.5 m/s^2 (4.4 inside).

Every pass is sampled in a local frame whose first root sits over the origin, as in training; the
shift is added back afterwards. Shapes: ``x_tgt``/``mask``/``join``/``start`` ``(T, D)``,
``world_xz (T, J, 2)``. The plan works on an explicit representation (kinema.representation.flat),
never on a model object.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from kinema.human.sampling import SampleTargets
from kinema.human.targets import UserTargets, encode_user_constraints, run_postprocess
from kinema.motion.core import Motion
from kinema.motion.smoothing import smooth_time
from kinema.pipeline.timeline import segment_bounds
from kinema.representation.flat import FlatRepresentation

#: seconds of each side of a join that its transition window regenerates
JOIN_SECONDS = 0.5
#: seconds at each end of a join's window imposed as full-body keyframes of the motion around it
JOIN_CONTEXT_SECONDS = 0.15
#: seconds at each end of a join's window over which it is cross-faded into the motion around it
JOIN_FADE_SECONDS = 0.5
#: share of the DDIM steps a join's window runs, starting from the hard cut noised to that level (SDEdit)
JOIN_STRENGTH = 0.6
#: frames (Gaussian sigma) the hard cut is smoothed over before it is noised
JOIN_START_SMOOTHING = 5.0


@dataclass
class PlannedSegment:
    prompt: str
    start: int  # first output frame
    end: int  # one past the last output frame

    @property
    def num_frames(self) -> int:
        return self.end - self.start


@dataclass
class PlannedJoin:
    """The transition window of one join: output frames ``[lo, hi)`` regenerated with ``prompt`` (the
    later segment's), the first ``head`` and last ``tail`` of them imposed as keyframes of the motion
    around the window (context every guidance branch sees); the window is cross-faded into that motion
    over its first ``fade_in`` and last ``fade_out`` frames."""

    prompt: str
    lo: int
    hi: int
    head: int
    tail: int
    fade_in: int
    fade_out: int

    @property
    def num_frames(self) -> int:
        return self.hi - self.lo


@dataclass(frozen=True)
class SegmentTargets:
    """One sample's conditions for one segment or join window, in its local frame: unnormalised
    ``x_tgt``/``mask (T, D)``, ``world_xz (T, J, 2)``/``world_mask (T, J)`` (or None), first-frame
    heading ``c_dir (2,)``, the ground ``shift (2,)`` metres to add back to the sampled root; for a join
    window only, ``join (T, D)``: the imposed keyframe entries, which ``mask`` holds too, and ``start
    (T, D)``: the unnormalised features the window's sampling starts from."""

    x_tgt: torch.Tensor
    mask: torch.Tensor
    world_xz: torch.Tensor | None
    world_mask: torch.Tensor | None
    c_dir: torch.Tensor
    shift: torch.Tensor
    join: torch.Tensor | None = None
    start: torch.Tensor | None = None


def stack_targets(rows: list[SegmentTargets]) -> tuple[SampleTargets, torch.Tensor]:
    """Per-sample segment targets stacked on a leading batch axis: the sampler's `SampleTargets` and
    the shifts ``(B, 2)``."""
    def stack(name):
        values = [getattr(r, name) for r in rows]
        return None if values[0] is None else torch.stack(values)

    return SampleTargets(stack("c_dir"), stack("x_tgt"), stack("mask"), stack("world_xz"),
                         stack("world_mask"), stack("join"), stack("start")), stack("shift")


@dataclass
class SegmentPlan:
    """Everything needed to generate a timeline once the constraints are encoded."""

    rep: FlatRepresentation
    segments: list[PlannedSegment]
    total_frames: int
    targets: UserTargets
    constraints: list = field(default_factory=list)
    joins: list[PlannedJoin] = field(default_factory=list)

    def _user(self, lo: int, hi: int):
        """Copies of the user targets on output frames ``[lo, hi)``."""
        user = self.targets
        wxz = None if user.world_xz is None else user.world_xz[lo:hi].clone()
        wm = None if user.world_mask is None else user.world_mask[lo:hi].clone()
        return user.x_tgt[lo:hi].clone(), user.mask[lo:hi].clone(), wxz, wm

    def segment_targets(self, k: int, motion: Motion | None, heading: float) -> SegmentTargets:
        """Segment k's own targets (its user constraints, no context) in its local frame: it starts
        where ``motion`` (the sample's motion so far; None for the first segment) ends, facing its last
        heading; the first segment faces ``heading`` unless a heading constraint on frame 0 says otherwise."""
        seg, rep = self.segments[k], self.rep
        x_tgt, mask, wxz, wm = self._user(seg.start, seg.end)
        if motion is None:
            shift = torch.zeros(2)
            c_dir = torch.tensor([math.cos(heading), math.sin(heading)])
            if bool(mask[0, rep.heading].all()):  # a heading constraint on the first frame wins
                c_dir = x_tgt[0, rep.heading].float()
        else:
            last = rep.from_motion(motion).float()[-1]
            shift, c_dir = last[rep.root_xz].clone(), last[rep.heading].clone()
        rep.shift_root_xz(x_tgt, -shift)
        if wxz is not None:
            wxz = wxz - shift
        return SegmentTargets(x_tgt, mask, wxz, wm, c_dir, shift)

    def join_targets(self, j: int, features: torch.Tensor) -> SegmentTargets:
        """Join j's window targets in its local frame: ``features (T, D)`` (unnormalised, the sample's
        assembled motion) imposed on the window's first ``head`` and last ``tail`` frames, as context
        (``join``), over the user constraints of the window's frames."""
        jn, rep = self.joins[j], self.rep
        x_tgt, mask, wxz, wm = self._user(jn.lo, jn.hi)
        around = torch.zeros(jn.num_frames, dtype=torch.bool)
        around[: jn.head] = True
        around[jn.num_frames - jn.tail :] = True
        ch = around[:, None] & rep.motion_channels[None, :]
        x_tgt = torch.where(ch, features[jn.lo : jn.hi].float(), x_tgt)
        mask = torch.where(ch, torch.ones_like(mask), mask)
        shift = features[jn.lo, rep.root_xz].float().clone()
        c_dir = features[jn.lo, rep.heading].float().clone()
        start = smooth_time(rep.shift_root_xz(features[jn.lo : jn.hi].float().clone(), -shift), JOIN_START_SMOOTHING)
        rep.shift_root_xz(x_tgt, -shift)
        if wxz is not None:
            wxz = wxz - shift
        return SegmentTargets(x_tgt, mask, wxz, wm, c_dir, shift, ch.float(), start)

    def postprocess(self, motion: Motion) -> tuple[Motion, dict]:
        """Guarded post-processing of one finished motion; returns it with its own report."""
        return run_postprocess(motion, self.constraints, self.rep)


def plan_joins(segments: list[PlannedSegment], fps: float) -> list[PlannedJoin]:
    """The transition window of every join: ``JOIN_SECONDS`` of each side regenerated plus
    ``JOIN_CONTEXT_SECONDS`` of keyframes at each end, all within the half of each neighbouring
    segment that faces the join (the whole segment at the timeline's ends), so windows never overlap.
    A side with no frame to spare (a one-frame middle segment) gets no window: a plain cut."""
    side, context = round(JOIN_SECONDS * fps), max(1, round(JOIN_CONTEXT_SECONDS * fps))
    fade = max(1, round(JOIN_FADE_SECONDS * fps))
    n, joins = len(segments), []
    for k in range(n - 1):
        before, after = segments[k], segments[k + 1]
        room_before = before.num_frames if k == 0 else before.num_frames // 2
        room_after = after.num_frames if k + 1 == n - 1 else after.num_frames // 2
        if room_before < 1 or room_after < 1:
            continue
        head, tail = min(context, room_before), min(context, room_after)
        lo = before.end - head - min(side, room_before - head)
        hi = after.start + tail + min(side, room_after - tail)
        fade_in, fade_out = max(head, min(fade, before.end - lo)), max(tail, min(fade, hi - after.start))
        joins.append(PlannedJoin(after.prompt, lo, hi, head, tail, fade_in, fade_out))
    return joins


def plan_segments(rep: FlatRepresentation, segments, constraints,
                  constraints_fps: float | None = None) -> SegmentPlan:
    """Frame ranges for every segment and join window (at ``rep.fps``) and the encoded user
    constraints for the whole output."""
    bounds = segment_bounds(segments, rep.fps)
    planned = [PlannedSegment(s.prompt, start, end)
               for s, start, end in zip(segments, bounds[:-1], bounds[1:], strict=True)]
    total_frames = bounds[-1]
    cons, targets = encode_user_constraints(rep, constraints, total_frames, constraints_fps)
    return SegmentPlan(rep, planned, total_frames, targets, cons, plan_joins(planned, rep.fps))
