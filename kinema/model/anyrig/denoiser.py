"""The any-rig denoiser: one token per joint per frame, for any skeleton (AnyTop / "How to Move Your
Dragon", adapted to a CPU budget).

``AnyRigDenoiser.forward(x_t, t, text_emb, codes, frame_mask, x_tgt, mask) -> x0`` maps noisy,
normalised per-joint features ``x_t (B, T, J, 13)`` (kinema.representation.joint) at diffusion step
``t (B,)`` to a prediction of the clean features, for rigs described by a `CodeBatch` (padded to J
joints with a joint mask). Constraints enter as in the human model (CondMDI imputation): targets
``x_tgt`` and a {0, 1} ``mask`` of the same shape give the token input ``[m x_tgt + (1 - m) x_t ; m]``.

Each token is ``Linear([x~ ; m]) + PE(frame) + TreePE(joint) + RestPE(joint) + flags(joint)``; the
root joint's token carries the root row of the representation (height, ground velocity, heading).
Blocks alternate spatial attention (the joints of one frame; padding joints masked as keys; a
learned per-head bias by hop distance between joints, as AnyTop's topology bias) and temporal
attention (the frames of one joint; padding frames masked), then a feed-forward; all three are
modulated by adaLN-Zero (DiT) from ``c = MLP(step) + Linear(text)``. A zero text embedding is the
"no text" condition (classifier-free guidance).

Normalisation statistics are two rows of buffers ``(2, 13)`` (root row, other joints), shared by all
rigs, which the trainer sets; a rig's features are in its own units (rest pose ~1 across).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from kinema.model.anyrig.config import AnyRigConfig
from kinema.model.layers import sinusoidal_embedding
from kinema.model.skeleton_codes import CodeBatch, rest_dim, tree_dim


def _mlp(i: int, w: int) -> nn.Sequential:
    return nn.Sequential(nn.Linear(i, w), nn.SiLU(), nn.Linear(w, w))


def _modulate(x: torch.Tensor, shift: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """adaLN: ``x (B, T, J, W)`` with ``shift``, ``scale`` ``(B, W)``."""
    return x * (1 + scale[:, None, None]) + shift[:, None, None]


class Attention(nn.Module):
    """Multi-head self-attention over the second-to-last axis of ``(N, L, W)`` with an additive mask."""

    def __init__(self, width: int, heads: int, dropout: float) -> None:
        super().__init__()
        self.heads, self.dropout = heads, dropout
        self.qkv = nn.Linear(width, 3 * width)
        self.out = nn.Linear(width, width)

    def forward(self, x: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
        N, L, W = x.shape
        q, k, v = self.qkv(x).view(N, L, 3, self.heads, W // self.heads).permute(2, 0, 3, 1, 4)
        p = self.dropout if self.training else 0.0
        y = F.scaled_dot_product_attention(q, k, v, attn_mask=bias, dropout_p=p)
        return self.out(y.transpose(1, 2).reshape(N, L, W))


class Block(nn.Module):
    """Spatial attention, temporal attention and feed-forward, each with adaLN-Zero modulation."""

    def __init__(self, config: AnyRigConfig) -> None:
        super().__init__()
        w = config.width
        self.norms = nn.ModuleList([nn.LayerNorm(w, elementwise_affine=False, eps=1e-6) for _ in range(3)])
        self.spatial = Attention(w, config.heads, config.dropout)
        self.temporal = Attention(w, config.heads, config.dropout)
        self.ff = nn.Sequential(nn.Linear(w, config.ff_dim), nn.GELU(), nn.Linear(config.ff_dim, w))
        self.drop = nn.Dropout(config.dropout)
        self.ada = nn.Linear(w, 9 * w)
        nn.init.zeros_(self.ada.weight)
        nn.init.zeros_(self.ada.bias)

    def forward(self, h: torch.Tensor, c: torch.Tensor, s_bias: torch.Tensor, t_bias: torch.Tensor) -> torch.Tensor:
        """``h (B, T, J, W)``, ``c (B, W)``, ``s_bias (B*T, H, J, J)``, ``t_bias (B*J, 1, 1, T)``."""
        B, T, J, W = h.shape
        mods = self.ada(F.silu(c)).chunk(9, dim=-1)
        x = _modulate(self.norms[0](h), mods[0], mods[1]).reshape(B * T, J, W)
        h = h + mods[2][:, None, None] * self.spatial(x, s_bias).view(B, T, J, W)
        x = _modulate(self.norms[1](h), mods[3], mods[4]).transpose(1, 2).reshape(B * J, T, W)
        h = h + mods[5][:, None, None] * self.temporal(x, t_bias).view(B, J, T, W).transpose(1, 2)
        x = _modulate(self.norms[2](h), mods[6], mods[7])
        return h + mods[8][:, None, None] * self.drop(self.ff(x))


class AnyRigDenoiser(nn.Module):
    """x0-predicting denoiser for any rig; see the module docstring. Build with ``AnyRigDenoiser(config)``."""

    def __init__(self, config: AnyRigConfig) -> None:
        super().__init__()
        self.config = config
        w, C = config.width, config.channels
        self.in_proj = nn.Linear(2 * C, w)
        self.tree_mlp = _mlp(tree_dim(config), w) if config.tree_pe else None
        self.rest_mlp = _mlp(rest_dim(config), w) if config.rest_pe else None
        self.flag_proj = nn.Linear(2, w)
        self.hop_emb = nn.Embedding(config.max_hops + 1, config.heads) if config.hop_bias else None
        self.time_mlp = _mlp(w, w)
        self.text_proj = nn.Linear(config.text_dim, w)
        self.blocks = nn.ModuleList([Block(config) for _ in range(config.layers)])
        self.final_norm = nn.LayerNorm(w, elementwise_affine=False, eps=1e-6)
        self.final_ada = nn.Linear(w, 2 * w)
        self.out_proj = nn.Linear(w, C)
        for lin in (self.final_ada, self.out_proj):
            nn.init.zeros_(lin.weight)
            nn.init.zeros_(lin.bias)
        self.register_buffer("pos_enc", sinusoidal_embedding(torch.arange(config.max_frames), w), persistent=False)
        self.register_buffer("feat_mean", torch.zeros(2, C))
        self.register_buffer("feat_std", torch.ones(2, C))

    # ------------------------------------------------------------------ normalisation
    def set_normalization(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """Statistics ``(2, C)``: row 0 for the rig's root joint, row 1 for every other joint."""
        self.feat_mean.copy_(torch.as_tensor(mean, dtype=torch.float32).reshape(2, -1))
        self.feat_std.copy_(torch.as_tensor(std, dtype=torch.float32).reshape(2, -1))

    def _stats(self, root_flag: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        r = root_flag[:, None, :, None]  # (B, 1, J, 1)
        mean = r * self.feat_mean[0] + (1 - r) * self.feat_mean[1]
        std = r * self.feat_std[0] + (1 - r) * self.feat_std[1]
        return mean, std

    def normalize(self, x: torch.Tensor, codes: CodeBatch) -> torch.Tensor:
        mean, std = self._stats(codes.flags[..., 0].to(x))
        return (x - mean) / std

    def denormalize(self, x: torch.Tensor, codes: CodeBatch) -> torch.Tensor:
        mean, std = self._stats(codes.flags[..., 0].to(x))
        return x * std + mean

    def num_parameters(self) -> int:
        return sum(p.numel() for p in self.parameters())

    # ------------------------------------------------------------------ forward
    def _joint_embedding(self, codes: CodeBatch) -> torch.Tensor:
        """``(B, J, W)``: flags + TreePE + RestPE of every joint."""
        e = self.flag_proj(codes.flags)
        if self.tree_mlp is not None:
            e = e + self.tree_mlp(codes.tree)
        if self.rest_mlp is not None:
            e = e + self.rest_mlp(codes.rest)
        return e

    def _biases(self, codes: CodeBatch, frame_mask: torch.Tensor, T: int, dtype) -> tuple[torch.Tensor, torch.Tensor]:
        B, J = codes.joint_mask.shape
        H = self.config.heads
        neg = torch.finfo(dtype).min
        key_pad = torch.where(codes.joint_mask, 0.0, neg).to(dtype)[:, None, None, :]  # (B, 1, 1, J)
        s = key_pad.expand(B, H, J, J)
        if self.hop_emb is not None:
            s = s + self.hop_emb(codes.hops).permute(0, 3, 1, 2).to(dtype)
        s_bias = s[:, None].expand(B, T, H, J, J).reshape(B * T, H, J, J)
        t = torch.where(frame_mask.bool(), 0.0, neg).to(dtype)  # (B, T)
        t_bias = t[:, None].expand(B, J, T).reshape(B * J, 1, 1, T)
        return s_bias, t_bias

    def forward(
        self,
        x_t: torch.Tensor,
        t: torch.Tensor,
        text_emb: torch.Tensor,
        codes: CodeBatch,
        frame_mask: torch.Tensor | None = None,
        x_tgt: torch.Tensor | None = None,
        mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """``x_t (B, T, J, C)`` normalised, ``t (B,)`` long, ``text_emb (B, text_dim)`` (zeros = no text),
        ``frame_mask (B, T)`` (True = real frame), ``x_tgt``/``mask (B, T, J, C)`` -> x0 ``(B, T, J, C)``."""
        B, T, J, C = x_t.shape
        if T > self.config.max_frames:
            raise ValueError(f"{T} frames exceed the model's {self.config.max_frames}")
        if frame_mask is None:
            frame_mask = torch.ones(B, T, dtype=torch.bool, device=x_t.device)
        if mask is None:
            mask = torch.zeros_like(x_t)
            x_tgt = torch.zeros_like(x_t)
        x_in = mask * x_tgt + (1.0 - mask) * x_t
        h = self.in_proj(torch.cat([x_in, mask], dim=-1))
        h = h + self.pos_enc[:T].to(h)[None, :, None] + self._joint_embedding(codes).to(h)[:, None]
        c = self.time_mlp(sinusoidal_embedding(t, self.config.width).to(h)) + self.text_proj(text_emb.to(h))
        s_bias, t_bias = self._biases(codes, frame_mask, T, h.dtype)
        for block in self.blocks:
            h = block(h, c, s_bias, t_bias)
        shift, scale = self.final_ada(F.silu(c)).chunk(2, dim=-1)
        return self.out_proj(_modulate(self.final_norm(h), shift, scale))
