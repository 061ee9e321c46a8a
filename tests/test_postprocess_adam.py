"""The hand-written cosine Adam of kinema.postprocess.exact: same maths as torch.optim.Adam + LambdaLR,
and post-processing no longer imports torch._dynamo (which cost 1.1-1.2 s on the first call)."""

from __future__ import annotations

import math
import subprocess
import sys

import pytest
import torch

from kinema.postprocess import PostTargets, exact
from kinema.postprocess.exact import CosineAdam
from tests.test_postprocess import posed_humanoid


class _TorchCosineAdam:
    """Reference: the torch.optim.Adam + LambdaLR pair ``optimise`` used before, behind CosineAdam's API."""

    def __init__(self, params, lr, iterations):
        self.params = list(params)
        self.opt = torch.optim.Adam(self.params, lr=lr)
        self.sched = torch.optim.lr_scheduler.LambdaLR(
            self.opt, lambda i: 0.5 * (1 + math.cos(math.pi * i / max(iterations, 1)))
        )

    def step(self, grads):
        for p, g in zip(self.params, grads, strict=True):
            p.grad = g.clone()
        self.opt.step()
        self.sched.step()


def _rosenbrock_run(opt_cls, iterations=40):
    x = torch.tensor([-1.2, 1.0, 0.5], dtype=torch.float64, requires_grad=True)
    y = torch.tensor([[0.3, -0.7]], dtype=torch.float64, requires_grad=True)
    opt = opt_cls([x, y], lr=0.05, iterations=iterations)
    for _ in range(iterations):
        loss = ((1 - x[:2]) ** 2).sum() + 100 * ((x[1:] - x[:-1] ** 2) ** 2).sum() + ((y - x[:2]) ** 4).sum()
        opt.step(torch.autograd.grad(loss, [x, y]))
    return x.detach(), y.detach()


def test_cosine_adam_matches_torch_adam_with_lambda_lr():
    ours = _rosenbrock_run(CosineAdam)
    ref = _rosenbrock_run(_TorchCosineAdam)
    for a, b in zip(ours, ref, strict=True):
        assert torch.allclose(a, b, rtol=0, atol=1e-12), (a, b)
    assert not torch.equal(ours[0], torch.tensor([-1.2, 1.0, 0.5], dtype=torch.float64))  # it moved


def _hand_targets(m):
    hand = m.skeleton.roles["right_hand"]
    f = torch.tensor([5, 10])
    return PostTargets(joint_positions={hand: (f, m.positions[f, hand] + torch.tensor([0.05, 0.1, -0.05]))})


def test_optimise_matches_the_torch_optimiser(monkeypatch):
    m = posed_humanoid(T=20, amount=0.2)
    targets = _hand_targets(m)
    ours, info = exact.optimise(m, targets, iterations=12)
    monkeypatch.setattr(exact, "CosineAdam", _TorchCosineAdam)
    ref, ref_info = exact.optimise(m, targets, iterations=12)
    assert torch.allclose(ours.local_rotations, ref.local_rotations, rtol=0, atol=1e-10)
    assert torch.allclose(ours.root_translation, ref.root_translation, rtol=0, atol=1e-10)
    assert info["loss_end"] == pytest.approx(ref_info["loss_end"], rel=1e-9)
    assert info["loss_end"] < info["loss_start"]


def test_hit_constraints_does_not_import_dynamo():
    code = (
        "import sys, torch\n"
        "from kinema.postprocess.exact import hit_constraints\n"
        "from tests.test_postprocess_adam import _hand_targets\n"
        "from tests.test_postprocess import posed_humanoid\n"
        "m = posed_humanoid(T=20, amount=0.2)\n"
        "hit_constraints(m, _hand_targets(m))\n"
        "assert 'torch._dynamo' not in sys.modules, 'torch._dynamo was imported'\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
