"""The documented noise generator of the portable runtimes: mulberry32 and Box-Muller.

``torch.randn`` cannot be reproduced outside PyTorch, so runtimes without Python draw a seed's initial
noise with this generator instead (docs/onnx_runtime.md, "Noise"); the JavaScript runtime (web/) draws the
same numbers. A seed gives the same motion in every portable runtime, not the motion Python's
``generate`` makes for that seed (give both the same initial noise to compare them).
"""

from __future__ import annotations

import math

import numpy as np

_MASK = 0xFFFFFFFF


def _imul(a: int, b: int) -> int:
    return (a * b) & _MASK


def uniforms(seed: int, count: int) -> np.ndarray:
    """``count`` mulberry32 numbers in [0, 1) from a 32-bit ``seed`` (``seed mod 2**32``)."""
    a = seed & _MASK
    out = np.empty(count, dtype=np.float64)
    for i in range(count):
        a = (a + 0x6D2B79F5) & _MASK
        t = _imul(a ^ (a >> 15), a | 1)
        t = ((t + _imul(t ^ (t >> 7), t | 61)) & _MASK) ^ t
        out[i] = ((t ^ (t >> 14)) & _MASK) / 4294967296.0
    return out


def standard_normal(seed: int, shape: tuple[int, ...]) -> np.ndarray:
    """float32 N(0, 1) noise of ``shape``, filled in row-major order by Box-Muller pairs
    ``sqrt(-2 ln(1 - u1)) * (cos, sin)(2 pi u2)`` of consecutive mulberry32 numbers."""
    n = int(np.prod(shape))
    u = uniforms(seed, 2 * ((n + 1) // 2)).reshape(-1, 2)
    r = np.sqrt(-2.0 * np.log(1.0 - u[:, 0]))
    z = np.stack([r * np.cos(2.0 * math.pi * u[:, 1]), r * np.sin(2.0 * math.pi * u[:, 1])], axis=1).reshape(-1)
    return z[:n].astype(np.float32).reshape(shape)
