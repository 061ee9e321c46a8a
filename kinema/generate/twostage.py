"""Two-stage sparse control (SFControl Sec. 3.1 + 3.2): keyjoints first, then the body.

Stage 1 samples a dense keyjoint trajectory ``(B, T, 20)`` (kinema.representation.keyjoint) from the
keyjoint denoiser (kinema.model.keyjoint) with the sparse keyjoint targets imputed: the network sees
them (training-time imputation) and its clean estimate is overwritten with them after every step,
with classifier-free text guidance ``x0 = D_none + w (D_text - D_none)``. Stage 2 completes the body by
imputing that trajectory, densely, into kinema's body model (the six joints' positions, the smoothed
root and the heading on every frame: :func:`kinema.representation.keyjoint.completion_targets`) through
the ordinary sampler. Shapes: keyjoints ``(B, T, 20)`` unnormalised (metres, world frame, Y up).
"""

from __future__ import annotations

import torch

from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import DDIMSampler, spaced_timesteps
from kinema.generate.sampling import SampleSettings, SampleTargets, sample_features
from kinema.model.keyjoint import KeyjointDenoiser
from kinema.representation.flat import FlatRepresentation
from kinema.representation.keyjoint import completion_targets, keyjoint_indices

#: DDIM steps of the keyjoint stage (the network is small: 50 steps of 5 s cost about 0.2 s)
KEYJOINT_STEPS = 50
KEYJOINT_TEXT_WEIGHT = 2.0


@torch.no_grad()
def sample_keyjoints(
    model: KeyjointDenoiser,
    sampler: DDIMSampler,
    text_emb: torch.Tensor | None,
    c_dir: torch.Tensor,
    k_tgt: torch.Tensor,
    k_mask: torch.Tensor,
    *,
    steps: int = KEYJOINT_STEPS,
    w_text: float = KEYJOINT_TEXT_WEIGHT,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Dense keyjoints ``(B, T, 20)`` meeting the sparse targets ``k_tgt`` where ``k_mask`` is 1."""
    B, T, C = k_tgt.shape
    tgt = model.normalize(torch.nan_to_num(k_tgt)) * k_mask
    text = torch.zeros(B, model.config.text_dim) if text_emb is None else text_emb.float()
    x = torch.randn((B, T, C), generator=generator)
    ts = spaced_timesteps(sampler.num_train_steps, steps, sampler.timestep_spacing)
    for t, prev in zip(ts, ts[1:] + [-1], strict=True):
        tb = torch.full((2 * B,), t, dtype=torch.long)
        both = model(
            torch.cat([x, x]),
            tb,
            torch.cat([torch.zeros_like(text), text]),
            torch.cat([c_dir, c_dir]),
            torch.cat([tgt, tgt]),
            torch.cat([k_mask, k_mask]),
        )
        d0, d1 = both[:B], both[B:]
        x0 = d0 + (w_text if text_emb is not None else 0.0) * (d1 - d0)
        x0 = k_mask * tgt + (1 - k_mask) * x0
        x = sampler.step_to(x0, t, prev, x)
    return model.denormalize(x)


def complete_body(
    denoiser,
    sampler: DDIMSampler,
    rep: FlatRepresentation,
    text_emb: torch.Tensor | None,
    keyjoints: torch.Tensor,
    guidance: Guidance,
    *,
    steps: int | None = None,
    generator: torch.Generator | None = None,
    **corrections,
) -> torch.Tensor:
    """Unnormalised body features ``(B, T, D)`` following ``keyjoints (B, T, 20)`` on every frame."""
    idx = keyjoint_indices(rep.skeleton)
    x_tgt, mask = completion_targets(keyjoints.float(), rep, idx)
    c_dir = x_tgt[:, 0, rep.heading]
    settings = SampleSettings(keyjoints.shape[1], guidance, steps, **corrections)
    return sample_features(
        denoiser, sampler, rep, text_emb, SampleTargets(c_dir, x_tgt, mask), settings, generator=generator
    )
