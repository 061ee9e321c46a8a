"""The stages' transformer encoder in bf16 with the attention softmax in fp32.

torch's fused encoder layer (``nn.TransformerEncoderLayer`` in eval mode) runs the attention softmax in
the weights' dtype. On these CPUs a bf16 softmax costs 1.5 ns per attention score against 0.5-0.7 ns
in fp32 (the bf16 kernel converts element by element), and with 4 heads over 111 tokens per row the
softmax was a fifth of a bf16 denoiser pass (docs/speed.md). ``encode`` computes the same layers with
the same weights: pre-LN self-attention and GELU feed-forward, but the scores, scaled, are turned into
probabilities in fp32 and back to bf16 before they weight the values. Attention runs over chunks of
``ATTENTION_ROWS`` rows, so its fp32 temporaries stay small (large ones are fresh memory from the
system on every call, and the page faults ate the gain at 24 rows).

Only for bf16 weights: in fp32 the fused layer is already exact and fast (kinema.model.layers uses it).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

#: rows (motions x guidance branches) per attention chunk
ATTENTION_ROWS = 4


def encode(encoder: nn.TransformerEncoder, tokens: torch.Tensor, key_padding: torch.Tensor | None) -> torch.Tensor:
    """``encoder(tokens, src_key_padding_mask=key_padding)`` for a pre-LN (``norm_first``) GELU encoder
    without dropout: ``tokens (B, N, width)``, ``key_padding (B, N)`` True where a key is ignored."""
    bias = None
    if key_padding is not None:
        bias = torch.zeros(key_padding.shape, dtype=torch.float32).masked_fill(key_padding, float("-inf"))
        bias = bias[:, None, None, :]  # (B, 1, 1, N): added to every head's scores
    x = tokens
    for layer in encoder.layers:
        x = x + _self_attention(layer.self_attn, layer.norm1(x), bias)
        x = x + layer.linear2(F.gelu(layer.linear1(layer.norm2(x))))
    return x if encoder.norm is None else encoder.norm(x)


def _self_attention(attn: nn.MultiheadAttention, x: torch.Tensor, bias: torch.Tensor | None) -> torch.Tensor:
    B, N, width = x.shape
    heads = attn.num_heads
    qkv = F.linear(x, attn.in_proj_weight, attn.in_proj_bias).view(B, N, 3, heads, width // heads)
    q, k, v = qkv.permute(2, 0, 3, 1, 4).contiguous().unbind(0)  # (B, heads, N, head_dim) each
    scale = 1.0 / math.sqrt(width // heads)
    out = []
    for lo in range(0, B, ATTENTION_ROWS):
        hi = lo + ATTENTION_ROWS
        scores = torch.matmul(q[lo:hi], k[lo:hi].transpose(-1, -2)).float().mul_(scale)
        if bias is not None:
            scores += bias[lo:hi]
        out.append(torch.matmul(scores.softmax(-1).to(v.dtype), v[lo:hi]))
    merged = torch.cat(out).transpose(1, 2).reshape(B, N, width)
    return attn.out_proj(merged)
