"""Per-channel normalisation statistics for motion features (saved with datasets and models)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import torch

#: channels whose spread is below this are left unscaled (e.g. constant heights), so that
#: normalising never divides by ~0.
MIN_STD = 1e-2


@dataclass
class NormStats:
    """Mean and standard deviation per feature channel, shape (D,)."""

    mean: torch.Tensor
    std: torch.Tensor

    @classmethod
    def compute(
        cls,
        chunks: Iterable[torch.Tensor],
        min_std: float = MIN_STD,
        xz_pairs: Sequence[tuple[int, int]] = (),
    ) -> NormStats:
        """Exact mean/std over all frames of ``chunks`` (each (T_i, D)), accumulated in float64.

        ``xz_pairs`` lists (x, z) channel pairs of ground-plane vectors. Training turns every clip to a
        random heading, which makes such pairs isotropic: their mean is 0 and both share the std
        ``sqrt((E[x^2] + E[z^2]) / 2)``. Statistics of the un-rotated data would be far too narrow
        (e.g. a dataset whose clips all start facing +Z has a heading std near 0)."""
        n, s, s2 = 0, None, None
        for x in chunks:
            x = x.reshape(-1, x.shape[-1]).double()
            n += x.shape[0]
            s = x.sum(0) if s is None else s + x.sum(0)
            s2 = (x**2).sum(0) if s2 is None else s2 + (x**2).sum(0)
        if not n:
            raise ValueError("no frames to compute statistics from")
        mean = s / n
        var = (s2 / n - mean**2).clamp_min(0)
        for ix, iz in xz_pairs:
            m2 = 0.5 * (s2[ix] + s2[iz]) / n
            mean[ix] = mean[iz] = 0.0
            var[ix] = var[iz] = m2
        return cls(mean.float(), var.sqrt().clamp_min(min_std).float())

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.mean.to(x)) / self.std.to(x)

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.std.to(x) + self.mean.to(x)

    def to_dict(self) -> dict:
        return {"mean": self.mean.tolist(), "std": self.std.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> NormStats:
        return cls(torch.tensor(d["mean"], dtype=torch.float32), torch.tensor(d["std"], dtype=torch.float32))
