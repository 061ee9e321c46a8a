"""`kinema data`: build the training cache of a motion dataset and summarise a build.

    kinema data build bandai-namco --root PATH --out DIR [--fps 20] [--limit N] [--workers 2] [--no-mirror]
    kinema data build quaternius --root PATH --out DIR [--fps 20] [--limit N]
    kinema data build quaternius-humanoids --root PATH --base BANDAI_BUILD --out DIR
    kinema data build folder --root DIR --out DIR [--fps 20] [--units m|cm|mm|auto] [--skip-uncaptioned]
    kinema data stats DIR|MANIFEST.json
    kinema data manifest --out MANIFEST.json DIR [DIR ...]

See docs/dataset.md for what a build contains and how splits, mirroring and ``--limit`` work.
"""

from __future__ import annotations

import time
from collections import defaultdict

from kinema.cli import data_multirig
from kinema.cli._args import positive_int
from kinema.errors import DataError

DATASETS = ("bandai-namco", "quaternius", "quaternius-humanoids", "folder")


def register(sub) -> None:
    """Add the `data` sub-command (with `build` and `stats`) to the top-level parser."""
    p = sub.add_parser(
        "data",
        help="build and inspect training datasets",
        description="Build and inspect training datasets (see docs/dataset.md).",
    )
    dsub = p.add_subparsers(dest="data_command", required=True)
    _register_build(dsub)

    s = dsub.add_parser("stats", help="what a build holds: per content/style/split, or per rig")
    s.add_argument("dir", help="a folder written by `kinema data build`, or a manifest file")
    s.set_defaults(func=_stats)

    m = dsub.add_parser("manifest", help="list several builds as one multi-rig training set")
    m.add_argument("dirs", nargs="+", help="build folders (motion caches or bandai-namco builds)")
    m.add_argument("--out", required=True, help="manifest file to write (JSON)")
    m.add_argument("--include-props", action="store_true", help="keep clips flagged 'prop' (excluded by default)")
    m.set_defaults(func=data_multirig.manifest)


_positive_int = positive_int


def _register_build(dsub) -> None:
    """`kinema data build`: one dataset (or folder) into a feature cache."""
    b = dsub.add_parser("build", help="turn a motion dataset into a feature cache for training")
    b.add_argument(
        "dataset", choices=DATASETS, help="bandai-namco, quaternius, quaternius-humanoids (their humanoid actions on "
        "the human skeleton, added to a bandai-namco --base build), or folder (your own BVH/GLB files with captions)"
    )
    b.add_argument("--root", required=True, help="folder holding the unpacked dataset(s)")
    b.add_argument("--out", required=True, help="output folder (replaced only once the build succeeds)")
    b.add_argument("--fps", type=float, default=20.0, help="frame rate of the features / motions (default 20)")
    b.add_argument(
        "--limit",
        type=_positive_int,
        default=None,
        help="bandai-namco: a content-balanced subset of N clips; quaternius: the first N files",
    )
    b.add_argument("--workers", type=_positive_int, default=2, help="bandai-namco: worker processes (default 2)")
    b.add_argument(
        "--no-mirror", dest="mirror", action="store_false", help="bandai-namco: do not add left/right mirrored copies"
    )
    b.add_argument(
        "--units",
        choices=("auto", "m", "cm", "mm"),
        default="auto",
        help="folder: length unit of BVH files (default auto: detected from the first frame's size)",
    )
    b.add_argument(
        "--skip-uncaptioned",
        action="store_true",
        help="folder: leave out clips without captions (listed) instead of stopping",
    )
    b.add_argument(
        "--train-rigs",
        nargs="*",
        default=None,
        metavar="RIG",
        help="quaternius / folder: rig ids never held out (quaternius default: parasaurolophus, the biped "
        "dinosaur; give the flag with no names for the plain hash split)",
    )
    b.add_argument(
        "--base",
        default=None,
        help="quaternius-humanoids: the bandai-namco build the humanoid clips are added to (its skeleton, fps, clips)",
    )
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    b.set_defaults(func=_build)


def _build(args) -> int:
    from kinema.data.build import build_dataset

    if args.dataset == "quaternius-humanoids":
        return _build_humanoids(args)
    if args.base is not None:
        raise DataError("--base is for quaternius-humanoids builds")
    if args.dataset != "bandai-namco":
        return data_multirig.build(args)
    if args.train_rigs is not None:
        raise DataError("--train-rigs is for multi-rig builds (quaternius, folder); bandai-namco is split by take")
    t0 = time.time()
    meta = build_dataset(
        args.root,
        args.out,
        fps=args.fps,
        limit=args.limit,
        workers=args.workers,
        mirror=args.mirror,
        progress=not args.quiet,
    )
    c = meta["counts"]
    print(
        f"wrote {args.out}: {c['clips']} clips ({c['source_clips']} source), {c['frames']} frames, "
        f"{c['hours']:.2f} h at {meta['fps']:g} fps, D = {meta['layout']['dim']} "
        f"in {time.time() - t0:.0f} s"
    )
    return 0


def _build_humanoids(args) -> int:
    from kinema.data.humanoid_build import build_humanoids

    if args.base is None:
        raise DataError("quaternius-humanoids needs --base BUILD (a `kinema data build bandai-namco` folder)")
    t0 = time.time()
    meta, report = build_humanoids(args.root, args.base, args.out, fps=args.fps)
    h = meta["humanoids"]
    for line in report.messages:
        print(line)
    print(
        f"wrote {args.out}: {meta['counts']['clips']} clips, of which {h['clips']} humanoid "
        f"({h['source_clips']} source clips, {h['seconds']:.0f} s, from {len(h['files'])} files; "
        f"{len(report.duplicates)} duplicates dropped, "
        f"{len(report.limited)} left out of limited rigs) in {time.time() - t0:.0f} s"
    )
    return 0


def _table(title: str, rows: dict[str, list[dict]], order: list[str] | None = None) -> list[str]:
    """Lines of one summary table: label, clips, of which mirrored, hours."""
    width = max([len(title)] + [len(k) for k in rows])
    lines = [f"{title:<{width}}  {'clips':>6}  {'mirrored':>8}  {'hours':>7}"]
    for key in order or sorted(rows):
        recs = rows.get(key, [])
        hours = sum(r["duration_s"] for r in recs) / 3600.0
        mirrored = sum(bool(r["mirrored"]) for r in recs)
        lines.append(f"{key:<{width}}  {len(recs):>6}  {mirrored:>8}  {hours:>7.3f}")
    return lines


def _stats(args) -> int:
    from kinema.data.dataset import load_clip_table
    from kinema.data.split import SPLITS

    if data_multirig.is_multirig(args.dir):
        return data_multirig.stats(args)
    meta, clips = load_clip_table(args.dir)
    by: dict[str, dict[str, list[dict]]] = {
        "content": defaultdict(list),
        "style": defaultdict(list),
        "split": defaultdict(list),
    }
    for r in clips:
        for field in by:
            by[field][r[field]].append(r)
    source = sum(not r["mirrored"] for r in clips)
    hours = sum(r["duration_s"] for r in clips) / 3600.0
    dim = meta.get("layout", {}).get("dim", "?")
    out = [
        f"{args.dir}: {meta.get('dataset', '?')} at {meta.get('fps', 0):g} fps, D = {dim}, "
        f"{len(clips)} clips ({source} source + {len(clips) - source} mirrored), {hours:.3f} h",
        "",
    ]
    out += _table("content", by["content"]) + [""]
    out += _table("style", by["style"]) + [""]
    out += _table("split", by["split"], order=list(SPLITS))
    out += _table("total", {"total": clips})[1:]
    print("\n".join(out))
    return 0
