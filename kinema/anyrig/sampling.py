"""DDIM sampling of per-joint features for one rig with the any-rig denoiser.

Long motions by overlapping windows ("How to Move Your Dragon" Sec. 3.4, in the MultiDiffusion form):
the whole sequence ``x_t (S, T, J, C)`` is noised once; at every DDIM step it is cut into the windows
of a `WindowPlan` (kinema.anyrig.windows: the model's ``window`` frames overlapping by at least
a quarter window, or a timeline's windows, each with its segment's prompt), all windows and all
guidance branches are denoised in ONE batched forward pass, and the windows' x0 predictions are
blended back with weights that ramp down towards each window's inner edges, so neighbouring windows
(and neighbouring segments) agree.

Constraints: targets ``x_tgt`` and a {0, 1} ``mask`` ``(T, J, C)`` (un-normalised features) enter the
denoiser's imputation path, and the guided x0 is overwritten on constrained entries. Guidance is
kinema.diffusion.guidance: separated (text and constraint weights) when there are constraints,
regular classifier-free guidance otherwise. The root row (ground velocity, height, heading) takes the
text weight at most `ROOT_TEXT_WEIGHT` (issue 34): extrapolating it away from the unconditional
prediction (which has the average travel of walks and idles alike) pushed idles backwards (4-s idles
of the fine-tune on three held-out rigs drifted 0.45-0.96 body sizes at w = 2, 0.11-0.43 at w = 1);
the body's rows keep the full weight. Only for a single prompt: across a timeline's joins the root row
guided less than the body tore the join (a synthetic dog's walk -> death: a 0.59 m step against 0.15
elsewhere). Shapes: ``(S, T, J, C)``; S = samples.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

import torch

from kinema.anyrig.windows import WindowPlan, window_starts, window_weights
from kinema.diffusion.guidance import Guidance, combine, split_branches
from kinema.diffusion.sampler import DDIMSampler, spaced_timesteps
from kinema.model.anyrig.denoiser import AnyRigDenoiser
from kinema.model.skeleton_codes import CodeBatch
from kinema.representation.joint import FeatureTargets

if TYPE_CHECKING:
    from kinema.pipeline.request import GenerationRequest

#: the largest text guidance weight of the root row (see the module docstring)
ROOT_TEXT_WEIGHT = 1.0


class WindowDenoiser:
    """``__call__(x_t (S, T, J, C), t) -> guided x0``: windows x branches as one batched pass.

    ``text_emb (P, D)`` holds one embedding per prompt (None: no text at all; a zero row: that prompt
    is empty) and ``plan`` says which prompt each window gets (kinema.anyrig.windows)."""

    def __init__(
        self,
        model: AnyRigDenoiser,
        codes: CodeBatch,
        plan: WindowPlan,
        text_emb: torch.Tensor | None,
        targets: FeatureTargets | None,
        guidance: Guidance,
    ) -> None:
        self.model, self.plan, self.T = model, plan, plan.frames
        self.W = plan.width
        self.weights, self.frame_mask = plan.weights(), plan.frame_mask()
        constrained = targets is not None and targets.any()
        self.guidance = guidance if constrained else guidance.without_constraints()
        if text_emb is None:  # no text: only the constraint term is left to guide with
            self.guidance = Guidance("regular", w_text=guidance.w_constr) if constrained else Guidance("none")
        self.names = self.guidance.branches
        self.soft_root = len(set(plan.prompts)) == 1  # one prompt: at a timeline's joins root and body must agree
        self.codes = codes
        text = text_emb if text_emb is not None else torch.zeros(1, model.config.text_dim)
        self.text = text[[p if text_emb is not None else 0 for p in plan.prompts]]  # (K, D): each window's
        J, C = codes.joint_mask.shape[1], model.config.channels
        if constrained:
            self.x_tgt = model.normalize(targets.x_tgt[None], codes)[0] * targets.mask
            self.mask = targets.mask.float()
        else:
            self.x_tgt, self.mask = torch.zeros(self.T, J, C), torch.zeros(self.T, J, C)

    def _windows(self, x: torch.Tensor) -> torch.Tensor:
        """``(S, T, ...)`` -> ``(S*K, W, ...)``; frames past the end of the motion are zeros (padding)."""
        x = torch.cat([x, x.new_zeros(x.shape[0], self.W, *x.shape[2:])], dim=1)
        return torch.stack([x[:, s : s + self.W] for s in self.plan.starts], dim=1).flatten(0, 1)

    def __call__(self, x_t: torch.Tensor, t: int) -> torch.Tensor:
        S, K = x_t.shape[0], len(self.plan.starts)
        xw = self._windows(x_t)
        tgt = self._windows(self.x_tgt[None].expand(S, -1, -1, -1))
        msk = self._windows(self.mask[None].expand(S, -1, -1, -1))
        n = xw.shape[0]
        text = self.text.repeat(S, 1)  # (S*K, D), sample-major like the windows
        texts, masks = [], []
        for name in self.names:
            texts.append(text if name in ("text", "cond") else torch.zeros_like(text))
            masks.append(msk if name in ("constr", "cond") else torch.zeros_like(msk))
        nb = len(self.names)
        out = self.model(
            xw.repeat(nb, 1, 1, 1),
            torch.full((n * nb,), t, dtype=torch.long),
            torch.cat(texts),
            self.codes.repeat(n * nb),
            self.frame_mask.repeat(S * nb, 1),
            tgt.repeat(nb, 1, 1, 1),
            torch.cat(masks),
        )
        branches = split_branches(out, self.names)
        x0w = combine(self.guidance, branches)
        if self.soft_root and self.guidance.w_text > ROOT_TEXT_WEIGHT and self.guidance.mode.value != "none":
            root = self.codes.flags[0, :, 0] > 0.5
            soft = replace(self.guidance, w_text=ROOT_TEXT_WEIGHT)
            x0w[:, :, root] = combine(soft, branches)[:, :, root]
        x0w = x0w.view(S, K, self.W, *x_t.shape[2:])
        x0 = torch.zeros_like(x_t)
        den = torch.zeros(self.T)
        for k, (s, L) in enumerate(zip(self.plan.starts, self.plan.lengths, strict=True)):
            w = self.weights[k, :L]
            x0[:, s : s + L] += w[:, None, None] * x0w[:, k, :L]
            den[s : s + L] += w
        x0 = x0 / den[None, :, None, None]
        x0 = self.mask * self.x_tgt + (1 - self.mask) * x0
        return x0 * self.codes.joint_mask[0][None, None, :, None]


@torch.no_grad()
def sample_features(
    model: AnyRigDenoiser,
    codes: CodeBatch,
    request: GenerationRequest,
    *,
    plan: WindowPlan,
    text_emb: torch.Tensor | None,
    targets: FeatureTargets | None,
    sampler: DDIMSampler,
    guidance: Guidance,
    progress: Callable[[int, int], None] | None = None,
) -> torch.Tensor:
    """Un-normalised features ``(request.samples, plan.frames, J, C)`` for the single rig of ``codes``;
    ``plan`` (one prompt: `single_plan`) places the windows and gives each one a row of ``text_emb (P, D)``.
    The request gives the samples, the seed (a fresh generator) and the steps (None: the sampler's); the
    caller resolves its guidance (with the model's defaults) into ``guidance``."""
    steps = sampler.num_inference_steps if request.steps is None else request.steps
    generator = torch.Generator().manual_seed(request.seed)
    den = WindowDenoiser(model, codes, plan, text_emb, targets, guidance)
    J, C = codes.joint_mask.shape[1], model.config.channels
    x = torch.randn(request.samples, plan.frames, J, C, generator=generator)
    ts = spaced_timesteps(sampler.num_train_steps, steps, sampler.timestep_spacing)
    for i, (t, prev) in enumerate(zip(ts, ts[1:] + [-1], strict=True)):
        x0 = den(x, t)
        x = sampler.step_to(x0, t, prev, x, generator=generator)
        if progress is not None:
            progress(i + 1, len(ts))
    return model.denormalize(x, codes)


__all__ = ["FeatureTargets", "WindowDenoiser", "sample_features", "window_starts", "window_weights"]
