"""kinema.model.bf16_encoder: the stages' encoder in bf16 with the attention softmax in fp32."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from kinema.model import bf16_encoder
from kinema.model.config import ModelConfig
from kinema.model.layers import StageTransformer


def _encoder(width: int = 32, heads: int = 4, layers: int = 2) -> nn.TransformerEncoder:
    torch.manual_seed(0)
    layer = nn.TransformerEncoderLayer(width, heads, 2 * width, 0.0, activation="gelu", batch_first=True,
                                       norm_first=True)
    return nn.TransformerEncoder(layer, layers, norm=nn.LayerNorm(width), enable_nested_tensor=False).eval()


@pytest.mark.parametrize("rows", [1, 3, 9])  # fewer, as many and more rows than one attention chunk
def test_encode_equals_torch_encoder_in_fp32(rows) -> None:
    """In fp32 the same layers give torch's own encoder's output to float rounding, with and without padded
    keys (the valid tokens never see the padded ones), so only the softmax's precision differs in bf16."""
    enc = _encoder()
    x = torch.randn(rows, 13, 32)
    pad = torch.zeros(rows, 13, dtype=torch.bool)
    pad[:, 10:] = True
    with torch.no_grad():
        for key_padding in (None, pad):
            want = enc(x, src_key_padding_mask=key_padding)
            got = bf16_encoder.encode(enc, x, key_padding)
            valid = slice(None) if key_padding is None else slice(0, 10)
            assert torch.allclose(got[:, valid], want[:, valid], atol=1e-5), (got - want)[:, valid].abs().max()


def test_encode_in_bf16_is_closer_to_fp32_than_torchs_bf16_layer() -> None:
    enc = _encoder()
    x = torch.randn(4, 40, 32)
    with torch.no_grad():
        exact = enc(x)
        enc.to(torch.bfloat16)
        fused = enc(x.to(torch.bfloat16)).float()
        ours = bf16_encoder.encode(enc, x.to(torch.bfloat16), None)
    assert ours.dtype == torch.bfloat16
    err_ours, err_fused = (ours.float() - exact).abs().mean(), (fused - exact).abs().mean()
    assert err_ours < 0.05 and err_ours <= 1.2 * err_fused, (err_ours, err_fused)


def test_stage_transformer_uses_it_for_bf16_weights_in_eval_only(monkeypatch) -> None:
    cfg = ModelConfig(num_joints=3, width=32, layers=1, heads=4, ff_mult=2, dropout=0.0, num_registers=2,
                      text_dim=8, max_frames=20)
    stage = StageTransformer(cfg, in_dim=12, out_dim=5).eval()
    calls = []
    encode = bf16_encoder.encode
    monkeypatch.setattr(bf16_encoder, "encode", lambda *a: calls.append(1) or encode(*a))
    args = (torch.randn(2, 6, 12), torch.tensor([3, 4]), torch.randn(2, 8), torch.randn(2, 2), None)
    with torch.no_grad():
        stage(*args)
        assert not calls  # fp32: torch's fused layer
        stage.to(torch.bfloat16)
        out = stage(*args)
        assert calls and out.dtype == torch.float32  # bf16 weights: this module, fp32 out
        stage.train()
        calls.clear()
        stage(*args)
        assert not calls
