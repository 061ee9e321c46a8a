"""Build the training cache of the Bandai Namco datasets: features, captions, splits and statistics.

One build turns the BVH files into a folder that training reads without touching BVH again::

    DIR/features.safetensors  one float32 tensor "features" (total_frames, D), all clips end to end
    DIR/clips.json            one record per clip (and per mirrored copy): labels, split, captions,
                              and the clip's rows [start, start + length) in "features"
    DIR/skeleton.json         the shared 21-joint skeleton (Skeleton.to_dict)
    DIR/stats.json            per-channel mean/std over the TRAIN split only, start-canonicalised, with
                              ground-plane (x, z) pairs made isotropic (NormStats.compute, xz_pairs)
    DIR/meta.json             fps, feature layout, smoothing and contact settings, source, counts

Why this shape: features are computed once (FK, smoothing and contact labels are the slow part), a
single tensor loads in one call without pickle, and the clip table keeps every choice (split,
captions, mirroring) inspectable as text. See docs/dataset.md for the rules (fps, splits, mirroring,
``limit``). The folder is written next to ``out_dir`` under a temporary name and renamed into place
only once complete, so an interrupted build never leaves a half-written cache behind.
"""

from __future__ import annotations

import multiprocessing as mp
import time
from collections import defaultdict
from dataclasses import asdict
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import torch

from kinema.data.bandai import ClipInfo, list_clips, load_clip, min_toe_height
from kinema.data.build_folder import write_build_folder
from kinema.data.captions import captions_for, mirror_content
from kinema.data.phrasings import extra_captions
from kinema.data.split import SPLITS, assign_splits, group_of
from kinema.errors import DataError
from kinema.motion.contacts import ContactThresholds
from kinema.motion.smoothing import DEFAULT_ROOT_SIGMA_SECONDS
from kinema.representation.kimodo_features import motion_to_features
from kinema.representation.layout import FeatureLayout
from kinema.representation.stats import NormStats
from kinema.representation.transform import canonicalize_start
from kinema.skeleton import Skeleton

FORMAT_VERSION = 1
FILES = ("features.safetensors", "clips.json", "skeleton.json", "stats.json", "meta.json")
MIRROR_SUFFIX = "_mirrored"
#: Fields of each clips.json record, in file order (documented in docs/dataset.md).
RECORD_KEYS = tuple(
    "clip_id source_clip_id dataset content style take mirrored split start length fps duration_s "
    "min_toe_height captions path".split()
)


def select_subset(clips: list[ClipInfo], limit: int | None) -> list[ClipInfo]:
    """A deterministic, content-balanced subset of ``limit`` clips (all clips when ``limit`` is None).

    Clips are grouped by (dataset, content). The groups are put in a fixed order - each dataset's
    groups sorted by content, the datasets interleaved (dataset-1 bow, dataset-2
    raise-up-both-hands, dataset-1 bye, ...) - and visited round-robin, taking each group's next
    clip in clip-id order, until ``limit`` clips are chosen. So a small limit covers as many
    motion types of both datasets as possible instead of 12 takes of ``dataset-1_bow``. The
    result is returned in clip-id order.
    """
    if limit is None:
        return list(clips)
    if limit < 1:
        raise DataError(f"limit must be at least 1, got {limit}")
    groups: dict[str, dict[str, list[ClipInfo]]] = defaultdict(lambda: defaultdict(list))
    for c in sorted(clips, key=lambda c: c.clip_id):
        groups[c.dataset][c.content].append(c)
    # interleave the datasets' sorted group lists: d1 g1, d2 g1, d1 g2, d2 g2, ...
    per_dataset = [[groups[d][k] for k in sorted(groups[d])] for d in sorted(groups)]
    queues = [lst[i] for i in range(max(map(len, per_dataset))) for lst in per_dataset if i < len(lst)]
    chosen: list[ClipInfo] = []
    depth = 0
    while len(chosen) < min(limit, len(clips)):
        for q in queues:
            if depth < len(q) and len(chosen) < limit:
                chosen.append(q[depth])
        depth += 1
    return sorted(chosen, key=lambda c: c.clip_id)


def _process_clip(task: tuple[ClipInfo, float, bool]) -> list[tuple[np.ndarray, dict]]:
    """Worker: features and record of one clip (and of its mirror). Runs in a child process."""
    info, fps, mirror = task
    motion = load_clip(info, fps)
    toe = min_toe_height(motion)
    skel = motion.skeleton
    base = {
        "dataset": info.dataset,
        "style": info.style,
        "take": info.take,
        "source_clip_id": info.clip_id,
        "fps": float(fps),
        "length": motion.num_frames,
        "duration_s": motion.num_frames / fps,
        "min_toe_height": round(toe, 5),
        "path": info.relpath,
        "skeleton": (skel.names, skel.parents, skel.offsets.numpy()),
    }
    travel = motion.root_translation[-1, [0, 2]] - motion.root_translation[0, [0, 2]]
    speed = float(travel.norm()) * fps / max(motion.num_frames - 1, 1)  # m/s, mean ground speed
    variants = [(motion, False)] + ([(motion.mirror(), True)] if mirror else [])
    out = []
    for m, mirrored in variants:
        feats = motion_to_features(m).to(torch.float32).numpy()
        rec = dict(base)
        rec["clip_id"] = info.clip_id + (MIRROR_SUFFIX if mirrored else "")
        rec["content"] = mirror_content(info.content) if mirrored else info.content
        rec["mirrored"] = mirrored
        # template captions first (evaluation prompts use captions[0]), then more verbs and speed words
        rec["captions"] = captions_for(info.content, info.style, mirrored=mirrored) + extra_captions(
            info.content, info.style, speed, mirrored=mirrored
        )
        out.append((feats, rec))
    return out


def _init_worker() -> None:
    """One torch thread per worker process: the parallelism comes from the processes."""
    torch.set_num_threads(1)


def _iter_results(tasks: list, workers: int):
    """Results of `_process_clip` in task order, in ``workers`` processes (in-process for <= 1)."""
    if workers <= 1 or len(tasks) <= 1:
        yield from map(_process_clip, tasks)
        return
    # fork (as torch's DataLoader does) works from any caller, scripts without a __main__ guard
    # included; spawn is the fallback where fork does not exist.
    ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
    with ctx.Pool(min(workers, len(tasks)), initializer=_init_worker) as pool:
        yield from pool.imap(_process_clip, tasks, chunksize=4)


def _shared_skeleton(records: list[dict]) -> tuple[Skeleton, float]:
    """The skeleton every clip shares, and the largest offset difference (m) between clips.

    Topology must be identical. Offsets come from the first clip; the root offset (unused by FK,
    since the root is placed by ``root_translation``) is set to the pelvis' rest height straight
    above the origin so that the rest pose stands on the floor.
    """
    names, parents, ref = records[0].pop("skeleton")
    worst = 0.0
    for rec in records[1:]:
        n, p, off = rec.pop("skeleton")
        if (n, p) != (names, parents):
            raise DataError(f"{rec['path']}: skeleton differs from {records[0]['path']} ({len(n)} joints)")
        worst = max(worst, float(np.abs(off[1:] - ref[1:]).max(initial=0.0)))
    offsets = ref.copy()
    offsets[0] = [0.0, ref[0][1], 0.0]
    return Skeleton(names, parents, offsets, name="bandai-namco"), worst


def with_clean_rest_pose(skeleton: Skeleton, feats: list, records: list[dict], fps: float) -> Skeleton:
    """The skeleton with ``rest_rotations`` = a natural standing pose (first frame of the first normal
    raise-up-both-hands clip, which starts standing still, or of the first clip), turned to face +Z.
    BVH export re-bases onto it so the exported rest pose is clean (kinema.motion.rest) instead of
    Bandai's pose lying along +X."""
    from kinema.motion.rest import standing_rest_pose
    from kinema.representation.kimodo_features import features_to_motion

    def preference(i: int):
        r = records[i]
        return r["mirrored"], r["content"] != "raise-up-both-hands", r["style"] != "normal", r["clip_id"]

    order = sorted(range(len(records)), key=preference)
    f = torch.from_numpy(np.asarray(feats[order[0]])).double()
    motion = features_to_motion(f, skeleton, fps)
    rest = standing_rest_pose(motion, 0)
    return Skeleton(
        skeleton.names,
        skeleton.parents,
        skeleton.offsets,
        rest,
        skeleton.end_sites,
        skeleton.role_overrides,
        skeleton.name,
    )


def _prepare_out(out_dir: Path) -> None:
    """Refuse to replace anything but an empty folder or an earlier build (never e.g. a home dir)."""
    if out_dir.exists():
        if not out_dir.is_dir():
            raise DataError(f"{out_dir}: output exists and is not a directory")
        if any(out_dir.iterdir()) and not (out_dir / "meta.json").is_file():
            raise DataError(f"{out_dir}: output directory is not empty and is not a kinema dataset build")
    out_dir.parent.mkdir(parents=True, exist_ok=True)


def _split_counts(records: list[dict]) -> dict:
    """Clip/frame/hour counts per split, for meta.json."""
    out = {}
    for s in SPLITS:
        recs = [r for r in records if r["split"] == s]
        frames = sum(r["length"] for r in recs)
        out[s] = {
            "clips": len(recs),
            "source_clips": sum(not r["mirrored"] for r in recs),
            "frames": frames,
            "hours": sum(r["duration_s"] for r in recs) / 3600.0,
        }
    return out


def build_dataset(
    root: str | Path,
    out_dir: str | Path,
    fps: float = 20,
    limit: int | None = None,
    workers: int = 2,
    mirror: bool = True,
    progress: bool = True,
) -> dict:
    """Build the Bandai Namco cache from ``root`` into ``out_dir``; returns the meta.json contents.

    ``fps`` is the frame rate of the features (20 as in the paper's experiments); ``limit`` keeps
    the content-balanced subset of `select_subset`; ``workers`` processes load clips in parallel;
    ``mirror`` adds a left/right mirrored copy of each clip with mirrored labels and captions.
    Splits are assigned over *all* clips under ``root`` (so a clip's split does not depend on
    ``limit``), per original clip id; a mirrored copy shares its original's split.
    """
    t0 = time.time()
    root, out_dir = Path(root), Path(out_dir).absolute()
    if not fps > 0:
        raise DataError(f"fps must be positive, got {fps}")
    all_clips = list_clips(root)
    if not all_clips:
        raise DataError(f"{root}: no .bvh.gz clips found")
    splits = assign_splits([(c.clip_id, group_of(c.clip_id)) for c in all_clips])
    clips = select_subset(all_clips, limit)
    _prepare_out(out_dir)

    feats, records = _load_clips(clips, splits, float(fps), mirror, workers, progress)
    skeleton, offset_spread = _shared_skeleton(records)
    layout = FeatureLayout(skeleton.num_joints)
    _assign_rows(feats, records, layout)
    skeleton = with_clean_rest_pose(skeleton, feats, records, float(fps))
    stats = _train_stats(feats, records, layout)
    features = torch.from_numpy(np.concatenate(feats, axis=0))
    del feats
    if not torch.isfinite(features).all():
        raise DataError("features contain NaN or inf")

    meta = _meta(root, clips, records, features, layout, fps, mirror, limit, offset_spread)
    files = {
        "clips.json": [{k: r[k] for k in RECORD_KEYS} for r in records],
        "skeleton.json": skeleton.to_dict(),
        "stats.json": stats.to_dict(),
    }
    write_build_folder(out_dir, features, files, meta, fps=fps, dim=layout.dim, t0=t0)
    return meta


def _load_clips(
    clips: list[ClipInfo], splits: dict, fps: float, mirror: bool, workers: int, progress: bool
) -> tuple[list[np.ndarray], list[dict]]:
    """Features and records of every clip (and mirror) in clip order, each record given its split."""
    from tqdm import tqdm

    feats: list[np.ndarray] = []
    records: list[dict] = []
    tasks = [(c, fps, mirror) for c in clips]
    bar = tqdm(total=len(tasks), desc="bandai-namco", unit="clip", disable=not progress)
    try:
        for result in _iter_results(tasks, max(1, int(workers))):
            for f, rec in result:
                rec["split"] = splits[rec["source_clip_id"]]
                feats.append(f)
                records.append(rec)
            bar.update(1)
    finally:
        bar.close()
    return feats, records


def _assign_rows(feats: list[np.ndarray], records: list[dict], layout: FeatureLayout) -> None:
    """Check each clip's feature shape and give its record the first row it will have in the big tensor."""
    start = 0
    for f, rec in zip(feats, records, strict=True):
        if f.shape != (rec["length"], layout.dim):
            raise DataError(f"{rec['path']}: features of shape {f.shape}, expected (T, {layout.dim})")
        rec["start"] = start
        start += rec["length"]


def _train_stats(feats: list[np.ndarray], records: list[dict], layout: FeatureLayout) -> NormStats:
    """Normalisation statistics of the train split only, so that no test clip leaks into training."""
    train = [torch.from_numpy(f) for f, r in zip(feats, records, strict=True) if r["split"] == "train"]
    if not train:
        raise DataError("no clip of the selection is in the train split; use a larger --limit")
    # statistics of what training sees: first frame over the origin, any heading (see NormStats)
    return NormStats.compute((canonicalize_start(f, layout) for f in train), xz_pairs=layout.xz_pairs())


def _meta(
    root: Path,
    clips: list[ClipInfo],
    records: list[dict],
    features: torch.Tensor,
    layout: FeatureLayout,
    fps: float,
    mirror: bool,
    limit: int | None,
    offset_spread: float,
) -> dict:
    """The meta.json contents (``build_seconds`` is filled in just before writing)."""
    toe = [r["min_toe_height"] for r in records]
    return {
        "format_version": FORMAT_VERSION,
        "dataset": "bandai-namco",
        "fps": float(fps),
        "layout": layout.to_dict(),
        "root_sigma_s": DEFAULT_ROOT_SIGMA_SECONDS,
        "contact_thresholds": asdict(ContactThresholds()),
        "source_root": str(root.absolute()),
        "mirror": bool(mirror),
        "limit": limit,
        "split_rule": "kinema.data.split.assign_splits over all clips, groups = dataset_content, 80/10/10",
        "kinema_version": _version(),
        "build_time": datetime.now(UTC).isoformat(timespec="seconds"),
        "build_seconds": None,
        "skeleton_offset_spread_m": offset_spread,
        "min_toe_height_range_m": [min(toe), max(toe)],
        "counts": {
            "source_clips": len(clips),
            "clips": len(records),
            "frames": int(features.shape[0]),
            "hours": sum(r["duration_s"] for r in records) / 3600.0,
            "splits": _split_counts(records),
        },
    }


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("kinema")
    except PackageNotFoundError:
        return "unknown"
