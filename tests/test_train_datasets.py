"""Training on some datasets of a build only (`kinema train --datasets`, TrainConfig.datasets)."""

from __future__ import annotations

import pytest

from kinema.data.dataset import MotionDataset
from kinema.errors import DataError
from kinema.train.trainer import TrainConfig, Trainer


def _cfg(**kw) -> TrainConfig:
    base = dict(model="tiny", steps=2, batch_size=4, lr=1e-3, warmup=1, text_encoder="hash-test-32", log_every=1,
                ckpt_every=1000, max_seconds=4.0, phase1_fraction=0.0, seed=5)
    base.update(kw)
    return TrainConfig(**base)


def test_a_run_on_one_dataset_draws_only_its_clips(tiny_data, tmp_path):
    ds = MotionDataset(tiny_data, "train")
    names = sorted({rec["dataset"] for rec in ds.clips})
    assert len(names) > 1  # so that keeping one leaves clips out
    name = names[0]
    trainer = Trainer(_cfg(datasets=[name]), tiny_data, tmp_path / "run")
    kept = trainer.dataset.clips
    assert kept and all(rec["dataset"] == name for rec in kept)
    assert len(kept) == sum(rec["dataset"] == name for rec in ds.clips)
    assert len(trainer.batches.clips) == len(kept)  # the batches come from those clips only
    trainer.run(progress=False)


def test_an_unknown_dataset_is_a_one_line_error(tiny_data, tmp_path):
    with pytest.raises(DataError, match=r"clips.json: no train clip comes from dataset 'bandai-nam' \(it has "):
        Trainer(_cfg(datasets=["bandai-nam"]), tiny_data, tmp_path / "run")
