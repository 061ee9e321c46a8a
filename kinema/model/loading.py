"""Load a trained denoiser (EMA weights by default) with everything needed to sample from it."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file

from kinema.diffusion.guidance import Guidance
from kinema.diffusion.sampler import DDIMSampler
from kinema.errors import KinemaError
from kinema.model.action_expert import WEIGHTS_FILE as EXPERT_WEIGHTS_FILE
from kinema.model.action_expert import ActionExpert
from kinema.model.config import ModelConfig
from kinema.model.denoiser import Denoiser
from kinema.model.grounding import DEFAULT_GROUNDING, Grounding
from kinema.model.precision import set_precision
from kinema.representation.flat import FlatRepresentation
from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats
from kinema.rig import Rig
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
    """A denoiser in eval mode plus its skeleton, fps, feature layout, representation (the rig, layout and
    the denoiser's own normalisation statistics), sampler, guidance and prompt-grounding defaults, and the
    folder's action expert, if any (kinema.model.action_expert)."""

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
    representation: FlatRepresentation
    grounding: Grounding = DEFAULT_GROUNDING
    precision: str = "fp32"
    expert: ActionExpert | None = None

    def for_prompt(self, prompt: str) -> LoadedModel:
        """The model that denoises a pass of ``prompt``: this one with the action expert's weights when the
        prompt names one of its actions, else this one."""
        return replace(self, denoiser=self.expert.denoiser) if self.serves_with_expert(prompt) else self

    def serves_with_expert(self, prompt: str) -> bool:
        """Whether :meth:`for_prompt` runs ``prompt`` on the action expert's weights."""
        return self.expert is not None and self.expert.serves(prompt)


def weights_file(ckpt: Path, ema: bool = True) -> Path:
    """The weights a checkpoint folder should be loaded from: the EMA copy when asked for and present
    (training checkpoints hold both, exported models only the EMA), else the raw training weights."""
    ema_file = ckpt / "ema.safetensors"
    return ema_file if ema and ema_file.exists() else ckpt / "model.safetensors"


def read_checkpoint_info(ckpt: Path) -> dict:
    """``checkpoint.json`` of a checkpoint folder as a dict; a missing, unreadable, garbled or
    non-object file is a one-line `KinemaError` naming it."""
    path = Path(ckpt) / "checkpoint.json"
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError) as err:
        raise KinemaError(f"{path}: cannot read the file ({err})") from None
    except json.JSONDecodeError as err:
        raise KinemaError(f"{path}: not valid JSON: line {err.lineno}, column {err.colno}: {err.msg} "
                          "(damaged checkpoint?)") from None
    except RecursionError:
        raise KinemaError(f"{path}: JSON nested too deeply to read (damaged checkpoint?)") from None
    if not isinstance(info, dict):
        raise KinemaError(f"{path}: expected a JSON object, got {type(info).__name__} (damaged checkpoint?)")
    return info


def read_weights(path: Path) -> dict[str, torch.Tensor]:
    """The tensors of a ``.safetensors`` file; a missing, empty, truncated or garbled file, or one holding
    NaN/inf, is a one-line `KinemaError` naming it (no half-loaded model)."""
    try:
        state = load_file(str(path))
    except FileNotFoundError:
        raise KinemaError(f"{path}: weights file not found") from None
    except (SafetensorError, OSError, ValueError) as err:
        raise KinemaError(f"{path}: not a readable safetensors weights file ({err}); damaged or "
                          "incompletely copied?") from None
    for name, tensor in state.items():
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            raise KinemaError(f"{path}: tensor {name!r} holds NaN or infinite values (damaged weights?)")
    return state


def read_grounding(info: dict, ckpt: Path) -> Grounding:
    """The prompt-grounding default saved in ``checkpoint.json`` (kinema.model.grounding), else
    :data:`DEFAULT_GROUNDING`."""
    if "grounding" not in info:
        return DEFAULT_GROUNDING
    return Grounding.from_dict(info["grounding"], f"{ckpt / 'checkpoint.json'}: field 'grounding'")


def load_denoiser(path: str | Path, ema: bool = True, precision: str = "fp32") -> LoadedModel:
    """Read ``checkpoint.json`` and the (EMA) safetensors weights of a checkpoint or run folder;
    ``precision`` ``"bf16"`` converts the transformer stages' weights (kinema.model.precision)."""
    ckpt = find_checkpoint(path)
    info = read_checkpoint_info(ckpt)
    state = read_weights(weights_file(ckpt, ema))
    try:
        config = ModelConfig.from_dict(info["model_config"])
        model = Denoiser(config)
        model.load_state_dict({k: v.float() for k, v in state.items()})
        layout = FeatureLayout(int(info["feature_layout"]["num_joints"]))
        skeleton = Skeleton.from_dict(info["skeleton"])
        rep = FlatRepresentation(Rig.from_skeleton(skeleton), float(info["fps"]),
                                 NormStats(model.feat_mean, model.feat_std))
        loaded = LoadedModel(
            denoiser=model.eval(),
            skeleton=skeleton,
            fps=float(info["fps"]),
            layout=layout,
            stats=NormStats.from_dict(info["stats"]),
            sampler=DDIMSampler.from_dict(info["sampler"]),
            guidance=Guidance.from_dict(info["guidance"]),
            text_encoder_id=str(info["text_encoder"]),
            info=info,
            path=ckpt,
            representation=rep,
            grounding=read_grounding(info, ckpt),
            precision=precision,
        )
    except KinemaError as err:  # e.g. a SkeletonError for a malformed skeleton entry
        raise KinemaError(f"{ckpt}: cannot load model ({err})") from None
    except (OSError, ValueError, KeyError, TypeError, AttributeError, RuntimeError) as err:
        raise KinemaError(f"{ckpt}: cannot load model ({type(err).__name__}: {err})") from None
    for p in loaded.denoiser.parameters():
        p.requires_grad_(False)
    if "action_expert" in info:
        loaded.expert = read_action_expert(info["action_expert"], ckpt, loaded.denoiser)
        set_precision(loaded.expert.denoiser, precision)
    set_precision(loaded.denoiser, precision)
    return loaded


def read_action_expert(entry, ckpt: Path, main: Denoiser) -> ActionExpert:
    """The action expert a model folder's checkpoint.json names (kinema.model.action_expert), for its main
    network ``main``; a bad entry or weights file is a one-line `KinemaError` naming the folder."""
    where = f"{ckpt / 'checkpoint.json'}: field 'action_expert'"
    return ActionExpert.from_entry(entry, read_weights(ckpt / EXPERT_WEIGHTS_FILE), main, where)
