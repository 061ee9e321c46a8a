"""Inference precision of the denoisers: fp32, or bf16 weights where the CPU multiplies bf16 fast.

``bf16`` converts the *weights* of every transformer stage (kinema.model.layers.StageTransformer) to
bfloat16; a stage casts its inputs to its weights' dtype and its output back, so everything around it
stays fp32: the feature normalisation, the root stage's un-normalised root and local-root conversion,
the sampler's arithmetic, constraint imputation and post-processing; inside a bf16 stage the attention
softmax runs in fp32 (kinema.model.bf16_encoder: faster on these CPUs). Weights, not autocast: autocast
casts the weights on every call and (on these CPUs) falls off oneDNN's bf16 fast path.

bf16 only pays on a CPU with bf16 dot-product instructions: AVX512-BF16 (AMD Zen 4, Intel Cooper Lake
and later) or AMX (Intel Sapphire Rapids and later). Elsewhere oneDNN emulates bf16 and it is slower
than fp32. ``auto`` picks bf16 only where the CPU has them and ``AUTO_BF16`` says quality holds
(decided by the evaluation in docs/speed.md, "bf16 inference").
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import torch
from torch import nn

from kinema.errors import KinemaError

PRECISIONS = ("auto", "fp32", "bf16")
#: environment variable holding the precision a ``load_model`` call without one uses (default auto);
#: every command's ``--precision`` sets it, so servers, batch workers and streams load alike
ENV = "KINEMA_PRECISION"
#: does ``auto`` pick bf16 on a CPU with bf16 instructions? (docs/speed.md, "bf16 inference")
AUTO_BF16 = True


@lru_cache(maxsize=1)
def cpu_bf16_flags() -> tuple[str, ...]:
    """The CPU's bf16 instruction flags (``avx512_bf16``, ``amx_bf16``) from /proc/cpuinfo; empty where
    it has none or the file is unreadable (not Linux)."""
    try:
        text = Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace")
    except OSError:
        return ()
    flags: set[str] = set()
    for line in text.splitlines():
        if line.startswith("flags"):
            flags |= set(line.split(":", 1)[-1].split())
            break
    return tuple(sorted(flags & {"avx512_bf16", "amx_bf16"}))


def fast_bf16() -> bool:
    """Whether this machine multiplies bf16 matrices faster than fp32 (bf16 instructions on the CPU)."""
    return bool(cpu_bf16_flags())


def resolve_precision(precision: str | None) -> str:
    """``"fp32"`` or ``"bf16"`` for a requested ``precision`` (None: ``$KINEMA_PRECISION``, else auto;
    auto: bf16 on a CPU with bf16 instructions when ``AUTO_BF16``, else fp32); anything else is a
    one-line KinemaError."""
    where = "precision"
    if precision is None:
        precision, where = os.environ.get(ENV, "auto") or "auto", ENV
    if precision not in PRECISIONS:
        raise KinemaError(f"{where}: expected one of {', '.join(PRECISIONS)}, got {precision!r}")
    if precision == "auto":
        return "bf16" if AUTO_BF16 and fast_bf16() else "fp32"
    return precision


def set_precision(module: nn.Module, precision: str) -> nn.Module:
    """Convert the parameters of ``module``'s transformer stages to ``precision`` (``fp32``/``bf16``)
    in place, leaving its buffers (normalisation statistics, positional encodings) in fp32."""
    dtype = torch.bfloat16 if precision == "bf16" else torch.float32
    for p in module.parameters():
        p.data = p.data.to(dtype)
    return module


def precision_of(module: nn.Module) -> str:
    """``"bf16"`` when ``module``'s weights are bfloat16, else ``"fp32"``."""
    p = next(module.parameters(), None)
    return "bf16" if p is not None and p.dtype == torch.bfloat16 else "fp32"
