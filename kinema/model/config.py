"""Hyper-parameters of the motion denoiser (Kimodo Sec. 4.2) and named presets.

A :class:`ModelConfig` fully determines the network's shape, so it is saved as JSON next to the
weights and a checkpoint can be rebuilt without guessing.  ``layers`` counts the encoder layers of
EACH transformer: the two-stage model has two transformers (root and body) of ``layers`` layers, the
one-stage baseline a single one.  The ``*-1stage`` presets double ``layers`` so the baseline has about
as many parameters as the two-stage model it is compared against (paper Sec. 6 ablation).

Presets (``get_config``):

- ``tiny``:  width 64, 2 layers, 4 heads, 4 registers -- unit tests only.
- ``small``: width 192, 4 layers per stage, 4 heads, 8 registers -- CPU default (2.9 M parameters).
  Chosen by measurement on the 2-core CI machine (batch 32 x 100 frames, dropout 0, AdamW):
  width 256/4 layers 0.84 s per step and 30 ms per guided forward; 192/4 0.55 s and 20 ms;
  192/3 0.42 s and 15 ms. 192/4 samples a 5-s motion with 50 DDIM steps in about a second and
  trains ~6k steps per CPU hour.
- ``medium``: width 384, 4 layers, 8 heads (head size 48 as in ``small``) -- 2x wider than ``small``,
  about 4x its parameters and step cost; for a longer CPU run or a GPU (docs/training.md).
- ``large``: width 512, 8 layers, 8 heads, 16 registers -- a GPU preset between ``medium`` and ``paper``
  (scripts/train_gpu.py picks the widest preset that fits its time budget).
- ``paper``: width 1024, 16 layers per stage, 8 heads, P = 49 registers, 4096-d text (LLM2Vec).
  With ``ff_mult = 2`` (feed-forward 2048, PyTorch's default) this is ~282 M parameters for a
  27-joint skeleton, as the paper reports; ``ff_mult = 4`` would give ~420 M, so the paper's
  feed-forward width must be 2x, and the smaller presets keep that ratio.
- ``<name>-1stage``: the one-stage baseline of any preset above, with twice the layers.

To tune a preset, edit ``PRESETS`` or pass overrides: ``get_config("small", 22, width=384)``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

from kinema.errors import KinemaError
from kinema.representation.layout import ROOT_DIM, FeatureLayout

ONE_STAGE_SUFFIX = "-1stage"

#: Preset hyper-parameters (everything except the skeleton-dependent ``num_joints``).
PRESETS: dict[str, dict[str, Any]] = {
    "tiny": {"width": 64, "layers": 2, "heads": 4, "ff_mult": 2, "dropout": 0.0, "num_registers": 4,
             "text_dim": 384},
    "small": {"width": 192, "layers": 4, "heads": 4, "ff_mult": 2, "dropout": 0.1, "num_registers": 8,
              "text_dim": 384},
    "medium": {"width": 384, "layers": 4, "heads": 8, "ff_mult": 2, "dropout": 0.1, "num_registers": 8,
               "text_dim": 384},
    "large": {"width": 512, "layers": 8, "heads": 8, "ff_mult": 2, "dropout": 0.1, "num_registers": 16,
              "text_dim": 384},
    "paper": {"width": 1024, "layers": 16, "heads": 8, "ff_mult": 2, "dropout": 0.1, "num_registers": 49,
              "text_dim": 4096},
}



def read_config_object(path: str | Path, what: str) -> dict:
    """The JSON object in the config file ``path``; unreadable, malformed, too deeply nested or non-object
    files are a one-line `KinemaError` naming ``what`` and the path."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise KinemaError(f"cannot read {what} {path}: {exc}") from exc
    except RecursionError:
        raise KinemaError(f"cannot read {what} {path}: JSON nested too deeply") from None
    if not isinstance(data, dict):
        raise KinemaError(f"{what} {path} is not a JSON object")
    return data


def reject_unknown_keys(cls, data, what: str) -> None:
    """Raise ``KinemaError("unknown {what}: [...]")`` for keys of ``data`` that are not fields of the
    dataclass ``cls`` (every config saved as JSON next to weights is read strictly: a typo is an error)."""
    unknown = set(data) - {f.name for f in fields(cls)}
    if unknown:
        raise KinemaError(f"unknown {what}: {sorted(unknown)}")

@dataclass
class ModelConfig:
    """Shape of the denoiser.

    Attributes:
        num_joints: skeleton size J; the feature dimension is ``FeatureLayout(J).dim = 5 + 12 J + 4``.
        width: token (model) dimension of every transformer.
        layers: encoder layers per transformer (per stage when ``two_stage``).
        heads: attention heads; must divide ``width``.
        ff_mult: feed-forward hidden size = ``ff_mult * width``.
        dropout: dropout inside the encoder layers (paper: 0.1 in phase 1, 0 in phase 2).
        num_registers: P extra all-zero conditioning tokens (paper P = 49).
        text_dim: size of the sentence embedding (384 for MiniLM, 4096 for LLM2Vec).
        two_stage: root-then-body denoiser (True, the paper's model) or the one-stage baseline.
        max_frames: longest sequence the positional encoding covers (200 = 10 s at 20 fps).
        fps: frame rate of the features; the local root of stage 2 uses it for finite differences.
    """

    num_joints: int
    width: int = 256
    layers: int = 4
    heads: int = 4
    ff_mult: int = 2
    dropout: float = 0.1
    num_registers: int = 8
    text_dim: int = 384
    two_stage: bool = True
    max_frames: int = 200
    fps: float = 20.0

    def __post_init__(self) -> None:
        for name in ("num_joints", "width", "layers", "heads", "ff_mult", "text_dim", "max_frames"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise KinemaError(f"model config: {name} must be a positive integer, got {value!r}")
        if isinstance(self.num_registers, bool) or not isinstance(self.num_registers, int) \
                or self.num_registers < 0:
            raise KinemaError(f"model config: num_registers must be an integer >= 0, "
                              f"got {self.num_registers!r}")
        if self.width % self.heads:
            raise KinemaError(f"model config: width {self.width} is not divisible by heads {self.heads}")
        if not isinstance(self.dropout, (int, float)) or not 0.0 <= self.dropout < 1.0:
            raise KinemaError(f"model config: dropout must be in [0, 1), got {self.dropout!r}")
        if not isinstance(self.fps, (int, float)) or isinstance(self.fps, bool) or self.fps <= 0:
            raise KinemaError(f"model config: fps must be > 0, got {self.fps!r}")
        if not isinstance(self.two_stage, bool):
            raise KinemaError(f"model config: two_stage must be a bool, got {self.two_stage!r}")
        self.dropout = float(self.dropout)
        self.fps = float(self.fps)

    # ------------------------------------------------------------------ derived sizes
    @property
    def layout(self) -> FeatureLayout:
        return FeatureLayout(self.num_joints)

    @property
    def feature_dim(self) -> int:
        """D, the per-frame feature size."""
        return self.layout.dim

    @property
    def body_dim(self) -> int:
        """D - 5, the body part predicted by stage 2."""
        return self.feature_dim - ROOT_DIM

    @property
    def ff_dim(self) -> int:
        return self.ff_mult * self.width

    @property
    def num_cond_tokens(self) -> int:
        """Conditioning tokens before the frames: timestep, text, heading and the P registers."""
        return 3 + self.num_registers

    # ------------------------------------------------------------------ serialisation
    def to_dict(self) -> dict[str, Any]:
        """JSON-serialisable fields plus the derived ``feature_dim`` (checked on load)."""
        return {**asdict(self), "feature_dim": self.feature_dim}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ModelConfig:
        """Rebuild from ``to_dict`` output; unknown keys or a mismatched ``feature_dim`` raise KinemaError."""
        data = dict(data)
        feature_dim = data.pop("feature_dim", None)
        reject_unknown_keys(cls, data, "model config keys")
        try:
            config = cls(**data)
        except TypeError as exc:
            raise KinemaError(f"bad model config: {exc}") from exc
        if feature_dim is not None and feature_dim != config.feature_dim:
            raise KinemaError(f"model config: feature_dim {feature_dim} does not match "
                              f"{config.num_joints} joints ({config.feature_dim})")
        return config

    def save_json(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load_json(cls, path: str | Path) -> ModelConfig:
        return cls.from_dict(read_config_object(path, "model config"))


def preset_names() -> list[str]:
    """All names ``get_config`` accepts."""
    return [*PRESETS, *(name + ONE_STAGE_SUFFIX for name in PRESETS)]


def get_config(name: str, num_joints: int, text_dim: int | None = None, **overrides: Any) -> ModelConfig:
    """Preset ``name`` for a skeleton of ``num_joints`` joints.

    ``text_dim`` defaults to the preset's (384, or 4096 for "paper"); ``overrides`` replace any other
    field (e.g. ``layers=6``).  A ``-1stage`` suffix gives the one-stage baseline with ``2 x layers``,
    applied after the overrides so that ``layers`` always means "per stage of the two-stage model".
    """
    base, one_stage = name, name.endswith(ONE_STAGE_SUFFIX)
    if one_stage:
        base = name[: -len(ONE_STAGE_SUFFIX)]
    if base not in PRESETS:
        raise KinemaError(f"unknown model preset {name!r}; expected one of {preset_names()}")
    values: dict[str, Any] = {**PRESETS[base], **overrides}
    if text_dim is not None:
        values["text_dim"] = text_dim
    if one_stage:
        values["two_stage"] = False
        values["layers"] = 2 * values["layers"]
    try:
        return ModelConfig(num_joints=num_joints, **values)
    except TypeError as exc:
        raise KinemaError(f"bad model config override: {exc}") from exc
