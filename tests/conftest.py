"""Shared fixtures: the Bandai Namco data (real or synthetic), a tiny built dataset and a tiny trained checkpoint.

Tests that need motion data take ``bandai_root``: the shared Bandai Namco folder
(``../shared/datasets/bandai-namco`` from the repository) when it exists, otherwise a synthetic folder in
the same layout, written once per session by `kinema.data.synthetic` (under a second). So the data, training,
evaluation and generation tests run on any machine: from an installed wheel, or on CI without the shared
folder. Set ``KINEMA_SYNTHETIC_DATA=1`` to use the synthetic data even where the shared folder exists, to
check that the suite passes without it. The few tests that check facts of the real data (its size, its
split fractions) take ``real_bandai_root`` instead and skip without the real data.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

# One precision for the whole suite on every CPU: `auto` would run the denoisers in bf16 on a CPU with bf16
# instructions and in fp32 elsewhere (CI), so thresholds measured in fp32 would meet other numbers here.
# tests/test_precision.py tests bf16 and the `auto` choice explicitly (issue 37).
os.environ.setdefault("KINEMA_PRECISION", "fp32")

REPO = Path(__file__).resolve().parents[1]
SHARED_BANDAI = REPO.parent / "shared/datasets/bandai-namco"
#: The clip that several tests use (a straight 9 s walk; the synthetic data has one of the same name).
WALK_CLIP = "Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh.gz"


def force_synthetic() -> bool:
    """True when KINEMA_SYNTHETIC_DATA asks for the synthetic data (any value but "", 0, false, no)."""
    return os.environ.get("KINEMA_SYNTHETIC_DATA", "").strip().lower() not in ("", "0", "false", "no")


def have_real_bandai() -> bool:
    """Whether the tests use the shared Bandai Namco data (present and not overridden)."""
    return SHARED_BANDAI.is_dir() and not force_synthetic()


@pytest.fixture(scope="session")
def synthetic_bandai(tmp_path_factory) -> Path:
    """The synthetic dataset, written at ``<tmp>/shared/datasets/bandai-namco`` next to an empty
    ``<tmp>/main``, mirroring the repository's place next to the shared folder (see `bandai_workdir`)."""
    from kinema.data.synthetic import write_synthetic_bandai

    base = tmp_path_factory.mktemp("synthetic")
    (base / "main").mkdir()
    return write_synthetic_bandai(base / "shared/datasets/bandai-namco")


@pytest.fixture(scope="session")
def bandai_root(request) -> Path:
    """The real Bandai Namco folder when available (and not overridden), else the synthetic one."""
    if have_real_bandai():
        return SHARED_BANDAI
    return request.getfixturevalue("synthetic_bandai")


@pytest.fixture(scope="session")
def real_bandai_root() -> Path:
    """The real Bandai Namco folder, for tests of facts that only the real data has; skips without it."""
    if not have_real_bandai():
        pytest.skip("checks facts of the real Bandai Namco data, which is absent (or KINEMA_SYNTHETIC_DATA is set)")
    return SHARED_BANDAI


@pytest.fixture(scope="session")
def bandai_workdir(bandai_root) -> Path:
    """A folder from which ``../shared/datasets/bandai-namco`` is `bandai_root`: the repository for the real
    data. Examples (examples/constraints) name their BVH files that way, relative to the repository."""
    return REPO if bandai_root == SHARED_BANDAI else bandai_root.parents[2] / "main"


@pytest.fixture(scope="session")
def walk_clip(bandai_root) -> Path:
    """``dataset-2_walk_normal_001.bvh.gz``: a straight walk of about 9 s, 30 fps, centimetres."""
    return bandai_root / WALK_CLIP


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
    cfg = TrainConfig(
        model="tiny",
        steps=60,
        batch_size=8,
        lr=1e-3,
        warmup=5,
        text_encoder="hash-test-32",
        log_every=10,
        ckpt_every=1000,
        max_seconds=6.0,
        sampling_steps=10,
    )
    Trainer(cfg, tiny_data, run).run(progress=False)
    return run
