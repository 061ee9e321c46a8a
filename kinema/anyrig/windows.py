"""Where the any-rig sampler's windows lie, which prompt each one gets, and how they are blended.

The any-rig denoiser sees ``window`` frames at a time. A motion longer than that, or a timeline of
several prompts, is covered by overlapping windows that are all denoised together at every DDIM step
and blended (kinema.anyrig.sampling). A `WindowPlan` lists them:

- one prompt (`single_plan`): windows of the model's length over the whole motion, overlapping by at
  least a quarter window (Dragon Sec. 3.4, MultiDiffusion form);
- a timeline (`segment_plan`): segment k owns output frames ``[b_k, b_k+1)`` (kinema.human.segments.
  segment_bounds, the human model's rule) and its windows, all with segment k's prompt, start
  ``overlap`` frames early, re-playing the end of segment k-1 as the human model's timeline does
  (kinema.pipeline.timeline). Those shared frames are cross-faded by the blending weights, which ramp
  over exactly the shared frames -- at every denoising step instead of once at the end, so both sides
  of a join are denoised to agree and no frame needs imposing as context.

A segment shorter than a window gets one shorter window; windows are padded to a common length with
masked frames (the denoiser's frame mask) and zero weight. Frames are at the model's fps.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

#: seconds of the previous segment a segment's windows re-play (as the human model's segments did before
#: its joins became regenerated windows, kinema.human.segments), at most a quarter window
OVERLAP_SECONDS = 0.5


def window_starts(T: int, W: int) -> list[int]:
    """Start frames of windows of ``W`` frames covering ``T`` frames, overlapping by >= ``W // 4``."""
    if T <= W:
        return [0]
    stride = W - max(1, W // 4)
    n = math.ceil((T - W) / stride) + 1
    return [round(i * (T - W) / (n - 1)) for i in range(n)]


@dataclass(frozen=True)
class WindowPlan:
    """Windows over ``frames`` frames: ``starts``, real ``lengths`` and the index of the prompt of each
    (into the list of prompts of the call); ``window`` is the model's window (ramps are at most a quarter)."""

    starts: tuple[int, ...]
    lengths: tuple[int, ...]
    prompts: tuple[int, ...]
    frames: int
    window: int

    @property
    def width(self) -> int:
        """Frames of every window as run (the longest; shorter ones are padded)."""
        return max(self.lengths)

    def frame_mask(self) -> torch.Tensor:
        """``(K, width)``: True on a window's real frames."""
        f = torch.arange(self.width)
        return torch.stack([f < n for n in self.lengths])

    def weights(self) -> torch.Tensor:
        """``(K, width)`` blending weights: 1 inside a window, ramping down linearly over the frames it
        shares with a neighbour at each inner edge (at most a quarter window), 0 on padding."""
        out = torch.zeros(len(self.starts), self.width)
        quarter = max(1, self.window // 4)
        spans = [(s, s + n) for s, n in zip(self.starts, self.lengths, strict=True)]
        for k, (s, e) in enumerate(spans):
            # frames shared with the windows that reach over this window's start / end
            shared_in = max((b - s for a, b in spans if a < s < b), default=quarter)
            shared_out = max((e - a for a, b in spans if a < e < b), default=quarter)
            f = torch.arange(e - s, dtype=torch.float32)
            w = torch.ones(e - s)
            if s > 0:
                w = torch.minimum(w, (f + 1) / (max(1, min(quarter, shared_in)) + 1))
            if e < self.frames:
                w = torch.minimum(w, (e - s - f) / (max(1, min(quarter, shared_out)) + 1))
            out[k, : e - s] = w
        return out

    def cut(self, x: torch.Tensor) -> torch.Tensor:
        """``(S, frames, ...)`` -> ``(S * K, width, ...)``, sample-major: every sample's windows (frames
        past the end of the motion are zeros, padding)."""
        x = torch.cat([x, x.new_zeros(x.shape[0], self.width, *x.shape[2:])], dim=1)
        return torch.stack([x[:, s : s + self.width] for s in self.starts], dim=1).flatten(0, 1)

    def blend(self, xw: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
        """The windows' ``(S * K, width, ...)`` (as `cut` lays them out) blended back to ``(S, frames, ...)``
        with ``weights`` (`weights`)."""
        K = len(self.starts)
        xw = xw.view(xw.shape[0] // K, K, *xw.shape[1:])
        out = xw.new_zeros(xw.shape[0], self.frames, *xw.shape[3:])
        den = torch.zeros(self.frames)
        for k, (s, n) in enumerate(zip(self.starts, self.lengths, strict=True)):
            w = weights[k, :n]
            out[:, s : s + n] += w.view(n, *([1] * (xw.dim() - 3))) * xw[:, k, :n]
            den[s : s + n] += w
        return out / den.view(1, self.frames, *([1] * (xw.dim() - 3)))


def single_plan(T: int, W: int) -> WindowPlan:
    """One prompt over ``T`` frames with windows of ``W`` frames (`window_starts`)."""
    starts = window_starts(T, W)
    return WindowPlan(tuple(starts), (min(W, T),) * len(starts), (0,) * len(starts), T, W)


def segment_overlap(fps: float, W: int) -> int:
    """Frames a segment's windows re-play of the previous segment: `OVERLAP_SECONDS`, at most ``W // 4``."""
    return max(1, min(round(OVERLAP_SECONDS * fps), W // 4))


def segment_plan(bounds: list[int], W: int, overlap: int) -> WindowPlan:
    """Windows of a timeline with segment boundaries ``bounds = [0, b_1, ..., T]`` (see module)."""
    starts, lengths, prompts = [], [], []
    for k, (b0, b1) in enumerate(zip(bounds[:-1], bounds[1:], strict=True)):
        lo = b0 if k == 0 else max(0, b0 - overlap)
        for s in window_starts(b1 - lo, W):
            starts.append(lo + s)
            lengths.append(min(W, b1 - lo))
            prompts.append(k)
    return WindowPlan(tuple(starts), tuple(lengths), tuple(prompts), bounds[-1], W)


def window_weights(starts: list[int], W: int, T: int) -> torch.Tensor:
    """``(K, min(W, T))`` blending weights of one prompt's windows ``starts`` (`WindowPlan.weights`)."""
    return WindowPlan(tuple(starts), (min(W, T),) * len(starts), (0,) * len(starts), T, W).weights()
