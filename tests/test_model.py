"""Tests for kinema.model: configs / presets, the two-stage denoiser and its one-stage baseline."""

from __future__ import annotations

import json

import pytest
import torch

from kinema.diffusion import Guidance, GuidanceMode
from kinema.errors import KinemaError
from kinema.model import (
    Denoiser,
    ModelConfig,
    get_config,
    impute,
    local_root_stats,
    padded_local_root,
    preset_names,
)
from kinema.representation.kimodo_features import global_to_local_root

J = 5  # small skeleton keeps the tests fast: D = 5 + 60 + 4 = 69
LENGTHS = (24, 17, 6)


def _model(name: str = "tiny", seed: int = 0, **overrides) -> Denoiser:
    torch.manual_seed(seed)
    model = Denoiser(get_config(name, J, text_dim=16, dropout=0.0, **overrides))
    D = model.config.feature_dim
    g = torch.Generator().manual_seed(seed + 1)
    # non-trivial statistics so the normalised <-> metric conversion of the root is exercised
    model.set_normalization(torch.randn(D, generator=g) * 0.3, torch.rand(D, generator=g) + 0.5)
    model.set_local_root_normalization(torch.randn(4, generator=g) * 0.1, torch.rand(4, generator=g) + 0.5)
    return model.eval()


def _inputs(model: Denoiser, lengths=LENGTHS, seed: int = 0) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(seed)
    B, T, D = len(lengths), max(lengths), model.config.feature_dim
    pad_mask = torch.arange(T)[None] < torch.tensor(lengths)[:, None]
    psi = torch.rand(B, generator=g) * 6.28
    return {
        "x_t": torch.randn(B, T, D, generator=g),
        "t": torch.randint(0, 1000, (B,), generator=g),
        "text_emb": torch.randn(B, model.config.text_dim, generator=g),
        "text_mask": torch.tensor([True, False, True])[:B],
        "c_dir": torch.stack([psi.cos(), psi.sin()], dim=-1),
        "x_tgt": torch.randn(B, T, D, generator=g),
        "mask": (torch.rand(B, T, D, generator=g) < 0.2).float(),
        "pad_mask": pad_mask,
    }


# ---------------------------------------------------------------------------- config
def test_config_json_round_trip(tmp_path) -> None:
    cfg = get_config("small", 22, text_dim=384, layers=3)
    path = tmp_path / "model.json"
    cfg.save_json(path)
    data = json.loads(path.read_text())
    assert data["feature_dim"] == 5 + 12 * 22 + 4 and data["layers"] == 3
    assert ModelConfig.load_json(path) == cfg
    assert ModelConfig.from_dict(cfg.to_dict()) == cfg


def test_config_errors() -> None:
    with pytest.raises(KinemaError):
        ModelConfig.from_dict({**get_config("tiny", J).to_dict(), "bogus": 1})
    with pytest.raises(KinemaError):
        ModelConfig.from_dict({**get_config("tiny", J).to_dict(), "feature_dim": 3})
    with pytest.raises(KinemaError):
        get_config("huge", J)
    with pytest.raises(KinemaError):
        get_config("tiny", J, width=66, heads=4)


def test_presets() -> None:
    assert set(preset_names()) >= {"tiny", "small", "paper", "small-1stage"}
    small, base = get_config("small-1stage", J), get_config("small", J)
    assert not small.two_stage and small.layers == 2 * base.layers and small.width == base.width
    assert get_config("paper", J).text_dim == 4096 and get_config("paper", J).num_registers == 49


def test_paper_parameter_count() -> None:
    """Paper Sec. 4.2: 'both transformers ... 16 layers, 8 heads, latent size 1024, 282 M parameters'."""
    with torch.device("meta"):
        model = Denoiser(get_config("paper", 27))
    n = model.num_parameters()
    assert abs(n - 282e6) / 282e6 < 0.2, n


def test_one_stage_matches_parameter_count() -> None:
    with torch.device("meta"):
        two = Denoiser(get_config("small", 22)).num_parameters()
        one = Denoiser(get_config("small-1stage", 22)).num_parameters()
    assert abs(one - two) / two < 0.15


# ---------------------------------------------------------------------------- forward
@pytest.mark.parametrize("name", ["tiny", "small", "tiny-1stage"])
def test_output_shapes_with_padding(name: str) -> None:
    model = _model(name)
    inp = _inputs(model)
    out = model(**inp)
    assert out.shape == inp["x_t"].shape and torch.isfinite(out).all()
    assert (out[~inp["pad_mask"]] == 0).all()
    # optional arguments
    assert model(inp["x_t"], inp["t"]).shape == inp["x_t"].shape


def test_one_stage_has_single_transformer() -> None:
    model = _model("tiny-1stage")
    assert hasattr(model, "stage") and not hasattr(model, "root_stage")


def test_impute_exact() -> None:
    inp = _inputs(_model())
    x = impute(inp["x_t"], inp["x_tgt"], inp["mask"])
    on = inp["mask"].bool()
    assert torch.equal(x[on], inp["x_tgt"][on]) and torch.equal(x[~on], inp["x_t"][~on])


@pytest.mark.parametrize("name", ["tiny", "tiny-1stage"])
def test_model_input_is_imputed_motion_and_mask(name: str) -> None:
    model = _model(name)
    inp = _inputs(model)
    seen = {}
    stage = model.root_stage if model.config.two_stage else model.stage

    def hook(module, args, out) -> None:
        seen["x"] = args[0]

    stage.in_proj.register_forward_hook(hook)
    model(**inp)
    D = model.config.feature_dim
    x_tilde, mask = seen["x"][..., :D], seen["x"][..., D:]
    on = inp["mask"].bool()
    assert torch.equal(mask, inp["mask"])
    assert torch.equal(x_tilde[on], inp["x_tgt"][on]) and torch.equal(x_tilde[~on], inp["x_t"][~on])


@pytest.mark.parametrize("name", ["tiny", "tiny-1stage"])
def test_padding_invariance(name: str) -> None:
    model = _model(name)
    inp = _inputs(model)
    ref = model(**inp)
    pad = ~inp["pad_mask"]
    g = torch.Generator().manual_seed(5)
    junk = dict(inp)
    for key in ("x_t", "x_tgt"):
        junk[key] = inp[key].clone()
        junk[key][pad] = torch.randn(int(pad.sum()), inp[key].shape[-1], generator=g) * 50
    junk["mask"] = inp["mask"].clone()
    junk["mask"][pad] = 1.0
    out = model(**junk)
    valid = inp["pad_mask"]
    torch.testing.assert_close(out[valid], ref[valid], atol=1e-5, rtol=1e-5)
    # and each sequence alone, unpadded, gives the same valid frames
    for b, n in enumerate(LENGTHS):
        one = {k: v[b : b + 1] for k, v in inp.items() if k != "pad_mask"}
        one = {k: (v[:, :n] if v.dim() == 3 else v) for k, v in one.items()}
        torch.testing.assert_close(model(**one)[0], ref[b, :n], atol=1e-5, rtol=1e-5)


def test_padded_local_root_matches_unpadded() -> None:
    g = torch.Generator().manual_seed(0)
    root = torch.randn(3, 12, 5, generator=g)
    pad_mask = torch.arange(12)[None] < torch.tensor([12, 7, 1])[:, None]
    local = padded_local_root(root, pad_mask, fps=20.0)
    for b, n in enumerate((12, 7, 1)):
        torch.testing.assert_close(local[b, :n], global_to_local_root(root[b, :n], 20.0))
        assert (local[b, n:] == 0).all()
    stats = local_root_stats([root[0], root[1, :7]], fps=20.0)
    assert stats.mean.shape == (4,) and (stats.std > 0).all()


def test_body_gradient_reaches_root_stage() -> None:
    model = _model().train()
    inp = _inputs(model)
    out = model(**inp)
    out[..., 5:].square().sum().backward()  # body output only
    grads = [p.grad for p in model.root_stage.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    assert model.root_stage.out_proj.weight.grad.abs().sum() > 0
    assert model.root_stage.in_proj.weight.grad.abs().sum() > 0


def test_dropped_text_equals_no_text() -> None:
    model = _model()
    inp = _inputs(model)
    dropped = model(**{**inp, "text_mask": torch.zeros(3, dtype=torch.bool)})
    none = model(**{**inp, "text_emb": None, "text_mask": None})
    torch.testing.assert_close(dropped, none)


def test_normalization_saved_in_state_dict() -> None:
    model = _model()
    other = Denoiser(model.config).eval()
    other.load_state_dict(model.state_dict())
    inp = _inputs(model)
    torch.testing.assert_close(other(**inp), model(**inp))
    assert torch.equal(other.feat_std, model.feat_std) and torch.equal(other.local_mean, model.local_mean)


# ---------------------------------------------------------------------------- guidance
def _branch(model: Denoiser, inp: dict, text: bool, constr: bool) -> torch.Tensor:
    return model(
        inp["x_t"],
        inp["t"],
        inp["text_emb"] if text else None,
        None,
        inp["c_dir"],
        inp["x_tgt"] if constr else None,
        inp["mask"] if constr else None,
        inp["pad_mask"],
    )


@pytest.mark.parametrize(
    "w, text, constr", [((1.0, 0.0), True, False), ((0.0, 1.0), False, True), ((0.0, 0.0), False, False)]
)
def test_forward_guided_separated_selects_branch(w, text, constr) -> None:
    model = _model()
    inp = _inputs(model)
    guided = model.forward_guided(
        inp["x_t"],
        inp["t"],
        inp["text_emb"],
        inp["c_dir"],
        inp["x_tgt"],
        inp["mask"],
        inp["pad_mask"],
        Guidance(GuidanceMode.SEPARATED, *w),
    )
    torch.testing.assert_close(guided, _branch(model, inp, text, constr), atol=1e-5, rtol=1e-5)


def test_forward_guided_regular_and_none() -> None:
    model = _model()
    inp = _inputs(model)
    args = (inp["x_t"], inp["t"], inp["text_emb"], inp["c_dir"], inp["x_tgt"], inp["mask"], inp["pad_mask"])
    cond = _branch(model, inp, True, True)
    torch.testing.assert_close(model.forward_guided(*args, Guidance(GuidanceMode.NONE)), cond, atol=1e-5, rtol=1e-5)
    torch.testing.assert_close(
        model.forward_guided(*args, Guidance(GuidanceMode.REGULAR, 1.0)), cond, atol=1e-5, rtol=1e-5
    )
    # no constraints: separated collapses to regular text CFG
    g = Guidance(GuidanceMode.SEPARATED, 2.0, 2.0)
    out = model.forward_guided(inp["x_t"], inp["t"], inp["text_emb"], inp["c_dir"], None, None, inp["pad_mask"], g)
    expected = 2.0 * _branch(model, inp, True, False) - _branch(model, inp, False, False)
    torch.testing.assert_close(out, expected, atol=1e-5, rtol=1e-5)


def test_set_dropout_zero_makes_training_mode_deterministic() -> None:
    model = _model("tiny")
    model.set_dropout(0.5)
    model.train()
    inp = _inputs(model)
    assert not torch.equal(model(**inp), model(**inp))
    model.set_dropout(0.0)
    torch.testing.assert_close(model(**inp), model(**inp))


def test_forward_guided_context_is_seen_by_every_branch() -> None:
    """A timeline's join frames (context_mask) enter every branch; they are not extrapolated as constraints."""
    model = _model()
    inp = _inputs(model)
    g = Guidance(GuidanceMode.SEPARATED, 2.0, 2.0)
    both = (inp["x_t"], inp["t"], inp["text_emb"], inp["c_dir"], inp["x_tgt"], inp["mask"], inp["pad_mask"])
    # only context: regular text CFG with the context in both branches
    ctx = model.forward_guided(*both, g, context_mask=inp["mask"])
    expected = 2.0 * _branch(model, inp, True, True) - _branch(model, inp, False, True)
    torch.testing.assert_close(ctx, expected, atol=1e-5, rtol=1e-5)
    # context plus constraints on other entries: the constraint branch sees both, the others the context
    ctx_mask = torch.zeros_like(inp["mask"])
    ctx_mask[:, :2] = inp["mask"][:, :2]
    mixed = model.forward_guided(*both, g, context_mask=ctx_mask)
    ctx_inp = {**inp, "mask": ctx_mask}
    d0 = _branch(model, ctx_inp, False, True)
    expected = -3.0 * d0 + 2.0 * _branch(model, ctx_inp, True, True) + 2.0 * _branch(model, inp, False, True)
    torch.testing.assert_close(mixed, expected, atol=1e-5, rtol=1e-5)
    assert not torch.allclose(mixed, model.forward_guided(*both, g), atol=1e-4)
