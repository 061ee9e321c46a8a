"""The keyjoint trajectory denoiser (SFControl Sec. 3.1): a small x0-predicting transformer over
keyjoint frames ``(B, T, 20)`` (kinema.representation.keyjoint), conditioned on text, the first-frame
heading and sparse keyjoint targets given by imputation (``[m * x_tgt + (1 - m) * x_t ; m]`` per frame).

It reuses the body model's transformer stage (kinema.model.layers.StageTransformer) at a small width:
the keyjoint frame is 20 numbers, so a 128-wide, 3-layer network samples 5 s in a few milliseconds
per step. Saved as ``keyjoint.safetensors`` + ``keyjoint.json`` (config, normalisation statistics,
training facts); loading checks every key.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file
from torch import nn

from kinema.atomic_files import atomic_write_bytes
from kinema.errors import KinemaError
from kinema.model.config import ModelConfig, reject_unknown_keys
from kinema.model.layers import StageTransformer
from kinema.representation.keyjoint import KEYJOINT_DIM

FORMAT = "kinema-keyjoint-1"


@dataclass
class KeyjointConfig:
    """Shape of the keyjoint denoiser (JSON; unknown keys are an error)."""

    width: int = 128
    layers: int = 3
    heads: int = 4
    ff_mult: int = 2
    num_registers: int = 4
    text_dim: int = 384
    max_frames: int = 200
    dropout: float = 0.1

    @classmethod
    def from_dict(cls, data: dict) -> KeyjointConfig:
        if not isinstance(data, dict):
            raise KinemaError(f"keyjoint config must be an object, got {type(data).__name__}")
        reject_unknown_keys(cls, data, "keyjoint config keys")
        return cls(**data)

    def stage_config(self) -> ModelConfig:
        return ModelConfig(
            num_joints=1,
            width=self.width,
            layers=self.layers,
            heads=self.heads,
            ff_mult=self.ff_mult,
            dropout=self.dropout,
            num_registers=self.num_registers,
            text_dim=self.text_dim,
            max_frames=self.max_frames,
        )


class KeyjointDenoiser(nn.Module):
    """``forward(x_t, t, text_emb, c_dir, x_tgt, mask) -> x0`` on normalised keyjoints ``(B, T, 20)``;
    ``text_emb (B, text_dim)`` (zeros = no text), ``c_dir (B, 2)``, ``x_tgt``/``mask (B, T, 20)``,
    ``pad_mask (B, T)`` True on real frames (None: all real)."""

    def __init__(self, config: KeyjointConfig) -> None:
        super().__init__()
        self.config = config
        self.stage = StageTransformer(config.stage_config(), 2 * KEYJOINT_DIM, KEYJOINT_DIM)
        self.register_buffer("mean", torch.zeros(KEYJOINT_DIM))
        self.register_buffer("std", torch.ones(KEYJOINT_DIM))

    def set_normalization(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        self.mean.copy_(mean.float())
        self.std.copy_(std.float().clamp_min(1e-3))

    def normalize(self, k: torch.Tensor) -> torch.Tensor:
        return (k - self.mean) / self.std

    def denormalize(self, k: torch.Tensor) -> torch.Tensor:
        return k * self.std + self.mean

    def forward(
        self,
        x_t: torch.Tensor,
        t: torch.Tensor,
        text_emb: torch.Tensor,
        c_dir: torch.Tensor,
        x_tgt: torch.Tensor,
        mask: torch.Tensor,
        pad_mask: torch.Tensor | None = None,
    ) -> torch.Tensor:
        x = mask * x_tgt + (1.0 - mask) * x_t
        return self.stage(torch.cat([x, mask], dim=-1), t, text_emb, c_dir, pad_mask)


def save_keyjoint_model(model: KeyjointDenoiser, folder: str | Path, info: dict) -> Path:
    """Write ``keyjoint.safetensors`` and ``keyjoint.json`` (config, ``info``) into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().contiguous() for k, v in model.state_dict().items()}
    tmp = folder / "keyjoint.safetensors.tmp"
    save_file(state, str(tmp))
    tmp.replace(folder / "keyjoint.safetensors")
    meta = {"format": FORMAT, "config": asdict(model.config), "info": info}
    atomic_write_bytes(folder / "keyjoint.json", (json.dumps(meta, indent=1) + "\n").encode())
    return folder


def load_keyjoint_model(folder: str | Path) -> tuple[KeyjointDenoiser, dict]:
    """The saved denoiser in eval mode and its ``info``; a missing or malformed file raises KinemaError."""
    folder = Path(folder)
    try:
        meta = json.loads((folder / "keyjoint.json").read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise KinemaError(f"{folder}: no keyjoint.json (not a keyjoint model folder)") from None
    except (OSError, ValueError) as exc:
        raise KinemaError(f"{folder / 'keyjoint.json'}: cannot read: {exc}") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise KinemaError(f"{folder / 'keyjoint.json'}: not a {FORMAT} file")
    model = KeyjointDenoiser(KeyjointConfig.from_dict(meta.get("config", {})))
    try:
        state = load_file(str(folder / "keyjoint.safetensors"))
        model.load_state_dict(state)
    except (SafetensorError, OSError, RuntimeError) as exc:
        raise KinemaError(f"{folder / 'keyjoint.safetensors'}: cannot load: {exc}") from None
    return model.eval(), dict(meta.get("info", {}))
