"""`kinema generate PROMPT --model creatures --rig RIG`: text (+ constraints) -> motion on any rig.

Used by `kinema generate` when ``--model`` names an any-rig model. ``--rig`` is a GLB/glTF or BVH file
(a GLB output keeps that rig's skinned mesh) or the id of a training rig; without ``--rig`` the known
rigs are listed. ``--timeline`` is a JSON list of ``{prompt, seconds}`` segments, as for the
human model. ``--constraints`` is the any-rig JSON list (kinema.anyrig.constraints.read_constraints)
or a docs/constraints.md file (world frame; kinema.anyrig.world), checked against the rig.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from kinema.cli._args import sample_paths

SUFFIXES = (".glb", ".bvh", ".bvh.gz", ".npz")


def list_rigs(model) -> str:
    rows = [f"{'rig':<40} {'joints':>6}  files"]
    for rid, joints, files in model.known_rigs():
        rows.append(f"{rid:<40} {joints:>6}  {', '.join(files[:3])}{' ...' if len(files) > 3 else ''}")
    return "\n".join(rows)


def run_anyrig(args: argparse.Namespace, path: Path) -> int:
    from kinema.errors import KinemaError
    from kinema.generate import load_model
    from kinema.io.atomic import check_output_path

    what = _prompt(args)
    if args.rig is not None and not args.out.name.lower().endswith(SUFFIXES):
        raise KinemaError(f"{args.out}: output must end in {', '.join(SUFFIXES)}")
    if args.constraints is not None and not args.constraints.is_file():
        raise KinemaError(f"{args.constraints}: no such constraints file")
    samples = args.samples or 1
    outputs = sample_paths(args.out, samples)
    if args.rig is not None:
        for out in outputs:
            check_output_path(out)
    model = load_model(path, text_cache=Path("cache/text"))
    if args.rig is None:
        print(list_rigs(model))
        if what:
            raise KinemaError(f"the any-rig model {args.model!r} needs --rig (a GLB/BVH file or a rig id listed above)")
        return 0
    res, notes = _generate(model, args, what, samples)
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
    if rep.residuals_deg:
        print(f"rotation target error after post-processing: max {max(rep.residuals_deg):.2f} deg")
    for w in [*notes, *rep.warnings]:
        print(f"warning: {w}")
    return 0


def _prompt(args: argparse.Namespace):
    """PROMPT, or the ``--timeline`` file (checked before the model loads; it overrides PROMPT and --seconds)."""
    from kinema.errors import KinemaError
    from kinema.pipeline.timeline import parse_timeline

    if args.timeline is None:
        return args.prompt or ""
    if args.timeline.suffix.lower() != ".json" or not args.timeline.is_file():
        raise KinemaError(f"{args.timeline}: no such timeline file (a .json list of {{prompt, seconds}})")
    parse_timeline(args.timeline)
    return str(args.timeline)


def _generate(model, args: argparse.Namespace, what, samples: int):
    """The motions for ``what`` on ``--rig`` with ``--constraints`` (an any-rig list, or a
    docs/constraints.md file in the world frame: kinema.anyrig.world), and notes of what the
    model left out. The constraints are checked against the rig before anything is generated."""
    from kinema.anyrig.world import generate_world, load_constraints_file

    rig = model.resolve_rig(args.rig)
    seconds = args.seconds or 4.0
    own, world = [], []
    if args.constraints is not None:
        frames = model.frames(what, seconds)
        own, world = load_constraints_file(
            args.constraints, rig.skeleton, model.fps, frames, source_fps=args.constraints_fps
        )
    kw = dict(
        seconds=seconds,
        steps=args.steps,
        seed=args.seed or 0,
        guidance=None if args.guidance is None else tuple(args.guidance),
        heading=math.radians(args.heading),
        postprocess=not args.no_postprocess,
    )
    if world:
        res, notes, _ = generate_world(model, what, rig=rig, constraints=world, samples=samples, **kw)
        return res, notes
    return model.generate(what, rig=rig, constraints=own, samples=samples, **kw), []
