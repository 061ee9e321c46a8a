"""Load a trained any-rig denoiser (EMA weights by default) with what sampling from it needs.

A checkpoint folder (training checkpoint or exported model) holds ``checkpoint.json`` with
``"kind": "anyrig"``, the model config, fps, text encoder id, sampler and guidance settings and the
training rigs (``train_rigs``: rig id -> `Rig.to_dict`, in normalised units; ``rig_files``: rig id ->
source files, when the exporter knew them), plus ``ema.safetensors`` / ``model.safetensors``, and, when
``"root_stage"`` names one, the root stage's ``root_stage.safetensors``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import DDIMSampler
from kinema.errors import KinemaError
from kinema.model.anyrig.config import AnyRigConfig
from kinema.model.anyrig.denoiser import AnyRigDenoiser
from kinema.model.anyrig.root_stage import RootStageConfig, RootStageDenoiser
from kinema.model.loading import find_checkpoint, read_checkpoint_info, read_weights, weights_file


def is_anyrig_checkpoint(path: str | Path) -> bool:
    """True when ``path`` (a run or checkpoint folder) holds an any-rig model."""
    try:
        return read_checkpoint_info(find_checkpoint(path)).get("kind") == "anyrig"
    except KinemaError:
        return False


@dataclass
class LoadedAnyRig:
    """An any-rig denoiser in eval mode plus its sampler, guidance defaults and training rigs."""

    denoiser: AnyRigDenoiser
    config: AnyRigConfig
    sampler: DDIMSampler
    guidance: Guidance
    text_encoder_id: str
    info: dict
    path: Path
    #: the root stage (kinema.model.anyrig.root_stage), when the folder has one
    root_stage: RootStageDenoiser | None = None

    @property
    def fps(self) -> float:
        return self.config.fps

    @property
    def train_rigs(self) -> dict[str, dict]:
        return dict(self.info.get("train_rigs", {}))

    @property
    def rig_files(self) -> dict[str, list[str]]:
        return dict(self.info.get("rig_files", {}))


def load_anyrig(path: str | Path, ema: bool = True) -> LoadedAnyRig:
    """Read ``checkpoint.json`` and the (EMA) weights; any problem is a one-line `KinemaError`."""
    ckpt = find_checkpoint(path)
    info = read_checkpoint_info(ckpt)
    if info.get("kind") != "anyrig":
        raise KinemaError(f"{ckpt}: not an any-rig model (kind {info.get('kind')!r})")
    state = read_weights(weights_file(ckpt, ema))
    try:
        config = AnyRigConfig.from_dict(info["model_config"])
        model = AnyRigDenoiser(config)
        model.load_state_dict({k: v.float() for k, v in state.items()})
        loaded = LoadedAnyRig(
            denoiser=model.eval(),
            config=config,
            sampler=DDIMSampler.from_dict(info["sampler"]),
            guidance=Guidance.from_dict(info["guidance"]),
            text_encoder_id=str(info["text_encoder"]),
            info=info,
            path=ckpt,
            root_stage=_root_stage(ckpt, info),
        )
    except KinemaError as err:
        raise KinemaError(f"{ckpt}: cannot load model ({err})") from None
    except (KeyError, TypeError, ValueError, RuntimeError) as err:
        raise KinemaError(f"{ckpt}: cannot load model ({type(err).__name__}: {err})") from None
    for m in (model, loaded.root_stage):
        for p in () if m is None else m.parameters():
            p.requires_grad_(False)
    return loaded


def _root_stage(ckpt: Path, info: dict) -> RootStageDenoiser | None:
    """The root stage named by ``info["root_stage"]`` with its weights from ``root_stage.safetensors``."""
    entry = info.get("root_stage")
    if entry is None:
        return None
    stage = RootStageDenoiser(RootStageConfig.from_dict(entry["config"]))
    stage.load_state_dict({k: v.float() for k, v in read_weights(ckpt / "root_stage.safetensors").items()})
    return stage.eval()
