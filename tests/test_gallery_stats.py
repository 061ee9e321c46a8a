"""scripts/gallery_stats.py: the numbers the model card's gallery table is built from."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import torch

NAMES = ["Hips", "Spine", "Chest", "Neck", "Head", "Hand_L", "Hand_R", "Toes_L", "Toes_R"]


def _stats_fn():
    path = Path(__file__).resolve().parents[1] / "scripts" / "gallery_stats.py"
    spec = importlib.util.spec_from_file_location("gallery_stats", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.motion_stats


def test_known_motion_gives_known_statistics():
    motion_stats = _stats_fn()
    T, fps = 41, 20.0
    pose = torch.tensor(
        [
            [0, 1.0, 0],
            [0, 1.2, 0],
            [0, 1.4, 0],
            [0, 1.55, 0],
            [0, 1.7, 0],
            [-0.3, 1.0, 0],
            [0.3, 1.0, 0],
            [-0.1, 0.0, 0.1],
            [0.1, 0.0, 0.1],
        ]
    )
    pos = pose.expand(T, -1, -1).clone()
    pos[..., 2] += torch.arange(T).view(T, 1) / fps * 1.5  # 1.5 m/s along +Z, upright, no jerk
    st = motion_stats(pos, fps, NAMES)
    assert abs(st["speed m/s"] - 1.5) < 1e-5 and st["lean deg"] < 1e-3
    assert abs(st["hand over head m"] + 0.7) < 1e-5 and st["toe lift m"] == 0.0 and st["jerk m/s^3"] < 0.01
    # bend forward 90 degrees at the hips on the last frame: the lean reaches 90 degrees
    pos[-1, 1:5] = pos[-1, 0] + torch.tensor([[0, 0, 0.2], [0, 0, 0.4], [0, 0, 0.55], [0, 0, 0.7]])
    assert abs(motion_stats(pos, fps, NAMES)["lean deg"] - 90.0) < 1e-3
