"""Checkpoints: safetensors weights + EMA weights + optimizer state + one JSON, written atomically.

Layout of a run folder::

    runs/NAME/
      latest                 one line: the name of the newest complete checkpoint folder
      ckpt-00001000/
        model.safetensors    raw weights
        ema.safetensors      EMA weights (used for sampling)
        optimizer.safetensors optimizer tensors ("state.<param index>.<name>")
        checkpoint.json      model config, feature layout, fps, normalisation stats, text encoder id,
                             optimizer param groups, training state (step, config, RNG seed)
      log.jsonl

A checkpoint folder is written under a temporary name and renamed when complete; ``latest`` is then
replaced atomically. A process killed mid-save leaves the previous checkpoint and pointer intact.
No pickle anywhere: tensors go through safetensors, everything else through JSON.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load_file, save_file

from kinema.atomic_files import atomic_folder, atomic_write_text
from kinema.errors import KinemaError
from kinema.model.loading import find_checkpoint

KEEP_LAST = 2


def _contiguous(state: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    return {k: v.detach().cpu().contiguous() for k, v in state.items()}


def optimizer_tensors(optimizer: torch.optim.Optimizer) -> tuple[dict[str, torch.Tensor], list[dict]]:
    """Split an optimizer state dict into flat tensors and JSON-able param groups."""
    sd = optimizer.state_dict()
    tensors = {}
    for idx, st in sd["state"].items():
        for name, val in st.items():
            t = val if torch.is_tensor(val) else torch.tensor(val)
            tensors[f"state.{idx}.{name}"] = t
    return tensors, sd["param_groups"]


def load_optimizer_tensors(optimizer: torch.optim.Optimizer, tensors: dict[str, torch.Tensor], groups: list[dict]):
    state: dict[int, dict[str, torch.Tensor]] = {}
    for key, val in tensors.items():
        _, idx, name = key.split(".", 2)
        state.setdefault(int(idx), {})[name] = val
    optimizer.load_state_dict({"state": state, "param_groups": groups})


def save_checkpoint(
    run_dir: str | Path,
    step: int,
    model: torch.nn.Module,
    ema: torch.nn.Module | None,
    optimizer: torch.optim.Optimizer | None,
    info: dict[str, Any],
) -> Path:
    """Write ``ckpt-<step>`` atomically, point ``latest`` at it, and prune older checkpoints."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    final = run_dir / f"ckpt-{step:08d}"
    with atomic_folder(final) as tmp:
        save_file(_contiguous(model.state_dict()), str(tmp / "model.safetensors"))
        if ema is not None:
            save_file(_contiguous(ema.state_dict()), str(tmp / "ema.safetensors"))
        payload = dict(info)
        if optimizer is not None:
            tensors, groups = optimizer_tensors(optimizer)
            save_file(_contiguous(tensors), str(tmp / "optimizer.safetensors"))
            payload["optimizer_param_groups"] = groups
        payload["step"] = step
        (tmp / "checkpoint.json").write_text(json.dumps(payload, indent=1))
    atomic_write_text(run_dir / "latest", final.name + "\n")
    old = sorted(p for p in run_dir.glob("ckpt-*") if p.is_dir() and p != final)
    for p in old[: max(0, len(old) - (KEEP_LAST - 1))]:
        shutil.rmtree(p, ignore_errors=True)
    return final


def load_checkpoint(path: str | Path, with_optimizer: bool = True) -> dict[str, Any]:
    """Read a checkpoint: ``{"info", "model", "ema", "optimizer"}`` (tensors as dicts)."""
    ckpt = find_checkpoint(path)
    try:
        info = json.loads((ckpt / "checkpoint.json").read_text())
        out: dict[str, Any] = {"info": info, "path": ckpt, "model": load_file(str(ckpt / "model.safetensors"))}
        ema = ckpt / "ema.safetensors"
        out["ema"] = load_file(str(ema)) if ema.exists() else None
        opt = ckpt / "optimizer.safetensors"
        out["optimizer"] = load_file(str(opt)) if with_optimizer and opt.exists() else None
    except (OSError, ValueError, SafetensorError, RecursionError) as err:
        raise KinemaError(f"{ckpt}: unreadable checkpoint ({type(err).__name__}: {err})") from None
    return out


# architecture fields that may differ between a fine-tune and its initial model (training-only settings)
_FREE_MODEL_FIELDS = ("dropout",)


def load_init_weights(path: str | Path, model_config, layout, skeleton, fps: float):
    """Weights to fine-tune from: ``(checkpoint folder, float32 state dict, NormStats)``.

    Accepts an exported model or a run/checkpoint folder (EMA weights preferred) and checks that it was
    trained for the same architecture, skeleton, fps and feature layout as the run being started, naming
    every field that differs.
    """
    from kinema.model.loading import weights_file
    from kinema.representation.stats import NormStats

    ckpt = find_checkpoint(path)
    try:
        info = json.loads((ckpt / "checkpoint.json").read_text())
        state = {k: v.float() for k, v in load_file(str(weights_file(ckpt, ema=True))).items()}
        stats = NormStats.from_dict(info["stats"])
        theirs = {k: v for k, v in info["model_config"].items() if k not in _FREE_MODEL_FIELDS}
        ours = {k: v for k, v in model_config.to_dict().items() if k not in _FREE_MODEL_FIELDS}
        diffs = [f"model_config.{k}: {theirs.get(k)!r} vs {ours.get(k)!r}"
                 for k in sorted(set(theirs) | set(ours)) if theirs.get(k) != ours.get(k)]
        if info["feature_layout"] != layout.to_dict():
            diffs.append("feature_layout")
        if info["skeleton"].get("names") != skeleton.to_dict().get("names"):
            diffs.append("skeleton joint names")
        if abs(float(info["fps"]) - float(fps)) > 1e-6:
            diffs.append(f"fps: {info['fps']} vs {fps}")
    except (OSError, ValueError, KeyError, TypeError, AttributeError, SafetensorError, RecursionError) as err:
        raise KinemaError(f"{ckpt}: cannot read weights to fine-tune from ({type(err).__name__}: {err})") from None
    if diffs:
        raise KinemaError(f"{ckpt}: cannot fine-tune from this model, it differs from the run being started in "
                          + "; ".join(diffs) + " (model vs run)")
    return ckpt, state, stats
