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

Two stages (issue 34, as Kimodo's root-then-body): a model with a root stage
(kinema.model.anyrig.root_stage) first samples the root row alone over the same windows
(`sample_root`), then the body with that root row given on every frame, in every guidance branch
(`root_context`: the training's "root row on every frame" mask). Requests that pin a joint other than
the root on a frame whose root is free keep one stage (`uses_root_stage`), so the root can move for them.

Channels that hold no feature (the contact slot of non-contact joints and of the root) are zeros in
training (the trainers mask their noisy input), so sampling keeps them zero in the denoiser's input too
(`real_channels`). Fed noise there (as until issue 34), the one-stage model's 4-s walks on four held-out
files turned 12-42 deg and its idles drifted 0.28-0.40 body sizes; with zeros 15-22 deg and 0.15-0.43
(worst of two seeds each; the alpaca's run / walk ground 1.24 -> 1.38).
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
from kinema.model.anyrig.root_stage import RootStageDenoiser
from kinema.model.skeleton_codes import CodeBatch
from kinema.representation.joint import CONTACT, NUM_CHANNELS, ROOT_HEADING_RATE, ROOT_PLACEMENT, FeatureTargets

if TYPE_CHECKING:
    from kinema.pipeline.request import GenerationRequest

#: the largest text guidance weight of the root row (see the module docstring)
ROOT_TEXT_WEIGHT = 1.0
#: the largest text guidance weight of a root stage (regular classifier-free guidance)
ROOT_STAGE_TEXT_WEIGHT = 1.0


def real_channels(codes: CodeBatch) -> torch.Tensor:
    """``(J, C)`` {0, 1}: the channels of the rig's joints that hold features (kinema.representation.joint:
    the contact slot only on contact joints, never on the root; nothing on padding joints). The others
    are zeros in training, so sampling keeps them zero in the denoiser's input."""
    flags, joints = codes.flags[0], codes.joint_mask[0].float()
    real = joints[:, None].expand(-1, NUM_CHANNELS).clone()
    real[:, CONTACT] *= (flags[:, 1] > 0.5).float() * (flags[:, 0] < 0.5).float()
    return real


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
        context: FeatureTargets | None = None,
    ) -> None:
        self.model, self.plan, self.T = model, plan, plan.frames
        self.weights, self.frame_mask = plan.weights(), plan.frame_mask()
        constrained = targets is not None and targets.any()
        self.guidance = guidance if constrained else guidance.without_constraints()
        if text_emb is None:  # no text: only the constraint term is left to guide with
            self.guidance = Guidance("regular", w_text=guidance.w_constr) if constrained else Guidance("none")
        self.names = self.guidance.branches
        self.soft_root = len(set(plan.prompts)) == 1  # one prompt: at a timeline's joins root and body must agree
        self.codes = codes
        self.real = real_channels(codes)
        text = text_emb if text_emb is not None else torch.zeros(1, model.config.text_dim)
        self.text = text[[p if text_emb is not None else 0 for p in plan.prompts]]  # (K, D): each window's
        J, C = codes.joint_mask.shape[1], model.config.channels
        # (1 or S, T, J, C): the user's targets (the constraint branch) and the context (every branch)
        zeros = torch.zeros(1, self.T, J, C)
        self.x_tgt, self.mask, self.context = zeros, zeros, zeros
        if constrained:
            self.mask = targets.mask.float().reshape(-1, self.T, J, C)
            self.x_tgt = model.normalize(targets.x_tgt.reshape(-1, self.T, J, C), codes) * self.mask
        if context is not None:
            self.context = context.mask.float().reshape(-1, self.T, J, C)
            given = model.normalize(context.x_tgt.reshape(-1, self.T, J, C), codes)
            self.x_tgt = self.context * given + (1 - self.context) * self.x_tgt

    def __call__(self, x_t: torch.Tensor, t: int) -> torch.Tensor:
        S = x_t.shape[0]
        xw = self.plan.cut(x_t * self.real)
        tgt = self.plan.cut(self.x_tgt.expand(S, -1, -1, -1))
        msk = self.plan.cut(self.mask.expand(S, -1, -1, -1))
        ctx = self.plan.cut(self.context.expand(S, -1, -1, -1))
        n = xw.shape[0]
        text = self.text.repeat(S, 1)  # (S*K, D), sample-major like the windows
        texts, masks = [], []
        for name in self.names:
            texts.append(text if name in ("text", "cond") else torch.zeros_like(text))
            masks.append(torch.maximum(msk, ctx) if name in ("constr", "cond") else ctx)
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
        x0 = self.plan.blend(x0w, self.weights)
        given = torch.maximum(self.mask, self.context)
        x0 = given * self.x_tgt + (1 - given) * x0
        return x0 * self.real


class RootStageWindows:
    """``__call__(x_t (S, T, 13), t) -> guided x0``: the root stage (kinema.model.anyrig.root_stage) over
    the windows of ``plan``, all windows and guidance branches in one batched pass. Root-row ``targets``
    (``(T, 13)`` each, un-normalised) are imputed in every branch; the text guides with
    `ROOT_STAGE_TEXT_WEIGHT` at most (regular classifier-free guidance)."""

    def __init__(self, stage: RootStageDenoiser, codes: CodeBatch, plan: WindowPlan, text_emb: torch.Tensor | None,
                 targets: FeatureTargets | None, guidance: Guidance) -> None:
        self.stage, self.plan, self.codes = stage, plan, codes
        self.weights, self.frame_mask = plan.weights(), plan.frame_mask()
        w = min(guidance.w_text, ROOT_STAGE_TEXT_WEIGHT)
        plain = text_emb is None or guidance.mode.value == "none" or w == 1.0  # one branch: the text as given
        self.guidance = Guidance("none") if plain else Guidance("regular", w_text=w)
        text = text_emb if text_emb is not None else torch.zeros(1, stage.config.text_dim)
        self.text = text[[p if text_emb is not None else 0 for p in plan.prompts]]
        C = NUM_CHANNELS
        self.real = real_channels(codes)[int(codes.flags[0, :, 0].argmax())]  # the root row's
        if targets is not None and targets.any():
            self.mask = targets.mask.float()
            self.x_tgt = stage.normalize(targets.x_tgt) * self.mask
        else:
            self.x_tgt, self.mask = torch.zeros(plan.frames, C), torch.zeros(plan.frames, C)

    def __call__(self, x_t: torch.Tensor, t: int) -> torch.Tensor:
        S = x_t.shape[0]
        xw = self.plan.cut(x_t * self.real)
        tgt = self.plan.cut(self.x_tgt[None].expand(S, -1, -1))
        msk = self.plan.cut(self.mask[None].expand(S, -1, -1))
        n = xw.shape[0]
        text = self.text.repeat(S, 1)
        names = self.guidance.branches
        texts = [text if name in ("text", "cond") else torch.zeros_like(text) for name in names]
        nb = len(names)
        out = self.stage(
            xw.repeat(nb, 1, 1),
            torch.full((n * nb,), t, dtype=torch.long),
            torch.cat(texts),
            self.codes.repeat(n * nb),
            self.frame_mask.repeat(S * nb, 1),
            tgt.repeat(nb, 1, 1),
            msk.repeat(nb, 1, 1),
        )
        x0 = self.plan.blend(combine(self.guidance, split_branches(out, names)), self.weights)
        return (self.mask * self.x_tgt + (1 - self.mask) * x0) * self.real


def _ddim(den, x: torch.Tensor, sampler: DDIMSampler, steps: int, generator: torch.Generator, progress) -> torch.Tensor:
    ts = spaced_timesteps(sampler.num_train_steps, steps, sampler.timestep_spacing)
    for i, (t, prev) in enumerate(zip(ts, ts[1:] + [-1], strict=True)):
        x = sampler.step_to(den(x, t), t, prev, x, generator=generator)
        if progress is not None:
            progress(i + 1, len(ts))
    return x


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
    root_stage: RootStageDenoiser | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> torch.Tensor:
    """Un-normalised features ``(request.samples, plan.frames, J, C)`` for the single rig of ``codes``;
    ``plan`` (one prompt: `single_plan`) places the windows and gives each one a row of ``text_emb (P, D)``.
    The request gives the samples, the seed (a fresh generator) and the steps (None: the sampler's); the
    caller resolves its guidance (with the model's defaults) into ``guidance``. With a ``root_stage``
    (`uses_root_stage`), the root row is sampled first (`sample_root`) and the body given it on every
    frame, in every guidance branch."""
    steps = sampler.num_inference_steps if request.steps is None else request.steps
    generator = torch.Generator().manual_seed(request.seed)
    J, C = codes.joint_mask.shape[1], model.config.channels
    context, body_progress = None, progress
    if root_stage is not None:  # one bar over both stages: the root's steps, then the body's
        root_progress, body_progress = _span(progress, 0, 2 * steps), _span(progress, steps, 2 * steps)
        row = sample_root(root_stage, codes, request.samples, plan=plan, text_emb=text_emb, targets=targets,
                          sampler=sampler, steps=steps, guidance=guidance, generator=generator,
                          progress=root_progress)
        context = root_context(row, codes)
        if targets is not None and bool((targets.mask <= context.mask).all()):
            targets = None  # the user's targets are all on the root row, which the context now carries
    den = WindowDenoiser(model, codes, plan, text_emb, targets, guidance, context)
    x = torch.randn(request.samples, plan.frames, J, C, generator=generator)
    return model.denormalize(_ddim(den, x, sampler, steps, generator, body_progress), codes)


def _span(progress: Callable[[int, int], None] | None, offset: int, total: int):
    """``progress`` for a part of a longer run: step i of the part is step ``offset + i`` of ``total``."""
    return None if progress is None else (lambda i, n: progress(offset + i, total))


def uses_root_stage(targets: FeatureTargets | None, codes: CodeBatch) -> bool:
    """Whether a request's ``targets`` leave the root to a root stage: the root path is not given whole, and
    no joint but the root is pinned on a frame whose root row is free (a hand or head target must be free
    to move the root to reach it)."""
    if targets is None or not targets.any():
        return True
    root = codes.flags[0, :, 0] > 0.5
    if bool(targets.mask[:, root][..., ROOT_PLACEMENT].all()):
        return False  # the whole root path is given (a copied root motion): nothing left for a root stage
    root_free = targets.mask[:, root].sum((1, 2)) == 0  # (T,)
    return not bool(targets.mask[root_free][:, ~root].any())


def sample_root(
    stage: RootStageDenoiser,
    codes: CodeBatch,
    samples: int,
    *,
    plan: WindowPlan,
    text_emb: torch.Tensor | None,
    targets: FeatureTargets | None,
    sampler: DDIMSampler,
    steps: int,
    guidance: Guidance,
    generator: torch.Generator,
    progress: Callable[[int, int], None] | None = None,
) -> torch.Tensor:
    """Root rows ``(samples, plan.frames, 13)``, un-normalised, from the root stage; the root row of
    ``targets`` (``(T, J, 13)``) is imputed."""
    root = int(codes.flags[0, :, 0].argmax())
    row = None if targets is None else FeatureTargets(targets.x_tgt[:, root], targets.mask[:, root])
    den = RootStageWindows(stage, codes, plan, text_emb, row, guidance)
    x = torch.randn(samples, plan.frames, NUM_CHANNELS, generator=generator)
    return stage.denormalize(_ddim(den, x, sampler, steps, generator, progress))


def root_context(rows: torch.Tensor, codes: CodeBatch) -> FeatureTargets:
    """Root rows ``(S, T, 13)`` as the body stage's context ``(S, T, J, 13)``: the root's placement and
    heading rate on every frame (its masked contact slot stays free)."""
    J = codes.joint_mask.shape[1]
    root = int(codes.flags[0, :, 0].argmax())
    x = torch.zeros(*rows.shape[:2], J, NUM_CHANNELS)
    m = torch.zeros_like(x)
    x[:, :, root] = rows
    m[:, :, root, ROOT_PLACEMENT + [ROOT_HEADING_RATE]] = 1.0
    return FeatureTargets(x, m)


__all__ = [
    "FeatureTargets",
    "RootStageWindows",
    "WindowDenoiser",
    "sample_features",
    "sample_root",
    "window_starts",
    "window_weights",
]
