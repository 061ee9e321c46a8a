"""Keyjoint targets in world space and the sampler's smooth joint displacement.

The model imputes joint-position targets into its input (Kimodo Sec. 4.2), but the posed skeleton
comes from the *rotation* channels through forward kinematics, and a small CPU-trained body stage
follows a single keyframed joint only loosely (measured on the shipped model, 38 end-effector targets
of the test suite: the FK joint misses by 13.9 cm on average, and the model's own joint-position
channel by as much, 14.4 cm, while the two agree with each other to 3.4 cm: the body is consistent
but short of the target). ``displace_joints`` nudges the clean estimate after every denoising step,
like :func:`kinema.human.sampling.displace_root` does for the root: the residual between each
keyjoint target and the FK joint is spread over neighbouring frames with a Gaussian and added to
that joint's position channels, so the next step sees (and the network poses a body around) a
trajectory that bends smoothly towards the target. Frames that pin every joint (full-body
keyframes) are left alone: the model already meets them (about 1 cm) and moving them raised that
error. The output skeleton is posed from the rotation channels, so the nudge reaches it only through
the network's later passes; the one after the last step changes position channels the decoder does not
read (a target on the pelvis itself is the exception: the pelvis position is decoded from them).

What was measured and rejected (24 validation cases, 50 steps; end-effector error 10.0 cm before):
gradient steps on the x0 rotations towards the targets (the next network pass undoes them: 9.6 cm,
full-body 1.0 -> 2.0 cm); decoding rotations from the predicted positions (10.4 cm); shifting the
imputed target by the accumulated miss (2.8 cm, but the hand snaps onto the target in one frame:
its acceleration at the keyframes rose from 26 to 71 m/s^2, ground truth 4).

Shapes: features ``(B, T, D)``; targets ``(B, T, J, 3)`` metres, world frame, Y up.
"""

from __future__ import annotations

from functools import cached_property

import torch

from kinema.representation.flat import FlatRepresentation


class KeyjointTargets:
    """World-space joint position targets ``pos (B, T, J, 3)`` where ``mask (B, T, J, 3)`` is 1.

    Built once from the sampler's unnormalised feature targets: a joint's y from its ``joint_pos``
    y target; its x/z from the world store (``world_xz (B, T, J, 2)`` where ``world_mask (B, T, J)``)
    when given there, else from the root-relative ``joint_pos`` x/z target plus that frame's root
    x/z target.
    """

    def __init__(self, rep: FlatRepresentation, x_tgt: torch.Tensor, mask: torch.Tensor,
                 world_xz: torch.Tensor | None = None, world_mask: torch.Tensor | None = None):
        jp = rep.split(x_tgt)["joint_pos"]
        m = (rep.split(mask)["joint_pos"] > 0).clone()
        rx, rz = rep.root_xz
        root_known = ((mask[..., rx] > 0) & (mask[..., rz] > 0))[..., None]  # (B, T, 1)
        pos = jp.clone()
        pos[..., 0] += x_tgt[..., rx, None]
        pos[..., 2] += x_tgt[..., rz, None]
        m[..., 0] &= root_known
        m[..., 2] &= root_known
        if world_xz is not None and world_mask is not None:
            wm = world_mask > 0
            pos[..., 0] = torch.where(wm, world_xz[..., 0].to(pos), pos[..., 0])
            pos[..., 2] = torch.where(wm, world_xz[..., 1].to(pos), pos[..., 2])
            m[..., 0] |= wm
            m[..., 2] |= wm
        self.pos, self.mask = pos, m.to(x_tgt.dtype)

    @property
    def any(self) -> bool:
        return bool(self.mask.any())

    @cached_property
    def residual_mask(self) -> torch.Tensor:
        """``mask`` without the frames that pin every joint (full-body keyframes): what
        :func:`joint_displacement` moves towards, worked out once for all the sampler's steps."""
        full = self.mask.flatten(-2).amin(-1) > 0  # (B, T)
        return self.mask * (~full)[..., None, None].to(self.mask)

    @cached_property
    def residual_frames(self) -> torch.Tensor:
        """The frames on which some row has a ``residual_mask`` target."""
        return self.residual_mask.flatten(2).amax(-1).amax(0).nonzero().flatten()


def gaussian_spread(residual: torch.Tensor, present: torch.Tensor, sigma_frames: float) -> torch.Tensor:
    """Spread sparse per-frame ``residual (B, T, J, 3)`` (zero where absent) over time.

    ``present (B, T, J)`` marks frames that carry a residual. Each frame gets the Gaussian-weighted
    residuals of nearby present frames divided by ``max(1, sum of weights)``: a lone keyframe keeps its
    full residual and its neighbours a fading share; between close keyframes the shares average.
    """
    T = residual.shape[1]
    t = torch.arange(T, dtype=residual.dtype)
    w = torch.exp(-0.5 * ((t[:, None] - t[None, :]) / sigma_frames) ** 2)  # (T out, T in)
    spread = torch.einsum("st,btjc->bsjc", w, residual)
    norm = torch.einsum("st,btj->bsj", w, present.to(residual.dtype)).clamp_min(1.0)
    return spread / norm[..., None]


def joint_displacement(feats: torch.Tensor, keys: KeyjointTargets, rep: FlatRepresentation,
                       sigma_frames: float) -> torch.Tensor:
    """Metres to add to the ``joint_pos`` channels of unnormalised ``feats (B, T, D)``: ``(B, T, J, 3)``.

    Keyjoint residuals (target - FK joint, posed by ``rep.pose``) spread over time (see module); frames
    whose every joint coordinate is constrained (full-body keyframes) contribute nothing. Only the frames
    with a residual are posed (posing is per frame): a hand target at one frame of 100 poses one frame.
    """
    m, frames = keys.residual_mask, keys.residual_frames
    P = rep.pose(feats[:, frames])
    posed = (keys.pos[:, frames] - P) * m[:, frames]
    residual = posed.new_zeros(posed.shape[:1] + keys.pos.shape[1:]).index_copy(1, frames, posed)
    return gaussian_spread(residual, m.amax(-1) > 0, sigma_frames)


def displace_joints(feats: torch.Tensor, keys: KeyjointTargets, rep: FlatRepresentation,
                    sigma_frames: float) -> torch.Tensor:
    """Unnormalised ``feats (B, T, D)`` with :func:`joint_displacement` added to ``joint_pos``."""
    out = feats.clone()
    jp = rep.joint_pos
    out[..., jp] = feats[..., jp] + joint_displacement(feats, keys, rep, sigma_frames).flatten(-2)
    return out
