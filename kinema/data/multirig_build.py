"""Shared steps of the multi-rig builds (quaternius, folder): rigs, scale, dedup, splits, writing.

Given the files of a build (`kinema.data.sources.SourceFile`, metres) and a ``describe`` callback
that captions one clip, `assemble` does what every multi-rig build needs:

1. **Rigs** group files by skeleton topology (joint names and parents, `topology_key`), not by
   file: the 34 cute fish share one rig. A rig's id is its first file's stem as a slug.
2. **Scale**: each file's skeleton and motions are scaled so that its rest pose's largest side is
   1 (helper joints ignored); the factor is stored per file and per rig (its first file's).
3. **Duplicates**: clips whose normalised animation data hash the same (`motion_hash`) on the same
   rig are kept once; the record of the kept clip lists the dropped ones.
4. **Splits**: with three or more rigs, whole rigs go to train/val/test (`assign_rig_splits`);
   with fewer, clips are split inside each rig (`assign_splits`, group = rig).

`write_build` then writes the cache (kinema.data.motion_cache) atomically.
"""

from __future__ import annotations

import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from kinema.data.motion_cache import CacheWriter, motion_hash, rest_extent, topology_key, travel
from kinema.data.sources import SourceFile, scale_motion
from kinema.data.split import assign_rig_splits, assign_splits
from kinema.errors import DataError
from kinema.motion.core import Motion

#: Smallest rest-pose extent (metres) taken as a size; below it the skin's extent is used.
MIN_EXTENT = 1e-4


@dataclass
class Description:
    """What a build says about one clip: captions, action label, subject noun, flags; ``motion`` replaces
    the clip's motion when the build changes it (travel recovered from planted feet), and ``record``
    adds fields to its clips.json record."""

    captions: list[str]
    action: str = ""
    subject: str = ""
    flags: list[str] = field(default_factory=list)
    motion: Motion | None = None
    record: dict = field(default_factory=dict)


#: ``describe(file, clip_name, normalised_motion, travel) -> Description``
Describe = Callable[[SourceFile, str, Motion, float], Description]


@dataclass
class Assembly:
    """The result of `assemble`: the filled writer, the clip records, and what was left out."""

    writer: CacheWriter
    uncaptioned: list[str]
    duplicates: int
    total_clips: int
    split_rule: str


def _slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-") or "rig"


def rig_ids(files: list[SourceFile]) -> dict[str, str]:
    """Topology key -> rig id (first file's stem as a slug, ``-2``, ``-3`` on collisions)."""
    ids: dict[str, str] = {}
    for f in files:
        key = topology_key(f.skeleton)
        if key in ids:
            continue
        base = _slug(Path(f.rel).name.split(".")[0])
        rid, n = base, 2
        while rid in ids.values():
            rid, n = f"{base}-{n}", n + 1
        ids[key] = rid
    return ids


def file_scale(f: SourceFile) -> float:
    """Factor that makes the file's rest pose 1 unit across: the joints' extent (helper joints
    ignored), or the skin's when the joints sit at one point (a lever's two bones coincide)."""
    extent = rest_extent(f.skeleton, f.helper_joints)
    mesh = getattr(f.skeleton, "mesh", None)
    if extent < MIN_EXTENT and mesh is not None and len(mesh.vertices):
        v = np.asarray(mesh.vertices, dtype=np.float64)
        extent = float((v.max(0) - v.min(0)).max())
    if not extent >= MIN_EXTENT:
        raise DataError(f"{f.rel}: rest pose has no extent (all joints at one point, no skin)")
    return 1.0 / extent


def assemble(files: list[SourceFile], fps: float, describe: Describe, *, train_rigs: tuple[str, ...] = ()) -> Assembly:
    """Rigs, scale, captions, dedup and splits of ``files`` (see the module docstring); rigs named
    in ``train_rigs`` are never held out."""
    writer = CacheWriter(fps=float(fps))
    rig_of = rig_ids(files)
    seen: dict[str, dict] = {}
    uncaptioned, dropped, total = [], 0, 0
    for f in files:
        scale = file_scale(f)
        rig_id = rig_of[topology_key(f.skeleton)]
        skeleton = f.skeleton.scaled(scale)
        writer.add_skeleton(f.rel, skeleton, scale, rig_id)
        for name, motion in f.clips.items():
            total += 1
            clip_id = f.rel if f.kind == "bvh" else f"{f.rel}#{name}"
            h = motion_hash(motion)  # source metres: equal animations on differently sized files agree
            m = scale_motion(motion, scale, skeleton)
            if h in seen:
                seen[h]["duplicates"].append(clip_id)
                dropped += 1
                continue
            dist = travel(m)
            d = describe(f, name, m, dist)
            if not d.captions:
                uncaptioned.append(clip_id)
                continue
            if d.motion is not None:
                m = d.motion
                dist = travel(m)
            rec = {
                "clip_id": clip_id,
                "rig": rig_id,
                "skeleton": f.rel,
                "path": f.rel,
                "clip_name": name,
                "content": d.action or name,
                "style": d.subject,
                "mirrored": False,
                "captions": list(d.captions),
                "flags": sorted(set(d.flags)),
                "hash": h,
                "travel": round(dist, 4),
                "duplicates": [],
                **d.record,
            }
            seen[h] = rec
            writer.add_clip(m, rec)
    split_rule = _assign(writer, frozenset(train_rigs))
    return Assembly(writer, uncaptioned, dropped, total, split_rule)


def _assign(writer: CacheWriter, train_rigs: frozenset[str] = frozenset()) -> str:
    """Set every rig's and clip's split; returns the rule used, for meta.json. Clips flagged
    ``prop`` do not count, and rigs with only props stay in train: a held-out lever says nothing."""
    unknown = sorted(train_rigs - set(writer.rigs))
    if unknown:
        known = ", ".join(sorted(writer.rigs))
        raise DataError(f"--train-rigs {' '.join(unknown)}: no such rig in this build (rigs: {known})")
    pinned = f"; kept in train: {', '.join(sorted(train_rigs))}" if train_rigs else ""
    counts: dict[str, int] = {}
    for rec in writer.clips:
        if "prop" not in rec["flags"]:
            counts[rec["rig"]] = counts.get(rec["rig"], 0) + 1
    if len(counts) >= 3:
        by_rig = assign_rig_splits(counts, train=train_rigs & set(counts))
        for rid, rig in writer.rigs.items():
            rig["split"] = by_rig.get(rid, "train")
        for rec in writer.clips:
            rec["split"] = writer.rigs[rec["rig"]]["split"]
        return f"kinema.data.split.assign_rig_splits over non-prop clips: whole rigs, about 80/10/10 of clips{pinned}"
    by_clip = assign_splits([(r["clip_id"], r["rig"]) for r in writer.clips])
    for rec in writer.clips:
        rec["split"] = "train" if rec["rig"] in train_rigs else by_clip[rec["clip_id"]]
    for rid, rig in writer.rigs.items():
        rig["split"] = "train" if rid in train_rigs else "mixed"
    return f"kinema.data.split.assign_splits per clip inside each rig (fewer than 3 rigs), 80/10/10{pinned}"


def counts(asm: Assembly, files: list[SourceFile]) -> dict:
    """Counts for meta.json and the build summary line."""
    clips = asm.writer.clips
    joints = [r["joints"] for r in asm.writer.rigs.values()]
    return {
        "files": len(files),
        "rigs": len(asm.writer.rigs),
        "joints_min": min(joints, default=0),
        "joints_max": max(joints, default=0),
        "source_clips": asm.total_clips,
        "duplicates_dropped": asm.duplicates,
        "uncaptioned_skipped": len(asm.uncaptioned),
        "clips": len(clips),
        "frames": sum(r["length"] for r in clips),
        "seconds": round(sum(r["duration_s"] for r in clips), 3),
        "splits": {s: sum(r["split"] == s for r in clips) for s in ("train", "val", "test")},
    }


def write_build(out_dir: Path, asm: Assembly, meta: dict, extra: Callable[[Path], dict] | None = None) -> dict:
    """Write the cache to ``out_dir`` atomically; ``extra(tmp)`` may add files and returns meta keys."""
    from kinema.atomic_files import atomic_folder
    from kinema.data.build import _prepare_out

    t0 = meta.pop("_t0", time.time())
    _prepare_out(out_dir)
    with atomic_folder(out_dir) as tmp:
        if extra is not None:
            meta.update(extra(tmp))
        meta["build_time"] = datetime.now(UTC).isoformat(timespec="seconds")
        meta["build_seconds"] = round(time.time() - t0, 1)
        return asm.writer.write(tmp, meta)
