"""Forward (noising) process of the motion diffusion model.

Kimodo (Sec. 4.3) trains its denoiser with DDPM, T = 1000 steps and x0 prediction, but does not say
which variance schedule it uses.  We default to the *cosine* schedule of Nichol & Dhariwal (2021,
"Improved DDPM"): x0-prediction motion diffusion models such as MDM use it, and it destroys signal
more gradually than the linear schedule, so far fewer of the 1000 training steps are spent on inputs
that are already almost pure noise.  The original DDPM "linear" schedule (betas 1e-4 .. 0.02) is
available for comparison.

Timesteps are 0-based indices ``t in {0, ..., T-1}`` (the paper writes ``t ~ U{1, ..., T}``; index
``t`` here is the paper's step ``t + 1``).  ``alphas_cumprod[t]`` is the fraction of signal variance
left after noising to step ``t``: ``x_t = sqrt(abar_t) x0 + sqrt(1 - abar_t) eps``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import torch

from kinema.errors import KinemaError

SCHEDULE_KINDS = ("cosine", "linear")

#: Offset ``s`` of the cosine schedule; keeps beta_0 from being vanishingly small.
COSINE_S = 0.008
#: Upper bound on any beta, avoiding the singularity of the cosine schedule at t = T.
MAX_BETA = 0.999
LINEAR_BETA_START = 1e-4
LINEAR_BETA_END = 0.02


def _cosine_betas(num_steps: int) -> torch.Tensor:
    """Betas such that alpha-bar follows cos^2 of a linearly increasing angle (Nichol & Dhariwal)."""

    def alpha_bar(u: float) -> float:
        return math.cos((u + COSINE_S) / (1.0 + COSINE_S) * math.pi / 2.0) ** 2

    betas = [
        min(1.0 - alpha_bar((i + 1) / num_steps) / alpha_bar(i / num_steps), MAX_BETA)
        for i in range(num_steps)
    ]
    return torch.tensor(betas, dtype=torch.float64)


def _linear_betas(num_steps: int) -> torch.Tensor:
    """The original DDPM schedule: betas evenly spaced from 1e-4 to 0.02."""
    return torch.linspace(LINEAR_BETA_START, LINEAR_BETA_END, num_steps, dtype=torch.float64)


def _gather(values: torch.Tensor, t: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """Pick ``values[t]`` per batch item, shaped (B, 1, ..., 1) to broadcast over ``like`` (B, ...)."""
    if t.dim() != 1 or t.shape[0] != like.shape[0]:
        raise ValueError(f"t must have shape (B,) = ({like.shape[0]},), got {tuple(t.shape)}")
    out = values.to(t.device)[t.long()]
    return out.to(device=like.device, dtype=like.dtype).reshape(-1, *([1] * (like.dim() - 1)))


@dataclass(frozen=True)
class NoiseSchedule:
    """Discrete DDPM noise schedule with ``num_train_steps`` steps of the given ``kind``.

    Immutable: the derived tables (betas, alpha-bar) are computed once in ``__post_init__``.
    """

    num_train_steps: int = 1000
    kind: str = "cosine"
    _betas: torch.Tensor = field(init=False, repr=False, compare=False)
    _alphas_cumprod: torch.Tensor = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if isinstance(self.num_train_steps, bool) or not isinstance(self.num_train_steps, int):
            raise ValueError(f"num_train_steps must be an int, got {self.num_train_steps!r}")
        if self.num_train_steps < 2:
            raise ValueError(f"num_train_steps must be >= 2, got {self.num_train_steps}")
        if self.kind == "cosine":
            betas = _cosine_betas(self.num_train_steps)
        elif self.kind == "linear":
            betas = _linear_betas(self.num_train_steps)
        else:
            raise ValueError(f"unknown schedule kind {self.kind!r}; expected one of {SCHEDULE_KINDS}")
        object.__setattr__(self, "_betas", betas)
        object.__setattr__(self, "_alphas_cumprod", torch.cumprod(1.0 - betas, dim=0))

    # ------------------------------------------------------------------ tables
    @property
    def betas(self) -> torch.Tensor:
        """Per-step noise variances beta_t, float64 tensor of length T (a copy)."""
        return self._betas.clone()

    @property
    def alphas_cumprod(self) -> torch.Tensor:
        """alpha-bar_t = prod_{s<=t} (1 - beta_s), float64 tensor of length T, decreasing in (0, 1)."""
        return self._alphas_cumprod.clone()

    def alpha_bar(self, t: int) -> float:
        """alpha-bar at 0-based step ``t``; ``t == -1`` means "no noise" and gives 1.0."""
        if t == -1:
            return 1.0
        if not 0 <= t < self.num_train_steps:
            raise ValueError(f"timestep {t} outside [0, {self.num_train_steps - 1}]")
        return float(self._alphas_cumprod[t])

    # ------------------------------------------------------------------ noising
    def q_sample(self, x0: torch.Tensor, t: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """Noise clean data to step ``t``: ``sqrt(abar_t) x0 + sqrt(1 - abar_t) noise``.

        ``x0`` and ``noise`` have shape (B, ...); ``t`` is a LongTensor (B,) of 0-based step indices,
        broadcast over the remaining dims.  The result has ``x0``'s dtype and device.
        """
        if noise.shape != x0.shape:
            raise ValueError(f"noise shape {tuple(noise.shape)} != x0 shape {tuple(x0.shape)}")
        if t.numel() and (int(t.min()) < 0 or int(t.max()) >= self.num_train_steps):
            raise ValueError(f"timesteps must lie in [0, {self.num_train_steps - 1}]")
        abar = self._alphas_cumprod
        return _gather(abar.sqrt(), t, x0) * x0 + _gather((1.0 - abar).sqrt(), t, x0) * noise

    def sample_timesteps(self, batch_size: int, generator: torch.Generator | None = None) -> torch.Tensor:
        """Uniform random training steps, a LongTensor (batch_size,) on the generator's device."""
        device = generator.device if generator is not None else None
        return torch.randint(
            0, self.num_train_steps, (batch_size,), generator=generator, device=device, dtype=torch.long
        )

    # ------------------------------------------------------------------ config
    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable settings; ``from_dict(to_dict())`` rebuilds an equal schedule."""
        return {"num_train_steps": self.num_train_steps, "kind": self.kind}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> NoiseSchedule:
        """Rebuild from ``to_dict`` output; bad or unknown keys raise ``KinemaError`` (config input)."""
        if not isinstance(data, dict):
            raise KinemaError(f"noise schedule config must be a mapping, got {type(data).__name__}")
        unknown = set(data) - {"num_train_steps", "kind"}
        if unknown:
            raise KinemaError(f"unknown noise schedule config keys: {sorted(unknown)}")
        try:
            return cls(**data)
        except (TypeError, ValueError) as exc:
            raise KinemaError(f"bad noise schedule config: {exc}") from exc
