"""``kinema data build quaternius-humanoids``: the Quaternius humanoid actions on the human skeleton, added
to a Bandai Namco build, as one flat training build.

    kinema data build quaternius-humanoids --root ../shared/datasets/quaternius --base cache/bandai20p \\
        --out cache/bandai20h

Every GLB under ``--root`` is read (kinema.data.sources); the ones kinema.retarget detects as humanoids
give their `HUMANOID_ACTIONS` clips, padded with the character's idle and retargeted onto the base
build's 21-joint skeleton (kinema.data.humanoid_clips), keeping the file's root: no travel is added.
The shared recovery of travel from planted feet (kinema.data.root_motion, made for steps) was tried on
these clips and is not used: on a fall it reads the sliding feet as travel (-4.5 m on the cyberpunk
death, whose hips already move 0.6 m), and through a roll the feet are off the floor (it gave the
cyberpunk roll 3.7 m forward and the knight's 0.4 m backward). Kicks, punches, jumps, ducks, nods,
dances and pick-ups are done on the spot; rolls stay on the spot as the files have them.

Each clip and its left/right mirror (content label and captions mirrored with it, as for the Bandai
clips) become feature rows in the human layout. A clip whose retargeted motion repeats one already kept
(same content, every joint within `DUPLICATE_M` on every frame: three of the four astronauts carry the
same animations as the first on the same proportions) is dropped and listed. Files the humanoid test
passes that are no humanoid body, or whose trunk comes out folded, are `EXCLUDED` (the cyberpunk flying
drones; the four space-pack mechs).

Rigs with `LIMITED` entries give only the actions listed there, for the reason given: the mechs' legs
come out bent on the human (their pelvis 0.5-0.6 m up against the captures' 0.93 m), so their kicks
reach hip height only just; they keep the actions no other character has (dance, pick up). A clip whose
toes go more than `SINK_M` below where they stand in its idle sinks into the floor on the human (two
mech pick-ups, by 0.17-0.22 m) and is dropped and listed.

The output holds the base build's clips unchanged (same rows, same splits) followed by the humanoid
clips, all in the train split (a few clips per action: held-out *phrasings*, not held-out clips,
evaluate them; kinema.data.humanoid_actions.HELD_OUT_PROMPTS); statistics are recomputed over the
train split of the whole. The licences differ: Bandai Namco CC BY-NC 4.0, Quaternius CC0 (meta.json).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch
from safetensors.torch import load_file

from kinema.data.build import MIRROR_SUFFIX, RECORD_KEYS, _prepare_out, _split_counts, _train_stats
from kinema.data.build_folder import write_build_folder
from kinema.data.captions import mirror_content
from kinema.data.humanoid_actions import STYLE, content_label, humanoid_captions
from kinema.data.humanoid_clips import PAD_SECONDS, HumanoidClip, action_clips
from kinema.data.quaternius import LICENCE, list_glbs
from kinema.data.sources import load_source
from kinema.errors import DataError, KinemaError
from kinema.representation.kimodo_features import motion_to_features
from kinema.representation.layout import FeatureLayout
from kinema.skeleton import Skeleton

DATASET = "quaternius-humanoids"
#: two clips of one content whose joints stay within this (metres) on every frame are one clip
DUPLICATE_M = 0.02
#: a clip whose toes go this far (metres) below their standing height sinks into the floor: dropped
SINK_M = 0.1
#: rig file-name prefixes -> (actions kept, why the others are left out)
_MECH = "legs bent on the human (pelvis 0.5-0.6 m): kept only for actions no other rig has"
LIMITED: dict[str, tuple[tuple[str, ...], str]] = {
    "mech_pack/": (("dance", "pick-up"), _MECH),
    "ultimate_space_pack/Mech_": (("dance", "pick-up"), _MECH),
}
#: files the humanoid test passes that are no humanoid body (file -> why)
_DRONE = "a flying drone with arms, found by the rest-pose geometry test (docs/retarget.md)"
_FOLDED = "the trunk comes out folded (spine -> chest 86 degrees from vertical when standing)"
EXCLUDED = {
    "cyberpunk_pack/Enemy_Flying.glb": _DRONE,
    "cyberpunk_pack/Enemy_Flying_Gun.glb": _DRONE,
    **{f"ultimate_space_pack/Mech_{n}-transformed.glb": _FOLDED
       for n in ("BarbaraTheBee", "FernandoTheFlamingo", "FinnTheFrog", "RaeTheRedPanda")},
}


@dataclass
class HumanoidReport:
    """What the build found: humanoid files used, files that are not humanoids, clips dropped and why."""

    used: dict[str, list[str]] = field(default_factory=dict)  # file -> content labels kept
    not_humanoid: list[str] = field(default_factory=list)
    excluded: list[str] = field(default_factory=list)
    no_actions: list[str] = field(default_factory=list)
    duplicates: list[str] = field(default_factory=list)
    sinking: list[str] = field(default_factory=list)
    limited: list[str] = field(default_factory=list)
    messages: list[str] = field(default_factory=list)


def _kept_actions(rel: str) -> tuple[tuple[str, ...], str] | None:
    return next((v for k, v in LIMITED.items() if rel.startswith(k)), None)


def _sink(clip: HumanoidClip) -> float:
    """How far (metres) the toes go below their height in the idle before the action."""
    names = list(clip.motion.skeleton.names)
    toes = clip.motion.positions[:, [names.index("Toes_L"), names.index("Toes_R")], 1]
    return float(toes[: clip.action_frames[0]].min() - toes.min())


def _is_duplicate(clip: HumanoidClip, content: str, kept: list[tuple[str, torch.Tensor]]) -> bool:
    P = clip.motion.positions
    return any(c == content and q.shape == P.shape and float((q - P).abs().max()) < DUPLICATE_M for c, q in kept)


def humanoid_clips(root: Path, human: Skeleton, fps: float, report: HumanoidReport) -> list[tuple[HumanoidClip, str]]:
    """(clip, content label) of every humanoid action clip under ``root``, duplicates and limited rigs'
    other actions left out (and listed in ``report``)."""
    from kinema.retarget import is_humanoid

    out: list[tuple[HumanoidClip, str]] = []
    kept: list[tuple[str, torch.Tensor]] = []
    for path in list_glbs(root):
        rel = path.relative_to(root).as_posix()
        if rel in EXCLUDED:
            report.excluded.append(f"{rel}: {EXCLUDED[rel]}")
            continue
        try:
            src = load_source(path, root, fps=fps)
        except KinemaError as exc:
            report.messages.append(f"skipped {rel}: {exc}")
            continue
        if not is_humanoid(src.skeleton):
            report.not_humanoid.append(rel)
            continue
        clips = action_clips(rel, src.clips, human)
        if not clips:
            report.no_actions.append(rel)
            continue
        limit = _kept_actions(rel)
        for c in clips:
            content = content_label(c.action, c.side)
            if limit is not None and c.action.content.split("-{")[0] not in limit[0]:
                report.limited.append(f"{rel}#{c.clip}: {content} ({limit[1]})")
                continue
            sink = _sink(c)
            if sink > SINK_M:
                report.sinking.append(f"{rel}#{c.clip} ({content}): toes {sink:.2f} m below the floor")
                continue
            if _is_duplicate(c, content, kept):
                report.duplicates.append(f"{rel}#{c.clip} ({content})")
                continue
            kept.append((content, c.motion.positions))
            out.append((c, content))
            report.used.setdefault(rel, []).append(content)
    return out


def _records(clip: HumanoidClip, content: str, fps: float) -> list[tuple[np.ndarray, dict]]:
    """Features and clips.json records of a clip and its mirror."""
    from kinema.data.bandai import min_toe_height

    source = f"{DATASET}/{clip.file}#{clip.clip}"  # the animation: shared by its idle lengths and mirror
    cid = source if clip.pad_seconds == PAD_SECONDS[0] else f"{source}@idle{clip.pad_seconds:g}s"
    out = []
    for motion, mirrored in ((clip.motion, False), (clip.motion.mirror(), True)):
        rec = {
            "clip_id": cid + (MIRROR_SUFFIX if mirrored else ""),
            "source_clip_id": source,
            "dataset": DATASET,
            "content": mirror_content(content) if mirrored else content,
            "style": STYLE,
            "take": Path(clip.file).stem,
            "mirrored": mirrored,
            "split": "train",
            "start": 0,
            "length": motion.num_frames,
            "fps": float(fps),
            "duration_s": motion.num_frames / fps,
            "min_toe_height": round(min_toe_height(motion), 5),
            "captions": humanoid_captions(clip.action, clip.side, mirrored=mirrored),
            "path": f"{clip.file}#{'+'.join(clip.chained)}",
        }
        out.append((motion_to_features(motion).to(torch.float32).numpy(), rec))
    return out


def _read_base(base: Path) -> tuple[torch.Tensor, list[dict], dict, dict]:
    try:
        meta = json.loads((base / "meta.json").read_text())
        records = json.loads((base / "clips.json").read_text())
        skeleton = json.loads((base / "skeleton.json").read_text())
        features = load_file(str(base / "features.safetensors"))["features"]
    except (OSError, ValueError, KeyError) as exc:
        raise DataError(f"{base}: not a readable bandai-namco build ({exc}); make one with "
                        "`kinema data build bandai-namco`") from None
    if meta.get("dataset") != "bandai-namco":
        raise DataError(f"{base}: --base must be a bandai-namco build, this one is {meta.get('dataset')!r}")
    return features, records, skeleton, meta


def build_humanoids(
    root: str | Path, base: str | Path, out_dir: str | Path, *, fps: float | None = None
) -> tuple[dict, HumanoidReport]:
    """Write ``out_dir``: the ``base`` build's clips plus the Quaternius humanoid actions under ``root``
    (see the module). ``fps`` must match the base build's (default: the base's). Returns (meta, report)."""
    t0 = time.time()
    root, base, out_dir = Path(root), Path(base), Path(out_dir).absolute()
    features, records, skel_dict, meta = _read_base(base)
    base_fps = float(meta["fps"])
    if fps is not None and abs(fps - base_fps) > 1e-9:
        raise DataError(f"--fps {fps:g} differs from the base build's {base_fps:g} fps")
    human = Skeleton.from_dict(skel_dict)
    layout = FeatureLayout(human.num_joints)
    _prepare_out(out_dir)
    report = HumanoidReport()
    clips = humanoid_clips(root, human, base_fps, report)
    if not clips:
        raise DataError(f"{root}: no humanoid action clip found (humanoids need the slots of docs/retarget.md)")
    feats, records = _merge(features, records, clips, base_fps)
    stats = _train_stats(feats, records, layout)
    all_features = torch.from_numpy(np.concatenate(feats, axis=0))
    if not torch.isfinite(all_features).all():
        raise DataError("humanoid features contain NaN or inf")
    meta = _build_meta(meta, base, root, report, records, int(all_features.shape[0]))
    files = {
        "clips.json": [{k: r[k] for k in RECORD_KEYS} for r in records],
        "skeleton.json": skel_dict,
        "stats.json": stats.to_dict(),
    }
    write_build_folder(out_dir, all_features, files, meta, fps=base_fps, dim=layout.dim, t0=t0)
    return meta, report


def _merge(features: torch.Tensor, records: list[dict], clips, fps: float) -> tuple[list[np.ndarray], list[dict]]:
    """The base build's clips (features, records) followed by the humanoid ``clips``' (each with its mirror),
    every record's ``start`` set to its place in the concatenated features."""
    feats = [features[r["start"] : r["start"] + r["length"]].numpy() for r in records]
    records = [dict(r) for r in records]
    for clip, content in clips:
        for f, rec in _records(clip, content, fps):
            feats.append(f)
            records.append(rec)
    start = 0
    for f, rec in zip(feats, records, strict=True):
        rec["start"], start = start, start + f.shape[0]
    return feats, records


def _build_meta(meta: dict, base: Path, root: Path, report: HumanoidReport, records: list[dict], frames: int) -> dict:
    """The base build's meta with the humanoid clips' source, licence, what was left out and the new counts."""
    new = [r for r in records if r["dataset"] == DATASET]
    meta = dict(meta)
    meta.update(
        dataset="bandai-namco+quaternius-humanoids",
        base_build=str(base.absolute()),
        humanoids={
            "source_root": str(root.absolute()),
            "licence": LICENCE,
            "style": STYLE,
            "clips": len(new),
            "source_clips": len({r["source_clip_id"] for r in new}),  # animations (each at two idle lengths)
            "seconds": round(sum(r["duration_s"] for r in new), 1),
            "files": report.used,
            "not_humanoid": report.not_humanoid,
            "excluded": report.excluded,
            "humanoid_without_actions": report.no_actions,
            "duplicates_dropped": report.duplicates,
            "sinking_dropped": report.sinking,
            "limited": report.limited,
            "messages": report.messages,
            "root_motion": "none added: the files' root kept (kinema.data.humanoid_build docstring)",
        },
        licence="Bandai Namco clips CC BY-NC 4.0; Quaternius clips CC0 1.0",
    )
    meta["counts"] = {
        "source_clips": len({r["source_clip_id"] for r in records}),
        "clips": len(records),
        "frames": frames,
        "hours": sum(r["duration_s"] for r in records) / 3600.0,
        "splits": _split_counts(records),
    }
    return meta
