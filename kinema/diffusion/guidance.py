"""Classifier-free guidance, including Kimodo's *separated* text / constraint guidance (Sec. 4.4).

Separated guidance combines three denoiser outputs,

    x0 = D0 + w_text (D_text - D0) + w_constr (D_constr - D0),

where D0 sees neither text nor constraints, D_text only the text and D_constr only the constraints,
so a user can turn the influence of each condition up or down on its own (defaults w = 2, 2).
"regular" guidance is the usual two-branch CFG, x0 = D0 + w (D_cond - D0) with w = ``w_text`` and
D_cond seeing everything; "none" runs the fully conditioned model once.

Every branch needs its own forward pass.  To keep sampling fast, ``stack_branches`` concatenates the
per-branch inputs along the batch axis so all branches run as ONE batched forward pass, and
``split_branches`` cuts the output back into per-branch tensors for ``combine``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import torch

from kinema.errors import KinemaError


class GuidanceMode(StrEnum):
    """How the denoiser outputs of the conditioning branches are combined."""

    NONE = "none"
    REGULAR = "regular"
    SEPARATED = "separated"


# Branch names.  "cond" = text + constraints, "uncond" = neither, "text" / "constr" = only that one.
_BRANCHES: dict[GuidanceMode, tuple[str, ...]] = {
    GuidanceMode.NONE: ("cond",),
    GuidanceMode.REGULAR: ("uncond", "cond"),
    GuidanceMode.SEPARATED: ("uncond", "text", "constr"),
}


def branches(mode: GuidanceMode | str) -> list[str]:
    """Names of the conditioning branches ``mode`` needs, in the order they are stacked.

    none -> ["cond"]; regular -> ["uncond", "cond"]; separated -> ["uncond", "text", "constr"].
    """
    return list(_BRANCHES[GuidanceMode(mode)])


@dataclass
class Guidance:
    """Guidance settings: the mode and the text / constraint weights (paper defaults 2 and 2).

    ``w_constr`` is only used by "separated"; "regular" uses ``w_text`` as its single weight.
    A weight of 1 applies the condition without extrapolation, 0 ignores it.
    """

    mode: GuidanceMode = GuidanceMode.SEPARATED
    w_text: float = 2.0
    w_constr: float = 2.0

    def __post_init__(self) -> None:
        self.mode = GuidanceMode(self.mode)
        for name in ("w_text", "w_constr"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
            setattr(self, name, float(value))

    @property
    def branches(self) -> list[str]:
        """Branch names for this guidance's mode (see module-level ``branches``)."""
        return branches(self.mode)

    def without_constraints(self) -> Guidance:
        """Equivalent, cheaper guidance for a request that has no constraints.

        With no constraints D_constr equals D0, so the separated formula collapses to regular CFG
        with ``w_text`` -- two branches instead of three.  Other modes are returned unchanged.
        """
        if self.mode is GuidanceMode.SEPARATED:
            return Guidance(GuidanceMode.REGULAR, self.w_text, self.w_constr)
        return Guidance(self.mode, self.w_text, self.w_constr)

    @classmethod
    def given(cls, value, default: Guidance, mode: GuidanceMode | str | None = None) -> Guidance:
        """A call's guidance: ``default`` for None, a `Guidance` as it is, or ``(w_text, w_constr)`` with
        ``mode`` (default: the default's mode)."""
        if value is None:
            return default
        if isinstance(value, Guidance):
            return value
        try:
            w_text, w_constr = (float(w) for w in value)
        except (TypeError, ValueError):
            raise KinemaError(f"guidance must be two numbers (w_text, w_constr), got {value!r}") from None
        return cls(default.mode if mode is None else mode, w_text, w_constr)

    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable settings."""
        return {"mode": self.mode.value, "w_text": self.w_text, "w_constr": self.w_constr}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Guidance:
        """Rebuild from ``to_dict`` output; malformed configs raise ``KinemaError``."""
        unknown = set(data) - {"mode", "w_text", "w_constr"}
        if unknown:
            raise KinemaError(f"unknown guidance config keys: {sorted(unknown)}")
        try:
            return cls(**data)
        except (TypeError, ValueError) as exc:
            raise KinemaError(f"bad guidance config: {exc}") from exc


def combine(guidance: Guidance, outputs: Mapping[str, torch.Tensor]) -> torch.Tensor:
    """Guided x0 from the per-branch denoiser outputs ``outputs[name]`` (all the same shape).

    Computed in the algebraically equal form ``(1 - w_text - w_constr) D0 + w_text D_text +
    w_constr D_constr`` (regular: ``(1 - w) D0 + w D_cond``), so weights (1, 0) return the text branch
    and (0, 0) the unconditional branch exactly, without rounding from ``D0 + (D - D0)``.
    """
    names = guidance.branches
    missing = [name for name in names if name not in outputs]
    if missing:
        raise KeyError(f"{guidance.mode.value} guidance needs branch outputs {names}; missing {missing}")
    shapes = {tuple(outputs[name].shape) for name in names}
    if len(shapes) != 1:
        raise ValueError(f"branch outputs differ in shape: {sorted(shapes)}")
    if guidance.mode is GuidanceMode.NONE:
        return outputs["cond"]
    if guidance.mode is GuidanceMode.REGULAR:
        w = guidance.w_text
        return (1.0 - w) * outputs["uncond"] + w * outputs["cond"]
    wt, wc = guidance.w_text, guidance.w_constr
    return (1.0 - wt - wc) * outputs["uncond"] + wt * outputs["text"] + wc * outputs["constr"]


def stack_branches(inputs: Mapping[str, torch.Tensor] | torch.Tensor, names: Sequence[str]) -> torch.Tensor:
    """Stack per-branch inputs along the batch axis for one batched forward pass.

    ``inputs`` maps each branch name to a (B, ...) tensor -- e.g. the text embedding, zeroed for the
    "uncond" and "constr" branches -- or is a single (B, ...) tensor shared by all branches (e.g.
    ``x_t`` or ``t``), which is repeated.  With k = ``len(names)`` branches the result is (k*B, ...),
    branch-major: rows ``[i*B, (i+1)*B)`` belong to ``names[i]``.
    """
    if not names:
        raise ValueError("need at least one branch name")
    if isinstance(inputs, torch.Tensor):
        return inputs.repeat(len(names), *([1] * (inputs.dim() - 1)))
    missing = [name for name in names if name not in inputs]
    if missing:
        raise KeyError(f"no input for branches {missing}")
    parts = [inputs[name] for name in names]
    if len({tuple(p.shape) for p in parts}) != 1:
        raise ValueError(f"branch inputs differ in shape: {[tuple(p.shape) for p in parts]}")
    return torch.cat(parts, dim=0)


def split_branches(stacked: torch.Tensor, names: Sequence[str]) -> dict[str, torch.Tensor]:
    """Inverse of ``stack_branches``: cut a (k*B, ...) tensor into ``{name: (B, ...)}`` views."""
    k = len(names)
    if k == 0:
        raise ValueError("need at least one branch name")
    if stacked.shape[0] % k:
        raise ValueError(f"batch size {stacked.shape[0]} is not a multiple of {k} branches")
    b = stacked.shape[0] // k
    return {name: stacked[i * b : (i + 1) * b] for i, name in enumerate(names)}
