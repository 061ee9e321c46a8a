"""`kinema generate PROMPT`: text (+ constraints, timelines) -> BVH / npz files."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub) -> None:
    p = sub.add_parser("generate", help="generate motion from text and constraints")
    p.add_argument("prompt", nargs="?", default="", help='e.g. "A person walks forward, then waves." ("" = no text)')
    p.add_argument("--seconds", type=float, default=5.0, help="duration (single prompt; default 5)")
    p.add_argument("--timeline", type=Path, help="JSON list of {prompt, seconds} segments (overrides PROMPT)")
    p.add_argument("--constraints", type=Path, help="constraints JSON (see docs/constraints.md)")
    p.add_argument("--samples", type=int, default=1, help="number of motions (different noise)")
    p.add_argument("--steps", type=int, help="DDIM steps (default: the model's setting)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--guidance", type=float, nargs=2, metavar=("W_TEXT", "W_CONSTR"),
                   help="separated guidance weights (default: the model's setting)")
    p.add_argument("--heading", type=float, default=0.0, help="first-frame facing in degrees about +Y (0 = +Z)")
    p.add_argument("--model", default="default", help="'default' (shipped) or a run/checkpoint folder")
    p.add_argument("--out", type=Path, default=Path("out/motion.bvh"), help=".bvh, .bvh.gz or .npz")
    p.add_argument("--fps", type=float, help="resample the output (default: the model's fps)")
    p.add_argument("--no-postprocess", action="store_true", help="raw model output (no foot lock / IK)")
    p.add_argument("--no-progress", action="store_true")
    p.set_defaults(func=run)


def _outputs(out: Path, n: int) -> list[Path]:
    if n == 1:
        return [out]
    name = out.name
    stem, suffix = (name[: -len(".bvh.gz")], ".bvh.gz") if name.lower().endswith(".bvh.gz") else (out.stem, out.suffix)
    return [out.with_name(f"{stem}_{i:02d}{suffix}") for i in range(n)]


def run(args: argparse.Namespace) -> int:
    import math

    from kinema.errors import KinemaError
    from kinema.generate.api import load_model

    if args.samples < 1:
        raise KinemaError("--samples must be at least 1")
    if args.steps is not None and args.steps < 1:
        raise KinemaError("--steps must be at least 1")
    suffix = args.out.name.lower()
    if not (suffix.endswith(".bvh") or suffix.endswith(".bvh.gz") or suffix.endswith(".npz")):
        raise KinemaError(f"{args.out}: output must end in .bvh, .bvh.gz or .npz")
    if args.constraints is not None and not args.constraints.exists():
        raise KinemaError(f"{args.constraints}: no such constraints file")
    model = load_model(args.model, text_cache=Path("cache/text"))
    what = str(args.timeline) if args.timeline else args.prompt
    motions = model.generate(
        what, seconds=args.seconds, constraints=args.constraints, samples=args.samples, steps=args.steps,
        guidance=tuple(args.guidance) if args.guidance else None, seed=args.seed,
        postprocess=not args.no_postprocess, heading=math.radians(args.heading), progress=not args.no_progress,
    )
    for motion, path in zip(motions, _outputs(args.out, len(motions)), strict=True):
        if args.fps:
            motion = motion.resample(args.fps)
        motion.save(path)
        print(f"wrote {path}: {motion.duration:.2f} s, {motion.num_frames} frames @ {motion.fps:g} fps, "
              f"{motion.num_joints} joints (lengths in metres)")
    rep = motions.report
    print(f"generated {len(motions)} motion(s), {rep.segments} segment(s) in {rep.seconds:.2f} s")
    for i, r in enumerate(rep.residuals):
        if r:
            print(f"constraint residuals (sample {i}): " + ", ".join(f"{k} {v}" for k, v in r.items()))
    return 0
