"""bf16 inference (issue 37): what ``precision`` loads, what stays fp32, and how it is chosen."""

from __future__ import annotations

import pytest
import torch

import kinema
from kinema.errors import KinemaError
from kinema.model import precision as P


def test_auto_follows_the_cpu_and_the_environment(monkeypatch):
    monkeypatch.delenv(P.ENV, raising=False)
    monkeypatch.setattr(P, "cpu_bf16_flags", lambda: ())
    assert P.resolve_precision(None) == "fp32" and P.resolve_precision("auto") == "fp32"  # a CPU without bf16
    monkeypatch.setattr(P, "cpu_bf16_flags", lambda: ("avx512_bf16",))
    assert P.resolve_precision("auto") == ("bf16" if P.AUTO_BF16 else "fp32")
    assert P.resolve_precision("fp32") == "fp32" and P.resolve_precision("bf16") == "bf16"
    monkeypatch.setenv(P.ENV, "fp32")
    assert P.resolve_precision(None) == "fp32"
    monkeypatch.setenv(P.ENV, "half")
    with pytest.raises(KinemaError, match="KINEMA_PRECISION: expected one of auto, fp32, bf16, got 'half'"):
        P.resolve_precision(None)
    with pytest.raises(KinemaError, match="precision: expected one of"):
        P.resolve_precision("fp16")


def test_bf16_weights_fp32_around_them():
    torch.set_num_threads(1)
    fp32, bf16 = kinema.load_model(precision="fp32"), kinema.load_model(precision="bf16")
    assert (fp32.precision, bf16.precision) == ("fp32", "bf16") and "bf16" in repr(bf16)
    den = bf16.loaded.denoiser
    assert {p.dtype for p in den.parameters()} == {torch.bfloat16}
    assert {b.dtype for b in den.buffers()} == {torch.float32}  # normalisation statistics, positional codes
    x = torch.randn(2, 20, den.config.feature_dim)
    with torch.no_grad():
        out16 = den(x, torch.full((2,), 300), torch.randn(2, den.config.text_dim))
        out32 = fp32.loaded.denoiser(x, torch.full((2,), 300), None)
    assert out16.dtype == torch.float32 and out32.dtype == torch.float32
    kw = {"seconds": 1.5, "steps": 3, "seed": 0, "postprocess": False}
    a, b = fp32.generate("A person walks forward.", **kw)[0], bf16.generate("A person walks forward.", **kw)[0]
    assert b.local_rotations.dtype == torch.float32 and bool(torch.isfinite(b.positions).all())
    assert 0 < float((a.positions - b.positions).norm(dim=-1).mean()) < 0.1  # differs, by centimetres


def test_the_any_rig_model_is_fp32_only():
    from kinema.generate import resolve_model_path

    try:
        resolve_model_path("creatures")
    except KinemaError:
        pytest.skip("this install ships no creatures model")
    with pytest.raises(KinemaError, match="runs in fp32 only, not bf16"):
        kinema.load_model("creatures", precision="bf16")
    assert kinema.load_model("creatures", precision="auto").pipeline_name == "anyrig"
