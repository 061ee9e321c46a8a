"""Anchoring a fine-tune to a frozen teacher on the clips it already knows (kinema.train.anchor)."""

from __future__ import annotations

import json

import pytest
import torch

from kinema.errors import KinemaError
from kinema.train.anchor import anchored_clips
from kinema.train.trainer import TrainConfig, Trainer


def _cfg(**kw) -> TrainConfig:
    base = dict(model="tiny", steps=8, batch_size=4, lr=3e-3, warmup=1, text_encoder="hash-test-32", log_every=1,
                ckpt_every=1000, max_seconds=4.0, phase1_fraction=0.0, seed=5)
    base.update(kw)
    return TrainConfig(**base)


def _prediction_gap(trainer: Trainer, teacher) -> float:
    """Mean squared difference between the trainer's model and ``teacher`` on three fixed noisy batches."""
    gaps = []
    for seed in range(3):
        g = torch.Generator().manual_seed(100 + seed)
        batch = trainer.batches.sample(g)
        t = trainer.schedule.sample_timesteps(batch.features.shape[0], g)
        x_t = trainer.schedule.q_sample(batch.features, t, torch.randn(batch.features.shape, generator=g))
        inputs = [x_t, t, trainer.text_table[batch.caption_index], batch.text_keep, batch.c_dir, batch.features,
                  torch.zeros_like(batch.features), batch.pad_mask]
        with torch.no_grad():
            diff = trainer.model.eval()(*inputs) - teacher(*inputs)
        gaps.append(float(diff[batch.pad_mask].square().mean()))
    return sum(gaps) / len(gaps)


def test_anchored_clips_by_dataset():
    recs = [{"dataset": "dataset-1"}, {"dataset": "quaternius-humanoids"}, {"dataset": "dataset-2"}]
    assert anchored_clips(recs, ["dataset-1", "dataset-2"]).tolist() == [True, False, True]
    assert anchored_clips(recs, []).tolist() == [True, True, True]
    with pytest.raises(KinemaError, match="no train clip comes from bandai-namco"):
        anchored_clips(recs, ["bandai-namco"])


def test_the_anchor_keeps_a_fine_tune_near_its_teacher(tiny_data, tmp_path):
    """Same data, steps and seed from the same start: the anchored run's predictions end closer to the teacher's,
    its first step's term is 0 (the student starts as the teacher) and later ones are not, and the log has it."""
    Trainer(_cfg(steps=4), tiny_data, tmp_path / "base").run(progress=False)
    base = str(tmp_path / "base")
    free = Trainer(_cfg(init_from=base), tiny_data, tmp_path / "free")
    free.init_weights(base)
    free.run(progress=False)
    held = Trainer(_cfg(init_from=base, anchor=base, anchor_weight=1000.0), tiny_data, tmp_path / "held")
    held.init_weights(base)
    held.run(progress=False)
    teacher = held.anchor.teacher
    assert _prediction_gap(held, teacher) < 0.7 * _prediction_gap(free, teacher)  # 0.18 vs 0.42 here
    log = [json.loads(line) for line in (tmp_path / "held" / "log.jsonl").read_text().splitlines()]
    assert log[0]["anchor"] == pytest.approx(0.0, abs=1e-6) and max(r["anchor"] for r in log[1:]) > 0
    assert "anchor" not in json.loads((tmp_path / "free" / "log.jsonl").read_text().splitlines()[0])


def test_an_anchor_in_other_statistics_is_refused(tiny_data, tmp_path):
    Trainer(_cfg(steps=2), tiny_data, tmp_path / "base").run(progress=False)
    info_path = tmp_path / "base" / "ckpt-00000002" / "checkpoint.json"
    info = json.loads(info_path.read_text())
    info["stats"]["std"] = [2.0 * x for x in info["stats"]["std"]]
    info_path.write_text(json.dumps(info))
    run = Trainer(_cfg(anchor=str(tmp_path / "base")), tiny_data, tmp_path / "run")
    with pytest.raises(KinemaError, match="normalisation statistics differ"):
        run.run(progress=False)
    with pytest.raises(KinemaError, match="anchor weight"):
        Trainer(_cfg(anchor=str(tmp_path / "base"), anchor_weight=0.0), tiny_data, tmp_path / "zero")
