"""Training noise levels for clips far outside the normalisation (issue 38).

Diffusion assumes normalised data of about unit scale: at the last training steps the noise hides it, so
the model must make the motion from the text there, and sampling starts from noise alone. A fine-tune
keeps the shipped model's normalisation statistics (its weights were trained in them), and in them the
Quaternius humanoid actions lie far out: a kick's foot 36 standard deviations, a jump's root 51, a
roll's pelvis rotation 139. Such a value still stands above the noise at almost every step
(``sqrt(alpha_bar_t) * 36 > 1`` up to t ~ 980 of 1000 on the cosine schedule), so the model learns to read
it from its noisy input and never to make it from the text. Measured on a fine-tune after 1000 steps
(scripts/kick_denoising_probe.py: kick clip, its caption): the x0 prediction lifts the foot 0.26-0.37 m
above the hips (the clip's 0.36) up to t = 900, with or without the text, and keeps it 0.36-0.80 m below
the hips from t = 960, with or without the text; sampling from noise never kicks. A run with this option
lifts it 0.60 m at t = 999 with the text and keeps it down without (docs/training.md, "Stop 50").

:func:`high_noise_timesteps` redraws, with probability ``share``, the training step of each row whose
clip reaches beyond ``min_std`` normalised units, from the steps where that clip's largest value is
under the noise (``sqrt(alpha_bar_t) * max|x0| <= 1``): those rows are learned where only the text can
tell the model what to make. Rows within ``min_std`` (the captures' own clips reach up to ~27 in the
shipped statistics, most stay under 8) keep their uniform steps.
"""

from __future__ import annotations

import torch

from kinema.diffusion.schedule import NoiseSchedule


def drowned_from(schedule: NoiseSchedule, peak: torch.Tensor, visible: float = 1.0) -> torch.Tensor:
    """Per row, the first 0-based step at which the noise hides a value of ``peak (B,)`` normalised units:
    the smallest ``t`` with ``sqrt(alpha_bar_t) * peak <= visible`` (the last step when none does)."""
    root_ab = schedule.alphas_cumprod.sqrt().to(peak.dtype)  # (T,), decreasing
    hidden = root_ab[None, :] * peak[:, None] <= visible  # (B, T), False then True along T
    last = torch.full(peak.shape, schedule.num_train_steps - 1, dtype=torch.int64)
    return torch.where(hidden.any(dim=1), hidden.to(torch.int64).argmax(dim=1), last)


def high_noise_timesteps(
    t: torch.Tensor,
    x0: torch.Tensor,
    schedule: NoiseSchedule,
    share: float,
    min_std: float,
    generator: torch.Generator,
    visible: float = 1.0,
) -> torch.Tensor:
    """``t (B,)`` with the rows of ``x0 (B, T, D)`` (normalised; padded frames zero) that reach beyond
    ``min_std`` redrawn with probability ``share``, uniformly from :func:`drowned_from` their largest
    ``|x0|`` (at most ``visible`` noise standard deviations) to the last step. ``share == 0`` returns ``t``
    and draws nothing (runs stay as before)."""
    if share <= 0:
        return t
    peak = x0.detach().abs().flatten(1).amax(dim=1).float()
    lo = drowned_from(schedule, peak, visible)
    u = torch.rand(t.shape, generator=generator)
    pick = torch.rand(t.shape, generator=generator)
    span = schedule.num_train_steps - lo
    high = lo + (u * span).long().clamp(max=span - 1)
    return torch.where((peak > min_std) & (pick < share), high, t)
