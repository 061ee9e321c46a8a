"""``kinema data build folder``: your own BVH/GLB files with captions -> a training cache.

Reads every ``.bvh``, ``.bvh.gz`` and ``.glb`` under ``root`` (any skeleton; BVH units given or
detected, kinema.data.sources), captions each clip from sidecar files (kinema.data.sidecar) and
writes a multi-rig motion cache (kinema.data.motion_cache) with the shared steps of
kinema.data.multirig_build (rigs by topology, per-file scale, exact duplicates dropped, splits).

Clips without captions stop the build with one line that names the first few and says how to
fix it; ``skip_uncaptioned=True`` (``--skip-uncaptioned``) drops them instead and lists them as
warnings. Training text-to-motion on a clip without text would teach nothing, and a silent skip
hides typos in caption file names.

When every clip shares one skeleton with human roles, the flat feature files of
kinema.data.folder_flat are written too and ``kinema train --data OUT`` works as on Bandai Namco.
"""

from __future__ import annotations

import time
from pathlib import Path

from kinema.data.build import _prepare_out
from kinema.data.folder_flat import flat_blocker, write_flat
from kinema.data.multirig_build import Description, assemble, counts, write_build
from kinema.data.sidecar import CaptionSource
from kinema.data.sources import SUFFIXES, SourceFile, list_sources, load_source, units_messages
from kinema.errors import DataError
from kinema.motion.core import Motion

#: How many uncaptioned clips the error names before "and N more".
NAMED = 3


def _check_root(root: Path) -> list[Path]:
    if not root.exists():
        raise DataError(f"{root}: folder does not exist")
    if not root.is_dir():
        raise DataError(f"{root}: not a folder")
    paths = list_sources(root)
    if not paths:
        raise DataError(f"{root}: no motion files ({', '.join(SUFFIXES)}) found")
    return paths


def _missing_message(root: Path, missing: list[str]) -> str:
    named = ", ".join(missing[:NAMED]) + (f" and {len(missing) - NAMED} more" if len(missing) > NAMED else "")
    return (
        f"{root}: {len(missing)} clip(s) have no captions ({named}); add a .txt sidecar with one caption per "
        "line, captions.csv (file,caption) or captions.jsonl, or pass --skip-uncaptioned"
    )


def build_folder(
    root: str | Path,
    out_dir: str | Path,
    *,
    fps: float = 20.0,
    units: str = "auto",
    skip_uncaptioned: bool = False,
    train_rigs: tuple[str, ...] | None = None,
    progress: bool = True,
) -> tuple[dict, list[str]]:
    """Build ``out_dir`` from the files under ``root``; returns (meta.json, messages to show).

    Messages: the detected units, skipped clips, unused caption-file entries, reader warnings.
    ``train_rigs``: rig ids never held out.
    Raises `DataError` (one line) for a missing root, no files, uncaptioned clips (unless
    skipped), unreadable files and an output folder that is not a previous build.
    """
    t0 = time.time()
    root, out_dir = Path(root), Path(out_dir).absolute()
    if not fps > 0:
        raise DataError(f"fps must be positive, got {fps}")
    paths = _check_root(root)
    _prepare_out(out_dir)  # before the long part: refuse a non-build output folder now
    captions = CaptionSource(root)
    from tqdm import tqdm

    files = [load_source(p, root, fps=fps, units=units) for p in tqdm(paths, desc="read", disable=not progress)]

    def describe(f: SourceFile, name: str, motion: Motion, travel: float) -> Description:
        caps = captions.captions(f.path, None if f.kind == "bvh" else name, single=len(f.clips) == 1)
        return Description(caps, action=name, subject="")

    asm = assemble(files, fps, describe, train_rigs=tuple(train_rigs or ()))
    if asm.uncaptioned and not skip_uncaptioned:
        raise DataError(_missing_message(root, asm.uncaptioned))
    if not asm.writer.clips:
        raise DataError(f"{root}: no captioned clips left to build from")
    messages = units_messages(files, units)
    messages += [f"skipped (no captions): {c}" for c in asm.uncaptioned]
    messages += [f"caption entry matches no clip: {k}" for k in captions.unused_keys()]
    messages += [f"{f.rel}: {w}" for f in files for w in f.warnings]
    blocker = flat_blocker(files, len(asm.writer.rigs))
    by_rel = {f.rel: f for f in files}
    meta = {
        "_t0": t0,
        "dataset": "folder",
        "source_root": str(root.absolute()),
        "units": "normalised: each file's rest pose is 1 unit across (see skeletons.json scale)",
        "source_units": units,
        "split_rule": asm.split_rule,
        "trainable": blocker is None,
        "not_trainable_because": blocker,
        "counts": counts(asm, files),
        "messages": messages,
    }
    extra = None if blocker else (lambda tmp: write_flat(tmp, by_rel, asm.writer.clips, float(fps)))
    return write_build(out_dir, asm, meta, extra), messages
