"""Train the text projection in whitened caption coordinates (a reparametrisation, not a new model).

Why: the denoiser sees a prompt only through MiniLM's pooled sentence embedding, in which the words a user
cares about are small directions: "runs forward slowly" vs "at full speed" have cosine 0.87, and the
caption "A happy person bows forward from the waist." is nearer "A happy person walks forward." than "A
person bows." (default model card). A gradient step on ``text_proj(e) = W e + b`` moves the text token
along such a direction only in proportion to the direction's tiny spread, so the model learns the big
contrasts (walk / wave / raise hands) and regresses the rest (speed, bow depth) to the mean.

Here the trained parameters are ``W'`` and ``b'`` of ``W' A (e - mu) + b'``, with ``mu`` the mean and
``A = (C + s * lam_max * I) ** -1/2`` the shrunk inverse square root of the covariance ``C`` of the
training captions' embeddings (eigenvalues ``lam``; ``s`` bounds the largest amplification to
``1 / sqrt(s * lam_max)``). The function is unchanged at the start; only the geometry the optimiser
works in differs. ``state_dict`` writes the folded ``weight = W' A`` and ``bias = b' - W' A mu`` (and
``load_state_dict`` takes them), so checkpoints, EMA copies and exported models keep the plain
``nn.Linear`` format and inference needs nothing of this module.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.nn import functional as F

from kinema.errors import KinemaError

__all__ = ["WhitenedLinear", "whitening", "whiten_text_projections"]


def whitening(embeddings: torch.Tensor, shrink: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``embeddings (N, E)`` (unique captions) -> ``(mu (E,), A (E, E))``, computed in float64."""
    if not 0 < shrink <= 1:
        raise KinemaError(f"text_whiten must be in (0, 1] (0 turns it off), got {shrink}")
    e = embeddings.double()
    mu = e.mean(0)
    cov = torch.cov((e - mu).T)
    lam, vec = torch.linalg.eigh(cov)
    lam = lam.clamp(min=0) + shrink * float(lam.max())
    a = vec @ torch.diag(lam.rsqrt()) @ vec.T
    return mu, a


class WhitenedLinear(nn.Module):
    """``y = W' A (x - mu) + b'``, trained in ``W', b'``; reads and writes the folded ``weight``/``bias``."""

    def __init__(self, linear: nn.Linear, mu: torch.Tensor, a: torch.Tensor) -> None:
        super().__init__()
        dtype = linear.weight.dtype
        self.register_buffer("mu", mu.to(dtype), persistent=False)
        self.register_buffer("a", a.to(dtype), persistent=False)
        # float64 copies for folding / unfolding, so a save -> load round trip changes W' by ~1 float32 ulp
        self.register_buffer("mu64", mu.double(), persistent=False)
        self.register_buffer("a64", a.double(), persistent=False)
        self.register_buffer("a_inv64", torch.linalg.inv(a.double()), persistent=False)
        w, b = self._raw(linear.weight.detach(), linear.bias.detach())
        self.raw_weight = nn.Parameter(w)
        self.raw_bias = nn.Parameter(b)
        self._register_state_dict_hook(WhitenedLinear._fold_hook)
        self._register_load_state_dict_pre_hook(self._unfold_hook)

    def _raw(self, weight: torch.Tensor, bias: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Folded ``(weight, bias)`` -> the trained ``(W', b')`` (computed in float64)."""
        w = weight.to(self.a64)
        dtype = self.a.dtype
        return (w @ self.a_inv64).to(dtype), (bias.to(self.a64) + w @ self.mu64).to(dtype)

    def folded(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The trained ``(W', b')`` -> the plain Linear's ``(weight, bias)`` (computed in float64)."""
        w = self.raw_weight.detach().to(self.a64) @ self.a64
        dtype = self.a.dtype
        return w.to(dtype), (self.raw_bias.detach().to(self.a64) - w @ self.mu64).to(dtype)

    @property
    def weight(self) -> torch.Tensor:
        return self.raw_weight @ self.a

    @property
    def bias(self) -> torch.Tensor:
        return self.raw_bias - self.weight @ self.mu

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        weight = self.weight  # once: the bias property would multiply W' A a second time
        return F.linear(x, weight, self.raw_bias - weight @ self.mu)

    @staticmethod
    def _fold_hook(module: WhitenedLinear, state: dict, prefix: str, local_metadata) -> dict:
        state.pop(prefix + "raw_weight")
        state.pop(prefix + "raw_bias")
        state[prefix + "weight"], state[prefix + "bias"] = module.folded()
        return state

    def _unfold_hook(self, state: dict, prefix: str, *args) -> None:
        if prefix + "weight" in state:
            w, b = self._raw(state.pop(prefix + "weight"), state.pop(prefix + "bias"))
            state[prefix + "raw_weight"], state[prefix + "raw_bias"] = w, b


def whiten_text_projections(model: nn.Module, text_table: torch.Tensor, shrink: float) -> int:
    """Swap every ``text_proj`` Linear of ``model`` for a :class:`WhitenedLinear` over the unique rows of
    ``text_table (N, E)``; returns how many were swapped. Call before the optimiser and EMA are built."""
    mu, a = whitening(torch.unique(text_table.double(), dim=0), shrink)
    owners = [m for m in model.modules() if isinstance(getattr(m, "text_proj", None), nn.Linear)]
    for owner in owners:
        owner.text_proj = WhitenedLinear(owner.text_proj, mu, a)
    return len(owners)
