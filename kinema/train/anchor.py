"""Anchoring a fine-tune to a teacher on the contents it already knows (issue 38).

Fine-tuning the default model on new actions (kicks, jumps, rolls from the Quaternius humanoids) at the
learning rate that teaches them makes the old contents worse: at 4500 steps R@3 on the Bandai test split
fell from 96.7 to 73.3 and FID rose from 0.17 to 0.46, and plain rehearsal afterwards brings them back only
slowly (docs/training.md, "Stop 51"). Averaging the weights of the fine-tune and its starting model
(WiSE-FT, ``kinema export --mix``) does not help here: half-way, the new actions are gone and the old
suite is worse than at either end ("Stop 52").

This keeps what the teacher knows in the loss instead, as *learning without forgetting* does (Li and
Hoiem 2016): on the rows of a batch drawn from the anchored clips (by dataset, e.g. the Bandai captures),
the student's clean-motion prediction is pulled towards the teacher's for the same noisy input, step,
text and constraints. The teacher's prediction is a dense target (every channel, every frame, at the
drawn noise level), where the clip itself is one sample of what the caption allows. The other rows (the
new actions) train on the data alone. Measured on issue 38 (docs/training.md, "Stop 52"): as a rehearsal
after a drifting fine-tune it brings the old contents back no faster than the data alone, and from the
start at a learning rate of 1e-3 it does not stop the drift; a tool, not yet a recipe.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import torch

from kinema.errors import KinemaError
from kinema.model.denoiser import Denoiser
from kinema.representation.stats import NormStats


class Anchor:
    """A frozen teacher and the clips whose rows are pulled towards its predictions."""

    def __init__(self, teacher: Denoiser, stats: NormStats, anchored: torch.Tensor, weight: float):
        if not (math.isfinite(weight) and weight > 0):
            raise KinemaError(f"anchor weight must be a finite number > 0, got {weight}")
        self.teacher = teacher.eval()
        for p in self.teacher.parameters():
            p.requires_grad_(False)
        self.teacher.set_dropout(0.0)
        self.stats, self.anchored, self.weight = stats, anchored, float(weight)

    def check_stats(self, stats: NormStats, source: str | Path) -> None:
        """The student must predict in the teacher's normalisation, or the two predictions do not compare."""
        if not (torch.equal(stats.mean, self.stats.mean) and torch.equal(stats.std, self.stats.std)):
            raise KinemaError(f"--anchor {source}: its normalisation statistics differ from the run's; anchor to "
                              "the model the run was fine-tuned from (or one fine-tuned from the same model)")

    def term(self, pred: torch.Tensor, inputs: Sequence[torch.Tensor], clip_index: torch.Tensor,
             pad_mask: torch.Tensor) -> torch.Tensor:
        """Mean squared difference between ``pred (B, T, D)`` and the teacher's prediction for the same
        ``inputs`` over the valid frames of the anchored rows, times the weight (0 when no row is anchored)."""
        rows = self.anchored[clip_index.cpu()].to(pred.device)
        if not bool(rows.any()):
            return pred.sum() * 0.0
        with torch.no_grad():  # the teacher sees the anchored rows only (rows of a batch are independent)
            target = self.teacher(*(x[rows] for x in inputs)).float()
        valid = pad_mask[rows].to(pred.dtype)[..., None]
        sq = (pred[rows] - target).square() * valid
        return self.weight * sq.sum() / (valid.sum() * pred.shape[-1]).clamp_min(1.0)


def anchored_clips(records: list[dict], datasets: Sequence[str]) -> torch.Tensor:
    """Per train clip, whether it is anchored: its ``dataset`` is one of ``datasets`` (all clips when empty);
    a name no clip has is a one-line error (a typo would otherwise anchor nothing)."""
    names = {rec.get("dataset", "") for rec in records}
    unknown = sorted(set(datasets) - names)
    if unknown:
        raise KinemaError(f"--anchor-datasets: no train clip comes from {', '.join(unknown)} (the build has "
                          f"{', '.join(sorted(names))})")
    return torch.tensor([not datasets or rec.get("dataset", "") in datasets for rec in records])
