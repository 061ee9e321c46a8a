"""Kimodo's two-stage transformer denoiser (paper Sec. 4.2) and its one-stage ablation baseline.

``Denoiser.forward`` maps a noisy, normalised motion ``x_t (B, T, D)`` at diffusion step ``t`` to a
prediction of the clean motion ``x0 (B, T, D)`` (normalised), conditioned on a text embedding, the
first-frame heading ``c_dir`` and kinematic constraints given as targets ``x_tgt`` plus a {0, 1} mask:

1. **Imputation** (CondMDI): ``x~ = m * x_tgt + (1 - m) * x_t``; the frame tokens are ``[x~ ; m]``.
2. **Stage 1 (root)** sees the full input and predicts the global root ``(B, T, 5)`` (normalised).
3. The root is un-normalised with the feature statistics held as buffers, converted to the *local*
   root (heading rate, planar velocity in the heading frame, height; ``global_to_local_root``) and
   normalised with the local-root statistics.  The conversion is differentiable, so the body loss
   also trains stage 1 (the model is trained end to end).
4. **Stage 2 (body)** sees ``[local root (4) ; body of x~ (D - 5) ; m (D)]`` and predicts the body
   ``(B, T, D - 5)``.  Output = ``[global root ; body]``.

With ``config.two_stage = False`` a single transformer maps ``[x~ ; m]`` to all D channels.

``forward_guided`` evaluates the classifier-free-guidance branches (no text / text / constraints /
both) as one batched pass and combines them with :mod:`kinema.diffusion.guidance`.

Both normalisation buffers default to the identity (mean 0, std 1); the trainer must set them
(``set_normalization``, ``set_local_root_normalization``) before training; they are saved in the
``state_dict`` so a checkpoint carries them.
"""

from __future__ import annotations

from collections.abc import Iterable

import torch
from torch import nn

from kinema.diffusion.guidance import Guidance, combine, split_branches, stack_branches
from kinema.diffusion.guidance_cache import GuidanceCache
from kinema.model.config import ModelConfig
from kinema.model.layers import StageTransformer
from kinema.representation.kimodo_features import global_to_local_root
from kinema.representation.layout import LOCAL_ROOT_DIM, LOCAL_ROOT_HEIGHT, LOCAL_ROOT_RATES, ROOT_DIM
from kinema.representation.stats import NormStats


def impute(x_t: torch.Tensor, x_tgt: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """``m * x_tgt + (1 - m) * x_t``; all ``(B, T, D)``.  For a {0, 1} mask and finite inputs, constrained
    entries equal ``x_tgt`` exactly and the others ``x_t`` exactly."""
    return mask * x_tgt + (1.0 - mask) * x_t


def padded_local_root(root: torch.Tensor, pad_mask: torch.Tensor | None, fps: float) -> torch.Tensor:
    """Local root ``(B, T, 4)`` of an un-normalised global root ``(B, T, 5)`` whose padded frames
    (``pad_mask (B, T)`` False) may hold anything.

    ``global_to_local_root`` uses forward differences and repeats the last difference on the last
    frame.  In a padded batch the last *valid* frame would difference against a padded frame, so here
    its velocities repeat the previous frame's (as on an unpadded sequence), a single valid frame gets
    zero velocity, and padded frames are zero.  Valid outputs never depend on padded inputs.
    """
    local = global_to_local_root(root, fps)
    if pad_mask is None:
        return local
    valid = pad_mask.to(torch.bool)
    # pair_ok[i]: frames i and i+1 both valid, so the forward difference at i is meaningful.
    pair_ok = torch.cat([valid[:, 1:] & valid[:, :-1], torch.zeros_like(valid[:, :1])], dim=1)
    prev_ok = torch.cat([torch.zeros_like(pair_ok[:, :1]), pair_ok[:, :-1]], dim=1)
    vel = local[..., LOCAL_ROOT_RATES]
    prev_vel = torch.cat([vel[:, :1], vel[:, :-1]], dim=1)
    fallback = torch.where(prev_ok[..., None], prev_vel, torch.zeros_like(vel))
    vel = torch.where(pair_ok[..., None], vel, fallback)
    local = torch.cat([vel, local[..., LOCAL_ROOT_HEIGHT]], dim=-1)
    return torch.where(valid[..., None], local, torch.zeros_like(local))


def local_root_stats(features: Iterable[torch.Tensor], fps: float) -> NormStats:
    """Normalisation statistics ``(4,)`` of the local root over un-normalised feature clips ``(T_i, D)``,
    for :meth:`Denoiser.set_local_root_normalization`."""
    return NormStats.compute(global_to_local_root(f[..., :ROOT_DIM].double(), fps) for f in features)


class Denoiser(nn.Module):
    """x0-predicting motion denoiser; see the module docstring.  Build with ``Denoiser(config)``."""

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        self.config = config
        D = config.feature_dim
        if config.two_stage:
            self.root_stage = StageTransformer(config, in_dim=2 * D, out_dim=ROOT_DIM)
            self.body_stage = StageTransformer(config, in_dim=LOCAL_ROOT_DIM + config.body_dim + D,
                                               out_dim=config.body_dim)
        else:
            self.stage = StageTransformer(config, in_dim=2 * D, out_dim=D)
        self.register_buffer("feat_mean", torch.zeros(D))
        self.register_buffer("feat_std", torch.ones(D))
        self.register_buffer("local_mean", torch.zeros(LOCAL_ROOT_DIM))
        self.register_buffer("local_std", torch.ones(LOCAL_ROOT_DIM))

    # ------------------------------------------------------------------ set-up
    def set_normalization(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """Feature statistics ``(D,)`` the inputs / outputs are normalised with."""
        self._set_stats(self.feat_mean, self.feat_std, mean, std)

    def set_local_root_normalization(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """Statistics ``(4,)`` of the local root fed to stage 2 (see :func:`local_root_stats`)."""
        self._set_stats(self.local_mean, self.local_std, mean, std)

    @staticmethod
    def _set_stats(mean_buf: torch.Tensor, std_buf: torch.Tensor, mean: torch.Tensor,
                   std: torch.Tensor) -> None:
        mean, std = torch.as_tensor(mean), torch.as_tensor(std)
        if mean.shape != mean_buf.shape or std.shape != std_buf.shape:
            raise ValueError(f"expected mean/std of shape {tuple(mean_buf.shape)}, "
                             f"got {tuple(mean.shape)} / {tuple(std.shape)}")
        if not bool(torch.all(std > 0)):
            raise ValueError("std must be positive")
        with torch.no_grad():
            mean_buf.copy_(mean)
            std_buf.copy_(std)

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        """Features ``(..., D)`` -> normalised, with the model's statistics."""
        return (x - self.feat_mean) / self.feat_std

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        """Normalised features ``(..., D)`` -> metres / seconds / radians."""
        return x * self.feat_std + self.feat_mean

    def set_dropout(self, p: float) -> None:
        """Change every dropout rate (the paper trains with 0.1 in phase 1 and 0 in phase 2)."""
        for module in self.modules():
            if isinstance(module, nn.Dropout):
                module.p = p
            elif isinstance(module, nn.MultiheadAttention):
                module.dropout = p
        self.config.dropout = p

    def num_parameters(self, trainable_only: bool = False) -> int:
        return sum(p.numel() for p in self.parameters() if p.requires_grad or not trainable_only)

    # ------------------------------------------------------------------ forward
    def forward(
        self,
        x_t: torch.Tensor,
        t: torch.Tensor,
        text_emb: torch.Tensor | None = None,
        text_mask: torch.Tensor | None = None,
        c_dir: torch.Tensor | None = None,
        x_tgt: torch.Tensor | None = None,
        mask: torch.Tensor | None = None,
        pad_mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Predict the clean motion.

        Args:
            x_t: ``(B, T, D)`` noisy normalised features.
            t: ``(B,)`` long diffusion steps (0-based); a 0-d tensor is broadcast.
            text_emb: ``(B, text_dim)`` sentence embeddings, or None for no text at all.
            text_mask: ``(B,)`` bool, False drops that row's text (classifier-free guidance); None = keep.
            c_dir: ``(B, 2)`` first-frame heading ``(cos psi, sin psi)``; None = psi 0, i.e. ``(1, 0)``.
            x_tgt: ``(B, T, D)`` normalised constraint targets (needed when ``mask`` is given).
            mask: ``(B, T, D)`` {0, 1} constraint mask; None = unconstrained (all zeros).
            pad_mask: ``(B, T)`` bool, True = valid frame; None = all valid.

        Returns:
            ``(B, T, D)`` normalised x0 prediction; padded frames are zero.
        """
        B, T, D = x_t.shape
        if D != self.config.feature_dim:
            raise ValueError(f"x_t has {D} channels, the model expects {self.config.feature_dim}")
        t = t.expand(B) if t.dim() == 0 else t
        text_emb, c_dir = self._text_and_heading(x_t, text_emb, text_mask, c_dir)
        x_tilde, mask = self._imputed(x_t, x_tgt, mask)
        out = self._run_stages(x_tilde, mask, (t, text_emb, c_dir, pad_mask))
        if pad_mask is not None:
            out = torch.where(pad_mask.to(torch.bool)[..., None], out, torch.zeros_like(out))
        return out

    def _text_and_heading(self, x_t, text_emb, text_mask, c_dir) -> tuple[torch.Tensor, torch.Tensor]:
        """The ``(B, text_dim)`` text condition (zeros for no text and for rows ``text_mask`` drops) and the
        ``(B, 2)`` heading (``(1, 0)`` when not given), in ``x_t``'s dtype."""
        B = x_t.shape[0]
        if text_emb is None:
            text_emb = x_t.new_zeros(B, self.config.text_dim)
        else:
            text_emb = text_emb.to(x_t.dtype)
            if text_mask is not None:
                keep = text_mask.to(torch.bool)[:, None]
                text_emb = torch.where(keep, text_emb, torch.zeros_like(text_emb))
        if c_dir is None:
            c_dir = x_t.new_tensor([1.0, 0.0]).expand(B, 2)
        return text_emb, c_dir

    @staticmethod
    def _imputed(x_t, x_tgt, mask) -> tuple[torch.Tensor, torch.Tensor]:
        """``x_t`` with the constrained entries replaced by their targets, and the mask (zeros for none)."""
        if mask is None:
            return x_t, torch.zeros_like(x_t)
        if x_tgt is None:
            raise ValueError("a constraint mask needs constraint targets x_tgt")
        mask = mask.to(x_t.dtype)
        return impute(x_t, x_tgt.to(x_t.dtype), mask), mask

    def _run_stages(self, x_tilde: torch.Tensor, mask: torch.Tensor, cond: tuple) -> torch.Tensor:
        """The normalised x0 ``(B, T, D)``: one stage, or the root stage and then the body stage on the
        local root the root stage predicts (Kimodo's two stages)."""
        if not self.config.two_stage:
            return self.stage(torch.cat([x_tilde, mask], dim=-1), *cond)
        pad_mask = cond[3]
        root_n = self.root_stage(torch.cat([x_tilde, mask], dim=-1), *cond)  # (B, T, 5)
        root = root_n * self.feat_std[:ROOT_DIM] + self.feat_mean[:ROOT_DIM]
        local = padded_local_root(root, pad_mask, self.config.fps)  # (B, T, 4)
        local_n = (local - self.local_mean) / self.local_std
        body_in = torch.cat([local_n, x_tilde[..., ROOT_DIM:], mask], dim=-1)
        body_n = self.body_stage(body_in, *cond)  # (B, T, D - 5)
        return torch.cat([root_n, body_n], dim=-1)

    def forward_guided(
        self,
        x_t: torch.Tensor,
        t: torch.Tensor,
        text_emb: torch.Tensor | None,
        c_dir: torch.Tensor | None,
        x_tgt: torch.Tensor | None,
        mask: torch.Tensor | None,
        pad_mask: torch.Tensor | None,
        guidance: Guidance,
        text_mask: torch.Tensor | None = None,
        context_mask: torch.Tensor | None = None,
        cache: GuidanceCache | None = None,
    ) -> torch.Tensor:
        """Guided x0 ``(B, T, D)``: all branches of ``guidance`` in ONE forward pass of batch ``k * B``.

        Branches: "uncond" = no text, no constraints; "text" = text only; "constr" = constraints only;
        "cond" = both.  Shapes as in :meth:`forward`.  Without a mask the separated mode is reduced to
        the equivalent, cheaper regular CFG (``Guidance.without_constraints``).

        ``context_mask (B, T, D)``: entries of ``mask`` that *every* branch sees (their targets in
        ``x_tgt``), i.e. context the guidance does not extrapolate: a timeline's join frames
        (kinema.human.segments). Given to the constraint branch only, as constraints, they are pushed
        ``w_constr`` times and the previous segment's motion outweighs the new prompt (issue 18). When
        the mask holds nothing but context, the constraint branch equals the unconditional one and the
        separated mode is reduced to regular CFG, as without a mask.

        ``cache`` (kinema.diffusion.guidance_cache): the separated mode runs the cache's cached branch only
        on its refresh calls and reuses that branch's last difference on the others.
        """
        guidance, x_tgt, mask, context = _guided_conditions(x_t, x_tgt, mask, context_mask, guidance)
        names = guidance.branches if cache is None else cache.branches(guidance)
        B = x_t.shape[0]
        t = t.expand(B) if t.dim() == 0 else t
        if text_mask is None:
            keep = torch.ones(B, dtype=torch.bool, device=x_t.device)
        else:
            keep = text_mask.to(torch.bool)
        drop = torch.zeros_like(keep)
        context_only = context

        def rep(x: torch.Tensor | None) -> torch.Tensor | None:
            return None if x is None else stack_branches(x, names)

        out = self(
            stack_branches(x_t, names),
            stack_branches(t, names),
            text_emb=rep(text_emb),
            text_mask=stack_branches({"uncond": drop, "text": keep, "constr": drop, "cond": keep}, names),
            c_dir=rep(c_dir),
            x_tgt=stack_branches(x_tgt, names),
            mask=stack_branches({"uncond": context_only, "text": context_only, "constr": mask, "cond": mask},
                                names),
            pad_mask=rep(pad_mask),
        )
        outputs = split_branches(out, names)
        return combine(guidance, outputs) if cache is None else cache.combine(guidance, outputs)


def _guided_conditions(x_t: torch.Tensor, x_tgt: torch.Tensor | None, mask: torch.Tensor | None,
                       context_mask: torch.Tensor | None, guidance: Guidance
                       ) -> tuple[Guidance, torch.Tensor, torch.Tensor, torch.Tensor]:
    """``forward_guided``'s (guidance, x_tgt, mask, context): zero targets and mask without a mask, the
    context merged into the mask, and the separated mode reduced to regular CFG when nothing but context
    is constrained."""
    if mask is None:
        guidance = guidance.without_constraints()
        mask = torch.zeros_like(x_t)
        x_tgt = torch.zeros_like(x_t)
    elif x_tgt is None:
        raise ValueError("a constraint mask needs constraint targets x_tgt")
    if context_mask is None:
        context = torch.zeros_like(mask)
    else:
        context = context_mask.to(mask.dtype)
        mask = torch.maximum(mask, context)
        if not bool((mask > context).any()):
            guidance = guidance.without_constraints()
    return guidance, x_tgt, mask, context
