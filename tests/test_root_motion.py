"""Root motion recovered from planted feet (kinema.data.root_motion): a treadmill walk travels, an idle
does not, and the travel goes the way the feet push."""

from __future__ import annotations

import math

import pytest
import torch

from kinema.data.root_motion import forward_agreement, recover_travel

FPS = 20.0


def _treadmill(frames: int = 80, speed: float = 0.5, stride: float = 0.2, lift: float = 0.05) -> torch.Tensor:
    """World positions (T, 3, 3) of a body on the spot (joint 0, 1 up) and two feet walking on a
    treadmill along +Z at ``speed``: each foot slides back at ``speed`` while planted (half the cycle)
    and swings forward, lifted, the other half."""
    period = 2 * stride / speed  # seconds per cycle: back ``stride`` planted, forward ``stride`` in the air
    t = torch.arange(frames, dtype=torch.float64) / FPS
    P = torch.zeros(frames, 3, 3, dtype=torch.float64)
    P[:, 0, 1] = 1.0
    for k, phase in ((1, 0.0), (2, 0.5)):
        u = ((t / period) + phase) % 1.0
        planted = u < 0.5
        z = torch.where(planted, stride / 2 - 2 * stride * u, -stride / 2 + 2 * stride * (u - 0.5))
        y = torch.where(planted, torch.zeros_like(u), lift * torch.sin(2 * math.pi * (u - 0.5)))
        P[:, k, 0] = 0.2 * (1 if k == 1 else -1)
        P[:, k, 1] = y
        P[:, k, 2] = z
    return P


def test_treadmill_walk_travels_forward_at_its_speed() -> None:
    P = _treadmill(speed=0.5)
    rec = recover_travel(P, [1, 2], FPS)
    assert rec.speed == pytest.approx(0.5, rel=0.1)
    assert float(rec.travel[-1, 2]) == pytest.approx(0.5 * (P.shape[0] - 1) / FPS, rel=0.1)
    assert abs(float(rec.travel[-1, 0])) < 0.02 and float(rec.travel[:, 1].abs().max()) == 0.0
    assert forward_agreement(rec.travel, (0, 0, 1)) > 0.99
    assert forward_agreement(rec.travel, (0, 0, -1)) < -0.99
    # planted feet no longer slide once the body travels
    moved = P + rec.travel[:, None]
    v = (moved[1:, 1:] - moved[:-1, 1:])[..., [0, 2]].norm(dim=-1) * FPS
    both = rec.planted[1:] & rec.planted[:-1]
    assert float(v[both].mean()) < 0.05


def test_idle_and_feet_off_the_floor_do_not_travel() -> None:
    P = _treadmill()
    still = P[:1].repeat(P.shape[0], 1, 1)
    still[:, 1, 2] += 0.002 * torch.sin(torch.arange(P.shape[0], dtype=torch.float64))  # a shuffle
    rec = recover_travel(still, [1, 2], FPS)
    assert rec.speed == 0.0 and float(rec.travel.abs().max()) == 0.0
    # "feet" that never come near the floor (a mech's knees) give nothing
    high = P.clone()
    high[:, 1:, 1] += 0.5
    high = torch.cat([high, torch.zeros(P.shape[0], 1, 3, dtype=torch.float64)], dim=1)  # the floor joint
    assert recover_travel(high, [1, 2], FPS).speed == 0.0


def test_up_axis_and_no_feet() -> None:
    P = _treadmill()
    zup = P[..., [0, 2, 1]].clone()  # the same walk with Z up: it goes along +Y
    zup[..., 1] *= -1
    rec = recover_travel(zup, [1, 2], FPS, up=(0, 0, 1))
    assert float(rec.travel[-1, 1]) < -1.0 and abs(float(rec.travel[-1, 2])) < 1e-9
    assert recover_travel(P, [], FPS).speed == 0.0
