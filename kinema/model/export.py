"""Pack a training checkpoint into a small, inference-only model folder (what kinema ships).

A packed folder holds ``checkpoint.json`` (model config, layout, skeleton, statistics, sampler and
guidance settings, training config and step: everything ``load_denoiser`` needs, minus optimizer
state) and ``ema.safetensors`` (the EMA weights, float16 by default; the loader computes in float32).
The folder is written under a temporary name and renamed into place, so a failed export never leaves
a half-written model behind.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import torch
from safetensors.torch import save_file

from kinema.atomic_files import atomic_folder
from kinema.diffusion.guidance import Guidance
from kinema.errors import KinemaError
from kinema.model.action_expert import MUST_MATCH as EXPERT_MUST_MATCH
from kinema.model.action_expert import WEIGHTS_FILE as EXPERT_WEIGHTS_FILE
from kinema.model.action_expert import expert_actions, mirror_side
from kinema.model.anyrig.loading import LoadedAnyRig, load_anyrig
from kinema.model.grounding import Grounding
from kinema.model.loading import (
    LoadedModel,
    find_checkpoint,
    load_denoiser,
    read_checkpoint_info,
    read_grounding,
    read_weights,
    weights_file,
)

#: checkpoint.json keys that only matter for resuming training.
_TRAINING_ONLY = ("optimizer_param_groups",)
DTYPES = {"float16": torch.float16, "bfloat16": torch.bfloat16, "float32": torch.float32}


def export_model(
    src: str | Path,
    out: str | Path,
    dtype: str = "float16",
    guidance: Guidance | None = None,
    sampling_steps: int | None = None,
    extra_info: dict | None = None,
    ema: bool = True,
    grounding: dict | None = None,
    root_stage: str | Path | None = None,
    mix: tuple[str | Path, float] | None = None,
    action_expert: tuple[str | Path, list[str]] | None = None,
    expert_mirror_side: str | None = None,
) -> Path:
    """Write the EMA weights of the run/checkpoint ``src`` as an inference model folder ``out``.

    ``src`` may be a model folder written by this function (re-packing: another dtype, sampling default or
    root stage); its checkpoint.json keeps the weights' first source, with ``repacked_from``.

    ``ema=False`` packs the raw (optimiser) weights instead: after a short fine-tune the EMA (decay
    0.995 every 10 steps, a ~2000-step horizon) still mostly holds the starting weights.

    ``guidance`` and ``sampling_steps`` replace the defaults saved with the model (e.g. values tuned on
    the validation split); ``grounding`` (some of kinema.model.grounding.Grounding's keys) replaces those
    keys of the saved prompt-grounding default; ``extra_info`` is merged into checkpoint.json under ``"export"``.
    ``root_stage``: an any-rig model's root-stage run or checkpoint (kinema.train.anyrig.root_stage), whose
    EMA weights are packed as ``root_stage.safetensors`` with its config under ``"root_stage"``.
    ``mix=(MODEL, SHARE)``: pack ``(1 - SHARE) * src + SHARE * MODEL``'s weights (`mix_weights`).
    ``action_expert=(RUN, ACTIONS)``: pack RUN's (EMA) weights as the model's action expert for prompts that
    name one of ACTIONS (kinema.model.action_expert; `_action_expert`); ``expert_mirror_side`` ("left" or
    "right"): the side whose expert prompts are generated as mirror images (kinema.human.mirrored_request).
    Returns ``out``. An existing ``out`` is replaced only once the new folder is complete.
    """
    if dtype not in DTYPES:
        raise KinemaError(f"unknown weight dtype {dtype!r}; choose one of {', '.join(DTYPES)}")
    ckpt = find_checkpoint(src)
    weights = weights_file(ckpt, ema)
    if not weights.is_file():
        raise KinemaError(f"{ckpt}: no {weights.name} (an exported model folder holds only EMA weights)")
    info = read_checkpoint_info(ckpt)
    state = read_weights(weights)
    if not isinstance(info.get("sampler", {}), dict):
        raise KinemaError(f"{ckpt / 'checkpoint.json'}: field 'sampler' must be an object (damaged checkpoint?)")
    for key in _TRAINING_ONLY:
        info.pop(key, None)
    _replace_defaults(info, ckpt, guidance, grounding, sampling_steps)
    packed = info.pop("export", None)  # ``src`` is itself a model folder: keep where its weights came from
    source = {"source": str(ckpt)} if packed is None else {"source": packed["source"], "repacked_from": str(ckpt)}
    info["export"] = {**source, "weights": weights.name, "dtype": dtype, **(extra_info or {})}
    if mix is not None:
        state, info["export"]["mixed_with"] = mix_weights(state, info, ckpt, *mix)
    if info.get("kind") == "anyrig":
        info["rig_files"] = rig_files(info)
    if expert_mirror_side is not None and action_expert is None:
        raise KinemaError("--expert-mirror-side: give --action-expert RUN too (the side is the expert's)")
    stage, expert = _companions(info, ckpt, root_stage, action_expert, expert_mirror_side)
    state = {k: v.to(DTYPES[dtype]).contiguous() for k, v in state.items()}
    expert = None if expert is None else {k: v.to(DTYPES[dtype]).contiguous() for k, v in expert.items()}
    return _write_folder(Path(out), info, state, stage, expert)


def _companions(info: dict, ckpt: Path, root_stage, action_expert,
                mirror: str | None = None) -> tuple[dict | None, dict | None]:
    """The networks packed beside the model's own weights, entered in ``info``: an any-rig model's root stage
    and a human model's action expert (float32 weights, or None when not given). A re-packed folder keeps
    its own only when they are given again."""
    stage = expert = None
    info.pop("root_stage", None)
    if root_stage is not None:
        if info.get("kind") != "anyrig":
            raise KinemaError(f"--root-stage: {ckpt} is not an any-rig model; only those have a root stage")
        info["root_stage"], stage = _root_stage(root_stage, info)
    info.pop("action_expert", None)
    if action_expert is not None:
        info["action_expert"], expert = _action_expert(*action_expert, info, ckpt)
        if mirror_side(mirror, "--expert-mirror-side") is not None:
            info["action_expert"]["mirror_side"] = mirror
    return stage, expert


#: what two checkpoints must share for their weights to be mixed: the same network, features and statistics
_MIX_MUST_MATCH = ("model_config", "feature_layout", "stats", "text_encoder", "fps")


def mix_weights(
    state: dict[str, torch.Tensor], info: dict, ckpt: Path, other: str | Path, share: float
) -> tuple[dict[str, torch.Tensor], dict]:
    """A weight-space ensemble of a fine-tune and the model it started from (WiSE-FT, Wortsman et al.
    2022): every float tensor becomes ``(1 - share) * state + share * other's`` (``other``'s EMA
    weights). Between the two ends the mix keeps part of what each learned: the fine-tune's new contents,
    the starting model's old ones. Only checkpoints of one network in one feature space and one
    normalisation mix (a fine-tune with ``--init-from`` keeps its starting model's statistics); anything
    else is a one-line `KinemaError`. Returns the weights and what was mixed (for checkpoint.json)."""
    if not 0.0 <= share <= 1.0:
        raise KinemaError(f"--mix: the share of the other model must lie in [0, 1], got {share:g}")
    other_ckpt, other_info = _same_network(other, info, ckpt, _MIX_MUST_MATCH, "--mix", "only a model and its "
                                           "own fine-tune (same network, features and statistics) can be mixed")
    theirs = read_weights(weights_file(other_ckpt, True))
    if set(theirs) != set(state) or any(theirs[k].shape != v.shape for k, v in state.items()):
        raise KinemaError(f"--mix: {other_ckpt}'s weights do not match {ckpt}'s tensor for tensor")
    mixed = {k: torch.lerp(v.float(), theirs[k].float(), share) if v.is_floating_point() else v
             for k, v in state.items()}
    return mixed, {"source": str(other_ckpt), "step": other_info.get("step"), "share": share}


def _same_network(other: str | Path, info: dict, ckpt: Path, keys: tuple[str, ...], flag: str,
                  why: str) -> tuple[Path, dict]:
    """The checkpoint folder and checkpoint.json of ``other``, a network packed with the model of
    ``info`` (at ``ckpt``): a one-line `KinemaError` (``flag``: ..., ``why``) names the first of the
    checkpoint.json ``keys`` in which they differ."""
    other_ckpt = find_checkpoint(other)
    other_info = read_checkpoint_info(other_ckpt)
    for key in keys:
        if other_info.get(key) != info.get(key):
            raise KinemaError(f"{flag}: {other_ckpt} has another {key} than {ckpt}; {why}")
    return other_ckpt, other_info


def _replace_defaults(
    info: dict, ckpt: Path, guidance: Guidance | None, grounding: dict | None, sampling_steps: int | None
) -> None:
    """Replace, in ``info``, the generation defaults saved with the model that the export was given."""
    if guidance is not None:
        info["guidance"] = guidance.to_dict()
    if grounding:
        if info.get("kind") == "anyrig":
            raise KinemaError(f"{ckpt}: an any-rig model keeps no training captions; it cannot save a grounding")
        base = read_grounding(info, ckpt).to_dict()
        info["grounding"] = Grounding.from_dict({**base, **grounding}, "grounding").to_dict()
    if sampling_steps is not None:
        if sampling_steps <= 0:
            raise KinemaError(f"sampling steps must be positive, got {sampling_steps}")
        info["sampler"] = dict(info["sampler"], num_inference_steps=int(sampling_steps))


def _root_stage(src: str | Path, info: dict) -> tuple[dict, dict[str, torch.Tensor]]:
    """The checkpoint.json entry and float32 EMA weights of the root-stage run ``src`` for the any-rig
    model described by ``info``."""
    ckpt = find_checkpoint(src)
    stage_info = read_checkpoint_info(ckpt)
    if stage_info.get("kind") != "anyrig-root-stage":
        raise KinemaError(f"{ckpt}: not a root-stage run (kind {stage_info.get('kind')!r})")
    if stage_info.get("anyrig_config") != info.get("model_config"):
        raise KinemaError(f"{ckpt}: trained for another any-rig model config than {info.get('model_config')}")
    entry = {
        "config": stage_info["model_config"],
        "source": str(ckpt),
        "step": stage_info.get("step"),
        "train_config": stage_info.get("train_config"),
        "elapsed_s": stage_info.get("elapsed_s"),
    }
    state = read_weights(weights_file(ckpt, True))
    return entry, {k: v.float().contiguous() for k, v in state.items()}


def _action_expert(src: str | Path, actions: list[str], info: dict, ckpt: Path) -> tuple[dict, dict[str, torch.Tensor]]:
    """The checkpoint.json entry and (EMA) weights of ``src`` as the action expert, for ``actions``, of the
    human model described by ``info`` (kinema.model.action_expert): only a network of the same
    architecture, features, statistics, text encoder, fps and skeleton (a fine-tune of the model with
    ``--init-from``) qualifies; anything else is a one-line `KinemaError`."""
    where = "--action-expert"
    if info.get("kind") == "anyrig":
        raise KinemaError(f"{where}: {ckpt} is an any-rig model; action experts are for the human model")
    actions = expert_actions(actions, "--expert-actions")
    expert_ckpt, expert_info = _same_network(src, info, ckpt, EXPERT_MUST_MATCH, where, "an action expert must "
                                             "be a fine-tune of the model (same network, features and statistics: "
                                             "--init-from)")
    weights = weights_file(expert_ckpt, True)
    packed = expert_info.get("export", {})
    entry = {
        "actions": list(actions),
        "weights": EXPERT_WEIGHTS_FILE,
        "source": packed.get("source", str(expert_ckpt)),
        "packed_from": str(expert_ckpt),
        "source_weights": packed.get("weights", weights.name),
        "step": expert_info.get("step"),
        "train_config": expert_info.get("train_config"),
        "elapsed_s": expert_info.get("elapsed_s"),
    }
    return entry, {k: v.float() for k, v in read_weights(weights).items()}


#: the files an export writes (any others in the folder, e.g. the card and its images, are kept)
_WRITTEN = ("ema.safetensors", "checkpoint.json", "root_stage.safetensors", EXPERT_WEIGHTS_FILE)


def _write_folder(out: Path, info: dict, state: dict[str, torch.Tensor], stage: dict | None = None,
                  expert: dict | None = None) -> Path:
    keep = [p for p in out.iterdir() if p.name not in _WRITTEN] if out.is_dir() else []
    with atomic_folder(out) as tmp:
        save_file(state, str(tmp / "ema.safetensors"))
        if stage is not None:
            save_file(stage, str(tmp / "root_stage.safetensors"))
        if expert is not None:
            save_file(expert, str(tmp / EXPERT_WEIGHTS_FILE))
        (tmp / "checkpoint.json").write_text(json.dumps(info, indent=1) + "\n")
        for p in keep:  # e.g. MODEL_CARD.md and images next to the weights survive a re-export
            (shutil.copytree if p.is_dir() else shutil.copy2)(p, tmp / p.name)
        load_weights(tmp)  # a folder that would not load never replaces ``out``
    return out


def load_weights(folder: Path) -> LoadedModel | LoadedAnyRig:
    """The denoiser of a checkpoint folder with its settings, whichever network it holds (for tools that
    work on weights: export, inspection; generation goes through kinema.generate.load_model)."""
    info = read_checkpoint_info(find_checkpoint(folder))
    return (load_anyrig if info.get("kind") == "anyrig" else load_denoiser)(folder)


def rig_files(info: dict) -> dict[str, list[str]]:
    """Any-rig models: rig id -> the source files of that training rig, read from the build the run
    trained on (``rigs.json`` of the motion cache named by ``info["data"]``), so ``--model creatures``
    can list them; {} when the build is not at hand."""
    path = Path(str(info.get("data", ""))) / "rigs.json"
    try:
        rigs = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {}
    rows = rigs.values() if isinstance(rigs, dict) else rigs
    train = info.get("train_rigs", {})
    return {r["rig"]: list(r.get("files", [])) for r in rows if isinstance(r, dict) and r.get("rig") in train}
