"""Hyper-parameters of the any-rig denoiser (one token per joint per frame) and its presets.

An :class:`AnyRigConfig` fully determines the network's shape; it is saved as JSON next to the
safetensors weights and rejects unknown keys on load, like :class:`kinema.model.config.ModelConfig`.
Unlike the human model it does not depend on a skeleton: joint count, topology and rest pose enter
as inputs (TreePE, RestPE, hop-distance attention bias), so one network serves any rig.

Presets (``get_anyrig_config``):

- ``anyrig-tiny``: width 32, 1 block, 2 heads -- unit tests only.
- ``anyrig-small``: width 64, 3 blocks, 4 heads, 40-frame windows -- the shipped ``creatures`` model.
  Sized by measurement on the shared 2-core machine at one thread (batch 16, window 40, up to 48
  joints; docs in the model card): a step must stay near a second so a 60-90 minute run gives
  a few thousand steps.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from kinema.errors import KinemaError
from kinema.model.config import read_config_object, reject_unknown_keys
from kinema.representation.joint import NUM_CHANNELS

ANYRIG_PRESETS: dict[str, dict[str, Any]] = {
    "anyrig-tiny": {"width": 32, "layers": 1, "heads": 2, "window": 16},
    "anyrig-small": {"width": 64, "layers": 3, "heads": 4, "window": 40},
}


@dataclass
class AnyRigConfig:
    """Shape of the any-rig denoiser.

    Attributes:
        width: token size of every joint-frame token.
        layers: blocks, each spatial attention (joints of a frame) + temporal attention (frames of a
            joint) + feed-forward, all modulated by adaLN-Zero from the text and diffusion step.
        heads: attention heads; must divide ``width``.
        ff_mult: feed-forward hidden size = ``ff_mult * width``.
        dropout: dropout on attention outputs and feed-forward (training only).
        text_dim: sentence-embedding size (384 for MiniLM).
        window: frames per training window and per sampling window (longer motions are blended
            from overlapping windows); also the length the frame positional encoding covers x 4.
        tree_depth / tree_branch: TreePE code size: the last ``tree_depth`` steps of a joint's path
            from the root, each a one-hot over ``tree_branch`` child slots (Shiv & Quirk 2019).
        rest_freqs: sinusoidal frequencies of RestPE (per coordinate of the rest offset and position).
        max_hops: hop distances above this share one attention-bias bucket.
        tree_pe / rest_pe / hop_bias: switch each skeleton encoding on or off (ablations).
        channels: per-joint feature channels (the per-joint representation's 13).
        fps: frame rate of the features.
    """

    width: int = 64
    layers: int = 3
    heads: int = 4
    ff_mult: int = 2
    dropout: float = 0.0
    text_dim: int = 384
    window: int = 40
    tree_depth: int = 12
    tree_branch: int = 6
    rest_freqs: int = 4
    max_hops: int = 8
    tree_pe: bool = True
    rest_pe: bool = True
    hop_bias: bool = True
    channels: int = NUM_CHANNELS
    fps: float = 20.0

    def __post_init__(self) -> None:
        ints = (
            "width",
            "layers",
            "heads",
            "ff_mult",
            "text_dim",
            "window",
            "tree_depth",
            "tree_branch",
            "rest_freqs",
            "max_hops",
            "channels",
        )
        for name in ints:
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise KinemaError(f"any-rig config: {name} must be a positive integer, got {value!r}")
        for name in ("tree_pe", "rest_pe", "hop_bias"):
            if not isinstance(getattr(self, name), bool):
                raise KinemaError(f"any-rig config: {name} must be true or false, got {getattr(self, name)!r}")
        if self.width % self.heads:
            raise KinemaError(f"any-rig config: width {self.width} is not divisible by heads {self.heads}")
        if isinstance(self.dropout, bool) or not isinstance(self.dropout, (int, float)) or not 0 <= self.dropout < 1:
            raise KinemaError(f"any-rig config: dropout must be in [0, 1), got {self.dropout!r}")
        if isinstance(self.fps, bool) or not isinstance(self.fps, (int, float)) or self.fps <= 0:
            raise KinemaError(f"any-rig config: fps must be > 0, got {self.fps!r}")
        if self.channels != NUM_CHANNELS:
            raise KinemaError(f"any-rig config: channels must be {NUM_CHANNELS} (the per-joint representation)")
        self.dropout, self.fps = float(self.dropout), float(self.fps)

    @property
    def ff_dim(self) -> int:
        return self.ff_mult * self.width

    @property
    def max_frames(self) -> int:
        """Frames the positional encoding is built for (sampling uses at most ``window``)."""
        return 4 * self.window

    def to_dict(self) -> dict[str, Any]:
        return {"kind": "anyrig", **asdict(self)}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> AnyRigConfig:
        """Rebuild from ``to_dict`` output; unknown keys or bad values raise `KinemaError`."""
        data = dict(data)
        kind = data.pop("kind", "anyrig")
        if kind != "anyrig":
            raise KinemaError(f"model config is of kind {kind!r}, not 'anyrig'")
        reject_unknown_keys(cls, data, "any-rig config keys")
        return cls(**data)

    def save_json(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_dict(), indent=2) + "\n")

    @classmethod
    def load_json(cls, path: str | Path) -> AnyRigConfig:
        return cls.from_dict(read_config_object(path, "any-rig config"))


def get_anyrig_config(name: str, **overrides: Any) -> AnyRigConfig:
    """Preset ``name`` (``anyrig-tiny`` / ``anyrig-small``) with ``overrides`` applied."""
    if name not in ANYRIG_PRESETS:
        raise KinemaError(f"unknown any-rig preset {name!r}; expected one of {sorted(ANYRIG_PRESETS)}")
    try:
        return AnyRigConfig(**{**ANYRIG_PRESETS[name], **overrides})
    except TypeError as exc:
        raise KinemaError(f"bad any-rig config override: {exc}") from None
