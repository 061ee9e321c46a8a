"""``kinema data build quaternius``: the Quaternius creature packs (CC0 GLBs) -> a motion cache.

Layout expected under ``root``: one folder per pack (``animals_pack/Fox.glb``, ...), each GLB one
skinned armature with keyframed animations (read by kinema.io.gltf at the build fps). Captions
come from the file's character and the cleaned clip name (kinema.data.creature_captions); the rest
(rigs by topology, per-file scale, exact duplicates dropped, whole rigs held out for val/test) is
kinema.data.multirig_build. Flags per clip:

- ``prop``: a prop animation (chest, lever, spike trap, bounce pad), to exclude from training;
- ``in_place``: a locomotion clip (walk, run, gallop, swim) whose joints' centroid ends less than
  `IN_PLACE` body sizes from where it started: the source animates it on the spot, so a trainer
  must not expect travel. All 157 kept locomotion clips of the shared files are (net travel at
  most 0.03 body sizes).

A file the reader cannot read is skipped and listed in the build's messages.
"""

from __future__ import annotations

import time
from pathlib import Path

from kinema.data.build import _prepare_out
from kinema.data.creature_captions import LOCOMOTION, clean_clip_name, creature_captions, is_prop, subject_for
from kinema.data.multirig_build import Description, assemble, counts, rig_ids, write_build
from kinema.data.sources import SourceFile, load_source
from kinema.errors import DataError, KinemaError
from kinema.motion.core import Motion

#: Largest net centroid travel (rest-pose sizes) of a locomotion clip flagged ``in_place``.
IN_PLACE = 0.1
LICENCE = "CC0 1.0 (public domain), Quaternius (quaternius.com)"


def list_glbs(root: Path) -> list[Path]:
    """Every ``.glb`` under ``root``, sorted by relative path."""
    if not root.is_dir():
        raise DataError(f"{root}: folder does not exist" if not root.exists() else f"{root}: not a folder")
    paths = sorted(p for p in root.rglob("*.glb") if p.is_file())
    if not paths:
        raise DataError(f"{root}: no .glb files found")
    return paths


def describe(f: SourceFile, name: str, motion: Motion, travel: float) -> Description:
    """Captions, action, subject and flags of one Quaternius clip."""
    action = clean_clip_name(name)
    in_place = action in LOCOMOTION and travel < IN_PLACE
    flags = (["prop"] if is_prop(f.rel, action) else []) + (["in_place"] if in_place else [])
    return Description(creature_captions(f.rel, name, in_place=in_place), action, subject_for(f.rel), flags)


def read_files(paths: list[Path], root: Path, fps: float, progress: bool) -> tuple[list[SourceFile], list[str]]:
    """Read every GLB; files the reader rejects are left out and named in the returned messages."""
    from tqdm import tqdm

    files, skipped = [], []
    for p in tqdm(paths, desc="quaternius", unit="file", disable=not progress):
        try:
            files.append(load_source(p, root, fps=fps))
        except KinemaError as exc:
            skipped.append(f"skipped {p.relative_to(root).as_posix()}: {exc}")
    return files, skipped


#: Rigs the default build keeps in train: the biped dinosaur (parasaurolophus, also the T-rex), so that
#: the model knows each kind of body its users ask for most (fish, quadruped, biped dinosaur, mech,
#: humanoid); the quadruped dinosaurs stay held out by the hash rule.
DEFAULT_TRAIN_RIGS = ("parasaurolophus",)


def _train_rigs(files: list[SourceFile], asked: tuple[str, ...] | None) -> tuple[str, ...]:
    """The rigs to keep in train: what the user asked for, or the defaults among ``files``'s rigs."""
    if asked is not None:
        return tuple(asked)
    present = set(rig_ids(files).values())
    return tuple(r for r in DEFAULT_TRAIN_RIGS if r in present)


def build_quaternius(
    root: str | Path,
    out_dir: str | Path,
    *,
    fps: float = 20.0,
    limit: int | None = None,
    train_rigs: tuple[str, ...] | None = None,
    progress: bool = True,
) -> tuple[dict, list[str]]:
    """Build the Quaternius cache; returns (meta.json, messages). ``limit`` keeps the first N files
    (sorted by path) for quick tests; splits are then computed over those files only. ``train_rigs``
    are never held out (default `DEFAULT_TRAIN_RIGS`, those of them the files hold; ``()`` = none)."""
    t0 = time.time()
    root, out_dir = Path(root), Path(out_dir).absolute()
    if not fps > 0:
        raise DataError(f"fps must be positive, got {fps}")
    paths = list_glbs(root)[:limit]
    _prepare_out(out_dir)
    files, messages = read_files(paths, root, float(fps), progress)
    if not files:
        raise DataError(f"{root}: no GLB file could be read ({messages[0] if messages else ''})")
    asm = assemble(files, fps, describe, train_rigs=_train_rigs(files, train_rigs))
    messages += [f"{f.rel}: {w}" for f in files for w in f.warnings]
    meta = {
        "_t0": t0,
        "dataset": "quaternius",
        "licence": LICENCE,
        "source_root": str(root.absolute()),
        "units": "normalised: each file's rest pose is 1 unit across (see skeletons.json scale)",
        "split_rule": asm.split_rule,
        "in_place_threshold": IN_PLACE,
        "trainable": False,
        "not_trainable_because": "creature rigs train with the any-rig trainer (kinema train-anyrig, docs/anyrig.md)",
        "limit": limit,
        "counts": counts(asm, files),
        "messages": messages,
    }
    meta["counts"]["props"] = sum("prop" in r["flags"] for r in asm.writer.clips)
    meta["counts"]["in_place"] = sum("in_place" in r["flags"] for r in asm.writer.clips)
    return write_build(out_dir, asm, meta), messages
