"""Objectives met by optimising the diffusion noise (DNO, Karunratanakul et al. 2023; SFControl Sec. 3.1.2).

The initial noise ``z (B, T, D)`` of a short deterministic DDIM chain (``ddim_steps``, default 5) is
optimised with Adam so that the generated motion minimises the sum of the bound objectives' losses
(kinema.objectives.terms) evaluated on its world joint positions. The chain is the sampler's own
(guided denoiser, root corrections and constraint imputation: kinema.human.sampling.clean_estimate_fn),
run with autograd, so explicit constraints keep working next to objectives. After every Adam step the
noise is projected back onto the sphere of radius ``sqrt(T D)`` where N(0, I) samples concentrate (the
DNO prior that keeps the chain's input typical); a ``realism`` objective adds a prior on the output.
The motion returned per sample is the best one seen (lowest total loss), so optimisation never makes
a sample worse by its own measure. Shapes: features ``(B, T, D)`` unnormalised; positions metres.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import torch

from kinema.diffusion.sampler import DDIMSampler, spaced_timesteps
from kinema.errors import KinemaError
from kinema.human.sampling import SampleSettings, SampleTargets, clean_estimate_fn
from kinema.model.loading import LoadedModel
from kinema.objectives.terms import Bound
from kinema.representation.flat import FlatRepresentation

#: DDIM steps inside the optimisation loop when the caller gives none (docs/objectives.md: trade-off)
DEFAULT_DDIM_STEPS = 5
#: Adam iterations when the caller gives none. kinema bench objectives (reach, 5-s walk, 5 DDIM steps,
#: one thread, load average 4.5): 8 iterations 10.1 s, 13.7 cm raw after snapping; 12 iterations 10.6 s,
#: 10.1 cm (noise optimisation alone 10.4 cm); 0 cm after post-processing both (docs/objectives.md)
DEFAULT_ITERATIONS = 12
DEFAULT_LR = 0.5


@dataclass(frozen=True)
class NoiseOptSettings:
    """``iterations`` Adam steps (0 = measure only) on the initial noise of a ``ddim_steps`` chain."""

    iterations: int = DEFAULT_ITERATIONS
    lr: float = DEFAULT_LR
    snap: bool = True  # impose the reached timing as explicit targets afterwards (kinema.objectives.snap)
    constraint_weight: float = 1.0  # keeps the call's explicit constraints (see constraint_penalty)

    def __post_init__(self):
        if isinstance(self.iterations, bool) or not isinstance(self.iterations, int) or self.iterations < 0:
            raise KinemaError(f"objective steps must be an integer >= 0, got {self.iterations!r}")
        if not (math.isfinite(self.lr) and self.lr > 0):
            raise KinemaError(f"objective learning rate must be positive, got {self.lr!r}")


def _chain(fn, sampler: DDIMSampler, z: torch.Tensor, steps: int) -> torch.Tensor:
    """The deterministic DDIM chain from noise ``z`` (normalised x0 out), differentiable."""
    ts = spaced_timesteps(sampler.num_train_steps, steps, sampler.timestep_spacing)
    x = z
    for t, prev in zip(ts, ts[1:] + [-1], strict=True):
        x0 = fn(x, torch.full((x.shape[0],), t, dtype=torch.long))
        x = sampler.step_to(x0, t, prev, x)
    return x


def constraint_penalty(rep: FlatRepresentation, feats: torch.Tensor, targets: SampleTargets) -> torch.Tensor:
    """Mean squared miss ``(B,)`` of the explicit targets, in normalised feature units, on the channels
    ``targets.mask`` constrains (0 without any). Imputation alone is soft: without this term the
    optimiser is free to trade a keyframe (e.g. a start pose) for an objective."""
    if targets.mask is None or targets.x_tgt is None:
        return feats.new_zeros(feats.shape[0])
    m = targets.mask.to(feats)
    miss = (rep.normalize(feats) - rep.normalize(torch.nan_to_num(targets.x_tgt.to(feats)))) * m
    return (miss**2).flatten(1).sum(dim=1) / m.flatten(1).sum(dim=1).clamp_min(1.0)


def total_loss(bound: list[Bound], P: torch.Tensor) -> torch.Tensor:
    """Sum of the weighted objective losses per sample ``(B,)``."""
    return torch.stack([b.loss(P) for b in bound]).sum(dim=0)


def errors(bound: list[Bound], P: torch.Tensor) -> list[list[float]]:
    """Per objective, its error for every sample (metres; realism in m/s^2)."""
    with torch.no_grad():
        return [[float(v) for v in b.error(P)] for b in bound]


def optimise_noise(
    loaded: LoadedModel,
    text_emb,
    targets: SampleTargets,
    settings: SampleSettings,
    bound: list[Bound],
    opt: NoiseOptSettings,
    *,
    generator: torch.Generator | None = None,
    progress: bool = False,
) -> tuple[torch.Tensor, torch.Tensor, dict]:
    """Optimised unnormalised features ``(B, T, D)``, the noise that gave them and a report
    ``{"iterations", "ddim_steps", "seconds", "loss": {"before", "after"}, "objectives": [{"type", "before",
    "after"}]}`` (per-sample lists); ``loaded``'s denoiser, sampler and representation."""
    t0, denoiser, sampler, rep = time.perf_counter(), loaded.denoiser, loaded.sampler, loaded.representation
    B, T, D = targets.batch_size, settings.num_frames, rep.dim
    steps = settings.steps or DEFAULT_DDIM_STEPS
    z = torch.randn((B, T, D), generator=generator).requires_grad_(True)
    radius = math.sqrt(T * D)
    adam = torch.optim.Adam([z], lr=opt.lr)
    best_loss = torch.full((B,), math.inf)
    best, best_z = torch.zeros(B, T, D), torch.zeros(B, T, D)
    first_loss, before = None, None
    bar = range(opt.iterations + 1)
    if progress:
        from tqdm.auto import tqdm  # optional progress bar, as kinema.diffusion.sampler does

        bar = tqdm(bar, desc="objectives", leave=False)
    for it in bar:
        fn = clean_estimate_fn(denoiser, rep, text_emb, targets, settings)  # fresh per pass: it keeps state
        feats = rep.denormalize(_chain(fn, sampler, z, steps))
        P = rep.pose(feats)
        loss = total_loss(bound, P) + opt.constraint_weight * constraint_penalty(rep, feats, targets)
        if it == 0:
            first_loss, before = loss.detach().clone(), errors(bound, P)
        better = loss.detach() < best_loss
        best_loss = torch.where(better, loss.detach(), best_loss)
        best[better] = feats.detach()[better]
        best_z[better] = z.detach()[better]
        if it == opt.iterations:
            break
        (grad,) = torch.autograd.grad(loss.sum(), z)
        z.grad = grad
        adam.step()
        with torch.no_grad():
            z.mul_(radius / z.flatten(1).norm(dim=1).clamp_min(1e-6)[:, None, None])
    after = errors(bound, rep.pose(best))
    report = {
        "iterations": opt.iterations,
        "ddim_steps": steps,
        "seconds": round(time.perf_counter() - t0, 3),
        "loss": {"before": [float(v) for v in first_loss], "after": [float(v) for v in best_loss]},
        "objectives": [
            {"type": b.spec.kind, "before": bf, "after": af} for b, bf, af in zip(bound, before, after, strict=True)
        ],
    }
    return best, best_z, report
