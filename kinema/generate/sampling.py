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

World-frame joint targets. Joint positions are stored with x/z relative to the smoothed root, so a
target given in world x/z (``world_xz (B, T, J, 2)`` where ``world_mask (B, T, J)``) can only be imputed
once the root is known. The root is predicted by the model itself, so after every denoising step the
relative target is refreshed from the current x0 estimate of the root: ``j_p.xz = world.xz - root.xz``.
The first step runs without these channels; by the last step root and target agree.
"""

from __future__ import annotations

import torch

from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import DDIMSampler
from kinema.model.denoiser import Denoiser
from kinema.motion.features import FeatureLayout


def displace_root(x0: torch.Tensor, tgt: torch.Tensor, mask: torch.Tensor, channels=(0, 2)) -> torch.Tensor:
    """Move the predicted smoothed-root trajectory onto its constraints with a smooth displacement.

    ``x0``/``tgt``/``mask`` ``(B, T, D)`` (normalised; the map is affine per channel, so a displacement
    there is a displacement in metres). For each root channel, the residuals ``tgt - x0`` on constrained
    frames are interpolated piecewise-linearly over time (through 0 at frame 0 when frame 0 is free, so
    the motion still starts where the model put it; held after the last constrained frame) and added to
    every frame. Unlike overwriting the constrained frames alone, the trajectory stays continuous, so
    the next denoising step sees (and the body stage follows) a root that leads to the targets.
    """
    out = x0.clone()
    B, T, _ = x0.shape
    time = torch.arange(T)
    for b in range(B):
        for c in channels:
            k = torch.nonzero(mask[b, :, c] > 0).flatten()
            if k.numel() == 0:
                continue
            r = tgt[b, k, c] - x0[b, k, c]
            if int(k[0]) != 0:
                k, r = torch.cat([k.new_zeros(1), k]), torch.cat([r.new_zeros(1), r])
            lo = (torch.searchsorted(k, time, right=True) - 1).clamp(0, k.numel() - 1)
            hi = (lo + 1).clamp(max=k.numel() - 1)
            span = (k[hi] - k[lo]).clamp_min(1).to(x0.dtype)
            w = ((time - k[lo]).to(x0.dtype) / span).clamp(0, 1)
            w = torch.where(hi > lo, w, torch.zeros_like(w))
            out[b, :, c] = x0[b, :, c] + (1 - w) * r[lo] + w * r[hi]
    return out


def _world_channels(num_joints: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Feature indices of joint_pos x and z for every joint: (J,), (J,)."""
    start = FeatureLayout(num_joints).slices["joint_pos"].start
    x = start + 3 * torch.arange(num_joints)
    return x, x + 2


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
    root_displacement: bool = True,
) -> torch.Tensor:
    """Run the reverse process for a batch of ``c_dir.shape[0]`` motions of ``num_frames`` frames."""
    B = c_dir.shape[0]
    D = denoiser.config.feature_dim
    J = denoiser.config.num_joints
    if steps is not None:
        sampler.set_timesteps(steps)
    has_world = world_xz is not None and world_mask is not None and bool(world_mask.any())
    if mask is None and has_world:
        mask = torch.zeros(B, num_frames, D)
        x_tgt = torch.zeros(B, num_frames, D)
    tgt = None
    if mask is not None:
        if x_tgt is None:
            raise ValueError("a constraint mask needs targets")
        mask = mask.float().clone()
        tgt = torch.nan_to_num(x_tgt.float()).clone()
    if text_emb is None:
        text_mask = torch.zeros(B, dtype=torch.bool)
        if mask is None:
            guidance = Guidance(mode="none")
    else:
        text_mask = None
    ix, iz = _world_channels(J)
    state = {"world_on": False}

    def refresh_world(x0_norm: torch.Tensor) -> None:
        """Re-target world-frame joints against the current root estimate (unnormalised)."""
        root = denoiser.denormalize(x0_norm)[..., [0, 2]]  # (B, T, 2)
        rel = world_xz - root[:, :, None, :]  # (B, T, J, 2)
        m = world_mask.float()
        tgt[..., ix] = torch.where(m > 0, rel[..., 0], tgt[..., ix])
        tgt[..., iz] = torch.where(m > 0, rel[..., 1], tgt[..., iz])
        mask[..., ix] = torch.maximum(mask[..., ix], m)
        mask[..., iz] = torch.maximum(mask[..., iz], m)
        state["world_on"] = True

    def denoise(x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        tgt_n = None if mask is None else denoiser.normalize(tgt) * mask
        x0 = denoiser.forward_guided(x_t, t, text_emb, c_dir, tgt_n, mask, None, guidance, text_mask=text_mask)
        if root_displacement and mask is not None:
            x0 = displace_root(x0, tgt_n, mask)
        if has_world:
            refresh_world(x0)
        return x0

    x = sampler.sample(denoise, (B, num_frames, D), generator=generator, progress=progress)
    return denoiser.denormalize(x)
