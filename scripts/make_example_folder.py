"""Build the worked examples of docs/dataset.md ("Your own data") from the shared datasets.

    python scripts/make_example_folder.py [--datasets ../shared/datasets] [--out out]

Writes two folders under ``--out`` (``out/`` is git-ignored: the data are never copied into the
repository):

- ``my-motions/``: eight Bandai Namco clips as plain, uncompressed BVH files in centimetres (their
  unit is left for the build to detect), captioned all three ways: ``walk/*.txt`` sidecars, a
  ``captions.csv`` and a ``captions.jsonl``. One skeleton with human roles, so ``kinema train`` can
  use its build. Licence: CC BY-NC 4.0 (Bandai Namco Research Inc.), like the source.
- ``my-creatures/``: three Quaternius GLBs (CC0) captioned per animation in ``captions.jsonl``
  (``Fox.glb#AnimalArmature|Gallop``): three skeletons, a multi-rig cache.

Captions of ``my-motions`` come from the clips' content/style labels (kinema.data.captions) as a
stand-in for captions you would write yourself.
"""

from __future__ import annotations

import argparse
import csv
import gzip
import json
import shutil
from pathlib import Path

from kinema.data.captions import captions_for
from kinema.data.split import parse_clip_name

BANDAI = "bandai-namco/Bandai-Namco-Research-Motiondataset-{n}/data/{clip}.bvh.gz"
#: (dataset, clip id, how it is captioned)
CLIPS = (
    (2, "dataset-2_walk_normal_001", "txt"),
    (2, "dataset-2_walk_active_001", "txt"),
    (2, "dataset-2_run_normal_001", "csv"),
    (2, "dataset-2_run_exhausted_001", "csv"),
    (2, "dataset-2_wave-left-hand_normal_001", "jsonl"),
    (2, "dataset-2_raise-up-both-hands_normal_001", "jsonl"),
    (1, "dataset-1_bow_normal_001", "jsonl"),
    (1, "dataset-1_walk-back_normal_001", "jsonl"),
)
CREATURES = ("animals_pack/Fox.glb", "dinosaurs_pack/Trex.glb", "cute_fish_pack/Koi.glb")


def make_motions(datasets: Path, out: Path) -> int:
    """Write ``out`` (replacing it) with the eight human clips and their captions; returns the count."""
    shutil.rmtree(out, ignore_errors=True)
    (out / "walk").mkdir(parents=True)
    rows, lines = [], []
    for n, clip, how in CLIPS:
        src = datasets / BANDAI.format(n=n, clip=clip)
        fields = parse_clip_name(clip)
        folder = out / ("walk" if how == "txt" else "")
        dest = folder / f"{fields['content']}_{fields['style']}.bvh"
        dest.write_bytes(gzip.decompress(src.read_bytes()))
        caps = captions_for(fields["content"], fields["style"])[:3]
        rel = dest.relative_to(out).as_posix()
        if how == "txt":
            dest.with_suffix(".txt").write_text("\n".join(caps) + "\n", encoding="utf-8")
        elif how == "csv":
            rows += [(rel, c) for c in caps]
        else:
            lines.append(json.dumps({"file": rel, "captions": caps}))
    with (out / "captions.csv").open("w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(["file", "caption"])
        writer.writerows(rows)
    (out / "captions.jsonl").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (out / "LICENSE.txt").write_text("Bandai Namco Research Motion Dataset clips: CC BY-NC 4.0.\n")
    return len(CLIPS)


def make_creatures(datasets: Path, out: Path) -> int:
    """Write ``out`` with three GLBs and a captions.jsonl naming each animation; returns the clips."""
    from kinema.data.creature_captions import creature_captions
    from kinema.io.gltf import read_gltf

    shutil.rmtree(out, ignore_errors=True)
    out.mkdir(parents=True)
    lines = []
    for rel in CREATURES:
        src = datasets / "quaternius" / rel
        shutil.copy(src, out / src.name)
        for name in read_gltf(src, fps=20).motions:
            lines.append(json.dumps({"file": f"{src.name}#{name}", "captions": creature_captions(rel, name)}))
    (out / "captions.jsonl").write_text("\n".join(lines) + "\n", encoding="utf-8")
    (out / "LICENSE.txt").write_text("Quaternius models: CC0 1.0 (public domain).\n")
    return len(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--datasets", type=Path, default=Path("../shared/datasets"), help="the shared datasets folder")
    p.add_argument("--out", type=Path, default=Path("out"), help="where to write the example folders")
    args = p.parse_args()
    if not (args.datasets / "bandai-namco").is_dir():
        raise SystemExit(f"{args.datasets}: no bandai-namco folder (pass --datasets)")
    n = make_motions(args.datasets, args.out / "my-motions")
    print(f"wrote {args.out / 'my-motions'}: {n} BVH clips with .txt, captions.csv and captions.jsonl captions")
    if (args.datasets / "quaternius").is_dir():
        n = make_creatures(args.datasets, args.out / "my-creatures")
        print(f"wrote {args.out / 'my-creatures'}: {len(CREATURES)} GLBs, {n} captioned animations")


if __name__ == "__main__":
    main()
