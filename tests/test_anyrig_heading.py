"""The sampled root heading read from the model's heading rate (kinema.anyrig.heading)."""

from __future__ import annotations

import math

import torch

from kinema.anyrig.heading import ROOT_HEADING_RATE, heading_from_rate
from kinema.representation.joint import ROOT_HEADING_COS, ROOT_HEADING_SIN

FPS = 20.0


def _feats(psi_cs: torch.Tensor, rate: torch.Tensor) -> torch.Tensor:
    f = torch.zeros(1, psi_cs.shape[0], 3, 13)
    f[0, :, 1, ROOT_HEADING_COS], f[0, :, 1, ROOT_HEADING_SIN] = torch.cos(psi_cs), torch.sin(psi_cs)
    f[0, :, 1, ROOT_HEADING_RATE] = rate
    f[0, :, 2, 0] = 7.0  # another joint's channel: left alone
    return f


def _psi(f: torch.Tensor) -> torch.Tensor:
    return torch.atan2(f[0, :, 1, ROOT_HEADING_SIN], f[0, :, 1, ROOT_HEADING_COS])


def test_a_jittering_cos_sin_with_no_rate_becomes_its_mean_heading() -> None:
    gen = torch.Generator().manual_seed(0)
    jitter = 0.6 * torch.randn(80, generator=gen)  # tens of degrees frame to frame
    out = heading_from_rate(_feats(0.5 + jitter, torch.zeros(80)), root=1, fps=FPS)
    psi = _psi(out)
    assert float((psi - psi[0]).abs().max()) < 1e-5  # no turning left
    assert abs(float(psi[0]) - 0.5) < 0.2  # where the cos/sin point on average
    assert torch.equal(out[0, :, 2], _feats(jitter, torch.zeros(80))[0, :, 2])


def test_a_steady_rate_turns_the_heading_by_its_integral() -> None:
    T, rate = 41, 0.5  # rad/s for 2 s: one radian
    true = 0.2 + rate * torch.arange(T) / FPS
    out = heading_from_rate(_feats(true, torch.full((T,), rate)), root=1, fps=FPS)
    psi = _psi(out)
    assert abs(float(psi[-1] - psi[0]) - 1.0) < 1e-4 and abs(float(psi[0]) - 0.2) < 1e-4
    assert math.isclose(
        float(out[0, 5, 1, ROOT_HEADING_COS] ** 2 + out[0, 5, 1, ROOT_HEADING_SIN] ** 2), 1.0, rel_tol=1e-5
    )
