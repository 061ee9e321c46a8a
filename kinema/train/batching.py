"""Training batches: length-bucketed sampling, random crops, heading/position augmentation, text pick.

Every batch is a pure function of ``(seed, rank, step)``: a run resumed at step s sees exactly the
batches and noise it would have seen without the interruption, with no sampler state to save.
Under DistributedDataParallel each rank draws from its own shard of the clips (clip i belongs to rank
``i % world_size``), which is what a distributed sampler does.

Batch shapes: ``features (B, T, D)`` normalised, ``pad_mask (B, T)`` True on real frames,
``c_dir (B, 2)`` first-frame heading, ``caption_index (B,)`` rows of the caption embedding table,
``text_keep (B,)`` False where the text is dropped for classifier-free guidance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats
from kinema.representation.transform import canonicalize_start


def step_generator(seed: int, rank: int, step: int) -> torch.Generator:
    """The generator for one training step of one rank."""
    return torch.Generator().manual_seed((seed * 1_000_003 + rank * 7_919 + step * 104_729) % (2**63 - 1))


@dataclass
class Batch:
    features: torch.Tensor
    raw_features: torch.Tensor  # unnormalised, for constraint sampling and the FK loss
    pad_mask: torch.Tensor
    lengths: torch.Tensor
    c_dir: torch.Tensor
    caption_index: torch.Tensor
    text_keep: torch.Tensor
    clip_index: torch.Tensor  # (B,) the train clip each row was cut from


class BatchSampler:
    """Draws length-bucketed, augmented batches from in-memory clips."""

    def __init__(
        self,
        clips: list[torch.Tensor],
        caption_ranges: list[tuple[int, int]],
        layout: FeatureLayout,
        stats: NormStats,
        batch_size: int,
        max_frames: int,
        min_frames: int = 8,
        num_buckets: int = 4,
        text_dropout: float = 0.1,
        random_heading: bool = True,
        rank: int = 0,
        world_size: int = 1,
        clip_weights: list[float] | None = None,
        crop_min_fraction: float = 0.5,
    ):
        if not 0.0 < crop_min_fraction <= 1.0:
            raise ValueError(f"crop_min_fraction must be in (0, 1], got {crop_min_fraction}")
        self.crop_min_fraction = crop_min_fraction
        mine = [i for i in range(len(clips)) if i % world_size == rank and clips[i].shape[0] >= min_frames]
        if not mine:
            raise ValueError("no training clips long enough for this rank")
        self.clips, self.caption_ranges = clips, caption_ranges
        self.layout, self.stats = layout, stats
        self.batch_size, self.max_frames, self.min_frames = batch_size, max_frames, min_frames
        self.text_dropout = text_dropout
        self.random_heading = random_heading
        # buckets by usable length (clips longer than max_frames are cropped anyway)
        usable = sorted(mine, key=lambda i: min(clips[i].shape[0], max_frames))
        n = max(1, min(num_buckets, len(usable)))
        size = math.ceil(len(usable) / n)
        self.buckets = [usable[k : k + size] for k in range(0, len(usable), size)]
        # Without weights a clip is drawn uniformly within its bucket and a bucket by its frames, so every
        # frame is seen about equally often; ``clip_weights`` (one per clip) scale both draws.
        self.clip_weights = None if clip_weights is None else torch.as_tensor(clip_weights, dtype=torch.float64)
        if self.clip_weights is not None and (self.clip_weights.shape != (len(clips),) or
                                              not bool((self.clip_weights > 0).all())):
            raise ValueError(f"clip_weights must hold one positive weight per clip ({len(clips)})")
        w = self.clip_weights if self.clip_weights is not None else torch.ones(len(clips), dtype=torch.float64)
        frames = torch.tensor([float(sum(w[i] * min(clips[i].shape[0], max_frames) for i in b)) for b in self.buckets])
        self.bucket_probs = frames / frames.sum()

    def sample(self, g: torch.Generator) -> Batch:
        """One batch drawn with generator ``g``."""
        bucket = self.buckets[int(torch.multinomial(self.bucket_probs, 1, generator=g))]
        if self.clip_weights is None:
            picks = torch.randint(len(bucket), (self.batch_size,), generator=g)
        else:
            picks = torch.multinomial(self.clip_weights[bucket], self.batch_size, replacement=True, generator=g)
        idx = [bucket[int(k)] for k in picks]
        longest = min(self.max_frames, max(self.clips[i].shape[0] for i in idx))
        # window length: uniform in [crop_min_fraction * longest, longest]; short windows of long clips
        # decouple a clip's speed from its length (room-limited runs: slow ones are the long ones)
        shortest = max(self.min_frames, int(longest * self.crop_min_fraction))
        target = int(torch.randint(min(shortest, longest), longest + 1, (1,), generator=g))
        lengths = [min(target, self.clips[i].shape[0]) for i in idx]
        T = max(lengths)
        raw = torch.zeros(self.batch_size, T, self.layout.dim)
        for b, (i, n) in enumerate(zip(idx, lengths, strict=True)):
            clip = self.clips[i]
            start = int(torch.randint(0, clip.shape[0] - n + 1, (1,), generator=g))
            raw[b, :n] = clip[start : start + n]
            raw[b, n:] = raw[b, n - 1]  # repeat the last frame: padding stays finite and in range
        angles = (torch.rand(self.batch_size, generator=g) * 2 - 1) * math.pi
        raw = canonicalize_start(raw, self.layout, angles if self.random_heading else None)
        heading = self.layout.slices["heading"]
        c_dir = raw[:, 0, heading]
        caption_index = torch.tensor(
            [lo + int(torch.randint(0, hi - lo, (1,), generator=g)) for lo, hi in (self.caption_ranges[i] for i in idx)]
        )
        text_keep = torch.rand(self.batch_size, generator=g) >= self.text_dropout
        lengths_t = torch.tensor(lengths)
        return Batch(
            features=self.stats.normalize(raw),
            raw_features=raw,
            pad_mask=torch.arange(T)[None, :] < lengths_t[:, None],
            lengths=lengths_t,
            c_dir=c_dir,
            caption_index=caption_index,
            text_keep=text_keep,
            clip_index=torch.tensor(idx),
        )
