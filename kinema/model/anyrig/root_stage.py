"""The any-rig model's root stage: the root row of a motion denoised first, from the text and the rig.

Kimodo denoises the root before the body (its two stages: a root denoiser, then a body denoiser
given the root). The any-rig denoiser (kinema.model.anyrig.denoiser) denoises all joints together, and
its idles drifted (issue 34): at mid diffusion steps its x0 prediction of the root's ground velocity
read travel into the shuffling legs of the noisy body, and the sampling chain summed the bias up.
`RootStageDenoiser` sees no body: it maps the noisy, normalised root row ``x_t (B, T, 13)``
(kinema.representation.joint: ground velocity, height, rotation, heading and heading rate) at step
``t (B,)`` to its clean prediction, from the text embedding and a summary of the rig -- every joint's
flags and RestPE code (kinema.model.skeleton_codes) through an MLP, pooled by masked mean and max over
the joints, so a long-legged deer and a rat get their own speeds and heights. The body stage is the
any-rig denoiser with this root row given on every frame (its training holds that case).

Frames are tokens: ``Linear([m x_tgt + (1 - m) x_t ; m]) + PE(frame)``, blocks of temporal attention
and feed-forward modulated by adaLN-Zero from ``c = MLP(step) + MLP(text) + rig``; constraints on the
root row enter by imputation as in the any-rig denoiser. Normalisation statistics: the root row's
``(13,)``, the any-rig model's row 0.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import torch
import torch.nn.functional as F
from torch import nn

from kinema.errors import KinemaError
from kinema.model.anyrig.denoiser import Attention
from kinema.model.layers import sinusoidal_embedding
from kinema.model.skeleton_codes import CodeBatch
from kinema.representation.joint import NUM_CHANNELS


@dataclass(frozen=True)
class RootStageConfig:
    """Size of the root stage. ``code_dim``: the rig codes' width per joint (flags + RestPE input of
    the any-rig model it belongs to); ``max_frames``: the longest window it takes."""

    code_dim: int
    width: int = 128
    layers: int = 4
    heads: int = 4
    ff_mult: int = 2
    text_dim: int = 384
    max_frames: int = 512

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise KinemaError(f"root stage config: {f.name} must be a positive integer, got {v!r}")
        if self.width % self.heads:
            raise KinemaError(f"root stage config: heads ({self.heads}) must divide width ({self.width})")

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> RootStageConfig:
        known = {f.name for f in fields(cls)}
        if set(d) - known:
            raise KinemaError(f"root stage config: unknown keys {sorted(set(d) - known)}")
        return cls(**d)


def rig_codes(codes: CodeBatch) -> torch.Tensor:
    """``(B, J, code_dim)``: what the root stage reads of each joint (flags and RestPE input)."""
    return torch.cat([codes.flags, codes.rest], dim=-1)


class _Block(nn.Module):
    """Temporal attention and feed-forward over frame tokens, with adaLN-Zero modulation."""

    def __init__(self, width: int, heads: int, ff_dim: int) -> None:
        super().__init__()
        self.norms = nn.ModuleList([nn.LayerNorm(width, elementwise_affine=False, eps=1e-6) for _ in range(2)])
        self.attn = Attention(width, heads, 0.0)
        self.ff = nn.Sequential(nn.Linear(width, ff_dim), nn.GELU(), nn.Linear(ff_dim, width))
        self.ada = nn.Linear(width, 6 * width)
        nn.init.zeros_(self.ada.weight)
        nn.init.zeros_(self.ada.bias)

    def forward(self, h: torch.Tensor, c: torch.Tensor, bias: torch.Tensor) -> torch.Tensor:
        m = self.ada(F.silu(c))[:, None].chunk(6, dim=-1)
        h = h + m[2] * self.attn(self.norms[0](h) * (1 + m[1]) + m[0], bias)
        return h + m[5] * self.ff(self.norms[1](h) * (1 + m[4]) + m[3])


class RootStageDenoiser(nn.Module):
    """x0-predicting denoiser of the root row alone; see the module docstring."""

    def __init__(self, config: RootStageConfig) -> None:
        super().__init__()
        self.config = config
        w, C = config.width, NUM_CHANNELS
        self.in_proj = nn.Linear(2 * C, w)
        self.rig_mlp = nn.Sequential(nn.Linear(config.code_dim, w), nn.SiLU(), nn.Linear(w, w))
        self.rig_proj = nn.Linear(2 * w, w)
        self.time_mlp = nn.Sequential(nn.Linear(w, w), nn.SiLU(), nn.Linear(w, w))
        self.text_mlp = nn.Sequential(nn.Linear(config.text_dim, w), nn.SiLU(), nn.Linear(w, w))
        self.blocks = nn.ModuleList([_Block(w, config.heads, config.ff_mult * w) for _ in range(config.layers)])
        self.final_norm = nn.LayerNorm(w, elementwise_affine=False, eps=1e-6)
        self.final_ada = nn.Linear(w, 2 * w)
        self.out_proj = nn.Linear(w, C)
        for lin in (self.final_ada, self.out_proj):
            nn.init.zeros_(lin.weight)
            nn.init.zeros_(lin.bias)
        self.register_buffer("pos_enc", sinusoidal_embedding(torch.arange(config.max_frames), w), persistent=False)
        self.register_buffer("feat_mean", torch.zeros(C))
        self.register_buffer("feat_std", torch.ones(C))

    def set_normalization(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        """The root row's statistics ``(13,)`` (the any-rig model's row 0)."""
        self.feat_mean.copy_(torch.as_tensor(mean, dtype=torch.float32).reshape(-1))
        self.feat_std.copy_(torch.as_tensor(std, dtype=torch.float32).reshape(-1))

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.feat_mean) / self.feat_std

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.feat_std + self.feat_mean

    def num_parameters(self) -> int:
        return sum(p.numel() for p in self.parameters())

    def rig_embedding(self, codes: CodeBatch) -> torch.Tensor:
        """``(B, W)``: the rig's joints' codes through an MLP, masked mean and max over the joints."""
        e = self.rig_mlp(rig_codes(codes))
        real = codes.joint_mask[..., None].to(e)
        mean = (e * real).sum(1) / real.sum(1).clamp_min(1.0)
        top = e.masked_fill(real == 0, torch.finfo(e.dtype).min).amax(1)
        return self.rig_proj(torch.cat([mean, top], dim=-1))

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
        """``x_t (B, T, 13)`` normalised, ``t (B,)``, ``text_emb (B, text_dim)`` (zeros = no text), the
        rigs' ``codes``, ``frame_mask (B, T)``, ``x_tgt`` / ``mask (B, T, 13)`` -> x0 ``(B, T, 13)``."""
        B, T, _ = x_t.shape
        if T > self.config.max_frames:
            raise ValueError(f"{T} frames exceed the root stage's {self.config.max_frames}")
        if mask is None or x_tgt is None:
            x_tgt, mask = torch.zeros_like(x_t), torch.zeros_like(x_t)
        h = self.in_proj(torch.cat([mask * x_tgt + (1.0 - mask) * x_t, mask], dim=-1)) + self.pos_enc[:T].to(x_t)
        # unit-length sentence embeddings scaled to unit-size components, so the text moves c from the start
        text = text_emb.to(h) * self.config.text_dim**0.5
        c = self.time_mlp(sinusoidal_embedding(t, self.config.width).to(h)) + self.text_mlp(text)
        c = c + self.rig_embedding(codes).to(h)
        bias = torch.zeros(B, 1, 1, T, dtype=h.dtype)
        if frame_mask is not None:
            bias = torch.where(frame_mask.bool(), 0.0, torch.finfo(h.dtype).min).to(h.dtype)[:, None, None, :]
        for block in self.blocks:
            h = block(h, c, bias)
        shift, scale = self.final_ada(F.silu(c))[:, None].chunk(2, dim=-1)
        return self.out_proj(self.final_norm(h) * (1 + scale) + shift)
