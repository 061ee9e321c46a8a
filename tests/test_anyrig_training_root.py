"""Any-rig training's root row (issue 34): rates clamped to the motions' own spread, and a loss weight."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import creature_fixtures
import pytest
import torch
from rig_fixtures import quadruped, walking

from kinema.model.anyrig.config import get_anyrig_config
from kinema.representation.joint import ROOT_FORWARD, ROOT_HEADING_RATE, ROOT_LATERAL
from kinema.rig import Rig
from kinema.train.anyrig.data import ROOT_RATES, clamp_root_rates, make_clip
from kinema.train.anyrig.trainer import AnyRigTrainConfig, AnyRigTrainer

creature_cache = creature_fixtures.creature_cache  # module-scoped fixture


def _clips(n: int = 20):
    skel = quadruped()
    rig, cfg = Rig.from_skeleton(skel), get_anyrig_config("anyrig-tiny", text_dim=32)
    out = []
    for k in range(n):
        m = walking(skel, frames=40, speed=0.05 * k)
        out.append(make_clip(m, rig, cfg, ["A quadruped walks."], "q"))
    return out, rig.root


def test_a_heading_flip_is_clamped_and_the_walks_are_not() -> None:
    clips, root = _clips()
    flip = clips[3].features[:, root]
    flip[17, ROOT_HEADING_RATE] = math.pi * 20.0  # half a turn in one frame at 20 fps, as a rolling body
    flip[17, ROOT_LATERAL] = 9.0
    before = [c.features.clone() for c in clips]
    spread = torch.cat([c.features[:, root, ROOT_HEADING_RATE] for c in clips]).std()
    bounds = clamp_root_rates(clips, tail=0.005)
    assert bounds.shape == (len(ROOT_RATES), 2) and bool((bounds[:, 0] <= bounds[:, 1]).all())
    rate = ROOT_RATES.index(ROOT_HEADING_RATE)
    assert float(clips[3].features[17, root, ROOT_HEADING_RATE]) == pytest.approx(float(bounds[rate, 1]))
    assert float(bounds[rate, 1]) < 5.0  # the flip does not set its own bound
    after = torch.cat([c.features[:, root, ROOT_HEADING_RATE] for c in clips]).std()
    assert float(after) < 0.2 * float(spread)
    # every other joint row and the root's height are untouched; the walks' forward speeds keep their spread
    for b, c in zip(before, clips, strict=True):
        keep = torch.ones(c.features.shape[1:], dtype=torch.bool)
        keep[root, list(ROOT_RATES)] = False
        assert torch.equal(b[:, keep], c.features[:, keep])
    fwd = [float(c.features[:, root, ROOT_FORWARD].mean()) for c in clips]
    fwd_before = [float(b[:, root, ROOT_FORWARD].mean()) for b in before]
    assert fwd[-1] - fwd[1] > 0.5 * (fwd_before[-1] - fwd_before[1])


class _Still(torch.nn.Module):
    """A 'denoiser' that predicts zeros: the loss is then the mean square of the normalised targets."""

    def __init__(self, model) -> None:
        super().__init__()
        self.inner = model

    def normalize(self, x, codes):
        return self.inner.normalize(x, codes)

    def forward(self, x_t, *args):
        return torch.zeros_like(x_t)


def test_root_weight_counts_the_root_row_that_many_times(creature_cache, tmp_path) -> None:
    cfg = get_anyrig_config("anyrig-tiny", text_dim=32)
    losses = {}
    for w in (1.0, 10.0):
        tc = AnyRigTrainConfig(steps=1, variants=0, text_encoder="hash-test-32", warmup=1, root_weight=w)
        tr = AnyRigTrainer(cfg, tc, creature_cache, tmp_path / f"w{w}", text_cache=None, log=lambda s: None)
        batch = tr.clips.sample_batch(torch.Generator().manual_seed(0), 256)
        x0 = tr.model.normalize(batch.x, batch.codes)
        real = (batch.frame_mask[:, :, None, None] & batch.channel_mask[:, None]).float()
        is_root = (batch.codes.flags[..., 0] > 0.5).float()[:, None, :, None] * real
        sq = x0**2 * real
        root_sq, body_sq = float((sq * is_root).sum()), float((sq * (real - is_root)).sum())
        n_root, n_body = float(is_root.sum()), float((real - is_root).sum())
        want = (w * root_sq + body_sq) / (w * n_root + n_body)
        got = float(tr.loss(_Still(tr.model), batch, torch.Generator().manual_seed(1)))
        assert got == pytest.approx(want, rel=1e-5)
        losses[w] = got
    assert losses[1.0] != pytest.approx(losses[10.0], rel=1e-3)


def test_the_seed_fixes_the_initial_weights(creature_cache, tmp_path) -> None:
    """The initial weights come from the run's seed, not from whatever the process drew before (a test
    run's earlier tests changed them, and with them a tiny model's outputs)."""
    cfg = get_anyrig_config("anyrig-tiny", text_dim=32)
    tc = AnyRigTrainConfig(steps=1, variants=0, text_encoder="hash-test-32", warmup=1)
    first = AnyRigTrainer(cfg, tc, creature_cache, tmp_path / "a", text_cache=None, log=lambda s: None)
    torch.rand(1000)  # the process's random state moves on
    again = AnyRigTrainer(cfg, tc, creature_cache, tmp_path / "b", text_cache=None, log=lambda s: None)
    for k, v in first.model.state_dict().items():
        assert torch.equal(v, again.model.state_dict()[k]), k
    other = AnyRigTrainer(cfg, replace(tc, seed=1), creature_cache, tmp_path / "c", text_cache=None, log=lambda s: None)
    assert any(not torch.equal(a, b) for a, b in zip(first.model.parameters(), other.model.parameters(), strict=True))


def test_an_on_the_spot_walk_of_unknown_travel_teaches_no_ground_velocity(tmp_path) -> None:
    """A locomotion clip the build could not give travel to (flag ``in_place``: no feet, a swim) does go
    somewhere: its still root is neither a target nor a constraint (body or root stage) under any caption,
    "in place" too; a clip whose travel was read keeps it under every caption."""
    from kinema.data.multirig_build import Description, assemble, write_build
    from kinema.data.sources import SourceFile
    from kinema.train.anyrig.data import GROUND_VELOCITY, AnyRigClips

    skel = quadruped()
    files = [SourceFile(Path("spot.bvh"), "spot.bvh", "bvh", {"walk": walking(skel, frames=24, speed=0.0)}),
             SourceFile(Path("read.bvh"), "read.bvh", "bvh", {"walk": walking(skel, frames=24, speed=0.05)})]

    def describe(f, name, motion, travel):
        noun = f.rel[:-4]
        if noun == "read":
            return Description([f"A {noun} walks.", f"The {noun} walks."])
        return Description([f"A {noun} walks.", f"A {noun} walks in place."], flags=["in_place"])

    write_build(tmp_path / "cache", assemble(files, 20.0, describe), {"dataset": "synthetic"})
    cfg = get_anyrig_config("anyrig-tiny", text_dim=32)
    clips = AnyRigClips(tmp_path / "cache", cfg, split="all", variants=1, log=lambda s: None)
    root = Rig.from_skeleton(skel).root
    seen = set()
    batch = clips.window_batch(clips.clips * 20, torch.Generator().manual_seed(0))
    for b, caption in enumerate(batch.captions):
        given = bool(batch.channel_mask[b, root, list(GROUND_VELOCITY)].all())
        assert given is caption.startswith(("A read", "The read")), caption
        assert not batch.channel_mask[b, root, list(GROUND_VELOCITY)].any() or given
        assert bool(batch.channel_mask[b, root, ROOT_HEADING_RATE])
        seen.add((caption, given))
    assert len(seen) == 4  # every caption of both clips (augmented copies too) was drawn


def test_the_loss_ignores_the_ground_velocity_of_an_unknown_travel_clip(creature_cache, tmp_path) -> None:
    cfg = get_anyrig_config("anyrig-tiny", text_dim=32)
    tc = AnyRigTrainConfig(steps=1, variants=0, text_encoder="hash-test-32", warmup=1)
    tr = AnyRigTrainer(cfg, tc, creature_cache, tmp_path / "r", text_cache=None, log=lambda s: None)
    skel = quadruped()
    rig = Rig.from_skeleton(skel)
    caption = tr.clips.clips[0].captions[:1]
    losses = {}
    for known in (True, False):
        for speed in (0.0, 0.3):
            clip = make_clip(walking(skel, frames=40, speed=0.0), rig, cfg, caption, "q", known)
            clip.features[:, rig.root, ROOT_FORWARD] = speed
            batch = tr.clips.window_batch([clip] * 4, torch.Generator().manual_seed(0))
            losses[known, speed] = tr.loss(tr.model, batch, torch.Generator().manual_seed(1)).item()
    assert losses[False, 0.0] == losses[False, 0.3]
    assert losses[True, 0.0] != pytest.approx(losses[True, 0.3], rel=1e-4)
