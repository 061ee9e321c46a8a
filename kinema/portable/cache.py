"""Exported folders kept in kinema's user cache, one per model: ``kinema web`` exports a model on first use.

The folder's name is the model's fingerprint (kinema.model.fingerprint) and the runtime format, so a
changed model or a new format gets a fresh export, and an unchanged one is exported once.
"""

from __future__ import annotations

from pathlib import Path

from kinema.atomic_files import atomic_folder
from kinema.generate.loading import resolve_model_path
from kinema.model.fingerprint import model_sha256
from kinema.model.loading import find_checkpoint
from kinema.portable.export import export_onnx
from kinema.portable.manifest import FILE_NAME, FORMAT
from kinema.runtime import user_cache_dir


def cached_export(model: str | Path = "default", cache_root: str | Path | None = None) -> Path:
    """The exported folder of ``model`` under ``cache_root`` (default: ``user_cache_dir("onnx")``), made
    by :func:`kinema.portable.export.export_onnx` when it is not there yet."""
    ckpt = find_checkpoint(resolve_model_path(model))
    root = Path(cache_root) if cache_root is not None else user_cache_dir("onnx")
    folder = root / f"{FORMAT}-{model_sha256(ckpt)[:16]}"
    if not (folder / FILE_NAME).is_file():
        with atomic_folder(folder) as tmp:
            export_onnx(ckpt, tmp)
    return folder
