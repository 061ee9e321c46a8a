"""Guidance caching: run one separated-guidance branch only on some sampling steps (issue 37).

Separated guidance needs three denoiser branches per step (kinema.diffusion.guidance), a prompt-only
request two, and the denoiser's cost is about linear in its rows, so a constrained sample costs ~1.4x a
prompt-only one.  The guidance *difference* of a branch, ``D_branch - D0``, changes slowly from one DDIM
step to the next, so a ``GuidanceCache`` runs the ``cached`` branch ("text" or "constr") only on every
``refresh_every``-th call (the first always) and, on the calls between, reuses the difference it
measured last:

    x0 = D0 + w_text (D_text - D0) + w_constr (D_constr - D0)      (refresh: all three branches)
    x0 = D0 + w_text (D_text - D0) + w_constr delta_constr         (others, cached = "constr": two branches)

A cache is stateful: one instance per sampling run (its calls are the run's steps, in order).
``refresh_every = 1`` runs every branch on every call, exactly as uncached separated guidance.
"""

from __future__ import annotations

from collections.abc import Mapping

import torch

from kinema.diffusion.guidance import Guidance, GuidanceMode, combine

#: Branches a cache can skip (the unconditional branch is the reference of both differences).
CACHEABLE_BRANCHES = ("text", "constr")


class GuidanceCache:
    """Per-run state of guidance caching: which branches the next call runs, and the combination."""

    def __init__(self, refresh_every: int, cached: str = "constr"):
        if isinstance(refresh_every, bool) or not isinstance(refresh_every, int) or refresh_every < 1:
            raise ValueError(f"refresh_every must be an integer >= 1, got {refresh_every!r}")
        if cached not in CACHEABLE_BRANCHES:
            raise ValueError(f"cached branch must be one of {CACHEABLE_BRANCHES}, got {cached!r}")
        self.refresh_every, self.cached = refresh_every, cached
        self.calls = 0  # calls seen (separated ones)
        self.refreshes = 0  # calls that ran the cached branch
        self.delta: torch.Tensor | None = None  # last D_cached - D0

    def branches(self, guidance: Guidance) -> list[str]:
        """Branch names the next call with ``guidance`` runs: all of its branches on a refresh call (or
        for a non-separated mode), else all but the cached one."""
        names = guidance.branches
        if guidance.mode is not GuidanceMode.SEPARATED or self._refresh_due():
            return names
        return [name for name in names if name != self.cached]

    def combine(self, guidance: Guidance, outputs: Mapping[str, torch.Tensor]) -> torch.Tensor:
        """Guided x0 from the branches :meth:`branches` asked for; counts the call and keeps the cached
        branch's difference when it ran."""
        if guidance.mode is not GuidanceMode.SEPARATED:
            return combine(guidance, outputs)
        self.calls += 1
        if self.cached in outputs:
            self.refreshes += 1
            self.delta = outputs[self.cached] - outputs["uncond"]
            return combine(guidance, outputs)
        if self.delta is None or self.delta.shape != outputs["uncond"].shape:
            raise ValueError("guidance cache: no cached difference of the right shape; refresh first")
        d0 = outputs["uncond"]
        other = "constr" if self.cached == "text" else "text"
        w_cached, w_other = ((guidance.w_text, guidance.w_constr) if self.cached == "text"
                             else (guidance.w_constr, guidance.w_text))
        return d0 + w_cached * self.delta + w_other * (outputs[other] - d0)

    def _refresh_due(self) -> bool:
        return self.delta is None or self.calls % self.refresh_every == 0
