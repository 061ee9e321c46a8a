"""Sample Kimodo features from a denoiser with DDIM, guidance and constraint imputation.

Shapes: ``text_emb (B, E)``, ``c_dir (B, 2)``, ``x_tgt``/``mask`` ``(B, T, D)`` in *unnormalised*
feature units (metres, radians...) — they are normalised here, with the model's statistics.
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

from collections.abc import Sequence

import torch

from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import DDIMSampler
from kinema.generate.keyjoints import FeaturePoser, KeyjointTargets, joint_displacement
from kinema.model.denoiser import Denoiser
from kinema.motion.features import FeatureLayout
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS, smooth_time

#: Gaussian (seconds) applied to the predicted smoothed-root x/z after every step. The smoothed root
#: is itself the pelvis under a 0.5-s Gaussian, so a further 0.25-s filter leaves a valid one almost
#: unchanged (combined width 0.56 s) while removing the frame-to-frame noise of an imprecise root stage.
ROOT_SMOOTHING_SECONDS = 0.25

#: Gaussian (seconds) over which a keyjoint's miss is spread into its position channels after every
#: step (kinema.generate.keyjoints): wide enough that the joint bends towards the target over a few
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
    there (kinema.motion.transform.canonicalize_start), and saying it stops an imprecise root stage from
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
    r[:, 0] = torch.where(m[:, 0], r[:, 0], r0)
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
    x0: torch.Tensor, tgt: torch.Tensor, mask: torch.Tensor, denoiser: Denoiser, sigma_frames: float,
) -> torch.Tensor:
    """Root x/z targets for :func:`displace_root` that put the *smoothed pelvis* on the target.

    ``x0``/``tgt``/``mask`` ``(B, T, D)`` normalised. On frames with a root x/z target but no pelvis
    x/z target, ``tgt.root_xz -= smooth(x0.pelvis_xz_offset)`` (Gaussian over ``sigma_frames``, the
    smoothed root's own filter), converted to normalised units; other channels and frames unchanged.
    """
    J = denoiser.config.num_joints
    rxz = FeatureLayout(J).root_xz
    ix, iz = _world_channels(J)
    pxz = [int(ix[0]), int(iz[0])]  # the pelvis is joint 0: its joint_pos is the offset from the root
    mean, std = denoiser.feat_mean, denoiser.feat_std
    bias = smooth_time(x0[..., pxz] * std[pxz] + mean[pxz], sigma_frames)  # (B, T, 2) metres
    free = (mask[..., rxz] > 0) & (mask[..., pxz] == 0)
    out = tgt.clone()
    out[..., rxz] = torch.where(free, tgt[..., rxz] - bias / std[rxz], tgt[..., rxz])
    return out


def _world_channels(num_joints: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Feature indices of joint_pos x and z for every joint: (J,), (J,)."""
    start = FeatureLayout(num_joints).slices["joint_pos"].start
    x = start + 3 * torch.arange(num_joints)
    return x, x + 2


#: Most rows x frames in one denoiser pass (guidance branches count as rows). The batch rows are
#: independent motions, so a large batch is sampled in chunks: on one CPU thread (shipped model, median
#: of 6 interleaved runs) a row of 100 frames cost 8.9 ms alone in a batch of 2, 6.5-6.8 ms in 12-48
#: rows, but a row of 200 frames 16.8 ms in 2, 14.6 ms in 6-12 and 19.0 ms in 48 rows (the attention
#: matrices outgrow the caches). 2400 keeps every pass near the fastest batch size.
MAX_BATCH_FRAMES = 2400


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
    world_xz: torch.Tensor | None = None,
    world_mask: torch.Tensor | None = None,
    init_noise: torch.Tensor | None = None,
    max_batch_frames: int = MAX_BATCH_FRAMES,
    context_mask: torch.Tensor | None = None,
    **options,
) -> torch.Tensor:
    """Run the reverse process for a batch of ``c_dir.shape[0]`` motions of ``num_frames`` frames.

    The batch rows are independent motions: row i depends only on its own noise and targets (the
    denoiser, the root / joint corrections and DDIM all act per row), so the batch is sampled in
    chunks of at most ``max_batch_frames`` rows x frames per denoiser pass. The initial noise is one
    ``(B, T, D)`` N(0, I) draw from ``generator`` (or ``init_noise``), so the chunking never changes
    which noise a row gets. ``options``: ``root_displacement``, ``root_smoothing``, ``anchor_start``,
    ``joint_poser``, ``joint_sigma`` (see the module docstring; with ``joint_poser``, the model's
    skeleton, keyjoint targets pull the clean estimate after every step,
    :func:`kinema.generate.keyjoints.displace_joints`).

    A mask with nothing constrained (and no world targets) is dropped: with an all-zero mask the
    separated-guidance constraint branch sees exactly the unconditional branch's input, so
    ``(1 - w_t - w_c) D0 + w_t D_text + w_c D_constr`` equals the two-branch ``(1 - w_t) D0 + w_t D_text``
    up to float rounding, and every step runs 2 branches instead of 3 (docs/speed.md).

    ``context_mask (B, T, D)``: entries of ``mask`` every guidance branch sees (a timeline's join
    frames; :meth:`kinema.model.denoiser.Denoiser.forward_guided`).
    """
    B, D = c_dir.shape[0], denoiser.config.feature_dim
    has_world = world_xz is not None and world_mask is not None and bool(world_mask.any())
    if not has_world:
        world_xz = world_mask = None
        if mask is not None and not bool(mask.any()):
            mask = x_tgt = context_mask = None  # nothing constrained: no constraint branch
    if init_noise is None:
        gen_device = generator.device if generator is not None else "cpu"
        init_noise = torch.randn((B, num_frames, D), generator=generator, device=gen_device)
    branches = _branch_count(guidance, text_emb is not None, mask is not None or has_world)
    chunk = max(1, max_batch_frames // (branches * num_frames))
    rows = [text_emb, c_dir, x_tgt, mask, world_xz, world_mask, init_noise, context_mask]
    out = []
    for lo in range(0, B, chunk):
        text_c, c_dir_c, x_tgt_c, mask_c, wxz_c, wm_c, noise_c, ctx_c = (None if v is None else v[lo : lo + chunk]
                                                                        for v in rows)
        out.append(_sample_rows(denoiser, sampler, num_frames, text_c, c_dir_c, guidance, x_tgt_c, mask_c, steps,
                                generator, progress, wxz_c, wm_c, init_noise=noise_c, context_mask=ctx_c,
                                **options))
    return torch.cat(out)


def _branch_count(guidance: Guidance, has_text: bool, constrained: bool) -> int:
    """Denoiser rows per motion at every step (what ``_sample_rows`` and ``forward_guided`` will run)."""
    if not has_text and not constrained:
        return 1  # no condition at all: the guidance is "none"
    if not constrained:
        guidance = guidance.without_constraints()
    return len(guidance.branches)


def _sample_rows(
    denoiser: Denoiser, sampler: DDIMSampler, num_frames: int, text_emb: torch.Tensor | None, c_dir: torch.Tensor,
    guidance: Guidance, x_tgt: torch.Tensor | None = None, mask: torch.Tensor | None = None,
    steps: int | None = None, generator: torch.Generator | None = None, progress: bool = False,
    world_xz: torch.Tensor | None = None, world_mask: torch.Tensor | None = None,
    root_displacement: bool = True, root_smoothing: float = ROOT_SMOOTHING_SECONDS, anchor_start: bool = True,
    joint_poser: FeaturePoser | None = None, joint_sigma: float = JOINT_SIGMA_SECONDS,
    init_noise: torch.Tensor | None = None, context_mask: torch.Tensor | None = None,
) -> torch.Tensor:
    """:func:`sample_features` for one chunk of rows, all in one denoiser batch per step."""
    B = c_dir.shape[0]
    D = denoiser.config.feature_dim
    J = denoiser.config.num_joints
    has_world = world_xz is not None and world_mask is not None and bool(world_mask.any())
    mask, tgt = _working_targets(B, num_frames, D, x_tgt, mask, has_world)
    smooth_frames = root_smoothing * denoiser.config.fps
    pelvis_frames = DEFAULT_ROOT_SIGMA_SECONDS * denoiser.config.fps
    layout = FeatureLayout(J)
    rxz, jp = layout.root_xz, layout.slices["joint_pos"]
    origin = tuple(float(v) for v in denoiser.normalize(torch.zeros(D))[rxz])
    if text_emb is None:
        text_mask = torch.zeros(B, dtype=torch.bool)
        if mask is None:
            guidance = Guidance(mode="none")
    else:
        text_mask = None
    keys = None
    if joint_poser is not None and mask is not None and joint_sigma > 0:
        keys = KeyjointTargets(tgt, mask, J, world_xz if has_world else None, world_mask if has_world else None)
        keys = keys if keys.any else None

    def denoise(x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        tgt_n = None if mask is None else denoiser.normalize(tgt) * mask
        x0 = denoiser.forward_guided(x_t, t, text_emb, c_dir, tgt_n, mask, None, guidance, text_mask=text_mask,
                                     context_mask=None if mask is None else context_mask)
        if smooth_frames > 0:
            x0 = x0.clone()
            x0[..., rxz] = smooth_time(x0[..., rxz], smooth_frames)
        if root_displacement:
            aim = tgt_n if mask is None else pelvis_offset_targets(x0, tgt_n, mask, denoiser, pelvis_frames)
            x0 = displace_root(x0, aim, mask, anchor_start=anchor_start, origin=origin, channels=rxz)
        if keys is not None:  # metres / std: the displacement in the normalised joint_pos channels
            disp = joint_displacement(denoiser.denormalize(x0), keys, joint_poser, joint_sigma * denoiser.config.fps)
            x0 = x0.clone()
            x0[..., jp] = x0[..., jp] + disp.flatten(-2) / denoiser.feat_std[jp]
        if has_world:
            _refresh_world(denoiser, x0, world_xz, world_mask, tgt, mask)
        return x0

    x = sampler.sample(denoise, (B, num_frames, D), generator=generator, progress=progress, num_inference_steps=steps,
                       init_noise=init_noise)
    return denoiser.denormalize(x)


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


def _refresh_world(denoiser: Denoiser, x0_norm: torch.Tensor, world_xz: torch.Tensor, world_mask: torch.Tensor,
                   tgt: torch.Tensor, mask: torch.Tensor) -> None:
    """Re-target world-frame joints against the current root estimate: ``tgt``/``mask`` in place (unnormalised)."""
    J = denoiser.config.num_joints
    ix, iz = _world_channels(J)
    root = denoiser.denormalize(x0_norm)[..., FeatureLayout(J).root_xz]  # (B, T, 2)
    rel = world_xz - root[:, :, None, :]  # (B, T, J, 2)
    m = world_mask.float()
    tgt[..., ix] = torch.where(m > 0, rel[..., 0], tgt[..., ix])
    tgt[..., iz] = torch.where(m > 0, rel[..., 1], tgt[..., iz])
    mask[..., ix] = torch.maximum(mask[..., ix], m)
    mask[..., iz] = torch.maximum(mask[..., iz], m)
