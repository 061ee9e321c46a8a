"""Shared fixtures: the shared Bandai Namco data, a tiny built dataset and a tiny trained checkpoint."""

from __future__ import annotations

from pathlib import Path

import pytest

BANDAI = Path(__file__).resolve().parents[2] / "shared/datasets/bandai-namco"


@pytest.fixture(scope="session")
def bandai_root() -> Path:
    if not BANDAI.exists():
        pytest.skip("shared Bandai Namco data not available")
    return BANDAI


@pytest.fixture(scope="session")
def tiny_data(bandai_root, tmp_path_factory) -> Path:
    """Six source clips (plus mirrors) at 20 fps, built with the real pipeline."""
    from kinema.data.build import build_dataset

    out = tmp_path_factory.mktemp("data") / "bandai6"
    build_dataset(bandai_root, out, fps=20, limit=6, workers=1, progress=False)
    return out


@pytest.fixture(scope="session")
def tiny_checkpoint(tiny_data, tmp_path_factory) -> Path:
    """A run folder with a tiny two-stage model trained briefly through both curriculum phases.

    Quality is irrelevant here: generation and post-processing tests need a real checkpoint with the
    real feature layout, skeleton, statistics and sampler settings."""
    from kinema.train.trainer import TrainConfig, Trainer

    run = tmp_path_factory.mktemp("runs") / "tiny"
    cfg = TrainConfig(model="tiny", steps=60, batch_size=8, lr=1e-3, warmup=5, text_encoder="hash-test-32",
                      log_every=10, ckpt_every=1000, max_seconds=6.0, sampling_steps=10)
    Trainer(cfg, tiny_data, run).run(progress=False)
    return run
