"""`kinema data` for multi-rig data: build quaternius / folder, per-rig stats, manifests.

Kept apart from kinema.cli.data (the Bandai Namco build and its content/style tables) so each file
stays small; kinema.cli.data dispatches here. See docs/dataset.md.
"""

from __future__ import annotations

import sys
import time
from collections import defaultdict
from pathlib import Path

from kinema.errors import DataError


def is_multirig(path: str) -> bool:
    """Whether ``path`` is a manifest file or a multi-rig motion cache (stats shows rigs for these)."""
    from kinema.data.motion_cache import is_motion_cache

    p = Path(path)
    return p.is_file() or is_motion_cache(p)


def build(args) -> int:
    """``kinema data build quaternius|folder``: build, print messages and one summary line."""
    t0 = time.time()
    if args.dataset == "quaternius":
        from kinema.data.quaternius import build_quaternius

        meta, messages = build_quaternius(
            args.root, args.out, fps=args.fps, limit=args.limit, train_rigs=args.train_rigs, progress=not args.quiet
        )
    else:
        from kinema.data.folder import build_folder

        if args.limit is not None:
            raise DataError("--limit is not supported by the folder build; point --root at a smaller folder")
        meta, messages = build_folder(
            args.root,
            args.out,
            fps=args.fps,
            units=args.units,
            skip_uncaptioned=args.skip_uncaptioned,
            train_rigs=args.train_rigs,
            progress=not args.quiet,
        )
    for m in messages:
        print(m, file=sys.stderr)
    c = meta["counts"]
    print(
        f"wrote {args.out}: {c['clips']} clips ({c['source_clips']} source, {c['duplicates_dropped']} duplicates "
        f"dropped) on {c['rigs']} rigs ({c['joints_min']}-{c['joints_max']} joints), {c['seconds'] / 60:.1f} min "
        f"at {meta['fps']:g} fps in {time.time() - t0:.0f} s"
    )
    if meta.get("trainable"):
        print(f"one human skeleton: `kinema train --data {args.out}` can use it")
    elif meta.get("not_trainable_because"):
        print(f"not for today's flat trainer: {meta['not_trainable_because']}")
    return 0


def manifest(args) -> int:
    """``kinema data manifest``: write a manifest listing several builds."""
    from kinema.data.multirig import DEFAULT_EXCLUDE, MultiRigData, write_manifest

    write_manifest(args.out, args.dirs, () if args.include_props else DEFAULT_EXCLUDE)
    data = MultiRigData(args.out)
    print(f"wrote {args.out}: {len(args.dirs)} builds, {len(data.rigs)} rigs, {len(data)} clips")
    return 0


def _rig_rows(clips: list[dict], rigs: dict[str, dict]) -> list[str]:
    by_rig: dict[str, list[dict]] = defaultdict(list)
    for r in clips:
        by_rig[r["rig"]].append(r)
    width = max([4] + [len(k) for k in by_rig])
    lines = [
        f"{'rig':<{width}}  {'joints':>6}  {'files':>5}  {'clips':>5}  {'seconds':>8}  {'captions':>8}  "
        f"{'flagged':>7}  split"
    ]
    for rid in sorted(by_rig, key=lambda k: (-len(by_rig[k]), k)):
        recs, rig = by_rig[rid], rigs.get(rid, {})
        secs = sum(r["duration_s"] for r in recs)
        caps = sum(len(r["captions"]) for r in recs)
        flagged = sum(bool(r.get("flags")) for r in recs)
        split = rig.get("split") or "?"
        lines.append(
            f"{rid:<{width}}  {rig.get('joints', '?'):>6}  {len(rig.get('files', [])):>5}  {len(recs):>5}  "
            f"{secs:>8.1f}  {caps:>8}  {flagged:>7}  {split}"
        )
    return lines


def _split_rows(clips: list[dict]) -> list[str]:
    lines = [f"{'split':<6}  {'rigs':>4}  {'clips':>5}  {'minutes':>7}"]
    for s in ("train", "val", "test"):
        recs = [r for r in clips if r["split"] == s]
        rigs = len({r["rig"] for r in recs})
        lines.append(f"{s:<6}  {rigs:>4}  {len(recs):>5}  {sum(r['duration_s'] for r in recs) / 60:>7.2f}")
    return lines


def stats(args) -> int:
    """Per-rig table (joints, files, clips, seconds, captions, flagged clips, split) and per split."""
    from kinema.data.multirig import MultiRigData

    data = MultiRigData(args.dir, exclude_flags=())
    clips = data.clips
    secs = sum(r["duration_s"] for r in clips)
    flags: dict[str, int] = defaultdict(int)
    for r in clips:
        for f in r.get("flags", ()):
            flags[f] += 1
    joints = [r["joints"] for r in data.rigs.values()]
    datasets = sorted({r["dataset"] for r in clips})
    head = [
        f"{args.dir}: {', '.join(datasets)}; {len(data.rigs)} rigs ({min(joints)}-{max(joints)} joints), "
        f"{len(clips)} clips, {secs / 60:.2f} min"
    ]
    for src in data.sources:
        c = getattr(src, "meta", {}).get("counts")
        if c:
            head.append(
                f"  {src.meta['dataset']}: {c['files']} files, {c['source_clips']} source clips, "
                f"{c['duplicates_dropped']} exact duplicates dropped, {c.get('uncaptioned_skipped', 0)} "
                "uncaptioned skipped"
            )
    if flags:
        head.append("  flags: " + ", ".join(f"{k} {v}" for k, v in sorted(flags.items())))
    print("\n".join(head + [""] + _rig_rows(clips, data.rigs) + [""] + _split_rows(clips)))
    return 0
