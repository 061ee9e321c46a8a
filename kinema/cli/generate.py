"""`kinema generate PROMPT`: text (+ constraints, timelines) -> BVH / npz files.

Every argument is checked before the model is loaded and the output paths before anything is
generated, so a mistake costs no generation time. When ``--constraints`` points into a Kimodo example
folder (a Kimodo ``meta.json`` next to the file), the prompt or timeline, seconds, seed, steps, samples
and guidance the command line leaves out are taken from that meta.json (one line says which).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from kinema.cli._args import add_precision_argument, positive_int, sample_paths
from kinema.cli.request_args import add_request_arguments, request_from_args
from kinema.runtime import text_cache_dir

#: Defaults of the arguments a Kimodo meta.json can fill (their argparse default is None = "not given").
DEFAULT_SECONDS = 5.0
DEFAULT_SEED = 0
DEFAULT_SAMPLES = 1
#: DDIM steps of --preview: 0.18 s per prompt-only 5-s clip of sampling, about half of what 5 steps lose
#: against 50 in FID, skate, jerk and end-effector error recovered (docs/speed.md)
PREVIEW_STEPS = 10


def register(sub) -> None:
    p = sub.add_parser("generate", help="generate motion from text and constraints, for any model and rig")
    add_request_arguments(p)  # every GenerationRequest field (kinema.cli.request_args)
    p.add_argument("--preview", action="store_true", help=f"fast draft: {PREVIEW_STEPS} DDIM steps (about 0.2 s "
                   "per 5-s clip of sampling; quality vs steps in docs/speed.md); not with --steps")
    p.add_argument("--model", help="'default' (the human model, shipped), 'creatures' (any rig; shipped) or a "
                                   "run/checkpoint folder; without it: 'default', or 'creatures' for a --rig that "
                                   "is no humanoid (a humanoid character gets the human model, retargeted)")
    p.add_argument("--out", type=Path, default=Path("out/motion.bvh"),
                   help=".bvh, .bvh.gz, .npz or .glb (a rig's GLB keeps its skinned mesh), .fbx for a character "
                        "(through Blender), .csv with --robot; default out/motion.bvh; with --samples N > 1: "
                        "OUT_00.bvh, OUT_01.bvh, ...")
    p.add_argument("--no-progress", action="store_true", help="no progress bars (quiet stderr)")
    p.add_argument("--threads", type=positive_int, help="CPU threads for torch (default: KINEMA_THREADS, else "
                   "2 on a quiet machine and 1 on a busy one; see docs/speed.md)")
    add_precision_argument(p)
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
    from kinema.input_files import check_input_file
    from kinema.objectives.io import load_objectives
    from kinema.pipeline.timeline import parse_timeline

    if args.preview:
        if args.steps is not None:
            raise KinemaError("--preview sets the DDIM steps (10): give either --preview or --steps")
        args.steps = PREVIEW_STEPS
    suffix = args.out.name.lower()
    if args.robot is not None and not suffix.endswith((".csv", ".npz")):
        raise KinemaError(f"{args.out}: a robot's motion is written as .csv (MuJoCo qpos table) or .npz")
    if not suffix.endswith((".bvh", ".bvh.gz", ".npz", ".glb", ".csv", ".fbx")):
        raise KinemaError(f"{args.out}: output must end in .bvh, .bvh.gz, .npz or .glb (.fbx with a --rig character, "
                          ".csv with --robot)")
    if suffix.endswith(".fbx") and args.rig is None:
        raise KinemaError(f"{args.out}: FBX output is for a character: give --rig CHARACTER (GLB, BVH or FBX)")
    if suffix.endswith(".csv") and args.robot is None:
        raise KinemaError(f"{args.out}: .csv holds a robot's joint angles; add --robot g1 (or an MJCF file)")
    if args.constraints is not None:
        check_input_file(args.constraints, "constraints file")
    if args.constraints is not None:
        load_objectives(args.constraints)  # objective syntax errors before the model loads
    if args.keyjoint_model not in (None, "none"):
        KeyjointPlanner.check(args.keyjoint_model)
    if args.timeline is not None:
        if args.timeline.suffix.lower() != ".json":
            raise KinemaError(f"{args.timeline}: a timeline must be a .json file")
        check_input_file(args.timeline, "timeline file")
        parse_timeline(args.timeline)  # a mistake in it fails now, not after loading the model


def run(args: argparse.Namespace) -> int:
    from kinema.atomic_files import check_output_path
    from kinema.cli.report import print_report, use_plain_warnings
    from kinema.errors import KinemaError
    from kinema.generate import load_model
    from kinema.retarget import save_character_motion
    from kinema.runtime import configure_threads

    use_plain_warnings()
    _check_inputs(args)
    configure_threads(args.threads)
    meta_path, filled = _from_kimodo_meta(args)
    if filled:
        print(f"using {', '.join(filled)} from Kimodo {meta_path} (give them on the command line to override)")
    if args.timeline is not None or not isinstance(args.prompt, str | None):
        # --timeline overrides PROMPT and --seconds (its segments carry their own)
        args.timeline, args.prompt, args.seconds = args.timeline or args.prompt, None, None
    request = request_from_args(args)
    outputs = sample_paths(args.out, request.samples)
    for path in outputs:  # before loading the model and generating: a bad --out costs nothing
        check_output_path(path)
    model = load_model(_model_name(args), text_cache=text_cache_dir())
    if request.steps is not None and request.steps > model.max_steps:
        source = f" (from {meta_path})" if "steps" in filled else ""
        raise KinemaError(f"--steps {request.steps}{source}: at most {model.max_steps}, the model's trained "
                          "diffusion steps")
    if request.rig is None and model.needs_rig:
        print(list_rigs(model))
        if request.prompt or request.timeline is not None:
            raise KinemaError(f"the any-rig model {model.path.name!r} needs --rig (a GLB/BVH file or a rig id listed "
                              "above)")
        return 0
    result = model.generate(request, progress=not args.no_progress)
    if result.robot_motions:
        for robot_motion, path in zip(result.robot_motions, outputs, strict=True):
            robot_motion.save(path)
            print(f"wrote {path}: {robot_motion.num_frames} frames @ {robot_motion.fps:g} fps of {request.robot} "
                  f"({len(robot_motion.joint_names)} hinge joints, radians, Z up)")
    else:
        for motion, path in zip(result, outputs, strict=True):
            if request.fps is not None:
                motion = motion.resample(request.fps, keep_duration=True)
            save_character_motion(motion, path)  # GLB, BVH, npz as Motion.save; FBX through Blender
            print(f"wrote {path}: {motion.duration:.2f} s, {motion.num_frames} frames @ {motion.fps:g} fps, "
                  f"{motion.num_joints} joints (lengths in metres)")
    print_report(result)
    return 0


def _model_name(args: argparse.Namespace) -> str:
    """``--model``, else the human model, or the model for any rig when ``--rig`` is a file that is no
    humanoid (said in one line)."""
    from kinema.retarget import load_character

    if args.model is not None:
        return args.model
    if args.rig is None or not Path(args.rig).is_file():
        return "default"
    character = load_character(args.rig)
    if character.is_humanoid:
        print(f"{args.rig}: a humanoid: generating with the human model and retargeting onto it")
        return "default"
    print(f"{args.rig}: not a humanoid: generating with the model for any rig ('creatures')")
    return "creatures"


def list_rigs(model) -> str:
    """The rigs a model drives without a rig file, one line each."""
    rows = [f"{'rig':<40} {'joints':>6}  files"]
    for r in model.rigs():
        rows.append(f"{r.name:<40} {len(r.joints):>6}  {', '.join(r.files[:3])}{' ...' if len(r.files) > 3 else ''}")
    return "\n".join(rows)
