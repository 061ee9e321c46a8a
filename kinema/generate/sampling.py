"""Sample Kimodo features from a denoiser with DDIM, guidance and constraint imputation.

Shapes: ``text_emb (B, E)``, ``c_dir (B, 2)``, ``x_tgt``/``mask`` ``(B, T, D)`` in *unnormalised*
feature units (metres, radians...) — they are normalised here, with the model's statistics.
Returns unnormalised features ``(B, T, D)``; constrained channels hold exactly their targets.
"""

from __future__ import annotations

import torch

from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import DDIMSampler
from kinema.model.denoiser import Denoiser


@torch.no_grad()
def sample_features(
    denoiser: Denoiser,
    sampler: DDIMSampler,
    num_frames: int,
    text_emb: torch.Tensor | None,
    c_dir: torch.Tensor,
    guidance: Guidance,
    x_tgt: torch.Tensor | None = None,
    mask: torch.Tensor | None = None,
    steps: int | None = None,
    generator: torch.Generator | None = None,
    progress: bool = False,
) -> torch.Tensor:
    """Run the reverse process for a batch of ``c_dir.shape[0]`` motions of ``num_frames`` frames."""
    B = c_dir.shape[0]
    D = denoiser.config.feature_dim
    if steps is not None:
        sampler.set_timesteps(steps)
    tgt_n = None
    if mask is not None:
        if x_tgt is None:
            raise ValueError("a constraint mask needs targets")
        tgt_n = denoiser.normalize(torch.nan_to_num(x_tgt.float())) * mask
    if text_emb is None:
        guidance = Guidance(mode="none") if mask is None else guidance
        text_mask = torch.zeros(B, dtype=torch.bool)
    else:
        text_mask = None

    def denoise(x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        x0 = denoiser.forward_guided(x_t, t, text_emb, c_dir, tgt_n, mask, None, guidance, text_mask=text_mask)
        if mask is not None:  # keep constrained channels exact in the running estimate
            x0 = mask * tgt_n + (1 - mask) * x0
        return x0

    x = sampler.sample(denoise, (B, num_frames, D), generator=generator, progress=progress)
    if mask is not None:
        x = mask * tgt_n + (1 - mask) * x
    return denoiser.denormalize(x)
