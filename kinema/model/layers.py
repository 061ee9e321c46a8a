"""Building blocks of the denoiser: sinusoidal encodings, conditioning tokens, one transformer stage.

Each stage of the Kimodo denoiser (Sec. 4.2) is the same kind of network: per-frame input tokens plus
conditioning tokens ``C = {c_text, c_dir, c_extra}`` and the diffusion step, all embedded to ``width``,
added to a sinusoidal positional encoding and run through a pre-LN transformer encoder.  The two
stages differ only in their input and output sizes, so both are a :class:`StageTransformer`.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from kinema.model import bf16_encoder
from kinema.model.config import ModelConfig


def sinusoidal_embedding(positions: torch.Tensor, dim: int, max_period: float = 10000.0) -> torch.Tensor:
    """``positions (N,)`` (integers or floats) -> ``(N, dim)`` float32 ``[cos(p w_k) ; sin(p w_k)]`` with
    geometric frequencies ``w_k = max_period^(-k / (dim/2))`` (Vaswani et al. 2017; odd ``dim`` pads 0)."""
    half = dim // 2
    k = torch.arange(half, dtype=torch.float32, device=positions.device)
    freqs = torch.exp(-math.log(max_period) * k / max(half, 1))
    args = positions.to(torch.float32)[:, None] * freqs[None]
    emb = torch.cat([torch.cos(args), torch.sin(args)], dim=-1)
    if dim % 2:
        emb = torch.cat([emb, torch.zeros_like(emb[:, :1])], dim=-1)
    return emb


class ConditionTokens(nn.Module):
    """Embeds the conditioning into ``3 + P`` tokens ``(B, 3 + P, width)``: [timestep, text, heading,
    P registers].

    - timestep: sinusoidal encoding of ``t`` -> Linear -> SiLU -> Linear (as in DDPM / MDM);
    - text: ``Linear(text_dim -> width)`` of the sentence embedding (the caller zeroes dropped text, so a
      dropped prompt is the embedding of the zero vector, i.e. the projection's bias);
    - heading ``c_dir = (cos, sin)``: ``Linear(2 -> width)``;
    - registers: the paper's P "extra all-zero tokens" of text size, embedded like the text token.
      ``text_proj(0) = text_proj.bias`` exactly, so we use the bias instead of multiplying P zero vectors
      by a ``text_dim x width`` matrix: same values and gradients, no wasted compute.  The registers
      are told apart only by their positional encodings, which the stage adds afterwards.
    """

    def __init__(self, config: ModelConfig) -> None:
        super().__init__()
        w = config.width
        self.width = w
        self.num_registers = config.num_registers
        self.time_mlp = nn.Sequential(nn.Linear(w, w), nn.SiLU(), nn.Linear(w, w))
        self.text_proj = nn.Linear(config.text_dim, w)
        self.dir_proj = nn.Linear(2, w)

    def forward(self, t: torch.Tensor, text_emb: torch.Tensor, c_dir: torch.Tensor) -> torch.Tensor:
        """``t (B,)`` long, ``text_emb (B, text_dim)`` (zeros = no text), ``c_dir (B, 2)``
        -> ``(B, 3 + P, width)``."""
        B = t.shape[0]
        time_tok = self.time_mlp(sinusoidal_embedding(t, self.width).to(text_emb.dtype))
        text_tok = self.text_proj(text_emb)
        dir_tok = self.dir_proj(c_dir.to(text_emb.dtype))
        registers = self.text_proj.bias.expand(B, self.num_registers, self.width)
        return torch.cat([torch.stack([time_tok, text_tok, dir_tok], dim=1), registers], dim=1)


class StageTransformer(nn.Module):
    """One transformer encoder over ``[conditioning tokens ; frame tokens]``.

    ``forward(frames (B, T, in_dim), t (B,), text_emb (B, text_dim), c_dir (B, 2), pad_mask (B, T) | None)
    -> (B, T, out_dim)``.  Frame tokens are ``Linear(in_dim -> width)``; every token gets a fixed
    sinusoidal positional encoding, the conditioning tokens taking positions ``0 .. 3+P-1`` and frame
    ``i`` position ``3 + P + i``.  Padded frames (``pad_mask`` False) are excluded as attention keys, so
    valid frames never see them; conditioning tokens are always valid.  Pre-LN layers with GELU, a final
    LayerNorm, then a linear head per frame.
    """

    def __init__(self, config: ModelConfig, in_dim: int, out_dim: int) -> None:
        super().__init__()
        self.cond = ConditionTokens(config)
        self.in_proj = nn.Linear(in_dim, config.width)
        layer = nn.TransformerEncoderLayer(
            d_model=config.width, nhead=config.heads, dim_feedforward=config.ff_dim, dropout=config.dropout,
            activation="gelu", batch_first=True, norm_first=True,
        )
        self.encoder = nn.TransformerEncoder(layer, num_layers=config.layers, norm=nn.LayerNorm(config.width),
                                             enable_nested_tensor=False)
        self.out_proj = nn.Linear(config.width, out_dim)
        self.num_cond = config.num_cond_tokens
        self.max_frames = config.max_frames
        positions = torch.arange(self.num_cond + config.max_frames)
        # Not persistent: derived from the config, so max_frames can change without touching weights.
        self.register_buffer("pos_enc", sinusoidal_embedding(positions, config.width), persistent=False)

    def forward(self, frames: torch.Tensor, t: torch.Tensor, text_emb: torch.Tensor, c_dir: torch.Tensor,
                pad_mask: torch.Tensor | None) -> torch.Tensor:
        B, T, _ = frames.shape
        if T > self.max_frames:
            raise ValueError(f"{T} frames exceed the model's max_frames={self.max_frames}")
        out_dtype, dtype = frames.dtype, self.in_proj.weight.dtype
        if dtype != out_dtype:  # bf16 weights (kinema.model.precision): the stage runs in their dtype
            frames, text_emb, c_dir = frames.to(dtype), text_emb.to(dtype), c_dir.to(dtype)
        tokens = torch.cat([self.cond(t, text_emb, c_dir), self.in_proj(frames)], dim=1)
        tokens = tokens + self.pos_enc[: self.num_cond + T].to(tokens.dtype)
        key_padding = None
        if pad_mask is not None:
            cond_valid = torch.ones(B, self.num_cond, dtype=torch.bool, device=pad_mask.device)
            key_padding = ~torch.cat([cond_valid, pad_mask.to(torch.bool)], dim=1)  # True = ignore
        if tokens.dtype == torch.bfloat16 and not self.training:  # the softmax in fp32 (kinema.model.bf16_encoder)
            hidden = bf16_encoder.encode(self.encoder, tokens, key_padding)
        else:
            hidden = self.encoder(tokens, src_key_padding_mask=key_padding)
        return self.out_proj(hidden[:, self.num_cond:]).to(out_dtype)
