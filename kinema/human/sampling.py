"""Sample Kimodo features from a denoiser with DDIM, guidance and constraint imputation.

Shapes: ``text_emb (B, E)``, ``c_dir (B, 2)``, ``x_tgt``/``mask`` ``(B, T, D)`` in *unnormalised*
feature units (metres, radians...) — they are normalised here, with the representation's statistics
(kinema.representation.flat, which also names every channel used below). Inputs come as two small
dataclasses: `SampleTargets` (per-row conditions) and `SampleSettings` (length, guidance, steps and
the corrections below).
Returns the model's unnormalised x0 prediction ``(B, T, D)``. Constraints enter through the model's
own imputation (Kimodo Sec. 4.2) and, for the smoothed root only, through ``displace_root`` after every
step (``root_displacement``, on by default; not in the paper): the small CPU-trained root stage predicts
global root positions far less precisely than the body stage predicts the body (measured on the
shipped model's run at step 5000, 24 validation cases, 25 steps: full-body keyframe error 92 -> 3.1 cm,
end-effector 103 -> 13 cm, 2D root 99 -> 7.6 cm with it). The constrained channels are never simply
overwritten in the output, and the evaluation measures constraints on the final motion (FK positions,
smoothed pelvis), so raw errors stay the model's; post-processing makes them exact.

Two more root-only corrections after every step (also not in the paper, both justified by how the
features are defined): the predicted smoothed-root x/z is filtered with a 0.25-s Gaussian
(``root_smoothing``; the smoothed root is the pelvis under a 0.5-s Gaussian, so a valid one barely
changes) and a free frame 0 is pinned to the origin when no root target exists (``anchor_start``; every
training crop starts there), else shifted with the first root target (see ``displace_root``).
Measured at step 6000 on a 4-s walk: root second differences 17-28 -> 0.3 cm/frame^2, start 0.5-0.7 m
-> 0; on 24 validation cases: 2D root 8.4 -> 4.8 cm, raw skate 53 -> 40 cm/s, jerk 1537 -> 839.

Where a root x/z target has no pelvis target beside it (waypoints, paths, end-effector constraints),
the displacement aims the root at ``target - smooth(pelvis offset)`` (``pelvis_offset_targets``): the
smoothed root is *defined* as the pelvis under a 0.5-s Gaussian, and what is measured (and what a user
sees) is that smoothed pelvis, ``smooth(root + offset)``; the model's pelvis offset keeps a small
low-frequency part, so aiming the root channel itself at the target left the smoothed pelvis short of
it. Measured on the shipped model, 50 steps: 24 validation cases 2D root 5.5 -> 4.2 cm, pelvis p95
9.4 -> 4.0 cm, every other metric unchanged; 100 test cases pelvis p95 12.4 -> 4.5 cm, per-case median
2D root 1.26 -> 0.57 cm, mean 5.18 -> 5.21 cm (set by five cases the model does not follow at all,
10-40 cm). Where a full-body keyframe gives the pelvis too, the pair (root, offset) is the target's
own and is left alone (shifting it there raised the full-body error 1.0 -> 1.5 cm). Aiming at
``target - (smooth(root + offset) - root)`` instead was worse on validation (2D root 4.8 cm, EE
10.4 vs 10.0 cm).

World-frame joint targets. Joint positions are stored with x/z relative to the smoothed root, so a
target given in world x/z (``world_xz (B, T, J, 2)`` where ``world_mask (B, T, J)``) can only be imputed
once the root is known. The root is predicted by the model itself, so after every denoising step the
relative target is refreshed from the current x0 estimate of the root: ``j_p.xz = world.xz - root.xz``.
The first step runs without these channels; by the last step root and target agree.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import torch

from kinema.diffusion.guidance import Guidance
from kinema.diffusion.guidance_cache import GuidanceCache
from kinema.human.keyjoints import KeyjointTargets, joint_displacement
from kinema.model.denoiser import Denoiser
from kinema.model.loading import LoadedModel
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS, smooth_time
from kinema.representation.flat import FlatRepresentation

#: Gaussian (seconds) applied to the predicted smoothed-root x/z after every step. The smoothed root
#: is itself the pelvis under a 0.5-s Gaussian, so a further 0.25-s filter leaves a valid one almost
#: unchanged (combined width 0.56 s) while removing the frame-to-frame noise of an imprecise root stage.
ROOT_SMOOTHING_SECONDS = 0.25

#: Gaussian (seconds) over which a keyjoint's miss is spread into its position channels after every
#: step (kinema.human.keyjoints): wide enough that the joint bends towards the target over a few
#: frames instead of snapping at the keyframe.
JOINT_SIGMA_SECONDS = 0.6


def displace_root(
    x0: torch.Tensor, tgt: torch.Tensor | None, mask: torch.Tensor | None, anchor_start: bool = True,
    origin: tuple[float, float] = (0.0, 0.0), channels: Sequence[int] = (0, 2),
) -> torch.Tensor:
    """Move the predicted smoothed-root x/z trajectory onto its targets with a smooth displacement.

    ``x0``/``tgt``/``mask`` ``(B, T, D)`` (normalised; the map is affine per channel, so a displacement
    there is a displacement in metres; ``tgt``/``mask`` may be None). For each root channel, the
    residuals ``tgt - x0`` on constrained frames are interpolated piecewise-linearly over time (held
    after the last constrained frame) and added to every frame. Unlike overwriting the constrained
    frames alone, the trajectory stays continuous, so the next denoising step sees (and the body stage
    follows) a root that leads to the targets.

    With ``anchor_start``, a channel with no target at frame 0 (i) holds its first target's residual
    back to frame 0 when it has targets: the model's own trajectory is shifted onto the first target
    instead of being stretched from the origin to it (root targets are world positions and may lie
    anywhere: a path that starts 1.9 m from the origin three frames in was missed by 39 cm; 100 test
    cases, 2D root 5.21 -> 2.59 cm; 24 validation cases 4.24 -> 2.11 cm; jerk unchanged or lower), or
    (ii) is pinned to the origin when it has none: every training crop starts with its smoothed root
    there (kinema.representation.transform.canonicalize_start), and saying it stops an imprecise root stage from
    starting the motion half a metre away (measured at step 6000: 0.5-0.7 m along +Z for a walk).
    ``origin`` is the origin in the normalised units of ``x0``. Without ``anchor_start`` a free frame 0
    keeps its value.
    ``channels`` are the root x/z indices (``FeatureLayout.root_xz``).
    """
    ch = list(channels)
    x = x0[..., ch]  # (B, T, 2)
    T = x.shape[1]
    if mask is None or tgt is None:
        m, r = torch.zeros_like(x, dtype=torch.bool), torch.zeros_like(x)
    else:
        m = mask[..., ch] > 0
        r = torch.where(m, tgt[..., ch] - x, torch.zeros_like(x))
    # frame 0 always carries a residual: its target, else (anchor_start) the first target's or the
    # origin's, else none
    r0 = x.new_tensor(origin) - x[:, 0] if anchor_start else torch.zeros_like(x[:, 0])
    if anchor_start:  # a free start follows the first target of its channel where there is one
        has = m.any(dim=1)  # (B, 2)
        first = torch.where(m, torch.arange(T).view(1, T, 1), T).amin(dim=1).clamp(max=T - 1)  # (B, 2)
        r0 = torch.where(has, r.gather(1, first[:, None, :])[:, 0], r0)
    r = r.clone()  # fresh tensors: the in-place edits below must not touch what autograd saved
    r[:, 0] = torch.where(m[:, 0], r[:, 0], r0)
    m = m.clone()
    m[:, 0] = True
    time = torch.arange(T).view(1, T, 1).expand_as(x)
    prev = torch.where(m, time, -1).cummax(dim=1).values  # last constrained frame <= t
    nxt = torch.where(m, time, T).flip(1).cummin(dim=1).values.flip(1)  # first constrained frame >= t
    span = (nxt - prev).clamp_min(1).to(x.dtype)
    w = torch.where(nxt < T, (time - prev).to(x.dtype) / span, torch.zeros_like(x))
    out = x0.clone()
    out[..., ch] = x + (1 - w) * r.gather(1, prev) + w * r.gather(1, nxt.clamp(max=T - 1))
    return out


def pelvis_offset_targets(
    x0: torch.Tensor, tgt: torch.Tensor, mask: torch.Tensor, rep: FlatRepresentation, sigma_frames: float,
) -> torch.Tensor:
    """Root x/z targets for :func:`displace_root` that put the *smoothed pelvis* on the target.

    ``x0``/``tgt``/``mask`` ``(B, T, D)`` normalised. On frames with a root x/z target but no pelvis
    x/z target, ``tgt.root_xz -= smooth(x0.pelvis_xz_offset)`` (Gaussian over ``sigma_frames``, the
    smoothed root's own filter), converted to normalised units; other channels and frames unchanged.
    """
    rxz, pxz = rep.root_xz, rep.pelvis_xz  # the pelvis's joint_pos x/z is its offset from the root
    mean, std = rep.mean, rep.std
    bias = smooth_time(x0[..., pxz] * std[pxz] + mean[pxz], sigma_frames)  # (B, T, 2) metres
    free = (mask[..., rxz] > 0) & (mask[..., pxz] == 0)
    out = tgt.clone()
    out[..., rxz] = torch.where(free, tgt[..., rxz] - bias / std[rxz], tgt[..., rxz])
    return out


#: Most rows x frames in one denoiser pass (guidance branches count as rows). The batch rows are
#: independent motions, so a large batch is sampled in chunks: on one CPU thread (shipped model, median
#: of 6 interleaved runs) a row of 100 frames cost 8.9 ms alone in a batch of 2, 6.5-6.8 ms in 12-48
#: rows, but a row of 200 frames 16.8 ms in 2, 14.6 ms in 6-12 and 19.0 ms in 48 rows (the attention
#: matrices outgrow the caches). 2400 keeps every pass near the fastest batch size.
MAX_BATCH_FRAMES = 2400


@dataclass(frozen=True)
class SampleTargets:
    """Per-row conditions of one batch: ``c_dir (B, 2)`` first-frame heading (cos, sin); optional
    unnormalised feature targets ``x_tgt``/``mask (B, T, D)`` and world joint x/z ``world_xz (B, T, J, 2)``
    where ``world_mask (B, T, J)`` (kinema.representation.encode); ``context_mask (B, T, D)``: entries of
    ``mask`` every guidance branch sees (a timeline's join frames;
    :meth:`kinema.model.denoiser.Denoiser.forward_guided`); ``start (B, T, D)``: unnormalised features
    the reverse process starts from instead of pure noise (a timeline's join windows;
    ``SampleSettings.strength``)."""

    c_dir: torch.Tensor
    x_tgt: torch.Tensor | None = None
    mask: torch.Tensor | None = None
    world_xz: torch.Tensor | None = None
    world_mask: torch.Tensor | None = None
    context_mask: torch.Tensor | None = None
    start: torch.Tensor | None = None

    @property
    def batch_size(self) -> int:
        return int(self.c_dir.shape[0])

    @property
    def has_world(self) -> bool:
        return self.world_xz is not None and self.world_mask is not None and bool(self.world_mask.any())

    def rows(self, lo: int, hi: int) -> SampleTargets:
        """Rows ``[lo, hi)`` of every tensor."""
        return SampleTargets(*(None if v is None else v[lo:hi] for v in
                               (self.c_dir, self.x_tgt, self.mask, self.world_xz, self.world_mask,
                                self.context_mask, self.start)))

    def pruned(self) -> SampleTargets:
        """Without world targets when none is set, and without a mask that constrains nothing."""
        if self.has_world:
            return self
        if self.mask is not None and not bool(self.mask.any()):
            return SampleTargets(self.c_dir, start=self.start)
        return replace(self, world_xz=None, world_mask=None)


@dataclass(frozen=True)
class SampleSettings:
    """How to sample: ``num_frames``, ``guidance``, DDIM ``steps`` (None: the sampler's default) and the
    per-step corrections of the module docstring (``root_displacement`` with ``anchor_start``,
    ``root_smoothing`` and ``joint_sigma`` in seconds; 0 / False turns one off). ``strength`` (0, 1]:
    the share of the steps run when the targets give a ``start`` (kinema.diffusion.sampler).
    ``guidance_refresh`` > 1 caches the separated guidance's ``guidance_cached`` branch ("text" or
    "constr"): it runs on every ``guidance_refresh``-th step only and its last difference is reused on the
    others (kinema.diffusion.guidance_cache); 1 (the default) runs every branch at every step."""

    num_frames: int
    guidance: Guidance
    steps: int | None = None
    root_displacement: bool = True
    anchor_start: bool = True
    root_smoothing: float = ROOT_SMOOTHING_SECONDS
    joint_sigma: float = JOINT_SIGMA_SECONDS
    strength: float = 1.0
    max_batch_frames: int = MAX_BATCH_FRAMES
    guidance_refresh: int = 1
    guidance_cached: str = "constr"


@torch.no_grad()
def sample_features(
    loaded: LoadedModel, text_emb: torch.Tensor | None, targets: SampleTargets, settings: SampleSettings, *,
    generator: torch.Generator | None = None, progress: bool = False, init_noise: torch.Tensor | None = None,
    on_step: Callable[[int, int], None] | None = None,
) -> torch.Tensor:
    """Run the reverse process of ``loaded``'s denoiser and DDIM sampler for ``targets.batch_size``
    motions of ``settings.num_frames`` frames; returns unnormalised features ``(B, T, D)`` of its
    representation.

    The batch rows are independent motions: row i depends only on its own noise and targets (the
    denoiser, the root / joint corrections and DDIM all act per row), so the batch is sampled in
    chunks of at most ``settings.max_batch_frames`` rows x frames per denoiser pass. The initial noise is one
    ``(B, T, D)`` N(0, I) draw from ``generator`` (or ``init_noise``), so the chunking never changes
    which noise a row gets.

    A mask with nothing constrained (and no world targets) is dropped: with an all-zero mask the
    separated-guidance constraint branch sees exactly the unconditional branch's input, so
    ``(1 - w_t - w_c) D0 + w_t D_text + w_c D_constr`` equals the two-branch ``(1 - w_t) D0 + w_t D_text``
    up to float rounding, and every step runs 2 branches instead of 3 (docs/speed.md).

    ``on_step(done, total)`` counts denoiser steps over all chunks of this call.
    """
    denoiser, sampler, rep = loaded.denoiser, loaded.sampler, loaded.representation
    B, T, D = targets.batch_size, settings.num_frames, rep.dim
    targets = targets.pruned()
    if init_noise is None:
        gen_device = generator.device if generator is not None else "cpu"
        init_noise = torch.randn((B, T, D), generator=generator, device=gen_device)
    constrained = targets.mask is not None or targets.has_world
    branches = _branch_count(settings.guidance, text_emb is not None, constrained)
    chunk = max(1, settings.max_batch_frames // (branches * T))
    out, starts = [], range(0, B, chunk)
    for c, lo in enumerate(starts):
        text = None if text_emb is None else text_emb[lo : lo + chunk]
        step = _StepCorrections(denoiser, rep, text, targets.rows(lo, lo + chunk), settings)
        count = None if on_step is None else (lambda d, n, c=c: on_step(c * n + d, len(starts) * n))
        start = None if targets.start is None else rep.normalize(targets.start[lo : lo + chunk].float())
        x = sampler.sample(step, (step.batch, T, D), generator=generator, progress=progress,
                           num_inference_steps=settings.steps, init_noise=init_noise[lo : lo + chunk], on_step=count,
                           start_x0=start, strength=settings.strength)
        out.append(rep.denormalize(x))
    return torch.cat(out)


def clean_estimate_fn(denoiser: Denoiser, rep: FlatRepresentation, text_emb: torch.Tensor | None,
                      targets: SampleTargets, settings: SampleSettings):
    """The clean-estimate function ``(x_t, t) -> x0`` (normalised) that :func:`sample_features` hands to
    DDIM: guided denoiser plus the corrections of the module docstring. For callers that run their own
    DDIM loop, e.g. a differentiable one (kinema.human.noise_optimisation); every operation is differentiable.
    Guidance caching is off here (the function may be called out of step order)."""
    return _StepCorrections(denoiser, rep, text_emb, targets.pruned(), replace(settings, guidance_refresh=1))


def _branch_count(guidance: Guidance, has_text: bool, constrained: bool) -> int:
    """Denoiser rows per motion at every step (what ``_StepCorrections`` and ``forward_guided`` will run)."""
    if not has_text and not constrained:
        return 1  # no condition at all: the guidance is "none"
    if not constrained:
        guidance = guidance.without_constraints()
    return len(guidance.branches)


class _StepCorrections:
    """The clean-estimate function DDIM calls at every step for one chunk of rows: guided denoiser, then
    root smoothing, root displacement, keyjoint displacement and world-target refresh (module docstring)."""

    def __init__(self, denoiser: Denoiser, rep: FlatRepresentation, text_emb: torch.Tensor | None,
                 targets: SampleTargets, settings: SampleSettings):
        self.denoiser, self.rep, self.text_emb, self.settings = denoiser, rep, text_emb, settings
        self.batch, T = targets.batch_size, settings.num_frames
        self.c_dir, self.has_world = targets.c_dir, targets.has_world
        self.world_xz, self.world_mask = targets.world_xz, targets.world_mask
        self.context_mask = targets.context_mask
        self.mask, self.tgt = _working_targets(self.batch, T, rep.dim, targets.x_tgt, targets.mask, self.has_world)
        self.smooth_frames = settings.root_smoothing * rep.fps
        self.pelvis_frames = DEFAULT_ROOT_SIGMA_SECONDS * rep.fps
        self.origin = tuple(float(v) for v in rep.normalize(torch.zeros(rep.dim))[rep.root_xz])
        self.guidance, self.text_mask = settings.guidance, None
        if text_emb is None:
            self.text_mask = torch.zeros(self.batch, dtype=torch.bool)
            if self.mask is None:
                self.guidance = Guidance(mode="none")
        self.keys = None
        if self.mask is not None and settings.joint_sigma > 0:
            keys = KeyjointTargets(rep, self.tgt, self.mask, self.world_xz if self.has_world else None,
                                   self.world_mask if self.has_world else None)
            self.keys = keys if keys.any else None
        self.cache = (GuidanceCache(settings.guidance_refresh, settings.guidance_cached)
                      if settings.guidance_refresh > 1 else None)

    def __call__(self, x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        rep, s, mask = self.rep, self.settings, self.mask
        tgt_n = None if mask is None else rep.normalize(self.tgt) * mask
        x0 = self.denoiser.forward_guided(x_t, t, self.text_emb, self.c_dir, tgt_n, mask, None, self.guidance,
                                          text_mask=self.text_mask,
                                          context_mask=None if mask is None else self.context_mask,
                                          cache=self.cache)
        rxz = rep.root_xz
        if self.smooth_frames > 0:
            x0 = x0.clone()
            x0[..., rxz] = smooth_time(x0[..., rxz], self.smooth_frames)
        if s.root_displacement:
            aim = tgt_n if mask is None else pelvis_offset_targets(x0, tgt_n, mask, rep, self.pelvis_frames)
            x0 = displace_root(x0, aim, mask, anchor_start=s.anchor_start, origin=self.origin, channels=rxz)
        if self.keys is not None:  # metres / std: the displacement in the normalised joint_pos channels
            disp = joint_displacement(rep.denormalize(x0), self.keys, rep, s.joint_sigma * rep.fps)
            jp = rep.joint_pos
            x0 = x0.clone()
            x0[..., jp] = x0[..., jp] + disp.flatten(-2) / rep.std[jp]
        if self.has_world:
            self.tgt, self.mask = _refresh_world(rep, x0, self.world_xz, self.world_mask, self.tgt, mask)
        return x0


def _working_targets(B: int, T: int, D: int, x_tgt: torch.Tensor | None, mask: torch.Tensor | None,
                     has_world: bool) -> tuple[torch.Tensor | None, torch.Tensor | None]:
    """(mask, targets) the sampler may update in place: float copies, NaN targets zeroed; zeros when
    only world-frame targets exist (their channels are filled by :func:`_refresh_world`); (None, None)
    without constraints."""
    if mask is None and has_world:
        mask, x_tgt = torch.zeros(B, T, D), torch.zeros(B, T, D)
    if mask is None:
        return None, None
    if x_tgt is None:
        raise ValueError("a constraint mask needs targets")
    return mask.float().clone(), torch.nan_to_num(x_tgt.float()).clone()


def _refresh_world(rep: FlatRepresentation, x0_norm: torch.Tensor, world_xz: torch.Tensor, world_mask: torch.Tensor,
                   tgt: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Re-target world-frame joints against the current root estimate: new ``(tgt, mask)`` (unnormalised).

    New tensors rather than in-place edits, so a differentiable chain (kinema.objectives) can reuse the
    previous step's targets in its backward pass."""
    tgt, mask = tgt.clone(), mask.clone()
    ix, iz = rep.joint_pos_axis(0), rep.joint_pos_axis(2)
    root = rep.denormalize(x0_norm)[..., rep.root_xz]  # (B, T, 2)
    rel = world_xz - root[:, :, None, :]  # (B, T, J, 2)
    m = world_mask.float()
    tgt[..., ix] = torch.where(m > 0, rel[..., 0], tgt[..., ix])
    tgt[..., iz] = torch.where(m > 0, rel[..., 1], tgt[..., iz])
    mask[..., ix] = torch.maximum(mask[..., ix], m)
    mask[..., iz] = torch.maximum(mask[..., iz], m)
    return tgt, mask
