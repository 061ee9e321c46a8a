"""Phases of a locomotion capture (kinema/data/phases.py): steady stretch, start and end at rest."""

from __future__ import annotations

import torch

from kinema.data.phases import find_phases, speed_profile

FPS = 20.0


def path(speeds: list[float]) -> torch.Tensor:
    """A straight ground path (T, 2) moving at ``speeds`` m/s per frame."""
    x = torch.cumsum(torch.tensor([0.0] + speeds[:-1], dtype=torch.float64) / FPS, 0)
    return torch.stack([x, torch.zeros_like(x)], dim=-1)


def test_a_steady_run_has_no_start_or_stop():
    p = find_phases(path([2.6] * 60), FPS)
    assert p is not None and not p.starts_at_rest and not p.ends_at_rest
    assert p.steady_start == 0 and p.steady_end == 60 and abs(p.steady_speed - 2.6) < 1e-6


def test_a_run_from_standing_to_standing_has_both():
    ramp = [2.6 * i / 20 for i in range(20)]
    p = find_phases(path([0.0] * 10 + ramp + [2.6] * 40 + ramp[::-1] + [0.0] * 10), FPS)
    assert p is not None and p.starts_at_rest and p.ends_at_rest
    assert 20 <= p.steady_start <= 30 and 70 <= p.steady_end <= 80


def test_standing_still_is_not_locomotion():
    assert find_phases(path([0.05] * 60), FPS) is None
    assert speed_profile(path([1.0] * 30), FPS).shape == (30,)
