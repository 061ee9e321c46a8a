"""Training steps for clips far outside the normalisation (kinema/train/noise_levels.py, issue 38)."""

from __future__ import annotations

import pytest
import torch

from kinema.diffusion.schedule import NoiseSchedule
from kinema.train.noise_levels import drowned_from, high_noise_timesteps

SCHEDULE = NoiseSchedule(1000, "cosine")


def test_the_noise_hides_a_larger_value_only_at_a_later_step():
    peaks = torch.tensor([0.5, 5.0, 36.0, 139.0, 1e9])
    first = drowned_from(SCHEDULE, peaks)
    assert first.tolist() == sorted(first.tolist()) and first[0] == 0 and first[-1] == 999
    root_ab = SCHEDULE.alphas_cumprod.sqrt()
    for p, t in zip(peaks[1:4].tolist(), first[1:4].tolist(), strict=True):
        assert root_ab[t] * p <= 1.0 < root_ab[t - 1] * p  # the first step where the value is under the noise
    assert 975 <= int(first[2]) <= 990  # a kick's foot (36 std) stands above the noise until ~t = 980


def test_a_smaller_visibility_hides_the_value_deeper():
    """``visible`` (stop 53): the first step where sqrt(alpha_bar) * peak <= visible; 0.25 starts later than 1."""
    peaks = torch.tensor([6.0, 15.0, 36.0])
    at_noise, deeper = drowned_from(SCHEDULE, peaks), drowned_from(SCHEDULE, peaks, visible=0.25)
    assert (deeper > at_noise).all()
    root_ab = SCHEDULE.alphas_cumprod.sqrt()
    for p, t in zip(peaks.tolist(), deeper.tolist(), strict=True):
        assert root_ab[t] * p <= 0.25 < root_ab[t - 1] * p


def test_only_rows_beyond_the_threshold_are_redrawn_and_only_where_the_noise_hides_them():
    x0 = torch.zeros(64, 20, 6)
    x0[:32, 5, 2] = 36.0  # far out
    x0[32:, 5, 2] = 6.0  # within the captures' range
    t = torch.full((64,), 10, dtype=torch.long)
    out = high_noise_timesteps(t, x0, SCHEDULE, 1.0, 8.0, torch.Generator().manual_seed(0))
    lo = int(drowned_from(SCHEDULE, torch.tensor([36.0]))[0])
    assert (out[:32] >= lo).all() and (out[:32] < 1000).all() and out[:32].unique().numel() > 3
    assert (out[32:] == 10).all()
    half = high_noise_timesteps(t, x0, SCHEDULE, 0.5, 8.0, torch.Generator().manual_seed(1))
    assert 4 <= int((half[:32] != 10).sum()) <= 28 and (half[32:] == 10).all()


def test_share_zero_changes_nothing_and_draws_nothing():
    g, ref = torch.Generator().manual_seed(3), torch.Generator().manual_seed(3)
    t = torch.arange(8)
    x0 = torch.full((8, 4, 3), 50.0)
    assert torch.equal(high_noise_timesteps(t, x0, SCHEDULE, 0.0, 8.0, g), t)
    assert torch.equal(torch.rand(4, generator=g), torch.rand(4, generator=ref))  # the run's draws are as before


def test_cli_trains_with_the_option_saves_it_and_rejects_bad_values(tiny_data, tmp_path, capsys):
    import json

    from kinema.cli import main

    out = tmp_path / "run"
    args = ["train", "--config", "tiny", "--data", str(tiny_data), "--out", str(out), "--batch-size", "2",
            "--steps", "2", "--text-encoder", "hash-test-32", "--no-progress"]
    assert main([*args, "--high-noise-share", "0.5", "--high-noise-min-std", "2", "--high-noise-visible", "0.25"]) == 0
    saved = json.loads((out / "train_config.json").read_text())
    assert (saved["high_noise_share"], saved["high_noise_min_std"], saved["high_noise_visible"]) == (0.5, 2.0, 0.25)
    capsys.readouterr()
    with pytest.raises(SystemExit):  # argparse: one line naming the option and the range
        main([*args, "--high-noise-share", "1.5"])
    err = capsys.readouterr().err.strip().splitlines()
    assert "--high-noise-share" in err[-1] and "[0, 1]" in err[-1]
