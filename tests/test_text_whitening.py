"""The whitened text projection (kinema.train.text_whitening): same function at the start, the plain
Linear format on disk, resumable, and a real change to which caption directions training moves."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from kinema.errors import KinemaError
from kinema.model.loading import load_denoiser
from kinema.train.text_whitening import WhitenedLinear, whitening
from kinema.train.trainer import TrainConfig, Trainer


def _embeddings(n: int = 400, dim: int = 12) -> torch.Tensor:
    """Embeddings whose spread falls 100x from the first axis to the last (like MiniLM captions)."""
    g = torch.Generator().manual_seed(0)
    return torch.randn(n, dim, generator=g) * torch.logspace(0, -2, dim) + 0.3


def test_whitening_gives_unit_spread_up_to_the_shrinkage():
    e = _embeddings()
    mu, a = whitening(e, 1e-8)
    w = (e.double() - mu) @ a
    assert torch.allclose(torch.cov(w.T), torch.eye(12, dtype=torch.float64), atol=1e-3)
    mu, a = whitening(e, 0.01)  # shrunk: the weakest axis (variance 1e-4 of the strongest) gains 10x, not 100x
    var = torch.cov(((e.double() - mu) @ a).T).diagonal()
    assert 0.005 < float(var[-1]) < 0.02 and float(var[0]) > 0.9
    with pytest.raises(KinemaError, match=r"text_whiten must be in \(0, 1\]"):
        whitening(e, 0.0)


def test_whitened_linear_is_the_same_function_and_saves_folded():
    e = _embeddings()
    lin = nn.Linear(12, 5)
    mu, a = whitening(e, 0.01)
    w = WhitenedLinear(lin, mu, a)
    x = torch.randn(7, 12)
    assert torch.allclose(w(x), lin(x), atol=1e-5)
    assert torch.allclose(w(torch.zeros(1, 12))[0], lin.bias, atol=1e-6)  # "no text" is still the bias
    state = w.state_dict()
    assert sorted(state) == ["bias", "weight"]
    assert torch.allclose(state["weight"], lin.weight, atol=1e-5)
    plain = nn.Linear(12, 5)
    plain.load_state_dict(state)
    again = WhitenedLinear(nn.Linear(12, 5), mu, a)
    again.load_state_dict(state)
    assert torch.allclose(plain(x), w(x), atol=1e-5) and torch.allclose(again(x), w(x), atol=1e-5)


def test_a_gradient_step_moves_weak_caption_directions_more_when_whitened():
    """Why it exists: the targets depend on the weakest embedding axis only (a small caption direction
    that should change the motion a lot); one SGD step learns far more of that response in whitened
    coordinates than in raw ones (about 1 / (its variance + the shrinkage), ~100x here)."""
    e = _embeddings() - 0.3
    target = 100.0 * e[:, -1:].expand(-1, 5)
    mu, a = whitening(e, 0.01)
    weak = torch.zeros(12)
    weak[-1] = 1.0

    def learnt(module: nn.Module) -> float:
        """Gain along the weak axis after one step (the targets want 100)."""
        ((module(e) - target) ** 2).mean().backward()
        with torch.no_grad():
            for p in module.parameters():
                p -= 0.1 * p.grad
            return float((module(weak[None]) - module(torch.zeros(1, 12))).mean())

    torch.manual_seed(1)
    lin = nn.Linear(12, 5)
    with torch.no_grad():
        lin.weight.zero_()
    raw = nn.Linear(12, 5)
    raw.load_state_dict(lin.state_dict())
    gain_whitened, gain_raw = learnt(WhitenedLinear(lin, mu, a)), learnt(raw)
    assert gain_whitened > 30 * gain_raw > 0


def test_training_with_whitening_resumes_exactly_and_exports_a_plain_model(tiny_data, tmp_path):
    def cfg(**kw):
        return TrainConfig(model="tiny", steps=6, batch_size=4, lr=1e-3, warmup=2, text_encoder="hash-test-32",
                           max_seconds=4.0, ckpt_every=3, text_whiten=0.05, **kw)

    straight = Trainer(cfg(), tiny_data, tmp_path / "a")
    assert any(isinstance(m, WhitenedLinear) for m in straight.model.modules())
    straight.run(progress=False)
    first = Trainer(cfg(), tiny_data, tmp_path / "b")
    first.run(progress=False, stop_after=3)
    resumed = Trainer(cfg(), tiny_data, tmp_path / "b")
    assert resumed.resume() and resumed.step == 3
    resumed.run(progress=False)
    # not bit-exact as unwhitened runs are: a checkpoint holds the folded weights, and unfolding them again
    # changes W' by about a float32 ulp, which Adam turns into up to ~1e-5 on parameters whose gradient is
    # ~0 (key biases); measured 1e-5 at lr 1e-3, so 5e-4 (half a step) still catches a wrong unfolding
    for (name, p), q in zip(straight.model.state_dict().items(), resumed.model.state_dict().values(), strict=True):
        assert torch.allclose(p, q, atol=5e-4), name
    loaded = load_denoiser(tmp_path / "a").denoiser  # a plain Denoiser: inference needs no whitening
    assert not any(isinstance(m, WhitenedLinear) for m in loaded.modules())
    ema = straight.ema.state_dict()
    for name, p in loaded.state_dict().items():
        assert torch.allclose(p, ema[name].float(), atol=1e-3), name
