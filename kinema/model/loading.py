"""Load a trained denoiser (EMA weights by default) with everything needed to sample from it."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from safetensors.torch import load_file

from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import DDIMSampler
from kinema.errors import KinemaError
from kinema.model.config import ModelConfig
from kinema.model.denoiser import Denoiser
from kinema.motion.features import FeatureLayout
from kinema.motion.stats import NormStats
from kinema.skeleton import Skeleton


def find_checkpoint(path: str | Path) -> Path:
    """A checkpoint folder from a run folder (via its ``latest`` pointer) or a checkpoint folder itself."""
    path = Path(path)
    if (path / "checkpoint.json").exists():
        return path
    pointer = path / "latest"
    if pointer.exists():
        ckpt = path / pointer.read_text().strip()
        if (ckpt / "checkpoint.json").exists():
            return ckpt
    raise KinemaError(f"{path}: no checkpoint found (expected checkpoint.json or a 'latest' pointer)")


@dataclass
class LoadedModel:
    """A denoiser in eval mode plus its skeleton, fps, feature layout, sampler and guidance defaults."""

    denoiser: Denoiser
    skeleton: Skeleton
    fps: float
    layout: FeatureLayout
    stats: NormStats
    sampler: DDIMSampler
    guidance: Guidance
    text_encoder_id: str
    info: dict
    path: Path


def weights_file(ckpt: Path, ema: bool = True) -> Path:
    """The weights a checkpoint folder should be loaded from: the EMA copy when asked for and present
    (training checkpoints hold both, exported models only the EMA), else the raw training weights."""
    ema_file = ckpt / "ema.safetensors"
    return ema_file if ema and ema_file.exists() else ckpt / "model.safetensors"


def load_denoiser(path: str | Path, ema: bool = True) -> LoadedModel:
    """Read ``checkpoint.json`` and the (EMA) safetensors weights of a checkpoint or run folder."""
    ckpt = find_checkpoint(path)
    try:
        info = json.loads((ckpt / "checkpoint.json").read_text())
        state = load_file(str(weights_file(ckpt, ema)))
        config = ModelConfig.from_dict(info["model_config"])
        model = Denoiser(config)
        model.load_state_dict({k: v.float() for k, v in state.items()})
        layout = FeatureLayout(int(info["feature_layout"]["num_joints"]))
        loaded = LoadedModel(
            denoiser=model.eval(),
            skeleton=Skeleton.from_dict(info["skeleton"]),
            fps=float(info["fps"]),
            layout=layout,
            stats=NormStats.from_dict(info["stats"]),
            sampler=DDIMSampler.from_dict(info["sampler"]),
            guidance=Guidance.from_dict(info["guidance"]),
            text_encoder_id=str(info["text_encoder"]),
            info=info,
            path=ckpt,
        )
    except (OSError, ValueError, KeyError, RuntimeError, json.JSONDecodeError) as err:
        raise KinemaError(f"{ckpt}: cannot load model ({type(err).__name__}: {err})") from None
    for p in loaded.denoiser.parameters():
        p.requires_grad_(False)
    return loaded
