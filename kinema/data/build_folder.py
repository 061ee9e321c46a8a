"""Writing a dataset build folder: JSON files and the features tensor go into a temporary sibling
folder that replaces the output folder only once everything is written, so an interrupted build
never leaves a half-written cache behind (used by kinema.data.build and kinema.data.folder_flat)."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
from pathlib import Path

import torch
from safetensors.torch import save_file


def write_json(path: Path, obj, indent: int | None = 1) -> None:
    """UTF-8 JSON with a final newline; ``indent=None`` for the large one-line files (stats)."""
    path.write_text(json.dumps(obj, indent=indent, ensure_ascii=False) + "\n", encoding="utf-8")


def write_build_folder(
    out_dir: Path, features: torch.Tensor, files: dict, meta: dict, *, fps: float, dim: int, t0: float
) -> None:
    """features.safetensors, clips/skeleton/stats JSON (``files``) and meta.json (its
    ``build_seconds`` counted from ``t0`` at the end) into a temporary folder swapped into ``out_dir``."""
    tmp = Path(tempfile.mkdtemp(prefix=f".{out_dir.name}.", suffix=".tmp", dir=out_dir.parent))
    try:
        save_file(
            {"features": features.contiguous()},
            str(tmp / "features.safetensors"),
            metadata={"format": "kinema-features", "fps": str(float(fps)), "dim": str(dim)},
        )
        write_json(tmp / "clips.json", files["clips.json"])
        write_json(tmp / "skeleton.json", files["skeleton.json"])
        write_json(tmp / "stats.json", files["stats.json"], indent=None)
        meta["build_seconds"] = round(time.time() - t0, 1)
        write_json(tmp / "meta.json", meta)
        _default_permissions(tmp)
        _swap_into_place(tmp, out_dir)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _default_permissions(folder: Path) -> None:
    """mkdtemp makes a private (0700) folder; give the build the usual umask-based permissions."""
    mask = os.umask(0)
    os.umask(mask)
    folder.chmod(0o777 & ~mask)
    for f in folder.iterdir():
        f.chmod(0o666 & ~mask)


def _swap_into_place(tmp: Path, out_dir: Path) -> None:
    """Rename the finished ``tmp`` folder to ``out_dir``, replacing an earlier build only now."""
    old = None
    if out_dir.exists():
        old = out_dir.with_name(f".{out_dir.name}.old-{os.getpid()}")
        out_dir.rename(old)
    try:
        tmp.rename(out_dir)
    except BaseException:
        if old is not None:
            old.rename(out_dir)
        raise
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
