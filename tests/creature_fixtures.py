"""Shared fixtures of the any-rig tests: a synthetic multi-rig motion cache (three shapes under three
names each) and a tiny any-rig model trained on it for a few steps (``anyrig-tiny``, hash text encoder).
Import them into a test module: ``from creature_fixtures import creature_cache, trained``."""

from __future__ import annotations

from pathlib import Path

import pytest
from rig_fixtures import fish, hexapod, quadruped, walking

from kinema.anyrig.pipeline import AnyRigModel
from kinema.data.multirig_build import Description, assemble, write_build
from kinema.data.sources import SourceFile
from kinema.model.anyrig.config import get_anyrig_config
from kinema.model.anyrig.loading import load_anyrig
from kinema.skeleton import Skeleton
from kinema.text import get_text_encoder
from kinema.train.anyrig.trainer import AnyRigTrainConfig, AnyRigTrainer


def _variant(skel: Skeleton, k: int) -> Skeleton:
    """The same shape under other joint names: a new rig for the build (rigs are keyed by topology)."""
    return Skeleton([f"{n}{k}" for n in skel.names], skel.parents, skel.offsets * (1 + 0.1 * k), name=f"{skel.name}{k}")


@pytest.fixture(scope="module")
def creature_cache(tmp_path_factory) -> Path:
    files = []
    for k in range(3):
        for skel in (quadruped(), fish(), hexapod()):
            s = _variant(skel, k)
            clips = {"walk": walking(s, frames=24, speed=0.0), "sway": walking(s, frames=12, speed=0.0)}
            files.append(SourceFile(Path(f"{s.name}.bvh"), f"{s.name}.bvh", "bvh", clips))

    def describe(f, name, motion, travel):
        return Description([f"A {f.rel.split('.')[0]} does a {name}."])

    out = tmp_path_factory.mktemp("creatures") / "cache"
    write_build(out, assemble(files, 20.0, describe), {"dataset": "synthetic"})
    return out


@pytest.fixture(scope="module")
def trained(creature_cache, tmp_path_factory) -> Path:
    run = tmp_path_factory.mktemp("run")
    cfg = get_anyrig_config("anyrig-tiny", text_dim=32)
    tc = AnyRigTrainConfig(steps=4, ckpt_every=2, log_every=2, variants=1, text_encoder="hash-test-32", warmup=2)
    trainer = AnyRigTrainer(cfg, tc, creature_cache, run, text_cache=None, log=lambda s: None)
    trainer.run()
    return run


def tiny_model(run: Path) -> AnyRigModel:
    """The any-rig model of a run folder with the tests' hash text encoder."""
    return AnyRigModel(load_anyrig(run), get_text_encoder("hash-test-32"))
