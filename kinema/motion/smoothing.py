"""Temporal smoothing used for the smoothed root (Kimodo Sec. 4.1).

The root's horizontal path is the pelvis path convolved with a Gaussian of standard deviation
``sigma`` seconds (default 0.5 s: removes the ~1 Hz side-to-side sway of walking while keeping turns
and starts/stops). The ends are padded by *point reflection* (``x[-k] = 2 x[0] - x[k]``), which keeps
a straight constant-speed path unchanged, instead of the lag that edge-repeat padding would cause.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

DEFAULT_ROOT_SIGMA_SECONDS = 0.5


def gaussian_kernel(sigma_frames: float, dtype=torch.float32) -> torch.Tensor:
    """Normalised 1-D Gaussian taps covering +-3 sigma (at least one tap)."""
    radius = max(int(math.ceil(3.0 * sigma_frames)), 0)
    if sigma_frames <= 0 or radius == 0:
        return torch.ones(1, dtype=dtype)
    x = torch.arange(-radius, radius + 1, dtype=torch.float64)
    k = torch.exp(-0.5 * (x / sigma_frames) ** 2)
    return (k / k.sum()).to(dtype)


def smooth_time(x: torch.Tensor, sigma_frames: float) -> torch.Tensor:
    """Gaussian-smooth ``x`` of shape ``(..., T, C)`` along T with point-reflected ends."""
    kernel = gaussian_kernel(sigma_frames, x.dtype).to(x.device)
    r = kernel.numel() // 2
    if r == 0:
        return x.clone()
    T = x.shape[-2]
    lead = x.shape[:-2]
    flat = x.reshape(-1, T, x.shape[-1]).transpose(1, 2)  # (N, C, T)
    pad = _point_reflect_pad(flat, r)
    C = flat.shape[1]
    out = F.conv1d(pad, kernel.view(1, 1, -1).expand(C, 1, -1), groups=C)
    return out.transpose(1, 2).reshape(*lead, T, x.shape[-1])


def _point_reflect_pad(x: torch.Tensor, r: int) -> torch.Tensor:
    """Pad (N, C, T) by r frames each side with 2*x_end - x_mirrored (repeating for short clips)."""
    T = x.shape[-1]
    idx_left = torch.arange(r, 0, -1).clamp(max=T - 1)
    idx_right = torch.arange(T - 2, T - 2 - r, -1).clamp(min=0)
    left = 2 * x[..., :1] - x[..., idx_left]
    right = 2 * x[..., -1:] - x[..., idx_right]
    return torch.cat([left, x, right], dim=-1)
