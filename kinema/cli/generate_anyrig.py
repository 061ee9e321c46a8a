"""`kinema generate PROMPT --model creatures --rig RIG`: text (+ constraints) -> motion on any rig.

Used by `kinema generate` when ``--model`` names an any-rig model. ``--rig`` is a GLB/glTF or BVH file
(a GLB output keeps that rig's skinned mesh) or the id of a training rig; without ``--rig`` the known
rigs are listed. ``--timeline`` is a JSON list of ``{prompt, seconds}`` segments, as for the
human model. ``--constraints`` is a JSON list (kinema.generate.anyrig_constraints.read_constraints).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

SUFFIXES = (".glb", ".bvh", ".bvh.gz", ".npz")


def list_rigs(model) -> str:
    rows = [f"{'rig':<40} {'joints':>6}  files"]
    for rid, joints, files in model.known_rigs():
        rows.append(f"{rid:<40} {joints:>6}  {', '.join(files[:3])}{' ...' if len(files) > 3 else ''}")
    return "\n".join(rows)


def run_anyrig(args: argparse.Namespace, path: Path) -> int:
    from kinema.errors import KinemaError
    from kinema.generate.anyrig_constraints import read_constraints
    from kinema.generate.api import load_model
    from kinema.generate.timeline import parse_timeline
    from kinema.io.atomic import check_output_path

    what = args.prompt or ""
    if args.timeline is not None:  # checked before the model loads; it overrides PROMPT and --seconds
        if args.timeline.suffix.lower() != ".json" or not args.timeline.is_file():
            raise KinemaError(f"{args.timeline}: no such timeline file (a .json list of {{prompt, seconds}})")
        parse_timeline(args.timeline)
        what = str(args.timeline)
    if args.rig is not None and not args.out.name.lower().endswith(SUFFIXES):
        raise KinemaError(f"{args.out}: output must end in {', '.join(SUFFIXES)}")
    constraints = read_constraints(args.constraints) if args.constraints is not None else []
    samples = args.samples or 1
    outputs = _outputs(args.out, samples)
    if args.rig is not None:
        for out in outputs:
            check_output_path(out)
    model = load_model(path, text_cache=Path("cache/text"))
    if args.rig is None:
        print(list_rigs(model))
        if what:
            raise KinemaError(f"the any-rig model {args.model!r} needs --rig (a GLB/BVH file or a rig id listed above)")
        return 0
    guidance = None if args.guidance is None else tuple(args.guidance)
    res = model.generate(
        what,
        rig=args.rig,
        seconds=args.seconds or 4.0,
        constraints=constraints,
        samples=samples,
        steps=args.steps,
        seed=args.seed or 0,
        guidance=guidance,
        heading=math.radians(args.heading),
        postprocess=not args.no_postprocess,
    )
    for motion, out in zip(res, outputs, strict=True):
        if args.fps is not None:
            motion = motion.resample(args.fps, keep_duration=True)
        motion.save(out)
        print(
            f"wrote {out}: {motion.duration:.2f} s, {motion.num_frames} frames @ {motion.fps:g} fps, "
            f"{motion.num_joints} joints"
        )
    rep = res.report
    print(
        f"generated {len(res)} motion(s) on {rep.joints} joints, {rep.segments} segment(s), {rep.windows} window(s), "
        f"{rep.steps} DDIM steps in {rep.seconds:.2f} s"
    )
    if rep.residuals_cm:
        print(f"constraint error after post-processing: max {max(rep.residuals_cm):.2f} cm")
    for w in rep.warnings:
        print(f"warning: {w}")
    return 0


def _outputs(out: Path, n: int) -> list[Path]:
    if n == 1:
        return [out]
    name = out.name
    stem, suffix = (name[: -len(".bvh.gz")], ".bvh.gz") if name.lower().endswith(".bvh.gz") else (out.stem, out.suffix)
    return [out.with_name(f"{stem}_{i:02d}{suffix}") for i in range(n)]
