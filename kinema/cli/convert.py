"""`kinema convert IN OUT`: motion files between BVH (.bvh/.bvh.gz), the kinema npz contract and glTF (.glb/.gltf).

Units: BVH lengths are read in the file's unit times ``--in-scale`` (0.01 for centimetre files such as
Bandai Namco) and written in metres times ``--out-scale`` (1 = metres, what Blender's importer expects
at scale 1.0; 100 = centimetres). npz and GLB files are always metres, Y up (see docs/formats.md).

A glTF input can hold many clips: ``--animation NAME`` picks one (full name or the part after
``Armature|``); ``all`` (the default) converts every clip: into one GLB, or into one BVH/npz file per
clip named ``OUT_<clip>.bvh``. A GLB output carries the rig's skinned mesh when the input had one
(a BVH/npz rig gets a generated bone mesh).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

from kinema.cli._args import positive_float

_OUT_SUFFIXES = (".npz", ".bvh", ".bvh.gz", ".glb")


def register(sub) -> None:
    """Add the `convert` sub-command to the top-level parser."""
    p = sub.add_parser("convert", help="convert motion files between BVH, npz and glTF/GLB")
    p.add_argument("input", type=Path, help=".bvh, .bvh.gz, .npz, .glb or .gltf")
    p.add_argument("output", type=Path, help=".bvh, .bvh.gz, .npz or .glb")
    p.add_argument(
        "--animation",
        default="all",
        metavar="NAME|all",
        help="glTF input: the clip to convert, or all (default; one BVH/npz file per clip)",
    )
    p.add_argument(
        "--in-scale",
        type=positive_float,
        default=1.0,
        help="multiply BVH input lengths by this to get metres (0.01 for centimetres)",
    )
    p.add_argument(
        "--exact-root",
        action="store_true",
        help="BVH input: keep the root where the file puts it even when its only child moves (BVH written from "
        "a GLB creature); by default the root follows that child, as Bandai Namco's dummy root needs",
    )
    p.add_argument(
        "--out-scale",
        type=positive_float,
        default=1.0,
        help="BVH output lengths = metres x this (1 = metres, 100 = centimetres)",
    )
    p.add_argument("--order", default="ZXY", help="Euler channel order of BVH output (default ZXY)")
    p.add_argument(
        "--drop",
        nargs="*",
        default=[],
        metavar="JOINT",
        help="joints to prune (folded into their children), e.g. joint_Root",
    )
    p.add_argument("--fps", type=positive_float, help="resample to this frame rate")
    p.set_defaults(func=run)


def clip_file_name(output: Path, clip: str) -> Path:
    """``OUT_<clip>.suffix`` for one clip of many: the clip name after ``Armature|``, made file-safe."""
    name = output.name
    suffix = next(s for s in _OUT_SUFFIXES if name.lower().endswith(s))
    short = re.sub(r"[^A-Za-z0-9_.-]+", "_", clip.split("|")[-1]).strip("._") or "clip"
    return output.with_name(f"{name[: -len(suffix)]}_{short}{name[-len(suffix) :]}")


def _read_clips(args: argparse.Namespace) -> dict:
    """Clip name -> Motion from the input (one clip for BVH/npz)."""
    from kinema.errors import KinemaError
    from kinema.io import load_motion
    from kinema.io.gltf import read_gltf

    suffix = args.input.name.lower()
    if suffix.endswith(".glb") or suffix.endswith(".gltf"):
        if args.in_scale != 1.0:
            raise KinemaError("--in-scale applies to BVH input; glTF files are read in metres")
        chosen = None if args.animation == "all" else [args.animation]
        asset = read_gltf(args.input, fps=args.fps, animations=chosen)
        if not asset.motions:
            raise KinemaError(f"{args.input}: has no animations to convert")
        return dict(asset.motions)
    if args.animation != "all":
        raise KinemaError("--animation applies to glTF input; BVH and npz files hold one motion")
    exact = {"root_follows_child": False} if args.exact_root and suffix.endswith((".bvh", ".bvh.gz")) else {}
    motion = load_motion(args.input, scale=args.in_scale, **exact)
    if args.fps is not None:
        motion = motion.resample(args.fps)
    return {args.input.name.split(".")[0]: motion}


def run(args: argparse.Namespace) -> int:
    from kinema.atomic_files import check_output_path
    from kinema.errors import KinemaError
    from kinema.io.gltf_writer import write_glb

    if not args.input.exists():
        raise KinemaError(f"{args.input}: no such file")
    name = args.output.name.lower()
    if not name.endswith(_OUT_SUFFIXES):
        raise KinemaError(f"{args.output}: unknown motion format (use .bvh, .bvh.gz, .npz or .glb)")
    check_output_path(args.output)
    clips = _read_clips(args)
    if args.drop:
        clips = {k: m.prune(args.drop) for k, m in clips.items()}
    if name.endswith(".glb"):
        write_glb(clips, args.output)
        first = next(iter(clips.values()))
        mesh = "its skinned mesh" if first.skeleton.mesh is not None else "a generated bone mesh"
        print(f"wrote {args.output}: {len(clips)} clip(s), {first.num_joints} joints, {mesh}, metres")
        return 0
    units = "metres" if name.endswith(".npz") or args.out_scale == 1 else f"metres x {args.out_scale:g}"
    options = {} if name.endswith(".npz") else {"scale": args.out_scale, "order": args.order}
    taken: set[Path] = set()
    for clip, motion in clips.items():
        out = args.output if len(clips) == 1 else clip_file_name(args.output, clip)
        k = 2
        while out in taken:  # two clips with the same short name (e.g. "Lever_On" and "Armature|Lever_On")
            out = clip_file_name(args.output, f"{clip.split('|')[-1]}_{k}")
            k += 1
        taken.add(out)
        motion.save(out, **options)
        print(
            f"wrote {out}: {motion.num_frames} frames @ {motion.fps:g} fps, "
            f"{motion.num_joints} joints, lengths in {units}"
        )
    return 0
