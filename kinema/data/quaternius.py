"""``kinema data build quaternius``: the Quaternius creature packs (CC0 GLBs) -> a motion cache.

Layout expected under ``root``: one folder per pack (``animals_pack/Fox.glb``, ...), each GLB one
skinned armature with keyframed animations (read by kinema.io.gltf at the build fps). Captions
come from the file's character and the cleaned clip name (kinema.data.creature_captions); the rest
(rigs by topology, per-file scale, exact duplicates dropped, whole rigs held out for val/test) is
kinema.data.multirig_build. Flags per clip:

- ``prop``: a prop animation (chest, lever, spike trap, bounce pad), to exclude from training;
- ``travel_recovered``: a legged locomotion clip (walk, run, gallop) that the source animates on the
  spot (its joints' centroid ends less than `IN_PLACE` body sizes from where it started: all 157 kept
  locomotion clips of the shared files do) gets the travel its planted feet imply
  (kinema.data.root_motion, the shared root-motion recovery: a planted foot does not slide, the body
  moves instead), added to the whole rig's translation; the record's ``recovered_speed`` is its mean
  ground speed (body sizes/s). Feet are the rig's contact joints (kinema.rig) except tail tips that
  touch the floor (`NOT_FEET`);
- ``in_place``: a locomotion clip still on the spot: a swim (fish have no feet to read travel from), a
  file that fails the forward check below, or a clip whose feet do not slide.

Idles, attacks, jumps and every other clip keep the source's root as it is (no travel invented). Each
rig's forward axis is checked against its walk: the cosine between the walk's recovered travel and the
rig's forward axis (+Z) goes to meta.json ``forward_check`` per file; a file whose walk goes more than
60 deg away from the axis keeps all its clips on the spot and is named in the build's messages (on the
shared files: the mechs Mike and Stan, whose contact joints are their knees; every other legged walk
agrees, cosine 1.00).

A file the reader cannot read is skipped and listed in the build's messages.
"""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

from kinema.data.build import _prepare_out
from kinema.data.creature_captions import LOCOMOTION, clean_clip_name, creature_captions, is_prop, subject_for
from kinema.data.multirig_build import Description, assemble, counts, rig_ids, write_build
from kinema.data.root_motion import forward_agreement, recover_travel
from kinema.data.sources import SourceFile, load_source
from kinema.errors import DataError, KinemaError
from kinema.motion.core import Motion
from kinema.rig import Rig

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


#: contact joints that are not feet (a dinosaur's tail tips touch the floor): no travel is read from them
NOT_FEET = re.compile(r"tail", re.I)
#: locomotion actions whose travel is not read from feet (fish and flyers have none)
NO_FEET_ACTIONS = ("swim",)
#: a rig's walk must go within 60 deg of its forward axis for its feet to be trusted
FORWARD_MIN = 0.5


def with_travel(motion: Motion, rig: Rig) -> tuple[Motion, float] | None:
    """``motion`` (on the spot) moved along the travel its planted feet imply, and its mean ground
    speed; None when the rig has no feet on the floor or the feet do not slide."""
    feet = [j for j in rig.contacts if not NOT_FEET.search(rig.skeleton.names[j])]
    rec = recover_travel(motion.positions, feet, motion.fps, up=rig.up)
    if rec.speed <= 0.0:
        return None
    root = motion.root_translation + rec.travel.to(motion.root_translation.dtype)
    moved = Motion(
        motion.skeleton, motion.fps, root, motion.local_rotations, motion.foot_contacts, motion.local_translations
    )
    return moved, rec.speed


class Describer:
    """``describe`` of the Quaternius build (kinema.data.multirig_build.Describe): captions, action,
    subject and flags of one clip, with travel recovered for legged locomotion (see the module); keeps
    each file's forward check (``forward_check``) and the messages about it."""

    def __init__(self) -> None:
        self.rigs: dict[str, Rig] = {}
        self.forward_check: dict[str, float | None] = {}
        self.messages: list[str] = []

    def _trusted(self, f: SourceFile, rig: Rig) -> bool:
        """Whether ``f``'s feet may give its clips travel: its walk (when it has one) must go where the
        rig's forward axis points (cosine >= `FORWARD_MIN`); otherwise the feet read are not feet (the
        mechs' knees) or the axis is not the rig's front, and its clips stay on the spot."""
        if f.rel not in self.forward_check:
            cos = None
            for name, motion in f.clips.items():
                if clean_clip_name(name) == "walk" and (got := with_travel(motion, rig)) is not None:
                    cos = round(forward_agreement(got[0].root_translation, rig.forward, rig.up), 3)
                    break
            self.forward_check[f.rel] = cos
            if cos is not None and cos < FORWARD_MIN:
                deg = math.degrees(math.acos(max(-1.0, min(1.0, cos))))
                self.messages.append(
                    f"{f.rel}: the walk read from its contact joints {rig.joint_names(rig.contacts)} goes "
                    f"{deg:.0f} deg away from the rig's forward axis {list(rig.forward)}: its clips stay on the spot"
                )
        cos = self.forward_check[f.rel]
        return cos is None or cos >= FORWARD_MIN

    def __call__(self, f: SourceFile, name: str, motion: Motion, travel: float) -> Description:
        action = clean_clip_name(name)
        flags = ["prop"] if is_prop(f.rel, action) else []
        on_spot = action in LOCOMOTION and travel < IN_PLACE
        moved, record = None, {}
        if on_spot and action.split("_")[0] not in NO_FEET_ACTIONS:
            rig = self.rigs.setdefault(f.rel, Rig.from_skeleton(motion.skeleton))
            got = with_travel(motion, rig) if self._trusted(f, rig) else None
            if got is not None:
                moved, speed = got
                on_spot = False
                flags.append("travel_recovered")
                record = {"recovered_speed": round(speed, 4)}
        if on_spot:
            flags.append("in_place")
        captions = creature_captions(f.rel, name, in_place=on_spot)
        return Description(captions, action, subject_for(f.rel), flags, moved, record)


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
    describe = Describer()
    asm = assemble(files, fps, describe, train_rigs=_train_rigs(files, train_rigs))
    messages += [f"{f.rel}: {w}" for f in files for w in f.warnings] + describe.messages
    meta = {
        "_t0": t0,
        "dataset": "quaternius",
        "licence": LICENCE,
        "source_root": str(root.absolute()),
        "units": "normalised: each file's rest pose is 1 unit across (see skeletons.json scale)",
        "split_rule": asm.split_rule,
        "in_place_threshold": IN_PLACE,
        "root_motion": "legged walks/runs/gallops animated on the spot travel as their planted feet imply "
        "(kinema.data.root_motion); idles and other clips keep the source's root",
        "forward_check": describe.forward_check,
        "trainable": False,
        "not_trainable_because": "creature rigs train with the any-rig trainer (kinema train-anyrig, docs/anyrig.md)",
        "limit": limit,
        "counts": counts(asm, files),
        "messages": messages,
    }
    meta["counts"]["props"] = sum("prop" in r["flags"] for r in asm.writer.clips)
    meta["counts"]["in_place"] = sum("in_place" in r["flags"] for r in asm.writer.clips)
    meta["counts"]["travel_recovered"] = sum("travel_recovered" in r["flags"] for r in asm.writer.clips)
    return write_build(out_dir, asm, meta), messages
