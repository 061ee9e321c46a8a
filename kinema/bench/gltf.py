"""`kinema bench gltf`: how fast kinema reads glTF/GLB rigs (files/s, clips/s, MB/s).

Two passes over every ``*.glb``/``*.gltf`` under a folder (default the shared Quaternius creatures):
``container`` parses the GLB/JSON container and decodes every accessor (the I/O floor), ``to Motion``
runs the full reader (rig, helper bones, skin with Draco decoding, every clip sampled at its own rate).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from kinema.errors import DataError


def gltf_files(root: Path, limit: int | None = None) -> list[Path]:
    files = sorted(p for p in root.rglob("*") if p.suffix.lower() in (".glb", ".gltf")) if root.is_dir() else []
    if not files:
        raise DataError(f"no *.glb / *.gltf files under {root}")
    return files[:limit] if limit is not None else files


def _container(path: Path) -> int:
    from kinema.io.gltf import load_document
    from kinema.io.gltf_data import GltfBuffers

    doc = load_document(path)
    buffers = GltfBuffers(doc, path)
    for i, acc in enumerate(doc.accessors):
        if acc.bufferView is not None or acc.sparse is not None:
            buffers.accessor(i)
    return len(doc.animations)


def _to_motion(path: Path) -> int:
    from kinema.io.gltf import read_gltf

    return len(read_gltf(path).motions)


def bench_gltf(files: list[Path], progress: bool = True) -> list[tuple]:
    """Rows (stage, files, clips, seconds, files/s, clips/s, MB/s) for the two passes."""
    from tqdm import tqdm

    megabytes = sum(f.stat().st_size for f in files) / 1e6
    stages: list[tuple[str, Callable[[Path], int]]] = [("container", _container), ("to Motion", _to_motion)]
    rows = []
    for label, fn in stages:
        clips, start = 0, time.perf_counter()
        for path in tqdm(files, desc=label, unit="file", mininterval=0.5, disable=not progress):
            clips += fn(path)
        elapsed = time.perf_counter() - start
        rows.append((label, len(files), clips, elapsed, len(files) / elapsed, clips / elapsed, megabytes / elapsed))
    return rows


def format_rows(rows: list[tuple], root: Path, megabytes: float) -> str:
    header = f"{'stage':<10} {'files':>6} {'clips':>6} {'seconds':>8} {'files/s':>8} {'clips/s':>8} {'MB/s':>7}"
    lines = [f"glTF benchmark: {rows[0][1]} files under {root} ({megabytes:.1f} MB)", header, "-" * len(header)]
    for label, n, clips, elapsed, fps, cps, mbps in rows:
        lines.append(f"{label:<10} {n:>6} {clips:>6} {elapsed:>8.2f} {fps:>8.1f} {cps:>8.1f} {mbps:>7.1f}")
    return "\n".join(lines)
