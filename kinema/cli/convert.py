"""`kinema convert IN OUT`: motion files between BVH (.bvh/.bvh.gz) and the kinema npz contract.

Units: BVH lengths are read in the file's unit times ``--in-scale`` (0.01 for centimetre files such as
Bandai Namco) and written in metres times ``--out-scale`` (1 = metres, what Blender's importer expects
at scale 1.0; 100 = centimetres). npz files are always metres, Y up (see docs/formats.md).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import positive_float


def register(sub) -> None:
    """Add the `convert` sub-command to the top-level parser."""
    p = sub.add_parser("convert", help="convert motion files: BVH -> BVH, BVH -> npz, npz -> BVH")
    p.add_argument("input", type=Path, help=".bvh, .bvh.gz or .npz")
    p.add_argument("output", type=Path, help=".bvh, .bvh.gz or .npz")
    p.add_argument("--in-scale", type=positive_float, default=1.0,
                   help="multiply BVH input lengths by this to get metres (0.01 for centimetres)")
    p.add_argument("--out-scale", type=positive_float, default=1.0,
                   help="BVH output lengths = metres x this (1 = metres, 100 = centimetres)")
    p.add_argument("--order", default="ZXY", help="Euler channel order of BVH output (default ZXY)")
    p.add_argument("--drop", nargs="*", default=[], metavar="JOINT",
                   help="joints to prune (folded into their children), e.g. joint_Root")
    p.add_argument("--fps", type=positive_float, help="resample to this frame rate")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from kinema.errors import KinemaError
    from kinema.io import load_motion
    from kinema.io.atomic import check_output_path

    if not args.input.exists():
        raise KinemaError(f"{args.input}: no such file")
    name = args.output.name.lower()
    if not (name.endswith(".npz") or name.endswith(".bvh") or name.endswith(".bvh.gz")):
        raise KinemaError(f"{args.output}: unknown motion format (use .bvh, .bvh.gz or .npz)")
    check_output_path(args.output)
    motion = load_motion(args.input, scale=args.in_scale)
    if args.drop:
        motion = motion.prune(args.drop)
    if args.fps is not None:
        motion = motion.resample(args.fps)
    if name.endswith(".npz"):
        motion.save(args.output)
        units = "metres"
    else:
        motion.save(args.output, scale=args.out_scale, order=args.order)
        units = "metres" if args.out_scale == 1 else f"metres x {args.out_scale:g}"
    print(f"wrote {args.output}: {motion.num_frames} frames @ {motion.fps:g} fps, "
          f"{motion.num_joints} joints, lengths in {units}")
    return 0
