"""Join windows of a timeline (kinema.human.segments.plan_joins) and how a window is spliced into the
motion around it (kinema.pipeline.timeline.splice); no model needed."""

from __future__ import annotations

import torch

from kinema.human.segments import PlannedSegment, plan_joins
from kinema.motion.core import Motion
from kinema.pipeline.timeline import splice
from kinema.skeleton import Skeleton

FPS = 20.0


def _segments(lengths: list[int]) -> list[PlannedSegment]:
    out, start = [], 0
    for i, n in enumerate(lengths):
        out.append(PlannedSegment(f"prompt {i}", start, start + n))
        start += n
    return out


def test_windows_cover_half_a_second_plus_keyframes_each_side() -> None:
    joins = plan_joins(_segments([80, 80, 80]), FPS)
    assert [(j.lo, j.hi, j.head, j.tail, j.fade_in, j.fade_out) for j in joins] == [
        (67, 93, 3, 3, 10, 10),
        (147, 173, 3, 3, 10, 10),
    ]
    assert [j.prompt for j in joins] == ["prompt 1", "prompt 2"]  # the later segment's text


def test_short_segments_shrink_the_windows_which_never_overlap() -> None:
    segs = _segments([80, 7, 5, 80])
    joins = plan_joins(segs, FPS)
    assert len(joins) == 3
    for a, b in zip(joins, joins[1:], strict=False):
        assert a.hi <= b.lo, (a, b)
    for j, (before, after) in zip(joins, zip(segs, segs[1:], strict=False), strict=True):
        assert j.lo < before.end < j.hi and j.head >= 1 and j.tail >= 1
        assert j.fade_in <= before.end - j.lo and j.fade_out <= j.hi - after.start


def test_a_one_frame_middle_segment_gets_plain_cuts() -> None:
    assert plan_joins(_segments([40, 1, 40]), FPS) == []
    assert plan_joins(_segments([40]), FPS) == []


def _constant(frames: int, x: float) -> Motion:
    skel = Skeleton(["a", "b"], [-1, 0], torch.tensor([[0.0, 1.0, 0.0], [0.0, 0.0, 0.5]]))
    rots = torch.zeros(frames, 2, 4)
    rots[..., 0] = 1
    root = torch.zeros(frames, 3)
    root[:, 0] = x
    return Motion(skel, FPS, root, rots)


def test_splice_replaces_the_window_and_fades_at_its_edges() -> None:
    motion, window = _constant(60, 0.0), _constant(20, 1.0)
    out = splice(motion, window, 20, 5, 4)
    x = out.root_translation[:, 0]
    assert out.num_frames == 60
    assert torch.all(x[:20] == 0) and torch.all(x[40:] == 0)  # outside the window: unchanged
    assert torch.allclose(x[25:36], torch.ones(11))  # between the fades: the window itself
    assert torch.all(torch.diff(x[19:26]) > 0) and torch.all(torch.diff(x[35:41]) < 0)  # raised-cosine fades
