"""`kinema bench train`: training step time, samples/s and FLOPs per step for each model preset.

Synthetic inputs of the real feature size (no dataset needed); the step is the full training step
(forward with constraint mask, Eq. 1-style loss, backward, AdamW). FLOPs come from PyTorch's
FlopCounterMode (matrix multiplies and attention; element-wise work is not counted).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import torch

from kinema.model.config import get_config
from kinema.model.denoiser import Denoiser


@dataclass
class TrainBenchRow:
    config: str
    params_m: float
    batch: int
    frames: int
    step_s: float
    samples_per_s: float
    gflops_per_step: float
    fwd3_ms: float  # one inference forward pass at batch 3 (the three guidance branches)


def _inputs(cfg, batch: int, frames: int, g: torch.Generator):
    D = cfg.feature_dim
    x = torch.randn(batch, frames, D, generator=g)
    return dict(
        x_t=x, t=torch.randint(0, 1000, (batch,), generator=g), text_emb=torch.randn(batch, cfg.text_dim, generator=g),
        text_mask=None, c_dir=torch.nn.functional.normalize(torch.randn(batch, 2, generator=g), dim=-1),
        x_tgt=x, mask=(torch.rand(batch, frames, D, generator=g) < 0.05).float(), pad_mask=None,
    )


def make_train_step(name: str, num_joints: int = 21, batch: int = 32, frames: int = 100, fps: float = 20.0):
    """``(model, step, cfg, generator)`` for one preset: ``step()`` runs one full training step on fixed
    synthetic inputs. Shared by the per-preset table and the threads measurement."""
    cfg = get_config(name, num_joints, fps=fps, max_frames=max(frames, 200))
    model = Denoiser(cfg)
    opt = torch.optim.AdamW(model.parameters(), lr=1e-4)
    g = torch.Generator().manual_seed(0)
    inp = _inputs(cfg, batch, frames, g)

    def step():
        out = model(**inp)
        loss = torch.nn.functional.smooth_l1_loss(out, inp["x_t"])
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()

    return model, step, cfg, g


def bench_config(name: str, num_joints: int = 21, batch: int = 32, frames: int = 100, repeats: int = 3,
                 fps: float = 20.0) -> TrainBenchRow:
    """Time one preset; ``frames`` tokens per sample (100 = 5 s at 20 fps)."""
    from torch.utils.flop_counter import FlopCounterMode

    model, step, cfg, g = make_train_step(name, num_joints, batch, frames, fps)
    counter = FlopCounterMode(display=False)
    with counter:
        step()
    step()  # warm-up
    t0 = time.perf_counter()
    for _ in range(repeats):
        step()
    step_s = (time.perf_counter() - t0) / repeats
    model.eval()
    inf = _inputs(cfg, 3, frames, g)
    with torch.no_grad():
        model(**inf)
        t0 = time.perf_counter()
        for _ in range(repeats):
            model(**inf)
        fwd = (time.perf_counter() - t0) / repeats
    return TrainBenchRow(name, model.num_parameters() / 1e6, batch, frames, step_s, batch / step_s,
                         counter.get_total_flops() / 1e9, fwd * 1000)


def format_table(rows: list[TrainBenchRow]) -> str:
    """One line per preset: parameters, step time, samples/s, FLOPs."""
    head = f"{'config':<14}{'params (M)':>11}{'batch x T':>11}{'step (s)':>10}{'samples/s':>11}" \
           f"{'GFLOP/step':>12}{'GFLOP/s':>9}{'fwd@3 (ms)':>12}"
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.config:<14}{r.params_m:>11.2f}{f'{r.batch}x{r.frames}':>11}{r.step_s:>10.3f}"
                     f"{r.samples_per_s:>11.1f}{r.gflops_per_step:>12.1f}{r.gflops_per_step / r.step_s:>9.1f}"
                     f"{r.fwd3_ms:>12.1f}")
    return "\n".join(lines)
