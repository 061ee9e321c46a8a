"""DDIM sampling of per-joint features for one rig with the any-rig denoiser.

Long motions by overlapping windows ("How to Move Your Dragon" Sec. 3.4, in the MultiDiffusion form):
the whole sequence ``x_t (S, T, J, C)`` is noised once; at every DDIM step it is cut into windows of
the model's ``window`` frames overlapping by at least a quarter window, all windows and all guidance
branches are denoised in ONE batched forward pass, and the windows' x0 predictions are blended back
with weights that ramp down towards each window's inner edges, so neighbouring windows agree.

Constraints: targets ``x_tgt`` and a {0, 1} ``mask`` ``(T, J, C)`` (un-normalised features) enter the
denoiser's imputation path, and the guided x0 is overwritten on constrained entries. Guidance is
kinema.diffusion.guidance: separated (text and constraint weights) when there are constraints,
regular classifier-free guidance otherwise. Shapes: ``(S, T, J, C)``; S = samples.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import torch

from kinema.diffusion.guidance import Guidance, combine, split_branches
from kinema.diffusion.sampler import DDIMSampler, spaced_timesteps
from kinema.model.anyrig import AnyRigDenoiser
from kinema.model.skeleton_codes import CodeBatch


@dataclass(frozen=True)
class FeatureTargets:
    """Un-normalised targets and their {0, 1} mask, both ``(T, J, C)``."""

    x_tgt: torch.Tensor
    mask: torch.Tensor

    def any(self) -> bool:
        return bool(self.mask.any())


def window_starts(T: int, W: int) -> list[int]:
    """Start frames of windows of ``W`` frames covering ``T`` frames, overlapping by >= ``W // 4``."""
    if T <= W:
        return [0]
    stride = W - max(1, W // 4)
    n = math.ceil((T - W) / stride) + 1
    return [round(i * (T - W) / (n - 1)) for i in range(n)]


def window_weights(starts: list[int], W: int, T: int) -> torch.Tensor:
    """``(K, min(W, T))`` blending weights: 1 inside, ramping down over the overlap at inner edges."""
    L = min(W, T)
    ramp = max(1, W // 4)
    base = torch.ones(len(starts), L)
    f = torch.arange(L, dtype=torch.float32)
    for k in range(len(starts)):
        if k > 0:
            base[k] = torch.minimum(base[k], (f + 1) / (ramp + 1))
        if k < len(starts) - 1:
            base[k] = torch.minimum(base[k], (L - f) / (ramp + 1))
    return base


class WindowDenoiser:
    """``__call__(x_t (S, T, J, C), t) -> guided x0``: windows x branches as one batched pass."""

    def __init__(
        self,
        model: AnyRigDenoiser,
        codes: CodeBatch,
        T: int,
        text_emb: torch.Tensor | None,
        targets: FeatureTargets | None,
        guidance: Guidance,
    ) -> None:
        self.model, self.T = model, T
        self.W = min(model.config.window, T)
        self.starts = window_starts(T, model.config.window)
        self.weights = window_weights(self.starts, model.config.window, T)
        constrained = targets is not None and targets.any()
        self.guidance = guidance if constrained else guidance.without_constraints()
        if text_emb is None:  # no text: only the constraint term is left to guide with
            self.guidance = Guidance("regular", w_text=guidance.w_constr) if constrained else Guidance("none")
        self.names = self.guidance.branches
        self.codes = codes
        self.text = text_emb if text_emb is not None else torch.zeros(1, model.config.text_dim)
        J, C = codes.joint_mask.shape[1], model.config.channels
        if constrained:
            self.x_tgt = model.normalize(targets.x_tgt[None], codes)[0] * targets.mask
            self.mask = targets.mask.float()
        else:
            self.x_tgt, self.mask = torch.zeros(T, J, C), torch.zeros(T, J, C)

    def _windows(self, x: torch.Tensor) -> torch.Tensor:
        return torch.stack([x[:, s : s + self.W] for s in self.starts], dim=1).flatten(0, 1)  # (S*K, W, J, C)

    def __call__(self, x_t: torch.Tensor, t: int) -> torch.Tensor:
        S, K = x_t.shape[0], len(self.starts)
        xw = self._windows(x_t)
        tgt = self._windows(self.x_tgt[None].expand(S, -1, -1, -1))
        msk = self._windows(self.mask[None].expand(S, -1, -1, -1))
        n = xw.shape[0]
        texts, masks = [], []
        for name in self.names:
            texts.append(
                self.text.expand(n, -1) if name in ("text", "cond") else torch.zeros_like(self.text).expand(n, -1)
            )
            masks.append(msk if name in ("constr", "cond") else torch.zeros_like(msk))
        nb = len(self.names)
        out = self.model(
            xw.repeat(nb, 1, 1, 1),
            torch.full((n * nb,), t, dtype=torch.long),
            torch.cat(texts),
            self.codes.repeat(n * nb),
            None,
            tgt.repeat(nb, 1, 1, 1),
            torch.cat(masks),
        )
        x0w = combine(self.guidance, split_branches(out, self.names)).view(S, K, self.W, *x_t.shape[2:])
        x0 = torch.zeros_like(x_t)
        den = torch.zeros(self.T)
        for k, s in enumerate(self.starts):
            w = self.weights[k][:, None, None]
            x0[:, s : s + self.W] += w * x0w[:, k]
            den[s : s + self.W] += self.weights[k]
        x0 = x0 / den[None, :, None, None]
        x0 = self.mask * self.x_tgt + (1 - self.mask) * x0
        return x0 * self.codes.joint_mask[0][None, None, :, None]


@torch.no_grad()
def sample_features(
    model: AnyRigDenoiser,
    codes: CodeBatch,
    *,
    frames: int,
    text_emb: torch.Tensor | None,
    targets: FeatureTargets | None,
    sampler: DDIMSampler,
    guidance: Guidance,
    steps: int,
    samples: int,
    generator: torch.Generator,
    progress: Callable[[int, int], None] | None = None,
) -> torch.Tensor:
    """Un-normalised features ``(samples, frames, J, C)`` for the single rig of ``codes``."""
    den = WindowDenoiser(model, codes, frames, text_emb, targets, guidance)
    J, C = codes.joint_mask.shape[1], model.config.channels
    x = torch.randn(samples, frames, J, C, generator=generator)
    ts = spaced_timesteps(sampler.num_train_steps, steps, sampler.timestep_spacing)
    for i, (t, prev) in enumerate(zip(ts, ts[1:] + [-1], strict=True)):
        x0 = den(x, t)
        x = sampler.step_to(x0, t, prev, x, generator=generator)
        if progress is not None:
            progress(i + 1, len(ts))
    return model.denormalize(x, codes)
