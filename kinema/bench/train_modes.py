"""`kinema bench train-modes`: training speed and loss parity of fp32, bf16 autocast and torch.compile.

Why: bf16 and compilation change the numbers a run computes, so they are worth having only if they are
faster *and* train as well. Every mode gets its own Trainer on the same data, config and seed, so all
modes see exactly the same batches, noise and timesteps; their steps are interleaved (one step of each
mode in turn), so load from other processes hits every mode alike and the speed ratios hold on a busy
machine. Steps during ``warmup`` (compilation, recompiles for new sequence lengths, allocator) are timed
separately. Parity: mean loss of each mode over the last ``tail`` steps and the mean relative per-step
difference to fp32 (same batch, same noise, so the per-step difference is the numeric drift alone).
"""

from __future__ import annotations

import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

#: mode name -> (bf16 autocast, torch.compile)
MODES = {"fp32": (False, False), "bf16": (True, False), "compile": (False, True), "compile+bf16": (True, True)}


@dataclass
class ModeRow:
    config: str
    mode: str
    steps: int
    warmup_s: float  # total seconds of the first ``warmup`` steps (compilation included)
    step_s: float  # median seconds per step after warm-up
    speedup: float  # fp32 median step / this mode's
    loss_tail: float  # mean loss over the last ``tail`` steps
    loss_rel_diff: float  # mean |loss - loss_fp32| / loss_fp32 over all steps


def _trainers(data: Path, config: str, modes, steps: int, batch: int, root: Path, cache_dir: Path | None):
    """One Trainer per mode, identical except for bf16 / compile."""
    from kinema.train.trainer import TrainConfig, Trainer

    out = {}
    for mode in modes:
        bf16, comp = MODES[mode]
        cfg = TrainConfig(model=config, steps=steps, batch_size=batch, warmup=min(50, steps // 4), log_every=10**9,
                          ckpt_every=10**9)
        out[mode] = Trainer(cfg, data, root / mode, cache_dir=cache_dir, bf16=bf16, compile=comp)
    return out


def bench_train_modes(data: str | Path, config: str = "small", modes=("fp32", "bf16", "compile"), steps: int = 300,
                      batch: int = 32, warmup: int = 20, tail: int = 100, cache_dir: Path | None = None,
                      progress: bool = True) -> tuple[list[ModeRow], dict[str, list[float]]]:
    """Train ``steps`` steps per mode, interleaved; returns the table rows and each mode's loss curve."""
    import torch
    from tqdm.auto import tqdm

    modes = list(dict.fromkeys(["fp32", *modes]))
    with tempfile.TemporaryDirectory(prefix="kinema-modes-") as tmp:
        trainers = _trainers(Path(data), config, modes, steps, batch, Path(tmp), cache_dir)
        models = {m: torch.compile(t.model) if t.compile else t.model for m, t in trainers.items()}
        times: dict[str, list[float]] = {m: [] for m in modes}
        losses: dict[str, list[float]] = {m: [] for m in modes}
        for _ in tqdm(range(steps), desc=f"train modes {config}", disable=not progress):
            for m in modes:
                t0 = time.perf_counter()
                rec = trainers[m].train_step(models[m])
                times[m].append(time.perf_counter() - t0)
                losses[m].append(rec["loss"])
    base_step = statistics.median(times["fp32"][warmup:])
    ref = losses["fp32"]
    rows = []
    for m in modes:
        med = statistics.median(times[m][warmup:])
        drift = statistics.fmean(abs(a - b) / abs(b) for a, b in zip(losses[m], ref, strict=True))
        rows.append(ModeRow(config, m, steps, sum(times[m][:warmup]), med, base_step / med,
                            statistics.fmean(losses[m][-tail:]), drift))
    return rows, losses


def format_modes(rows: list[ModeRow], tail: int = 100) -> str:
    """The table printed by `kinema bench train-modes`."""
    head = (f"{'config':<8}{'mode':<14}{'steps':>6}{'warm-up s':>10}{'s/step':>8}{'x fp32':>8}"
            f"{f'loss (last {tail})':>17}{'|dloss|/loss':>14}")
    lines = [head, "-" * len(head)]
    for r in rows:
        lines.append(f"{r.config:<8}{r.mode:<14}{r.steps:>6}{r.warmup_s:>10.1f}{r.step_s:>8.3f}{r.speedup:>8.2f}"
                     f"{r.loss_tail:>17.4f}{r.loss_rel_diff:>14.2%}")
    return "\n".join(lines)
