"""``load_model``: a model folder -> the `MotionPipeline` its ``checkpoint.json`` names.

Like diffusers' ``from_pretrained``, the saved config says which pipeline class reads it (the
``"pipeline"`` key: ``"human"`` or ``"anyrig"``); checkpoints written before that key existed are
told apart by their ``"kind"`` (``"anyrig"`` for the per-joint model, absent for the human one).
Nothing else in kinema asks which kind a model is: callers use the `MotionPipeline` interface.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from kinema.anyrig.pipeline import AnyRigPipeline
from kinema.errors import KinemaError
from kinema.human.pipeline import HumanPipeline
from kinema.model.loading import find_checkpoint, read_checkpoint_info
from kinema.model.precision import resolve_precision
from kinema.pipeline.base import MotionPipeline
from kinema.text import MemoryCachedEncoder, get_text_encoder

#: prompt embeddings kept in memory by a loaded model (thread-safe LRU, kinema.text.MemoryCachedEncoder)
TEXT_MEMORY_ENTRIES = 1024

#: the value of ``checkpoint.json``'s "pipeline" key -> the class that loads and runs it
PIPELINES: dict[str, type[MotionPipeline]] = {"human": HumanPipeline, "anyrig": AnyRigPipeline}


def pipeline_name(info: dict) -> str:
    """The pipeline a checkpoint's ``checkpoint.json`` (as a dict) names; old checkpoints by their kind."""
    name = info.get("pipeline")
    if name is None:
        return "anyrig" if info.get("kind") == "anyrig" else "human"
    return str(name)


def resolve_model_path(name_or_path: str | Path) -> Path:
    """``"default"`` (the model shipped inside the package), another shipped model's name (``"creatures"``)
    or a run / checkpoint folder."""
    if not isinstance(name_or_path, str | Path):
        raise KinemaError(f"model: expected a model name or a folder path, got {type(name_or_path).__name__}")
    shipped_models = Path(str(files("kinema") / "assets" / "models"))
    if str(name_or_path) in ("default", ""):
        shipped = shipped_models / "default"
        if not (shipped / "checkpoint.json").exists():
            raise KinemaError("this kinema install ships no default model yet; pass a checkpoint with --model PATH")
        return shipped
    path = Path(name_or_path)
    if not path.exists():
        shipped = shipped_models / str(name_or_path)
        if path.name == str(name_or_path) and (shipped / "checkpoint.json").exists():
            return shipped  # another model shipped inside the package, e.g. "creatures"
        raise KinemaError(f"{path}: no such model folder")
    return path


def load_model(name_or_path: str | Path = "default", text_cache: Path | None = None,
               text_memory: int = TEXT_MEMORY_ENTRIES, precision: str | None = None) -> MotionPipeline:
    """Load a model for generation: ``"default"``, ``"creatures"`` or a path to a run/checkpoint folder.

    Prompt embeddings are kept in memory (the last ``text_memory`` prompts, thread-safe LRU; 0 = off),
    so repeated prompts are encoded once per process; ``text_cache`` (a folder) adds a disk cache
    behind it that persists between processes (the CLI passes kinema.runtime's user cache).
    ``precision``: ``"fp32"``, ``"bf16"`` (the denoiser's weights in bfloat16) or ``"auto"`` (bf16 on a
    CPU with bf16 instructions, for a pipeline that offers it); None: ``$KINEMA_PRECISION``, else auto
    (kinema.model.precision, docs/speed.md).
    """
    path = resolve_model_path(name_or_path)
    ckpt = find_checkpoint(path)
    info = read_checkpoint_info(ckpt)
    name = pipeline_name(info)
    if name not in PIPELINES:
        raise KinemaError(f"{ckpt / 'checkpoint.json'}: field 'pipeline': unknown pipeline {name!r} "
                          f"(known: {', '.join(sorted(PIPELINES))})")

    def text_encoder_for(encoder_id: str):
        encoder = get_text_encoder(encoder_id, cache_dir=text_cache)
        return MemoryCachedEncoder(encoder, text_memory) if text_memory else encoder

    cls = PIPELINES[name]
    chosen = resolve_precision(precision)
    if chosen not in cls.precisions:
        if precision == chosen:  # asked for by name
            raise KinemaError(f"precision: the {name} model {path.name!r} runs in {', '.join(cls.precisions)} only, "
                              f"not {precision}")
        chosen = "fp32"
    return cls.load(ckpt, text_encoder_for, **({} if chosen == "fp32" else {"precision": chosen}))
