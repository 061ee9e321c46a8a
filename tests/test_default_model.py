"""The default human model shipped inside the package (kinema/assets/models/default)."""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

import pytest
import torch

import kinema
from kinema.cli import main
from kinema.motion.core import load_motion

SHIPPED = Path(str(files("kinema") / "assets" / "models" / "default"))


@pytest.fixture(scope="module")
def model():
    return kinema.load_model()


def test_shipped_files_size_and_licence() -> None:
    names = sorted(p.name for p in SHIPPED.iterdir())
    assert names == ["MODEL_CARD.md", "checkpoint.json", "ema.safetensors", "walk.png"]
    assert sum(p.stat().st_size for p in SHIPPED.iterdir()) <= 25e6
    card = (SHIPPED / "MODEL_CARD.md").read_text()
    for needed in ("CC BY-NC 4.0", "non-commercial", "Kobayashi", "arXiv:2306.08861", "kinema train",
                   "kinema evaluate", "Ground truth", "kinema bench"):
        assert needed in card, needed


def test_default_model_meets_waypoints_after_postprocessing(model) -> None:
    cons = [{"type": "root2d", "times": [1.5, 3.0], "smooth_root_2d": [[0.0, 1.5], [1.0, 3.0]]}]
    m = model.generate("A person walks forward.", seconds=4, constraints=cons, seed=1, steps=20)[0]
    from kinema.motion.features import motion_to_features

    root = motion_to_features(m)[:, [0, 2]]  # smoothed root x, z
    for t, xz in ((1.5, (0.0, 1.5)), (3.0, (1.0, 3.0))):
        got = root[round(t * m.fps)]
        assert (got - torch.tensor(xz, dtype=got.dtype)).norm() < 0.01, (t, got)


def test_readme_main_command(tmp_path, capsys) -> None:
    out = tmp_path / "walk.bvh"
    assert main(["generate", "A person walks forward happily.", "--seconds", "4", "--out", str(out),
                 "--steps", "10", "--no-progress"]) == 0
    assert str(out) in capsys.readouterr().out
    motion = load_motion(out)
    assert motion.num_frames == 80 and motion.skeleton.num_joints == 21
