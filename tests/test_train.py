"""Training: loss goes down, overfitting one clip reproduces it through DDIM, exact resume, DDP."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from kinema.human.sampling import SampleSettings, SampleTargets, sample_features
from kinema.model.loading import load_denoiser
from kinema.representation.kimodo_features import features_to_motion
from kinema.representation.transform import canonicalize_start
from kinema.train.trainer import TrainConfig, Trainer


def _cfg(**kw) -> TrainConfig:
    base = dict(model="tiny", steps=40, batch_size=4, lr=1e-3, warmup=5, text_encoder="hash-test-32",
                log_every=5, ckpt_every=1000, max_seconds=4.0)
    base.update(kw)
    return TrainConfig(**base)


def _single_clip_data(tiny_data: Path, tmp_path: Path, frames: int = 40) -> Path:
    """A copy of the dataset whose train split is one short clip (everything else moved to test)."""
    import shutil

    out = tmp_path / "one"
    shutil.copytree(tiny_data, out)
    clips = json.loads((out / "clips.json").read_text())
    first = next(i for i, c in enumerate(clips) if c["split"] == "train" and c["length"] >= frames)
    for i, c in enumerate(clips):
        c["split"] = "train" if i == first else "test"
    clips[first]["length"] = frames
    (out / "clips.json").write_text(json.dumps(clips))
    return out


def _fixed_batches_loss(trainer: Trainer, n: int = 8) -> float:
    """The phase-1 training loss of ``trainer.model`` (no dropout, no update) averaged over ``n`` fixed
    batches, timesteps and noises. Unlike the logged per-step losses, which vary threefold from one
    random batch to the next, the same number before and after training measures what was learned."""
    from kinema.train.losses import motion_loss

    model, losses = trainer.model, []
    model.eval()
    with torch.no_grad():
        for i in range(n):
            g = torch.Generator().manual_seed(1000 + i)
            batch = trainer.batches.sample(g)
            x0 = batch.features
            t = trainer.schedule.sample_timesteps(x0.shape[0], g)
            x_t = trainer.schedule.q_sample(x0, t, torch.randn(x0.shape, generator=g))
            pred = model(x_t, t, trainer.text_table[batch.caption_index], batch.text_keep, batch.c_dir, x0,
                         torch.zeros_like(x0), batch.pad_mask)
            loss, _ = motion_loss(pred, x0, batch.pad_mask, trainer.layout, trainer.skeleton, trainer.stats,
                                  trainer.weights)
            losses.append(float(loss))
    model.train()
    return sum(losses) / n


def test_loss_drops_when_overfitting_a_few_clips(tiny_data, tmp_path):
    trainer = Trainer(_cfg(steps=60, phase1_fraction=1.0), tiny_data, tmp_path / "run")
    before = _fixed_batches_loss(trainer)
    trainer.run(progress=False)
    after = _fixed_batches_loss(trainer)
    # measured: about 0.47 of the start on the real clips, 0.56-0.65 on the synthetic ones (seeds 0-3)
    assert after < 0.75 * before, (before, after)
    log = [json.loads(line) for line in (tmp_path / "run" / "log.jsonl").read_text().splitlines()]
    assert len(log) == 12 and all(torch.isfinite(torch.tensor(r["loss"])) for r in log)


def test_overfit_one_clip_reproduces_it_through_ddim(tiny_data, tmp_path):
    data = _single_clip_data(tiny_data, tmp_path)
    cfg = _cfg(steps=400, batch_size=8, lr=2e-3, warmup=20, text_dropout=0.0, phase1_fraction=1.0,
               max_seconds=2.0, ema_decay=0.9, ema_every=1, phase1_dropout=0.0,
               random_heading=False)
    trainer = Trainer(cfg, data, tmp_path / "run")
    trainer.batches.min_frames = 40  # always the whole clip: the target is unambiguous
    trainer.run(progress=False)
    loaded = load_denoiser(tmp_path / "run")
    gt = canonicalize_start(trainer.batches.clips[0][None], trainer.layout)[0]
    text = trainer.text_table[:1]
    settings = SampleSettings(40, loaded.guidance.__class__(mode="none"), steps=20)
    out = sample_features(loaded, text, SampleTargets(gt[None, 0, 3:5]), settings,
                          generator=torch.Generator().manual_seed(0))
    pos = features_to_motion(out[0], loaded.skeleton, loaded.fps).positions
    ref = features_to_motion(gt, loaded.skeleton, loaded.fps).positions
    err = (pos - ref).norm(dim=-1).mean().item()
    assert err < 0.05, f"mean joint error {err * 100:.1f} cm"


@pytest.fixture
def one_thread():
    """One torch thread: with two, a reduction's order follows how busy the cores are, and the last bits of
    a result with it (a resumed run then differed from the straight one on a loaded machine)."""
    n = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(n)


def test_checkpoint_resume_is_exact(tiny_data, tmp_path, one_thread):
    straight = Trainer(_cfg(steps=10, ckpt_every=5, phase1_fraction=0.5), tiny_data, tmp_path / "a")
    straight.run(progress=False)
    first = Trainer(_cfg(steps=10, ckpt_every=5, phase1_fraction=0.5), tiny_data, tmp_path / "b")
    first.run(progress=False, stop_after=5)
    resumed = Trainer(_cfg(steps=10, ckpt_every=5, phase1_fraction=0.5), tiny_data, tmp_path / "b")
    assert resumed.resume() and resumed.step == 5
    resumed.run(progress=False)
    for (name, p), q in zip(straight.model.state_dict().items(), resumed.model.state_dict().values(), strict=True):
        assert torch.equal(p, q), name
    for p, q in zip(straight.ema.state_dict().values(), resumed.ema.state_dict().values(), strict=True):
        assert torch.equal(p, q)


def test_interrupted_save_keeps_previous_checkpoint(tiny_data, tmp_path, monkeypatch):
    trainer = Trainer(_cfg(steps=4, ckpt_every=2), tiny_data, tmp_path / "run")
    trainer.run(progress=False, stop_after=2)
    import kinema.train.checkpoint as ck

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(ck, "save_file", boom)
    with pytest.raises(KeyboardInterrupt):
        trainer.run(progress=False)
    monkeypatch.undo()
    again = Trainer(_cfg(steps=4, ckpt_every=2), tiny_data, tmp_path / "run")
    assert again.resume() and again.step == 2
    assert not [p for p in (tmp_path / "run").iterdir() if p.name.startswith(".")]


def test_two_process_gloo_run(tiny_data, tmp_path):
    env = dict(os.environ, OMP_NUM_THREADS="1")
    cmd = [sys.executable, "-m", "torch.distributed.run", "--nproc_per_node", "2", "--master_port", "29533",
           "-m", "kinema", "train", "--config", "tiny", "--data", str(tiny_data), "--out", str(tmp_path / "ddp"),
           "--steps", "4", "--batch-size", "2", "--ckpt-every", "2", "--text-encoder", "hash-test-32",
           "--no-progress"]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    info = json.loads((tmp_path / "ddp" / "ckpt-00000004" / "checkpoint.json").read_text())
    assert info["world_size"] == 2 and info["step"] == 4
    assert (tmp_path / "ddp" / "log.jsonl").exists()


def test_cli_resume_may_change_the_schedule_but_nothing_else(tiny_data, tmp_path, capsys):
    from kinema.cli import main

    out = tmp_path / "run"
    base = ["train", "--config", "tiny", "--data", str(tiny_data), "--out", str(out), "--batch-size", "2",
            "--text-encoder", "hash-test-32", "--no-progress"]
    assert main([*base, "--steps", "4", "--ckpt-every", "2", "--phase1-fraction", "0.5"]) == 0
    resumed = ["train", "--data", str(tiny_data), "--out", str(out), "--resume", "--no-progress"]
    assert main([*resumed, "--steps", "6", "--phase1-fraction", "0.25", "--content-balance", "0.5"]) == 0
    saved = json.loads((out / "train_config.json").read_text())
    assert (saved["steps"], saved["phase1_fraction"], saved["model"]) == (6, 0.25, "tiny")
    assert saved["content_balance"] == 0.5
    info = json.loads((out / "ckpt-00000006" / "checkpoint.json").read_text())
    assert info["step"] == 6 and info["phase"] == 2
    capsys.readouterr()
    assert main([*resumed, "--steps", "8", "--lr", "0.5"]) == 2
    err = capsys.readouterr().err
    assert "--resume keeps the run's settings" in err and "'lr'" in err


def test_content_balance_weights_rare_contents_up():
    from kinema.train.trainer import content_weights

    recs = [{"content": "walk"}] * 9 + [{"content": "bow"}, {"clip_id": "unlabelled"}]
    assert content_weights(recs, 0.0) is None
    w = content_weights(recs, 0.5)
    assert w[0] == pytest.approx(1 / 3) and w[9] == 1.0 and w[10] == 1.0
    w1 = content_weights(recs, 1.0)
    assert sum(w1[:9]) == pytest.approx(w1[9])  # power 1: every content gets the same total weight
    with pytest.raises(Exception, match="content_balance"):
        content_weights(recs, -1.0)


def test_content_weight_scales_named_contents_after_balancing():
    from kinema.train.trainer import content_weights

    recs = [{"content": "walk"}] * 9 + [{"content": "punch-left"}] * 2 + [{"content": "punch-right"}] * 2
    w = content_weights(recs, 1.0, {"punch-left": 5.0, "punch-right": 5.0})
    assert sum(w[:9]) == pytest.approx(1.0) and sum(w[9:11]) == pytest.approx(5.0) and sum(w[11:]) == pytest.approx(5.0)
    # one content per source clip (the relabelling it replaces) gives the same weights
    relabelled = [{"content": "walk"}] * 9 + [{"content": f"punch-{i}"} for i in range(4)]
    assert content_weights(relabelled, 1.0) == content_weights(recs, 1.0, {"punch-left": 2.0, "punch-right": 2.0})
    assert content_weights(recs, 0.0, {"walk": 2.0})[:10] == [2.0] * 9 + [1.0]
    with pytest.raises(Exception, match="no clip of the training clips has the content 'kick'"):
        content_weights(recs, 1.0, {"kick": 2.0})
    with pytest.raises(Exception, match="must be a finite number > 0"):
        content_weights(recs, 1.0, {"walk": 0.0})


def test_trainer_names_the_build_of_an_unknown_content_weight(tiny_data, tmp_path):
    from kinema.errors import KinemaError

    with pytest.raises(KinemaError, match=r"clips\.json \(train split\) has the content 'punch-left'"):
        Trainer(_cfg(steps=2, content_weight={"punch-left": 5.0}), tiny_data, tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_cli_content_weight_reads_content_equals_factor():
    from kinema.cli.train import _content_factor

    assert _content_factor("punch-left=5") == ("punch-left", 5.0)
    assert _content_factor("pick-up=0.5") == ("pick-up", 0.5)
    for bad in ("punch-left", "=5", "punch-left=lots"):
        with pytest.raises(argparse.ArgumentTypeError, match="CONTENT=X"):
            _content_factor(bad)


def test_batch_sampler_draws_clips_in_proportion_to_their_weights():
    from kinema.representation.layout import FeatureLayout
    from kinema.representation.stats import NormStats
    from kinema.train.batching import BatchSampler

    layout = FeatureLayout(3)
    clips = [torch.full((20, layout.dim), float(k)) for k in range(4)]  # clip k is filled with k
    stats = NormStats(torch.zeros(layout.dim), torch.ones(layout.dim))
    kw = dict(num_buckets=1, text_dropout=0.0, random_heading=False)
    ranges = [(k, k + 1) for k in range(4)]
    weighted = BatchSampler(clips, ranges, layout, stats, 64, 20, clip_weights=[1.0, 1.0, 1.0, 5.0], **kw)
    g = torch.Generator().manual_seed(0)
    picks = torch.cat([weighted.sample(g).caption_index for _ in range(40)])
    share = float((picks == 3).double().mean())
    assert abs(share - 5 / 8) < 0.03, share
    uniform = BatchSampler(clips, ranges, layout, stats, 64, 20, **kw)
    picks = torch.cat([uniform.sample(g).caption_index for _ in range(40)])
    assert abs(float((picks == 3).double().mean()) - 0.25) < 0.03
    with pytest.raises(ValueError, match="one positive weight per clip"):
        BatchSampler(clips, ranges, layout, stats, 8, 20, clip_weights=[1.0, 0.0, 1.0, 1.0], **kw)


def test_crop_min_fraction_sets_the_shortest_training_window(tiny_data, tmp_path):
    from kinema.errors import KinemaError
    from kinema.representation.layout import FeatureLayout
    from kinema.representation.stats import NormStats
    from kinema.train.batching import BatchSampler

    layout = FeatureLayout(3)
    clips = [torch.zeros(100, layout.dim)]
    stats = NormStats(torch.zeros(layout.dim), torch.ones(layout.dim))
    kw = dict(num_buckets=1, text_dropout=0.0, random_heading=False)

    def lengths(frac: float) -> set[int]:
        s = BatchSampler(clips, [(0, 1)], layout, stats, 2, 100, crop_min_fraction=frac, **kw)
        g = torch.Generator().manual_seed(0)
        return {int(s.sample(g).lengths[0]) for _ in range(300)}

    half, fifth = lengths(0.5), lengths(0.2)
    assert min(half) == 50 and max(half) == 100  # the default: windows of half the clip or longer
    assert min(fifth) < 25 and min(fifth) >= 20 and max(fifth) == 100
    assert lengths(1.0) == {100}
    with pytest.raises(ValueError, match="crop_min_fraction"):
        BatchSampler(clips, [(0, 1)], layout, stats, 2, 100, crop_min_fraction=0.0, **kw)
    assert Trainer(_cfg(crop_min_fraction=0.25, steps=2), tiny_data, tmp_path / "r").batches.crop_min_fraction == 0.25
    with pytest.raises(KinemaError, match="crop_min_fraction"):
        Trainer(_cfg(crop_min_fraction=1.5), tiny_data, tmp_path / "bad")


def test_fine_tune_starts_from_the_given_weights(tiny_data, tmp_path):
    Trainer(_cfg(steps=6), tiny_data, tmp_path / "base").run(progress=False)
    base = load_denoiser(tmp_path / "base")  # EMA weights, float32
    ft = Trainer(_cfg(steps=4, seed=3, phase1_fraction=0.0, init_from=str(tmp_path / "base")), tiny_data,
                 tmp_path / "ft")
    assert ft.init_weights(ft.cfg.init_from).name == "ckpt-00000006"
    for (name, p), q, e in zip(base.denoiser.state_dict().items(), ft.model.state_dict().values(),
                               ft.ema.state_dict().values(), strict=True):
        assert torch.equal(p, q) and torch.equal(p, e), name
    assert ft.step == 0 and ft.keyframe_cap(0) == ft.cfg.max_keyframes  # its model already did the ramp
    ft.run(progress=False)
    info = json.loads((tmp_path / "ft" / "ckpt-00000004" / "checkpoint.json").read_text())
    assert info["train_config"]["init_from"] == str(tmp_path / "base") and info["phase"] == 2
    fresh = Trainer(_cfg(steps=4, phase1_fraction=0.0), tiny_data, tmp_path / "fresh")
    assert fresh.keyframe_cap(0) == 1  # a run from scratch ramps the keyframe count up


def test_a_resumed_fine_tune_keeps_its_starting_models_statistics(tiny_data, tmp_path):
    """A fine-tune trains in its starting model's normalisation; resumed, it must go on in it (it used to
    switch to the dataset's own statistics, while the weights' buffers kept the old ones)."""
    Trainer(_cfg(steps=2), tiny_data, tmp_path / "base").run(progress=False)
    info_path = tmp_path / "base" / "ckpt-00000002" / "checkpoint.json"
    info = json.loads(info_path.read_text())
    info["stats"]["std"] = [2.0 * x for x in info["stats"]["std"]]  # a model trained in other statistics
    info_path.write_text(json.dumps(info))
    cfg = dict(steps=4, seed=3, phase1_fraction=0.0, init_from=str(tmp_path / "base"), ckpt_every=2)
    ft = Trainer(_cfg(**cfg), tiny_data, tmp_path / "ft")
    ft.init_weights(ft.cfg.init_from)
    ft.run(progress=False, stop_after=2)
    again = Trainer(_cfg(**cfg), tiny_data, tmp_path / "ft")
    assert not torch.equal(again.stats.std, ft.stats.std)  # a new Trainer starts in the dataset's
    assert again.resume() and again.step == 2
    assert torch.equal(again.stats.std, ft.stats.std) and again.batches.stats is again.stats
    again.run(progress=False)
    saved = json.loads((tmp_path / "ft" / "ckpt-00000004" / "checkpoint.json").read_text())["stats"]["std"]
    assert saved == info["stats"]["std"]


def test_fine_tune_refuses_a_different_architecture(tiny_data, tmp_path, capsys):
    from kinema.cli import main

    Trainer(_cfg(steps=2), tiny_data, tmp_path / "base").run(progress=False)
    base = ["train", "--data", str(tiny_data), "--batch-size", "2", "--text-encoder", "hash-test-32",
            "--no-progress", "--steps", "2"]
    assert main([*base, "--config", "small", "--out", str(tmp_path / "ft"), "--init-from",
                 str(tmp_path / "base")]) == 2
    err = capsys.readouterr().err
    assert "cannot fine-tune from this model" in err and "model_config.width" in err
    assert main([*base, "--out", str(tmp_path / "ft2"), "--init-from", str(tmp_path / "nowhere")]) == 2
    assert "no such model folder" in capsys.readouterr().err


def test_foot_contact_weight_reaches_the_loss_and_is_checked(tiny_data, tmp_path):
    from kinema.errors import KinemaError

    trainer = Trainer(_cfg(foot_contact=0.5, steps=2), tiny_data, tmp_path / "run")
    assert trainer.weights.foot_contact == 0.5
    rec = trainer.train_step(trainer.model)
    assert rec["foot_contact"] >= 0 and "foot_contact" not in _plain_step_terms(tiny_data, tmp_path)
    with pytest.raises(KinemaError, match="foot_contact"):
        Trainer(_cfg(foot_contact=-1.0), tiny_data, tmp_path / "bad")


def _plain_step_terms(tiny_data, tmp_path) -> dict:
    """The logged terms of one step of the default configuration (no foot-contact term)."""
    trainer = Trainer(_cfg(steps=2), tiny_data, tmp_path / "plain")
    return trainer.train_step(trainer.model)
