"""Training data of the any-rig model: per-joint features of many rigs, bucketed by joint count.

`AnyRigClips` reads a multi-rig build or manifest (kinema.data.multirig), computes each clip's
per-joint features ``(T, J, 13)`` on its rig (and on ``variants`` rig-augmented copies,
kinema.train.anyrig.augment), the rig's skeleton codes, and its captions. `sample_batch` draws a
batch from one joint-count bucket (so a 6-joint fish does not pay for a 48-joint fox): batch size
``token_budget // J_max`` of the bucket, windows of ``window`` frames -- a random crop of a longer
clip, a looping clip tiled, any other shorter clip padded with a frame mask -- and a random heading.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import torch

from kinema.data.multirig import MultiRigData
from kinema.errors import DataError
from kinema.model.anyrig.config import AnyRigConfig
from kinema.model.skeleton_codes import CodeBatch, SkeletonCodes, batch_codes, skeleton_codes
from kinema.representation.joint import (
    NUM_CHANNELS,
    POS,
    ROOT_FORWARD,
    ROOT_HEADING,
    ROOT_HEADING_RATE,
    ROOT_LATERAL,
    JointRepresentation,
)
from kinema.rig import Rig
from kinema.rig.ties import find_ties
from kinema.train.anyrig.augment import augment

#: joint-count buckets (upper bounds, inclusive)
BUCKETS = (8, 16, 32, 64)
#: a clip whose last frame is this close to its first (rig units, root-relative positions) loops
LOOP_TOL = 0.05
#: the root row's rates (ground velocity, heading rate) are clamped to their quantiles at this share and
#: 1 - this share of all training frames (see `clamp_root_rates`)
ROOT_RATE_TAIL = 0.005
ROOT_RATES = (ROOT_LATERAL, ROOT_FORWARD, ROOT_HEADING_RATE)
#: the root row's ground velocity, unknown on a clip flagged ``TRAVEL_UNKNOWN``
GROUND_VELOCITY = (ROOT_LATERAL, ROOT_FORWARD)
#: build flag of a locomotion clip the source animates on the spot and whose travel the build could not
#: recover (kinema.data.quaternius: no feet, feet that are knees, a swim). Such a clip does travel, by how
#: much is unknown, so the root's ground velocity is not one of its real channels (neither learned as 0 nor
#: given as a constraint) under any of its captions, "in place" included: taught zero under the one
#: caption that says "runs in place.", the root stage carried the zero over to "walks." (card, stop 46).
TRAVEL_UNKNOWN = "in_place"


def travel_known(rec: dict) -> bool:
    """Whether the root travel of a build record's clip is real (see `TRAVEL_UNKNOWN`)."""
    return TRAVEL_UNKNOWN not in rec.get("flags", ())


@dataclass
class Clip:
    features: torch.Tensor  # (T, J, 13) float32, un-normalised
    channel_mask: torch.Tensor  # (J, 13) bool: the channels the clip teaches (`make_clip`)
    codes: SkeletonCodes
    captions: list[str]
    rig: str
    loops: bool
    content: str = ""  # the build's content name ("idle", "walk"); samplers may weight by it

    @property
    def num_joints(self) -> int:
        return self.features.shape[1]


@dataclass
class Batch:
    x: torch.Tensor  # (B, T, J, C) un-normalised
    frame_mask: torch.Tensor  # (B, T)
    channel_mask: torch.Tensor  # (B, J, C)
    codes: CodeBatch
    captions: list[str]


def _loops(f: torch.Tensor) -> bool:
    return f.shape[0] > 4 and float((f[0, :, POS] - f[-1, :, POS]).abs().max()) < LOOP_TOL


def make_clip(motion, rig: Rig, config: AnyRigConfig, captions: list[str], rig_id: str, travel: bool = True,
              content: str = "") -> Clip:
    """One clip's features and the channels it teaches: its real channels, without the root's ground
    velocity when its travel is unknown (``travel`` False, `travel_known`)."""
    rep = JointRepresentation(rig, motion.fps)
    f = rep.from_motion(motion).float()
    mask = rep.channel_mask
    if not travel:
        mask = mask.clone()
        mask[rig.root, list(GROUND_VELOCITY)] = False
    return Clip(f, mask, skeleton_codes(rig, config), list(captions), rig_id, _loops(f), content)


class AnyRigClips:
    """All clips of one split as features, with ``variants`` augmented copies each (see module)."""

    def __init__(
        self,
        path: str | Path,
        config: AnyRigConfig,
        *,
        split: str = "train",
        variants: int = 0,
        seed: int = 0,
        log=print,
    ) -> None:
        t0 = time.time()
        data = MultiRigData(path, split=split)
        if not len(data):
            raise DataError(f"{path}: no clips in split {split!r}")
        if any(abs(r["fps"] - config.fps) > 1e-6 for r in data.clips):
            raise DataError(f"{path}: clips are not all at the model's {config.fps:g} fps")
        gen = torch.Generator().manual_seed(seed)
        rigs: dict[str, Rig] = {}
        first: dict[str, str | None] = {}
        own: dict[str, list] = {}
        self.clips: list[Clip] = []
        for i, rec in enumerate(data.clips):
            m = data.motion(i)
            rig = rigs.setdefault(rec["rig"], Rig.from_skeleton(m.skeleton))
            if first.setdefault(rec["rig"], rec.get("skeleton")) == rec.get("skeleton"):
                own.setdefault(rec["rig"], []).append(m.global_transforms()[::-1])  # the stored skeleton's clips
            caps, known, content = rec["captions"], travel_known(rec), rec.get("content", "")
            self.clips.append(make_clip(m, rig, config, caps, rec["rig"], known, content))
            for _ in range(variants):
                a = augment(m, gen, keep=(*rig.contacts, rig.root))
                self.clips.append(make_clip(a, Rig.from_skeleton(a.skeleton), config, caps, rec["rig"], known, content))
        #: (channels of ROOT_RATES, 2): the low and high bound each root rate was clamped to
        self.root_bounds = clamp_root_rates(self.clips)
        self.config = config
        self.rigs = rigs
        #: rig id -> its joint ties (kinema.rig.ties) from the clips of the skeleton stored for it
        self.ties = {rid: find_ties(r.skeleton, r.root, own.get(rid, [])) for rid, r in rigs.items()}
        self.buckets = self._bucket()
        log(
            f"{len(data)} clips on {len(rigs)} rigs (+{variants} augmented copies each): "
            f"{sum(c.features.shape[0] for c in self.clips)} frames in {time.time() - t0:.0f} s"
        )

    def _bucket(self) -> dict[int, list[int]]:
        out: dict[int, list[int]] = {}
        for i, c in enumerate(self.clips):
            b = next(b for b in BUCKETS if c.num_joints <= b) if c.num_joints <= BUCKETS[-1] else c.num_joints
            out.setdefault(b, []).append(i)
        return out

    def stats(self) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and std ``(2, 13)`` (root row, other joints) over every channel the clips teach, every frame (an
        unknown travel is not a zero, `TRAVEL_UNKNOWN`); the heading's cos/sin get mean 0 and std sqrt(1/2),
        as training turns clips to random headings."""
        mean, std = torch.zeros(2, NUM_CHANNELS), torch.ones(2, NUM_CHANNELS)
        for row in (0, 1):
            xs, ms = [], []
            for c in self.clips:
                is_root = c.codes.flags[:, 0] > 0.5
                sel = is_root if row == 0 else ~is_root
                xs.append(c.features[:, sel].reshape(-1, NUM_CHANNELS).double())
                ms.append(c.channel_mask[sel].expand(c.features.shape[0], -1, -1).reshape(-1, 13))
            x, m = torch.cat(xs), torch.cat(ms).double()
            n = m.sum(0).clamp_min(1)
            mu = (x * m).sum(0) / n
            sd = (((x - mu) ** 2 * m).sum(0) / n).sqrt()
            mean[row], std[row] = mu.float(), sd.clamp_min(1e-2).float()
        mean[0, ROOT_HEADING], std[0, ROOT_HEADING] = 0.0, math.sqrt(0.5)
        return mean, std

    def sample_batch(self, gen: torch.Generator, token_budget: int) -> Batch:
        """One bucket (chosen in proportion to its frames), ``token_budget // J`` windows from it."""
        keys = sorted(self.buckets)
        weights = torch.tensor(
            [sum(self.clips[i].features.shape[0] for i in self.buckets[k]) for k in keys], dtype=torch.float64
        )
        k = keys[int(torch.multinomial(weights, 1, generator=gen))]
        idx = self.buckets[k]
        J = max(self.clips[i].num_joints for i in idx)
        B = max(2, token_budget // J)
        pick = [idx[int(j)] for j in torch.randint(len(idx), (B,), generator=gen)]
        return self.window_batch([self.clips[i] for i in pick], gen)

    def window_batch(self, clips: list[Clip], gen: torch.Generator) -> Batch:
        W = self.config.window
        B, J = len(clips), max(c.num_joints for c in clips)
        x = torch.zeros(B, W, J, 13)
        frame_mask = torch.zeros(B, W, dtype=torch.bool)
        channel_mask = torch.zeros(B, J, 13, dtype=torch.bool)
        captions = []
        for b, c in enumerate(clips):
            w = window(c, W, gen)
            x[b, : w.shape[0], : c.num_joints] = w
            frame_mask[b, : w.shape[0]] = True
            k = int(torch.randint(len(c.captions), (1,), generator=gen))
            channel_mask[b, : c.num_joints] = c.channel_mask
            captions.append(c.captions[k])
            root = int(c.codes.flags[:, 0].argmax())
            turn = float(torch.rand(1, generator=gen)) * 2 * math.pi
            x[b, :, root, ROOT_HEADING] = _turn(x[b, :, root, ROOT_HEADING], turn)
        x = x * frame_mask[:, :, None, None]
        return Batch(x, frame_mask, channel_mask, batch_codes([c.codes for c in clips], J), captions)


def clamp_root_rates(clips: list[Clip], tail: float = ROOT_RATE_TAIL) -> torch.Tensor:
    """Clamp every clip's root ground velocity and heading rate, in place, to the ``tail`` and ``1 - tail``
    quantiles over all frames of ``clips``; returns the bounds ``(len(ROOT_RATES), 2)``.

    A body that rolls over or falls has an ill-defined heading: the Quaternius deaths and rolls flip it by
    half a turn between two frames, a heading rate of 63 rad/s (and a lateral velocity of several body
    sizes a second). These 1 % of frames set the rates' standard deviation (heading rate 2.13 rad/s, while
    90 % of frames turn slower than 0.72), so the normalised rates of every walk and idle sat within 0.3
    of zero and the model's small errors there were tens of degrees a second of turning and a drifting idle
    (issue 34). Clamped, the rates' spread is that of the motions themselves."""
    rows = [c.features[:, int(c.codes.flags[:, 0].argmax())] for c in clips]
    every = torch.cat(rows)[:, list(ROOT_RATES)].double()
    q = torch.tensor([tail, 1.0 - tail], dtype=torch.float64)
    bounds = torch.stack([torch.quantile(every[:, k], q) for k in range(every.shape[1])]).float()
    for row in rows:  # views into each clip's features
        for k, ch in enumerate(ROOT_RATES):
            row[:, ch].clamp_(float(bounds[k, 0]), float(bounds[k, 1]))
    return bounds


def _turn(cs: torch.Tensor, delta: float) -> torch.Tensor:
    """(cos psi, sin psi) rows turned to psi + delta."""
    c, s = math.cos(delta), math.sin(delta)
    return torch.stack([cs[:, 0] * c - cs[:, 1] * s, cs[:, 1] * c + cs[:, 0] * s], dim=-1)


def window(c: Clip, W: int, gen: torch.Generator) -> torch.Tensor:
    """``W`` frames of a clip (see module); fewer (to be padded) for a short clip that does not loop."""
    f = c.features
    if f.shape[0] < W and c.loops:
        period = f[:-1]  # the last frame repeats the first
        f = period.repeat(math.ceil(W / period.shape[0]) + 1, 1, 1)
    if f.shape[0] <= W:
        return f
    s = int(torch.randint(f.shape[0] - W + 1, (1,), generator=gen))
    return f[s : s + W]
