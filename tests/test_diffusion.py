"""Tests for kinema.diffusion: noise schedule, DDIM sampler, separated classifier-free guidance."""

from __future__ import annotations

import json
import math

import pytest
import torch

from kinema.diffusion import (
    DDIMSampler,
    Guidance,
    GuidanceMode,
    NoiseSchedule,
    branches,
    combine,
    spaced_timesteps,
    split_branches,
    stack_branches,
)
from kinema.errors import KinemaError

SHAPE = (4, 30, 8)  # (batch, frames, features)


def _x0(seed: int = 0) -> torch.Tensor:
    return torch.randn(SHAPE, generator=torch.Generator().manual_seed(seed))


def _toy_denoiser(x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """A deterministic stand-in for a network: some smooth function of x_t and t."""
    return torch.tanh(x_t) * (1.0 - t.float().reshape(-1, 1, 1) / 2000.0)


# ---------------------------------------------------------------------------- schedule
@pytest.mark.parametrize("kind", ["cosine", "linear"])
def test_alphas_cumprod_monotone_in_unit_interval(kind: str) -> None:
    abar = NoiseSchedule(kind=kind).alphas_cumprod
    assert abar.dtype == torch.float64 and abar.shape == (1000,)
    assert bool(((abar > 0) & (abar < 1)).all())
    assert bool((abar[1:] < abar[:-1]).all())
    assert abar[0] > 0.999 and abar[-1] < 1e-3


def test_cosine_schedule_values() -> None:
    sched = NoiseSchedule()
    assert bool((sched.betas <= 0.999).all())

    # alpha-bar tracks cos^2 of the normalised step away from the clipped end.
    def f(u: float) -> float:
        return math.cos((u + 0.008) / 1.008 * math.pi / 2) ** 2

    assert sched.alphas_cumprod[499].item() == pytest.approx(f(0.5) / f(0.0), rel=1e-9)


def test_q_sample_statistics() -> None:
    sched = NoiseSchedule()
    gen = torch.Generator().manual_seed(1)
    x0 = torch.full((2000, 16), 3.0)
    noise = torch.randn(x0.shape, generator=gen)
    t0 = torch.zeros(2000, dtype=torch.long)
    assert torch.allclose(sched.q_sample(x0, t0, noise), x0, atol=0.05)
    t_last = torch.full((2000,), 999, dtype=torch.long)
    xt = sched.q_sample(x0, t_last, noise)
    assert abs(xt.mean().item()) < 0.05 and abs(xt.std().item() - 1.0) < 0.05
    # Per-item timesteps broadcast over the remaining dims.
    mixed = sched.q_sample(x0[:2], torch.tensor([0, 999]), noise[:2])
    assert torch.allclose(mixed[0], x0[0], atol=0.05) and torch.allclose(mixed[1], noise[1], atol=0.1)


def test_schedule_validation_and_dict_round_trip() -> None:
    sched = NoiseSchedule(num_train_steps=50, kind="linear")
    assert NoiseSchedule.from_dict(sched.to_dict()) == sched
    with pytest.raises(ValueError):
        NoiseSchedule(kind="sigmoid")
    with pytest.raises(KinemaError):
        NoiseSchedule.from_dict({"kind": "cosine", "beta": 3})
    with pytest.raises(ValueError):
        sched.q_sample(torch.zeros(2, 3), torch.tensor([0, 50]), torch.zeros(2, 3))


# ---------------------------------------------------------------------------- timesteps
@pytest.mark.parametrize("n", [1, 7, 10, 50, 100, 333, 999, 1000])
def test_set_timesteps_trailing_spacing(n: int) -> None:
    sampler = DDIMSampler(num_inference_steps=n)
    ts = sampler.timesteps
    assert ts.dtype == torch.long and ts.shape == (n,)
    assert ts[0].item() == 999 and ts[-1].item() >= 0
    assert bool((ts[1:] < ts[:-1]).all())  # strictly descending => unique
    gaps = (ts[:-1] - ts[1:]).tolist()
    assert max(gaps, default=0) - min(gaps, default=0) <= 1  # evenly spaced up to rounding


def test_set_timesteps_values_and_leading() -> None:
    assert spaced_timesteps(1000, 10) == [999, 899, 799, 699, 599, 499, 399, 299, 199, 99]
    assert spaced_timesteps(1000, 4, "leading") == [750, 500, 250, 0]
    sampler = DDIMSampler(num_inference_steps=100)
    sampler.set_timesteps(25)
    assert sampler.num_inference_steps == 25 and len(sampler.timesteps) == 25
    with pytest.raises(ValueError):
        sampler.set_timesteps(1001)
    with pytest.raises(ValueError):
        sampler.set_timesteps(0)


# ---------------------------------------------------------------------------- DDIM
@pytest.mark.parametrize("n", [10, 50, 100])
def test_ddim_with_oracle_denoiser_ends_at_x0(n: int) -> None:
    x0 = _x0()
    sampler = DDIMSampler(num_inference_steps=n)
    init = torch.randn(SHAPE, generator=torch.Generator().manual_seed(7))
    seen: list[int] = []

    def oracle(x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        # With eta = 0 and a perfect x0, every x_t stays on the forward path of the initial noise
        # (up to sqrt(abar_{T-1}) ~ 5e-5 of signal that pure N(0, I) noise lacks at the first step).
        expected = sampler.add_noise(x0, init, t)
        assert torch.allclose(x_t, expected, atol=1e-3)
        seen.append(int(t[0]))
        return x0.clone()

    out = sampler.sample(oracle, SHAPE, init_noise=init)
    assert torch.equal(out, x0)
    assert seen == sampler.timesteps.tolist()


def test_ddim_eta_zero_is_deterministic_per_seed() -> None:
    sampler = DDIMSampler(num_inference_steps=20)
    a = sampler.sample(_toy_denoiser, SHAPE, torch.Generator().manual_seed(3))
    b = sampler.sample(_toy_denoiser, SHAPE, torch.Generator().manual_seed(3))
    c = sampler.sample(_toy_denoiser, SHAPE, torch.Generator().manual_seed(4))
    assert torch.equal(a, b)
    assert not torch.allclose(a, c)


def test_ddim_stochastic_eta_reproducible_and_oracle_exact() -> None:
    sampler = DDIMSampler(num_inference_steps=20, eta=1.0)
    a = sampler.sample(_toy_denoiser, SHAPE, torch.Generator().manual_seed(3))
    b = sampler.sample(_toy_denoiser, SHAPE, torch.Generator().manual_seed(3))
    deterministic = DDIMSampler(num_inference_steps=20).sample(_toy_denoiser, SHAPE, torch.Generator().manual_seed(3))
    assert torch.equal(a, b) and not torch.allclose(a, deterministic)
    x0 = _x0()
    out = sampler.sample(lambda x, t: x0, SHAPE, torch.Generator().manual_seed(0))
    assert torch.equal(out, x0)


def test_step_rejects_unknown_or_mixed_timesteps() -> None:
    sampler = DDIMSampler(num_inference_steps=10)
    x = torch.zeros(2, 3)
    with pytest.raises(ValueError):
        sampler.step(x, 500, x)
    with pytest.raises(ValueError):
        sampler.step(x, torch.tensor([999, 899]), x)
    assert sampler.step(x, torch.tensor([999, 999]), x).shape == x.shape
    assert sampler.step(x, 99, x) is x  # final step returns the x0 prediction


def test_sample_progress_bar_runs() -> None:
    sampler = DDIMSampler(num_inference_steps=3)
    out = sampler.sample(_toy_denoiser, (1, 2, 3), torch.Generator().manual_seed(0), progress=True)
    assert out.shape == (1, 2, 3)


def test_config_json_round_trip_reproduces_samples(tmp_path) -> None:
    sampler = DDIMSampler(NoiseSchedule(kind="linear"), num_inference_steps=17, eta=0.5)
    path = tmp_path / "model" / "sampler.json"
    sampler.save_json(path)
    loaded = DDIMSampler.load_json(path)
    assert loaded.config == sampler.config == json.loads(path.read_text())
    assert torch.equal(loaded.timesteps, sampler.timesteps)
    a = sampler.sample(_toy_denoiser, SHAPE, torch.Generator().manual_seed(11))
    b = loaded.sample(_toy_denoiser, SHAPE, torch.Generator().manual_seed(11))
    assert torch.equal(a, b)
    assert DDIMSampler.from_dict(sampler.to_dict()).config == sampler.config


def test_load_json_errors(tmp_path) -> None:
    with pytest.raises(KinemaError):
        DDIMSampler.load_json(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(KinemaError):
        DDIMSampler.load_json(bad)
    bad.write_text(json.dumps({"num_inference_steps": 5000}))
    with pytest.raises(KinemaError):
        DDIMSampler.load_json(bad)


# ---------------------------------------------------------------------------- guidance
def _outputs() -> dict[str, torch.Tensor]:
    gen = torch.Generator().manual_seed(5)
    return {name: torch.randn(SHAPE, generator=gen) for name in ("uncond", "cond", "text", "constr")}


def test_branches_per_mode() -> None:
    assert branches("none") == ["cond"]
    assert branches(GuidanceMode.REGULAR) == ["uncond", "cond"]
    assert branches("separated") == ["uncond", "text", "constr"]
    assert Guidance().branches == ["uncond", "text", "constr"]
    with pytest.raises(ValueError):
        branches("double")


def test_combine_separated() -> None:
    out = _outputs()
    assert torch.equal(combine(Guidance("separated", 1.0, 0.0), out), out["text"])
    assert torch.equal(combine(Guidance("separated", 0.0, 1.0), out), out["constr"])
    assert torch.equal(combine(Guidance("separated", 0.0, 0.0), out), out["uncond"])
    u, te, co = out["uncond"], out["text"], out["constr"]
    expected = u + 2.0 * (te - u) + 2.0 * (co - u)
    assert torch.allclose(combine(Guidance(), out), expected, atol=1e-5)


def test_combine_regular_and_none() -> None:
    out = _outputs()
    u, c = out["uncond"], out["cond"]
    assert torch.allclose(combine(Guidance("regular", w_text=3.5), out), u + 3.5 * (c - u), atol=1e-5)
    assert torch.equal(combine(Guidance("none"), out), c)
    with pytest.raises(KeyError):
        combine(Guidance(), {"uncond": u, "text": c})


def test_guidance_without_constraints_and_dict() -> None:
    g = Guidance(w_text=2.5, w_constr=1.5)
    out = _outputs()
    out["constr"] = out["uncond"]  # no constraints: the constraint branch equals the unconditional one
    out["cond"] = out["text"]
    cheap = g.without_constraints()
    assert cheap.mode is GuidanceMode.REGULAR
    assert torch.allclose(combine(cheap, out), combine(g, out), atol=1e-5)
    assert Guidance.from_dict(g.to_dict()) == g
    with pytest.raises(KinemaError):
        Guidance.from_dict({"mode": "separated", "w": 1})


def test_stack_split_round_trip() -> None:
    names = branches("separated")
    per_branch = {name: torch.randn(SHAPE) for name in names}
    stacked = stack_branches(per_branch, names)
    assert stacked.shape == (3 * SHAPE[0], *SHAPE[1:])
    back = split_branches(stacked, names)
    assert list(back) == names
    for name in names:
        assert torch.equal(back[name], per_branch[name])
    shared = torch.randn(SHAPE)
    rep = split_branches(stack_branches(shared, names), names)
    assert all(torch.equal(v, shared) for v in rep.values())
    t = torch.tensor([5, 5, 5, 5])
    assert stack_branches(t, names).tolist() == [5] * 12
    with pytest.raises(ValueError):
        split_branches(torch.zeros(7, 2), names)


def test_guided_sampling_single_batched_forward() -> None:
    """All guidance branches go through the denoiser as one (k*B) batch per step."""
    guidance = Guidance()
    names = guidance.branches
    calls: list[int] = []
    cond_scale = {"uncond": 0.0, "text": 1.0, "constr": -1.0}

    def model(x: torch.Tensor, t: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
        calls.append(x.shape[0])
        return torch.tanh(x) + scale.reshape(-1, 1, 1)

    def denoise(x_t: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        scales = {n: torch.full((x_t.shape[0],), cond_scale[n]) for n in names}
        out = model(stack_branches(x_t, names), stack_branches(t, names), stack_branches(scales, names))
        return combine(guidance, split_branches(out, names))

    sampler = DDIMSampler(num_inference_steps=5)
    result = sampler.sample(denoise, SHAPE, torch.Generator().manual_seed(0))
    assert calls == [3 * SHAPE[0]] * 5
    assert torch.isfinite(result).all()


@pytest.mark.parametrize("strength, kept", [(1.0, 10), (0.6, 6), (0.01, 1)])
def test_start_x0_runs_the_last_share_of_the_steps_from_the_noised_start(strength: float, kept: int) -> None:
    """SDEdit: the chain starts at the first kept step, from ``start_x0`` noised to it with the draw."""
    sampler = DDIMSampler(num_inference_steps=10)
    start, noise = _x0(3), _x0(4)
    seen: list[tuple[int, torch.Tensor]] = []

    def denoise(x, t):
        seen.append((int(t[0]), x.clone()))
        return start

    out = sampler.sample(denoise, SHAPE, init_noise=noise, start_x0=start, strength=strength)
    assert [t for t, _ in seen] == sampler.timesteps.tolist()[10 - kept :]
    t0 = torch.full((SHAPE[0],), seen[0][0], dtype=torch.long)
    assert torch.allclose(seen[0][1], sampler.add_noise(start, noise, t0))
    assert torch.allclose(out, start, atol=1e-4)  # an oracle denoiser ends at its clean estimate
