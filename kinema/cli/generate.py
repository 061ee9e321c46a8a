"""`kinema generate PROMPT`: text (+ constraints, timelines) -> BVH / npz files.

Every argument is checked before the model is loaded and the output paths before anything is
generated, so a mistake costs no generation time. When ``--constraints`` points into a Kimodo example
folder (a Kimodo ``meta.json`` next to the file), the prompt or timeline, seconds, seed, steps, samples
and guidance the command line leaves out are taken from that meta.json (one line says which).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import (
    add_grounding_arguments,
    finite_float,
    grounding_overrides,
    non_negative_float,
    non_negative_int,
    positive_float,
    positive_int,
    sample_paths,
    seed,
)

#: Defaults of the arguments a Kimodo meta.json can fill (their argparse default is None = "not given").
DEFAULT_SECONDS = 5.0
DEFAULT_SEED = 0
DEFAULT_SAMPLES = 1
#: DDIM steps of --preview: 0.18 s per prompt-only 5-s clip of sampling, about half of what 5 steps lose
#: against 50 in FID, skate, jerk and end-effector error recovered (docs/speed.md)
PREVIEW_STEPS = 10


def register(sub) -> None:
    p = sub.add_parser("generate", help="generate motion from text and constraints")
    p.add_argument("prompt", nargs="?", default=None, help='e.g. "A person walks forward, then waves." ("" = no text)')
    p.add_argument("--seconds", type=positive_float, help=f"duration (single prompt; default {DEFAULT_SECONDS:g})")
    p.add_argument("--timeline", type=Path, help="JSON list of {prompt, seconds} segments (overrides PROMPT)")
    p.add_argument("--constraints", type=Path, help="constraints JSON (see docs/constraints.md); a Kimodo meta.json "
                   "next to it fills the settings not given here")
    p.add_argument("--constraints-fps", type=positive_float, metavar="FPS",
                   help="frame rate the constraint file's frame_indices are at (default: the file's 'fps', "
                        "Kimodo's 30 next to a Kimodo meta.json, else the model's)")
    p.add_argument("--samples", type=positive_int,
                   help=f"number of motions (different noise; default {DEFAULT_SAMPLES}); with more than one, "
                        "the files get _00, _01, ... before the extension (out/motion_00.bvh, ...)")
    p.add_argument("--steps", type=positive_int, help="DDIM steps (default: the model's setting; at most its "
                   "trained diffusion steps)")
    p.add_argument("--preview", action="store_true", help=f"fast draft: {PREVIEW_STEPS} DDIM steps (about 0.2 s "
                   "per 5-s clip of sampling; quality vs steps in docs/speed.md); not with --steps")
    p.add_argument("--seed", type=seed, help=f"random seed, 0 to 2**64 - 1 (default {DEFAULT_SEED})")
    p.add_argument("--guidance", type=non_negative_float, nargs=2, metavar=("W_TEXT", "W_CONSTR"),
                   help="separated guidance weights, finite and >= 0 (default: the model's setting)")
    p.add_argument("--heading", type=finite_float, default=0.0,
                   help="first-frame facing in degrees about +Y (0 = +Z)")
    p.add_argument("--model", default="default", help="'default' (shipped), 'creatures' (any rig; shipped) or a "
                                                      "run/checkpoint folder")
    p.add_argument("--rig", help="any-rig models: a GLB/glTF or BVH file to animate, or a training rig id "
                                 "(leave out to list them); a .glb output keeps the rig's skinned mesh")
    p.add_argument("--out", type=Path, default=Path("out/motion.bvh"),
                   help=".bvh, .bvh.gz, .npz or .glb (with a generated bone mesh); default out/motion.bvh; "
                        "with --samples N > 1: OUT_00.bvh, OUT_01.bvh, ...")
    p.add_argument("--fps", type=positive_float, help="resample the output, keeping its duration "
                   "(default: the model's fps)")
    p.add_argument("--no-postprocess", action="store_true", help="raw model output (no foot lock / IK)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars (quiet stderr)")
    p.add_argument("--objective-steps", type=non_negative_int, metavar="N",
                   help="noise-optimisation iterations for the constraints file's objectives (default 12; "
                   "docs/objectives.md)")
    p.add_argument("--keyjoint-model", metavar="MODEL",
                   help="two-stage control: 'default' (the shipped keyjoint model) or a keyjoint model folder "
                        "plans pelvis, head, hands and feet from the constraints first, then the body follows "
                        "(docs/constraints.md; one prompt up to 10 s, no objectives)")
    add_grounding_arguments(p)
    p.add_argument("--threads", type=positive_int, help="CPU threads for torch (default: KINEMA_THREADS, else "
                   "2 on a quiet machine and 1 on a busy one; see docs/speed.md)")
    p.set_defaults(func=run)


def _from_kimodo_meta(args: argparse.Namespace):
    """Fill the arguments the user left out (None) from a Kimodo meta.json next to ``--constraints``.

    Returns ``(meta path, names filled)`` or ``(None, [])``; ``args.prompt`` may become a timeline list.
    """
    from kinema.constraints import find_kimodo_meta, read_kimodo_meta
    from kinema.errors import KinemaError

    path = None if args.constraints is None else find_kimodo_meta(args.constraints)
    if path is None:
        return None, []
    meta = read_kimodo_meta(path)
    filled = []
    if args.prompt is None and args.timeline is None:
        what = meta.prompt_or_timeline()
        if not isinstance(what, str) and args.seconds is not None:
            raise KinemaError(f"--seconds: {path} holds a timeline of {len(meta.segments)} prompts with their own "
                              "durations; leave out --seconds, or give a PROMPT or --timeline")
        args.prompt = what
        filled.append("prompt" if isinstance(what, str) else "timeline")
    if args.seconds is None and args.timeline is None and isinstance(args.prompt, str):
        args.seconds = meta.seconds
        filled.append("seconds")
    for name, value in (("seed", meta.seed), ("steps", meta.steps), ("samples", meta.samples)):
        if getattr(args, name) is None and value is not None:
            setattr(args, name, value)
            filled.append(name)
    if args.guidance is None and meta.guidance is not None:
        args.guidance = meta.guidance
        filled.append("guidance")
    return path, filled


def _check_inputs(args: argparse.Namespace) -> None:
    """Output suffix, constraint and timeline files: checked before anything is loaded."""
    from kinema.errors import KinemaError
    from kinema.human.keyjoint_planning import KeyjointPlanner
    from kinema.objectives.io import load_objectives
    from kinema.pipeline.timeline import parse_timeline

    if args.preview:
        if args.steps is not None:
            raise KinemaError("--preview sets the DDIM steps (10): give either --preview or --steps")
        args.steps = PREVIEW_STEPS
    suffix = args.out.name.lower()
    if not suffix.endswith((".bvh", ".bvh.gz", ".npz", ".glb")):
        raise KinemaError(f"{args.out}: output must end in .bvh, .bvh.gz, .npz or .glb")
    if args.constraints is not None and not args.constraints.is_file():
        raise KinemaError(f"{args.constraints}: no such constraints file")
    if args.constraints is not None:
        load_objectives(args.constraints)  # objective syntax errors before the model loads
    if args.keyjoint_model is not None:
        KeyjointPlanner.check(args.keyjoint_model)
    if args.timeline is not None:
        if args.timeline.suffix.lower() != ".json":
            raise KinemaError(f"{args.timeline}: a timeline must be a .json file")
        if not args.timeline.is_file():
            raise KinemaError(f"{args.timeline}: no such timeline file")
        parse_timeline(args.timeline)  # a mistake in it fails now, not after loading the model


def run(args: argparse.Namespace) -> int:
    import math

    from kinema.cli.generate_anyrig import run_anyrig
    from kinema.cli.objective_table import objective_table
    from kinema.cli.report import grounding_lines, print_warnings, residual_table, use_plain_warnings
    from kinema.diffusion.guidance import Guidance
    from kinema.errors import KinemaError
    from kinema.generate import load_model, resolve_model_path
    from kinema.io.atomic import check_output_path
    from kinema.model.anyrig.loading import is_anyrig_checkpoint
    from kinema.runtime import configure_threads

    use_plain_warnings()
    model_path = resolve_model_path(args.model)
    if is_anyrig_checkpoint(model_path):  # a model for any rig: its own options (kinema.cli.generate_anyrig)
        if grounding_overrides(args):
            raise KinemaError(f"--grounding: the any-rig model {args.model!r} keeps no training captions to ground "
                              "prompts on")
        return run_anyrig(args, model_path)
    if args.rig is not None:
        raise KinemaError(f"--rig: the model {args.model!r} is for one skeleton; use --model creatures for any rig")
    _check_inputs(args)
    configure_threads(args.threads)
    meta_path, filled = _from_kimodo_meta(args)
    samples = DEFAULT_SAMPLES if args.samples is None else args.samples
    outputs = sample_paths(args.out, samples)
    for path in outputs:  # before loading the model and generating: a bad --out costs nothing
        check_output_path(path)
    if filled:
        print(f"using {', '.join(filled)} from Kimodo {meta_path} (give them on the command line to override)")
    model = load_model(args.model, text_cache=Path("cache/text"))
    max_steps = model.loaded.sampler.num_train_steps
    if args.steps is not None and args.steps > max_steps:
        source = f" (from {meta_path})" if "steps" in filled else ""
        raise KinemaError(f"--steps {args.steps}{source}: at most {max_steps}, the model's trained diffusion steps")
    if args.timeline is not None:
        what, seconds = str(args.timeline), None
    else:
        what = "" if args.prompt is None else args.prompt
        seconds = args.seconds if args.seconds is not None else (DEFAULT_SECONDS if isinstance(what, str) else None)
    guidance = args.guidance
    if guidance is not None and not isinstance(guidance, Guidance):
        guidance = tuple(guidance)
    extra = {} if args.constraints_fps is None else {"constraints_fps": args.constraints_fps}
    motions = model.generate(
        what, seconds=seconds, constraints=args.constraints, samples=samples, steps=args.steps,
        guidance=guidance, seed=DEFAULT_SEED if args.seed is None else args.seed,
        postprocess=not args.no_postprocess, heading=math.radians(args.heading), progress=not args.no_progress,
        objective_steps=args.objective_steps, keyjoint_model=args.keyjoint_model,
        grounding=grounding_overrides(args) or None, **extra,
    )
    for motion, path in zip(motions, outputs, strict=True):
        if args.fps is not None:
            motion = motion.resample(args.fps, keep_duration=True)
        motion.save(path)
        print(f"wrote {path}: {motion.duration:.2f} s, {motion.num_frames} frames @ {motion.fps:g} fps, "
              f"{motion.num_joints} joints (lengths in metres)")
    rep = motions.report
    print(f"generated {len(motions)} motion(s), {rep.segments} segment(s), {rep.steps} DDIM steps in "
          f"{rep.seconds:.2f} s")
    for line in grounding_lines(rep.prompts):
        print(line)
    table = residual_table(rep.residuals)
    if table:
        print(table)
    table = objective_table(rep.objectives)
    if table:
        print(table)
    print_warnings(rep.warnings)
    return 0
